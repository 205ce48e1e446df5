"""Perception: labelled point clouds rendered from MuJoCo cameras, PLY files, unlabelled segmentation.

Importing this package selects a headless OpenGL backend for MuJoCo (``MUJOCO_GL``) if none is set.
"""

from hsi_planning.perception.cloud import UNLABELLED, LabelledCloud, read_ply, voxel_downsample, write_ply
from hsi_planning.perception.labels import body_labels, geom_labels, label_maps
from hsi_planning.perception.render import (
    CloudConfig,
    CloudRenderer,
    render_cloud,
    render_rgb,
    scene_cloud,
    scene_renderer,
)
from hsi_planning.perception.segment import Plane, SegmentConfig, SegmentInfo, segment_unlabelled
from hsi_planning.perception.view import NO_GEOM, CameraView

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
    "geom_labels",
    "label_maps",
    "read_ply",
    "render_cloud",
    "render_rgb",
    "scene_cloud",
    "scene_renderer",
    "segment_unlabelled",
    "voxel_downsample",
    "write_ply",
]
