"""Scenes: YAML specs → MuJoCo models, world-frame meshes, ground-truth labels, randomized layouts."""

from hsi_planning.scene.furniture import SupportSurface
from hsi_planning.scene.geometry import (
    articulated_parts,
    container_of,
    handle_position,
    object_names,
    opening_axis,
    scene_meshes,
    support_of,
    supports_in,
)
from hsi_planning.scene.labels import Label, LabelTable, scene_labels
from hsi_planning.scene.layout import LayoutConfig, generate_layouts
from hsi_planning.scene.mjcf import build_mjcf, write_mjcf
from hsi_planning.scene.model import moved_object, object_pose, support_surface, support_surfaces
from hsi_planning.scene.reach import ReachConfig, exposing_fraction, target_reachable
from hsi_planning.scene.spec import CameraSpec, FurnitureSpec, ObjectSpec, SceneSpec, load_scene_spec

__all__ = [
    "CameraSpec",
    "FurnitureSpec",
    "Label",
    "LabelTable",
    "LayoutConfig",
    "ObjectSpec",
    "ReachConfig",
    "SceneSpec",
    "SupportSurface",
    "articulated_parts",
    "build_mjcf",
    "container_of",
    "exposing_fraction",
    "generate_layouts",
    "handle_position",
    "load_scene_spec",
    "moved_object",
    "object_names",
    "object_pose",
    "opening_axis",
    "scene_labels",
    "scene_meshes",
    "support_of",
    "support_surface",
    "support_surfaces",
    "supports_in",
    "target_reachable",
    "write_mjcf",
]
