"""Scene validation: unique names, existing supports, objects inside their supports, no overlaps.

Objects are checked with their exact compound shapes: the xy convex hull of each object (its
footprint) must lie inside the usable rectangle of its support, the object must fit under the
support's ceiling, and two objects whose height intervals overlap must have disjoint footprints.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull

from hsi_planning.errors import SceneError
from hsi_planning.scene.furniture import GAP, HANDLE_STANDOFF, SupportSurface, furniture_frame
from hsi_planning.scene.model import FLOOR_NAME, object_pose_on, support_surfaces
from hsi_planning.scene.objects import object_prims
from hsi_planning.scene.spec import FurnitureSpec, ObjectKind, ObjectSpec, SceneSpec

#: Penetration tolerated between touching items (numerical noise) [m].
TOLERANCE = 1e-6


@functools.lru_cache(maxsize=512)
def _local_points(kind: ObjectKind, size: tuple[float, ...] | None, scale: float) -> NDArray[np.float64]:
    shape = ObjectSpec(name="shape", kind=kind, on="-", size=size, scale=scale)
    pts = np.concatenate([p.mesh().vertices for p in object_prims(shape)])
    pts.setflags(write=False)
    return pts


def object_points(o: ObjectSpec, pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mesh vertices (N, 3) [m] of object ``o`` placed at ``pose`` (4, 4)."""
    pts = _local_points(o.kind, o.size, o.scale)
    return np.asarray(pts @ pose[:3, :3].T + pose[:3, 3], dtype=float)


def footprint(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Counter-clockwise convex hull (K, 2) [m] of the xy projection of ``points`` (N, 3)."""
    xy = points[:, :2]
    hull = ConvexHull(xy)
    return np.asarray(xy[hull.vertices], dtype=float)


def polygon_gap(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Separation [m] of two convex polygons (K, 2) along the best separating edge normal.

    Positive: disjoint (a lower bound of their distance); negative: overlapping by that much.
    """
    best = -np.inf
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.column_stack([edges[:, 1], -edges[:, 0]])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        pa, pb = a @ normals.T, b @ normals.T
        gaps = np.maximum(pb.min(axis=0) - pa.max(axis=0), pa.min(axis=0) - pb.max(axis=0))
        best = max(best, float(gaps.max()))
    return best


def furniture_footprint(f: FurnitureSpec) -> NDArray[np.float64]:
    """Footprint rectangle (4, 2) [m] of a piece of furniture including fronts and handles."""
    w, d, _ = f.size
    front = f.thickness + GAP + HANDLE_STANDOFF + 0.006 if f.kind in ("cabinet", "drawer_unit") else 0.0
    local = np.array([[-d / 2 - front, -w / 2], [d / 2, -w / 2], [d / 2, w / 2], [-d / 2 - front, w / 2]])
    frame = furniture_frame(f)
    return np.asarray(local @ frame[:2, :2].T + frame[:2, 3], dtype=float)


def check_inside(o: ObjectSpec, support: SupportSurface, points: NDArray[np.float64]) -> None:
    """Raise :class:`SceneError` unless the object lies within its support's usable box."""
    local = (points - support.frame[:3, 3]) @ support.frame[:3, :3]
    hx, hy = support.half_extents
    over = max(float(np.abs(local[:, 0]).max() - hx), float(np.abs(local[:, 1]).max() - hy))
    if over > TOLERANCE:
        raise SceneError(
            f"object '{o.name}' sticks out of support '{support.name}' by {over * 1000:.1f} mm;"
            f" the usable area is ±{hx:.3f} m (depth) × ±{hy:.3f} m (width) around its centre,"
            f" xy={list(o.xy)}"
        )
    height = float(local[:, 2].max())
    if height > support.ceiling + TOLERANCE:
        raise SceneError(
            f"object '{o.name}' is {height:.3f} m tall but support '{support.name}' has only"
            f" {support.ceiling:.3f} m free height"
        )


def _check_names(spec: SceneSpec) -> None:
    seen: set[str] = {FLOOR_NAME}
    for name in [f.name for f in spec.furniture] + [o.name for o in spec.objects]:
        if name in seen:
            raise SceneError(f"scene '{spec.name}': name {name!r} is used twice (or is reserved: 'floor')")
        seen.add(name)
    cams = [c.name for c in spec.cameras]
    if len(set(cams)) != len(cams):
        raise SceneError(f"scene '{spec.name}': camera names {cams} are not unique")


def validate_scene(spec: SceneSpec) -> None:
    """Check a whole scene; raise :class:`SceneError` naming the first offending item."""
    if not spec.name:
        raise SceneError("scene name must not be empty")
    _check_names(spec)
    prints = [furniture_footprint(f) for f in spec.furniture]
    for i, fi in enumerate(spec.furniture):
        for j in range(i):
            if polygon_gap(prints[i], prints[j]) < -TOLERANCE:
                raise SceneError(f"furniture '{fi.name}' overlaps furniture '{spec.furniture[j].name}'")
    supports = support_surfaces(spec)
    placed: list[tuple[str, NDArray[np.float64], float, float]] = []
    for o in spec.objects:
        if o.on not in supports:
            raise SceneError(f"object '{o.name}': support {o.on!r} does not exist; valid: {list(supports)}")
        support = supports[o.on]
        pts = object_points(o, object_pose_on(o, support))
        check_inside(o, support, pts)
        poly, z0, z1 = footprint(pts), float(pts[:, 2].min()), float(pts[:, 2].max())
        for name, other, w0, w1 in placed:
            if min(z1, w1) - max(z0, w0) > TOLERANCE and polygon_gap(poly, other) < -TOLERANCE:
                raise SceneError(
                    f"object '{o.name}' overlaps object '{name}'"
                    f" by {-polygon_gap(poly, other) * 1000:.1f} mm;"
                    " move one of them (xy) so their footprints are disjoint"
                )
        placed.append((o.name, poly, z0, z1))
