"""World-frame meshes of a scene and geometric queries planners need (supports, openings, handles).

:func:`scene_meshes` turns the very primitives that :func:`~hsi_planning.scene.mjcf.build_mjcf` writes
into trimesh meshes, one per body (label), at the rest configuration (doors and drawers closed).
"""

from __future__ import annotations

import numpy as np
import trimesh
from numpy.typing import NDArray

from hsi_planning.errors import SceneError
from hsi_planning.scene.furniture import SupportSurface, opening_direction
from hsi_planning.scene.model import scene_bodies, support_surface, support_surfaces
from hsi_planning.scene.spec import SceneSpec


def scene_meshes(spec: SceneSpec) -> dict[str, trimesh.Trimesh]:
    """One world-frame mesh per body, keyed by label name (the floor is a 10 m slab, top at z = 0)."""
    return {body.name: body.mesh() for body in scene_bodies(spec)}


def object_names(spec: SceneSpec) -> list[str]:
    """Names of the free objects, in spec order."""
    return [o.name for o in spec.objects]


def support_of(spec: SceneSpec, obj: str) -> SupportSurface:
    """The support surface object ``obj`` rests on."""
    return support_surface(spec, spec.object_by_name(obj).on)


def container_of(spec: SceneSpec, obj: str) -> str:
    """Name of the furniture holding object ``obj`` (e.g. ``cabinet1``)."""
    return support_of(spec, obj).furniture


def opening_axis(spec: SceneSpec, name: str) -> NDArray[np.float64]:
    """World unit vector (3,) pointing out of the opening of ``name``.

    ``name`` may be furniture, a support/part (``shelf1/board2``, ``drawer_unit1/drawer1``) or an object
    (its container). Cabinets, drawer units and shelves open along their front normal (a drawer slides
    out along it); tables and counters are open above (+z).
    """
    furniture = {f.name: f for f in spec.furniture}
    if name in {o.name for o in spec.objects}:
        name = container_of(spec, name)
    base = name.split("/", 1)[0]
    if base not in furniture:
        valid = sorted([*furniture, *(o.name for o in spec.objects)])
        raise SceneError(f"opening_axis: {name!r} is no furniture, part or object; valid: {valid}")
    return opening_direction(furniture[base])


def handle_position(spec: SceneSpec, part: str) -> NDArray[np.float64]:
    """World position (3,) [m] of the handle bar centre of a door or drawer (closed)."""
    for body in scene_bodies(spec):
        if body.name == part and "handle_x" in body.extras:
            local = np.array([body.extras["handle_x"], body.extras["handle_y"], body.extras["handle_z"], 1.0])
            return np.asarray((body.pose @ local)[:3], dtype=float)
    parts = [b.name for b in scene_bodies(spec) if "handle_x" in b.extras]
    raise SceneError(f"handle_position: {part!r} has no handle; valid: {parts}")


def articulated_parts(spec: SceneSpec) -> list[str]:
    """Names of doors and drawers (bodies with a hinge or slide joint)."""
    return [b.name for b in scene_bodies(spec) if b.joint is not None]


def supports_in(spec: SceneSpec, furniture: str) -> list[SupportSurface]:
    """Support surfaces of one piece of furniture."""
    spec.furniture_by_name(furniture)
    return [s for s in support_surfaces(spec).values() if s.furniture == furniture]
