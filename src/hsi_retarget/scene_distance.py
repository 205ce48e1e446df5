"""Signed distance from points to the scene: an Open3D ``RaycastingScene`` of the scene's world-frame
meshes (closest point; negative when the point lies clearly behind the closest triangle, i.e. inside a
closed mesh), with a cheap lower bound from a coarse grid filled on demand, so that points far from
everything need not be queried exactly (:meth:`SceneDistance.lower_bound`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np
import open3d as o3d
import trimesh
from numpy.typing import NDArray

from hsi_planning.errors import RetargetError

F64 = NDArray[np.float64]
_BOUND_CELL = 0.05  #: [m] node spacing of :meth:`SceneDistance.lower_bound`'s grid
_BOUND_PAD = 0.5  #: [m] that grid's extent beyond the meshes' bounding box


class SceneDistance:
    """Signed distance [m] from points to a set of world-frame triangle meshes (Open3D raycasting scene)."""

    def __init__(
        self,
        meshes: Mapping[str, trimesh.Trimesh],
        exclude: Iterable[str] = (),
        ground: Iterable[str] = ("floor",),
        padding: float = 0.0,
    ) -> None:
        """Index ``meshes`` (name -> world-frame mesh) except those named in ``exclude`` or below them
        (``cabinet1`` also drops ``cabinet1/door1``). The meshes named in ``ground`` can be left out per
        query (:meth:`query`, :meth:`lower_bound`: a robot's base stands on the floor). ``padding`` [m] >= 0
        is taken off every distance: the meshes grown by it (geometry known only that well, e.g. a drawer
        where a hand holds it).

        Raises:
            RetargetError: nothing left to index.
        """
        drop = tuple(exclude)
        kept = {n: m for n, m in meshes.items() if not any(n == d or n.startswith(d + "/") for d in drop)}
        if not kept:
            raise RetargetError(f"no scene mesh left after excluding {list(drop)}")
        if not (padding >= 0.0 and np.isfinite(padding)):
            raise RetargetError(f"SceneDistance padding [m] must be finite and >= 0, got {padding}")
        self.padding = float(padding)  #: [m] taken off every distance
        self.names: tuple[str, ...] = tuple(kept)
        self._scene = _raycasting(kept.values())
        lifted = [m for n, m in kept.items() if n not in set(ground)]
        self._lifted = _raycasting(lifted) if lifted and len(lifted) < len(kept) else None
        verts = np.concatenate([np.asarray(m.vertices, dtype=np.float64) for m in kept.values()])
        lo = verts.min(axis=0) - _BOUND_PAD
        shape = np.ceil((verts.max(axis=0) + _BOUND_PAD - lo) / _BOUND_CELL).astype(np.int64) + 1
        self._grid_origin, self._grid = lo, np.full(tuple(shape), np.nan)  # signed distance at the nodes
        self._lifted_grid = np.full(tuple(shape), np.nan)  # the same without the ground meshes

    @classmethod
    def from_spec(cls, spec: object, exclude: Iterable[str] = ()) -> SceneDistance:
        """From a scene spec (:func:`hsi_planning.scene.scene_meshes`)."""
        from hsi_planning.scene import scene_meshes

        return cls(scene_meshes(spec), exclude)  # type: ignore[arg-type]

    def lower_bound(self, points: F64, grounded: NDArray[np.bool_] | None = None) -> F64:
        """(N,) [m] lower bounds of the distances of ``points`` (N, 3) [m]: the distance is 1-Lipschitz, so
        it is at least its value at the nearest node of a coarse grid (filled on demand) minus the way there.
        Points off that grid (more than its padding beyond the meshes) get ``-inf``. Points where
        ``grounded`` (N,) is False are bounded without the ground meshes (default: all with)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if grounded is None or self._lifted is None:
            return self._bound(pts, self._grid, self._scene) - self.padding
        raised = ~np.asarray(grounded, dtype=bool)
        bound = np.empty(pts.shape[0])
        bound[~raised] = self._bound(pts[~raised], self._grid, self._scene)
        bound[raised] = self._bound(pts[raised], self._lifted_grid, self._lifted)  # a grid of their own
        return bound - self.padding

    def _bound(self, pts: F64, grid: F64, scene: o3d.t.geometry.RaycastingScene) -> F64:
        """:meth:`lower_bound` from ``grid`` (filled on demand from ``scene``)."""
        idx = np.rint((pts - self._grid_origin) / _BOUND_CELL).astype(np.int64)
        inside = np.all((idx >= 0) & (idx < np.asarray(grid.shape)), axis=1)
        bound = np.full(pts.shape[0], -np.inf)
        if inside.any():
            cells = idx[inside]
            nodes = self._grid_origin + cells * _BOUND_CELL
            values = grid[cells[:, 0], cells[:, 1], cells[:, 2]]
            todo = np.isnan(values)
            if todo.any():
                values[todo] = self._exact(nodes[todo], scene)[0]
                grid[cells[todo, 0], cells[todo, 1], cells[todo, 2]] = values[todo]
            bound[inside] = values - np.linalg.norm(pts[inside] - nodes, axis=1)
        return bound

    def query(self, points: F64, grounded: NDArray[np.bool_] | None = None) -> tuple[F64, F64]:
        """Distances (N,) [m] (negative inside a closed mesh; less the padding) and unit gradients (N, 3)
        (the direction that increases the distance) of ``points`` (N, 3) [m]. Points where ``grounded``
        (N,) is False are measured without the ground meshes (default: all with; a robot's base stands on
        the floor)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if grounded is None or self._lifted is None:
            dist, grad = self._exact(pts)
            return dist - self.padding, grad
        raised = ~np.asarray(grounded, dtype=bool)
        dist, grad = np.empty(pts.shape[0]), np.empty((pts.shape[0], 3))
        dist[~raised], grad[~raised] = self._exact(pts[~raised])
        dist[raised], grad[raised] = self._exact(pts[raised], self._lifted)
        return dist - self.padding, grad

    def _exact(self, pts: F64, scene: o3d.t.geometry.RaycastingScene | None = None) -> tuple[F64, F64]:
        if pts.shape[0] == 0:
            return np.zeros(0), np.zeros((0, 3))
        ans = (self._scene if scene is None else scene).compute_closest_points(
            o3d.core.Tensor.from_numpy(np.ascontiguousarray(pts, dtype=np.float32))
        )
        closest = ans["points"].numpy()  # float32: the subtraction below widens it exactly
        tri_normal = ans["primitive_normals"].numpy().astype(np.float64)
        delta = pts - closest
        dist = np.sqrt(np.add.reduce(delta * delta, axis=1))  # np.linalg.norm(axis=1) without its wrapper
        # inside: the point lies behind the closest triangle's plane (a point outside next to an edge can get
        # the other face's triangle, with a slightly negative dot product: not inside)
        side = np.where(np.einsum("ij,ij->i", delta, tri_normal) < -0.5 * dist, -1.0, 1.0)
        direction = np.where(dist[:, None] > 1e-9, delta / np.maximum(dist, 1e-12)[:, None], tri_normal)
        return side * dist, direction * side[:, None]


def _raycasting(meshes: Iterable[trimesh.Trimesh]) -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    for mesh in meshes:
        scene.add_triangles(
            o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.faces, dtype=np.uint32)),
        )
    return scene
