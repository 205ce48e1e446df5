"""Perception: labelled point clouds rendered from MuJoCo cameras, PLY files, unlabelled segmentation.

Importing this package selects a headless OpenGL backend for MuJoCo (``MUJOCO_GL``) if none is set.
"""

from hsi_planning.perception.cloud import UNLABELLED, LabelledCloud, read_ply, voxel_downsample, write_ply
from hsi_planning.perception.render import (
    NO_GEOM,
    CameraView,
    CloudConfig,
    CloudRenderer,
    body_labels,
    render_cloud,
    render_rgb,
)
from hsi_planning.perception.segment import Plane, SegmentConfig, SegmentInfo, segment_unlabelled

__all__ = [
    "NO_GEOM",
    "UNLABELLED",
    "CameraView",
    "CloudConfig",
    "CloudRenderer",
    "LabelledCloud",
    "Plane",
    "SegmentConfig",
    "SegmentInfo",
    "body_labels",
    "read_ply",
    "render_cloud",
    "render_rgb",
    "segment_unlabelled",
    "voxel_downsample",
    "write_ply",
]
