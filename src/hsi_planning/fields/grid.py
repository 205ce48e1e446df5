"""The object-centric grid E_t: an axis-aligned cube of sample nodes around the target.

Layout (decided here, used by every field): the grid has ``n = size / resolution + 1`` nodes per axis
(33 for the default 0.80 m cube at 0.025 m), placed at ``centre + (i - (n - 1) / 2) · resolution``, so the
outermost nodes lie exactly on the cube faces and the centre is a node. Each node is the **centre of a
cell** (voxel) of edge ``resolution``; the cells together cover the cube grown by half a cell
(0.825 m for the defaults). Field arrays are indexed ``field[i, j, k]`` with i along x, j along y and k
along z, and :meth:`GridSpec.points` lists the nodes in the same (C) order, so
``field.reshape(-1)`` pairs with ``grid.points()`` row by row.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from hsi_planning.errors import ConfigError, PlanningError

FloatArray = NDArray[np.float64]


def _as_points(points: ArrayLike, what: str = "points") -> FloatArray:
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise PlanningError(f"{what} must have shape (N, 3) or (3,), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise PlanningError(f"{what} contain NaN or infinite values")
    return arr


@dataclass(frozen=True)
class GridSpec:
    """A cube of ``n³`` nodes (cell centres) of spacing ``resolution`` centred at ``centre``.

    Attributes:
        centre: (3,) [m] world position of the middle node.
        size: [m] distance between the outermost node planes (edge of the cube through the nodes).
        resolution: [m] node spacing = cell edge; ``size / resolution`` must be an integer.
    """

    centre: tuple[float, float, float]
    size: float = 0.80
    resolution: float = 0.025

    def __post_init__(self) -> None:
        centre = np.asarray(self.centre, dtype=np.float64).reshape(-1)
        if centre.shape != (3,) or not np.isfinite(centre).all():
            raise ConfigError(f"grid centre must be 3 finite numbers [m], got {self.centre!r}")
        if not (math.isfinite(self.size) and math.isfinite(self.resolution)):
            raise ConfigError("grid size and resolution must be finite")
        if self.resolution <= 0.0 or self.size <= 0.0:
            raise ConfigError(f"grid size {self.size} m and resolution {self.resolution} m must be > 0")
        ratio = self.size / self.resolution
        if abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio) or round(ratio) < 2:
            raise ConfigError(
                f"grid size {self.size} m must be an integer multiple (≥ 2) of the resolution "
                f"{self.resolution} m (ratio {ratio:.6g})"
            )
        object.__setattr__(self, "centre", (float(centre[0]), float(centre[1]), float(centre[2])))
        object.__setattr__(self, "size", float(self.size))
        object.__setattr__(self, "resolution", float(self.resolution))

    @classmethod
    def around(
        cls,
        target_points: ArrayLike,
        size: float = 0.80,
        resolution: float = 0.025,
        shift: float = 0.0,
        direction: ArrayLike | None = None,
    ) -> GridSpec:
        """Grid centred at the bounding-box centre of ``target_points`` (N, 3) [m].

        The centre moves ``shift`` [m] along the unit vector of ``direction`` (3,) (the approach side,
        e.g. from the contact point towards the hand's start); no move when ``direction`` is None or zero.
        """
        pts = _as_points(target_points, "target points")
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        if direction is not None and shift != 0.0:
            d = np.asarray(direction, dtype=np.float64).reshape(3)
            norm = float(np.linalg.norm(d))
            if np.isfinite(norm) and norm > 1e-12:
                centre = centre + shift * d / norm
        return cls(
            centre=(float(centre[0]), float(centre[1]), float(centre[2])), size=size, resolution=resolution
        )

    @property
    def n(self) -> int:
        """Nodes per axis."""
        return round(self.size / self.resolution) + 1

    @property
    def shape(self) -> tuple[int, int, int]:
        """Shape (n, n, n) of every field array."""
        return (self.n, self.n, self.n)

    @property
    def origin(self) -> FloatArray:
        """(3,) [m] world position of node (0, 0, 0) (the minimum corner node)."""
        return np.asarray(self.centre, dtype=np.float64) - 0.5 * self.size

    def axes(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The node coordinates along x, y and z, each (n,) [m]."""
        o = self.origin
        steps = np.arange(self.n, dtype=np.float64) * self.resolution
        return (o[0] + steps, o[1] + steps, o[2] + steps)

    def points(self) -> FloatArray:
        """(n³, 3) [m] node (cell centre) positions in C order, matching ``field.reshape(-1)``."""
        x, y, z = self.axes()
        grids = np.meshgrid(x, y, z, indexing="ij")
        return np.stack([g.reshape(-1) for g in grids], axis=1)

    def to_unit(self, points: ArrayLike) -> FloatArray:
        """(N, 3) [-] grid-local coordinates: the node cube maps to [-1, 1]³."""
        pts = _as_points(points)
        return np.asarray((pts - np.asarray(self.centre)) / (0.5 * self.size), dtype=np.float64)

    def continuous_index(self, points: ArrayLike) -> FloatArray:
        """(N, 3) [-] fractional node index of each point (node i at index i)."""
        pts = _as_points(points)
        return (pts - self.origin) / self.resolution

    def contains(self, points: ArrayLike) -> NDArray[np.bool_]:
        """(N,) True where a point lies inside a cell of the grid (the cube grown by half a cell)."""
        idx = np.rint(self.continuous_index(points))
        return np.asarray(((idx >= 0) & (idx <= self.n - 1)).all(axis=1))

    def index(self, points: ArrayLike) -> NDArray[np.int64]:
        """(N, 3) index of the cell containing each point (its nearest node).

        Raises:
            PlanningError: a point lies outside every cell (test with :meth:`contains` first).
        """
        idx = np.rint(self.continuous_index(points)).astype(np.int64)
        outside = ~((idx >= 0) & (idx <= self.n - 1)).all(axis=1)
        if outside.any():
            first = int(np.flatnonzero(outside)[0])
            raise PlanningError(
                f"{int(outside.sum())} point(s) lie outside the grid (first: index {first}); the grid "
                f"covers {self.origin - 0.5 * self.resolution} .. "
                f"{self.origin + self.size + 0.5 * self.resolution} [m]"
            )
        return idx

    def _check_field(self, field: ArrayLike, trailing: tuple[int, ...] = ()) -> FloatArray:
        arr = np.asarray(
            np.ma.filled(field, np.nan) if np.ma.isMaskedArray(field) else field, dtype=np.float64
        )
        if arr.shape != self.shape + trailing:
            raise PlanningError(
                f"field shape {arr.shape} does not match the grid, expected {self.shape + trailing}"
            )
        return arr

    def interpolate(self, field: ArrayLike, points: ArrayLike) -> FloatArray:
        """(N,) trilinear interpolation of ``field`` (n, n, n) at ``points`` (N, 3) [m].

        Points outside the node cube take the value at the nearest point of the cube (clamped).
        """
        arr = self._check_field(field)
        coords = np.clip(self.continuous_index(points), 0.0, self.n - 1).T
        return np.asarray(ndimage.map_coordinates(arr, coords, order=1, mode="nearest"), dtype=np.float64)

    def gradient(self, field: ArrayLike) -> FloatArray:
        """(n, n, n, 3) gradient [field unit / m]: central differences inside, one-sided at borders."""
        arr = self._check_field(field)
        parts: list[FloatArray] = list(np.gradient(arr, self.resolution, edge_order=1))
        return np.stack(parts, axis=-1)

    def interpolate_gradient(self, gradient: ArrayLike, points: ArrayLike) -> FloatArray:
        """(N, 3) trilinear interpolation of a :meth:`gradient` (n, n, n, 3) at ``points`` (N, 3) [m]."""
        arr = self._check_field(gradient, (3,))
        coords = np.clip(self.continuous_index(points), 0.0, self.n - 1).T
        out = [ndimage.map_coordinates(arr[..., c], coords, order=1, mode="nearest") for c in range(3)]
        return np.stack(out, axis=1).astype(np.float64)
