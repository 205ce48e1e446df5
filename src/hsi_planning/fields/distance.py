"""Distance fields on the grid: geodesic distance to the target (fast marching) and Euclidean distance
to the nearest obstacle point, and their bounded inverses D_t and D_o.

Geodesic distance (D_t): the level set φ₀ = e(x) − δ, with e the Euclidean distance from a node to the
nearest target point and δ = ``surface_offset``, is negative on the nodes hugging the target surface (and
on the filled inside of a closed target). ``skfmm.distance`` propagates the distance to that level set
through the free nodes only (obstacle nodes are masked, so the front goes around them); adding δ back
gives the distance to the sampled target surface. Because φ₀ is itself a distance function near the
surface, fast marching is initialised accurately (sub-cell) there.
"""

from __future__ import annotations

import logging

import numpy as np
import skfmm
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import PlanningError
from hsi_planning.fields.grid import GridSpec
from hsi_planning.fields.nearest import NearestPoints

_LOG = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def point_distance(grid: GridSpec, points: ArrayLike) -> FloatArray:
    """(n, n, n) [m] Euclidean distance from every node to the nearest of ``points`` (N, 3) [m].

    Every point counts, also those outside the grid. No points: ``inf`` everywhere.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if pts.shape[0] == 0:
        return np.full(grid.shape, np.inf)
    return NearestPoints(pts).distance(grid.points()).reshape(grid.shape)


def inverse_field(distance: NDArray[np.floating], floor: float, far: float) -> NDArray[np.float32]:
    """(n, n, n) float32 ``1 / max(distance, floor)``, exactly 0 where ``distance >= far`` (blocked)."""
    d = np.asarray(distance, dtype=np.float64)
    out = np.where(d >= far, 0.0, 1.0 / np.maximum(d, floor))
    return out.astype(np.float32)


def target_distance(
    grid: GridSpec,
    surface_distance: FloatArray,
    interior: BoolArray,
    obstacle: BoolArray,
    *,
    surface_offset: float,
    unreachable_distance: float,
    order: int = 2,
) -> FloatArray:
    """(n, n, n) [m] geodesic distance to the target surface with obstacle nodes impassable.

    Args:
        grid: the grid.
        surface_distance: (n, n, n) [m] Euclidean node distance to the nearest target point.
        interior: (n, n, n) nodes enclosed inside a closed target (distance 0), may be all False.
        obstacle: (n, n, n) obstacle occupancy (should exclude the target).
        surface_offset: [m] δ of the seed level set (see the module doc).
        unreachable_distance: [m] value stored on obstacle nodes and on free nodes no path reaches.
        order: fast-marching order (1 or 2).

    Returns:
        Distances ≥ 0: 0 on the seed nodes (within δ of a target point, or inside a closed target),
        ``unreachable_distance`` on obstacle nodes and where no free path leads to the target.
    """
    e = np.asarray(surface_distance, dtype=np.float64)
    if e.shape != grid.shape or interior.shape != grid.shape or obstacle.shape != grid.shape:
        raise PlanningError(f"distance and mask arrays must have the grid shape {grid.shape}")
    if not np.isfinite(e).any():
        raise PlanningError("no target point: the geodesic distance needs a target surface")
    offset = surface_offset
    if not (e <= offset).any():
        # A target thinner than the node spacing between nodes: seed at the nearest node(s) instead.
        offset = float(e.min()) * (1.0 + 1e-6) + 1e-9
        _LOG.debug("no node within surface_offset of the target; seeding at %.4f m", offset)
    surface = e <= offset
    seed = surface | interior
    # Strictly negative on the seed nodes: a node exactly on level 0 is ambiguous for skfmm.
    tiny = 1e-6 * grid.resolution
    phi0 = np.where(surface, np.minimum(e - offset, -tiny), e - offset)
    phi0 = np.where(interior & ~surface, -np.maximum(e, tiny), phi0)
    masked = np.ma.MaskedArray(phi0, mask=obstacle & ~seed)
    try:
        fmm = skfmm.distance(masked, dx=grid.resolution, order=order)
    except ValueError as exc:  # skfmm: no zero level set (every free node is a seed)
        raise PlanningError(f"fast marching of the target distance failed: {exc}") from exc
    blocked = np.ma.getmaskarray(fmm)
    values = np.asarray(np.ma.filled(fmm, 0.0), dtype=np.float64)
    dist = np.where(seed, 0.0, np.minimum(values + offset, unreachable_distance))
    dist[blocked & ~seed] = unreachable_distance
    return np.asarray(dist)
