"""Signed distance to scene obstacles, for checking a wrist (sphere) path against the furniture.

Wraps an open3d :class:`RaycastingScene` over trimesh meshes: the unsigned distance and the closest
surface point come from open3d; the sign (negative inside) from the meshes' convex components
(half-space tests; scene meshes are unions of convex primitives) or, for a non-convex watertight
component, trimesh's ray-parity ``contains``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import SceneError

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class _Component:
    """One connected part of a mesh used for the inside test."""

    planes: NDArray[np.float64] | None  #: (F, 4) half-spaces n·x - d <= 0 inside (convex part), or None
    mesh: trimesh.Trimesh | None  #: non-convex watertight part (ray-parity inside test), or None
    lower: NDArray[np.float64]  #: (3,) [m] bounding-box minimum
    upper: NDArray[np.float64]  #: (3,) [m] bounding-box maximum


def _convex_planes(part: trimesh.Trimesh) -> NDArray[np.float64]:
    normals = np.asarray(part.face_normals, dtype=np.float64)
    offsets = np.einsum("ij,ij->i", normals, np.asarray(part.triangles_center, dtype=np.float64))
    planes = np.round(np.column_stack([normals, offsets]), 9)
    return np.asarray(np.unique(planes, axis=0), dtype=np.float64)


def _components(mesh: trimesh.Trimesh) -> list[_Component]:
    parts = mesh.split(only_watertight=False) if len(mesh.faces) else []
    out: list[_Component] = []
    for part in parts:
        lower, upper = (np.asarray(b, dtype=np.float64) for b in part.bounds)
        if part.is_watertight and part.is_convex:
            out.append(_Component(_convex_planes(part), None, lower, upper))
        elif part.is_watertight:
            out.append(_Component(None, part, lower, upper))
        else:
            _LOG.debug("open mesh component with %d faces: surface only (never 'inside')", len(part.faces))
    return out


class ObstacleField:
    """Signed distance [m] from points to a set of named obstacle meshes (world frame).

    Args:
        meshes: name -> trimesh mesh [m], world frame. Each name is one geometry of the field.
    """

    def __init__(
        self,
        meshes: Mapping[str, trimesh.Trimesh],
        _parts: Mapping[str, list[_Component]] | None = None,
    ) -> None:
        self._meshes = {str(k): v.copy() for k, v in meshes.items() if len(v.faces) > 0}
        self._names = tuple(self._meshes)
        self._scene = o3d.t.geometry.RaycastingScene()
        self._parts: dict[str, list[_Component]] = {}
        for name in self._names:
            mesh = self._meshes[name]
            verts = o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.vertices, dtype=np.float32))
            faces = o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.faces, dtype=np.uint32))
            self._scene.add_triangles(verts, faces)
            self._parts[name] = list(_parts[name]) if _parts and name in _parts else _components(mesh)
        self._components = [c for name in self._names for c in self._parts[name]]
        self._without: dict[frozenset[str], ObstacleField] = {}

    @classmethod
    def empty(cls) -> ObstacleField:
        """A field without obstacles (free space): every distance is ``inf``."""
        return cls({})

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the obstacle meshes, in geometry-id order."""
        return self._names

    def without(self, names: Iterable[str]) -> ObstacleField:
        """A new field without the named meshes (e.g. the object being grasped); unknown names are ignored."""
        drop = frozenset(names) & frozenset(self._names)
        if not drop:
            return self
        if drop not in self._without:  # cached: the approach and leave of one object share it
            keep = {k: v for k, v in self._meshes.items() if k not in drop}
            self._without[drop] = ObstacleField(keep, _parts=self._parts)
        return self._without[drop]

    def _check(self, points: ArrayLike) -> NDArray[np.float64]:
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3 or not np.isfinite(pts).all():
            raise SceneError(f"points must be a finite (N, 3) array [m], got shape {pts.shape}")
        return pts

    def _closest(self, pts: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        ans = self._scene.compute_closest_points(
            o3d.core.Tensor.from_numpy(np.ascontiguousarray(pts, dtype=np.float32))
        )
        closest = ans["points"].numpy().astype(np.float64)
        ids = ans["geometry_ids"].numpy().astype(np.int64)
        return closest, ids

    def inside(self, points: ArrayLike) -> NDArray[np.bool_]:
        """(N,) whether each point [m] lies inside an obstacle."""
        pts = self._check(points)
        result = np.zeros(len(pts), dtype=bool)
        for comp in self._components:
            cand = ~result & np.all((pts >= comp.lower - 1e-9) & (pts <= comp.upper + 1e-9), axis=1)
            if not cand.any():
                continue
            sub = pts[cand]
            if comp.planes is not None:
                hit = np.all(sub @ comp.planes[:, :3].T - comp.planes[:, 3] <= 0.0, axis=1)
            else:
                assert comp.mesh is not None
                hit = np.asarray(comp.mesh.contains(sub), dtype=bool)
            idx = np.flatnonzero(cand)
            result[idx[hit]] = True
        return result

    def distance(self, points: ArrayLike) -> NDArray[np.float64]:
        """(N,) [m] signed distance of ``points`` (N, 3) [m] to the nearest obstacle surface (< 0 inside)."""
        pts = self._check(points)
        if not self._names:
            return np.full(len(pts), np.inf)
        closest, _ = self._closest(pts)
        dist = np.linalg.norm(pts - closest, axis=1)
        return np.asarray(np.where(self.inside(pts), -dist, dist), dtype=np.float64)

    def push_direction(self, points: ArrayLike) -> NDArray[np.float64]:
        """(N, 3) unit vectors that increase the signed distance (away from the nearest surface; zeros
        in free space without obstacles)."""
        pts = self._check(points)
        if not self._names:
            return np.zeros_like(pts)
        closest, _ = self._closest(pts)
        diff = pts - closest
        norm = np.linalg.norm(diff, axis=1, keepdims=True)
        direction = np.divide(diff, norm, out=np.zeros_like(diff), where=norm > 1e-12)
        return np.asarray(np.where(self.inside(pts)[:, None], -direction, direction), dtype=np.float64)

    def nearest_name(self, points: ArrayLike) -> list[str]:
        """Name of the nearest obstacle mesh for each point (for messages)."""
        pts = self._check(points)
        if not self._names:
            return ["" for _ in range(len(pts))]
        _, ids = self._closest(pts)
        return [self._names[i] if 0 <= i < len(self._names) else "" for i in ids]


def box_mesh(center: ArrayLike, size: ArrayLike) -> trimesh.Trimesh:
    """Axis-aligned box mesh: ``center`` (3,) [m], ``size`` (3,) full extents [m] (helper for tests/demos)."""
    extents = np.asarray(size, dtype=np.float64)
    if extents.shape != (3,) or np.any(extents <= 0):
        raise SceneError(f"box size must be 3 positive extents [m], got {size!r}")
    box: trimesh.Trimesh = trimesh.creation.box(
        extents=extents, transform=trimesh.transformations.translation_matrix(center)
    )
    return box
