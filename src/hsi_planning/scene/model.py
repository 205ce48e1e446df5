"""The resolved scene: every labelled body with its world pose and primitives, and the support surfaces.

This is the single source of truth from which the MJCF, the meshes and the labels are derived. Body
order (= label id order): ``floor``, then each furniture (carcass, boards, doors/drawers) in spec
order, then the objects in spec order.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import SceneError
from hsi_planning.scene.furniture import SupportSurface, furniture_bodies, furniture_supports
from hsi_planning.scene.objects import object_friction, object_mass, object_prims
from hsi_planning.scene.shapes import BodyPlan, box_from_bounds, pose_matrix, rot_z
from hsi_planning.scene.spec import ObjectSpec, SceneSpec

FLOOR_HALF_SIZE = 5.0  #: half size of the visible/meshed floor square [m]
FLOOR_NAME = "floor"


def support_surfaces(spec: SceneSpec) -> dict[str, SupportSurface]:
    """Every support surface of the scene, keyed by support name (spec order)."""
    out: dict[str, SupportSurface] = {}
    for f in spec.furniture:
        for s in furniture_supports(f):
            out[s.name] = s
    return out


def support_surface(spec: SceneSpec, name: str) -> SupportSurface:
    """One support surface; :class:`SceneError` lists the valid names if ``name`` is unknown."""
    supports = support_surfaces(spec)
    if name not in supports:
        raise SceneError(f"scene '{spec.name}': no support {name!r}; valid: {sorted(supports)}")
    return supports[name]


def object_pose_on(o: ObjectSpec, support: SupportSurface) -> NDArray[np.float64]:
    """World pose (4, 4) of an object's frame (bottom centre) resting on ``support`` [m]."""
    local = pose_matrix((o.xy[0], o.xy[1], 0.0), rot_z(math.radians(o.yaw)))
    return support.frame @ local


def object_pose(spec: SceneSpec, name: str) -> NDArray[np.float64]:
    """World pose (4, 4) of object ``name`` at rest [m]."""
    o = spec.object_by_name(name)
    return object_pose_on(o, support_surface(spec, o.on))


def object_body(o: ObjectSpec, support: SupportSurface) -> BodyPlan:
    """The body of a free object resting on ``support``."""
    return BodyPlan(
        name=o.name,
        semantic_class=o.kind,
        kind="object",
        pose=object_pose_on(o, support),
        prims=tuple(object_prims(o)),
        mass=object_mass(o),
        friction=object_friction(o),
    )


def floor_body() -> BodyPlan:
    """The floor: a plane at z = 0 in MuJoCo, a thin slab (top face at z = 0) as a mesh."""
    h = FLOOR_HALF_SIZE
    slab = box_from_bounds((-h, -h, -0.01), (h, h, 0.0), FLOOR_NAME, rgba=(0.5, 0.5, 0.52, 1.0))
    return BodyPlan(FLOOR_NAME, FLOOR_NAME, "floor", np.eye(4), (slab,))


def scene_bodies(spec: SceneSpec) -> list[BodyPlan]:
    """All labelled bodies in label order (floor first)."""
    bodies = [floor_body()]
    for f in spec.furniture:
        bodies += furniture_bodies(f)
    supports = support_surfaces(spec)
    bodies += [object_body(o, supports[o.on]) for o in spec.objects]
    return bodies


def moved_object(spec: SceneSpec, name: str, offset: ArrayLike) -> SceneSpec:
    """``spec`` with object ``name`` shifted on its support by the horizontal world ``offset`` (3,) [m] (its
    vertical part is dropped: the object stays on its support). Not validated
    (:func:`~hsi_planning.scene.validate.validate_scene` says whether it still fits)."""
    obj = spec.object_by_name(name)
    rot = support_surface(spec, obj.on).frame[:3, :3]
    shift = np.asarray(offset, dtype=np.float64).reshape(3)
    local = rot.T @ np.array([shift[0], shift[1], 0.0])
    new = dataclasses.replace(obj, xy=(obj.xy[0] + float(local[0]), obj.xy[1] + float(local[1])))
    return dataclasses.replace(spec, objects=tuple(new if o.name == name else o for o in spec.objects))
