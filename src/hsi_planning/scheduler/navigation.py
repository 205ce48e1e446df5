"""Navigation of the root: a floor map from the labelled cloud and 2D fast marching with CHOICE Eq. 23.

**Floor map.** Cloud points between ``min_height`` and ``max_height`` above the floor (furniture, objects,
open doors and drawers: anything the body could hit) are projected onto a grid of ``resolution``; the
clearance of a cell is its Euclidean distance to the nearest occupied cell, less half a cell diagonal
(conservative for points anywhere in a cell). The root may stand where the clearance is at least the
body radius. Extra obstacles (a door's swept leaf) are added as floor segments.

**Fast marching (Eq. 23).** The arrival time T solves |∇T| = c(x) with T = 0 at the goal g, on the free
cells only (scikit-fmm). The cost adds CHOICE's approach-direction term near the goal, so that the person
walks the last ``l`` metres into the standing pose facing the furniture::

    c(x) = 1 + κ · (1 − cos θ(x)) / 2   if |x − g| < l,   else 1          (Eq. 23, as implemented)

where θ(x) is the angle between x − g and −h (h: the unit heading of the standing pose, so −h points
back from the furniture to where the person comes from), l = ``approach_length`` (0.4 m) and
κ = ``approach_weight``. The exact form of the paper's Eq. 23 was not available to us; this is our
reading of "approach-direction cost within l = 0.4 m". The path descends T from the start cell to the
goal (8-neighbour steepest descent), then is smoothed where that stays clear.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import skfmm
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import distance_transform_edt, uniform_filter1d

from hsi_planning.errors import ConfigError, PlanningError

F64 = NDArray[np.float64]
_NEIGHBOURS = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if (di, dj) != (0, 0)]


@dataclass(frozen=True)
class NavigationConfig:
    """Floor map, fast marching and walking settings."""

    resolution: float = 0.04  #: [m] floor grid cell size
    min_height: float = 0.05  #: [m] points lower than this are floor
    max_height: float = 1.9  #: [m] points higher than this cannot be hit by the body
    margin: float = 1.0  #: [m] map border around the points of interest
    approach_length: float = 0.4  #: [m] l of Eq. 23: distance over which the approach direction counts
    approach_weight: float = 10.0  #: [-] κ of Eq. 23: extra cost of arriving against the heading
    walk_speed: float = 0.8  #: [m/s] walking speed of the root
    turn_speed: float = 2.0  #: [rad/s] turning speed in place
    keyframe_spacing: float = 0.3  #: [m] root keyframe spacing along a path
    #: [m] shorter paths, and goals closer than this along a clear straight line, are stepped (straight
    #: there) without turning to walk along them
    side_step_length: float = 0.6
    smooth_window: int = 5  #: [cells] moving-average window of the path smoothing
    #: [m] a root start (where the body stands now, e.g. a robot's base re-planning after a push) may have
    #: up to this much less clearance than the body radius; the path leaves it through cells at least as
    #: clear until it reaches the full clearance
    start_slack: float = 0.05

    def __post_init__(self) -> None:
        for name in ("resolution", "walk_speed", "turn_speed", "keyframe_spacing", "approach_length"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"NavigationConfig.{name} must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.min_height < self.max_height:
            raise ConfigError("NavigationConfig needs 0 <= min_height < max_height [m]")
        if not 0.0 <= self.start_slack < 0.5:
            raise ConfigError(f"NavigationConfig.start_slack must be in [0, 0.5) m, got {self.start_slack}")
        if self.margin < 0.0 or self.approach_weight < 0.0 or self.smooth_window < 1:
            raise ConfigError("NavigationConfig: margin >= 0 m, approach_weight >= 0, smooth_window >= 1")


class FloorMap:
    """Occupancy and clearance of the floor (see the module docstring).

    Args:
        obstacles: (N, 2) [m] floor positions of obstacle points.
        lower: (2,) [m] map corner; upper: (2,) [m] opposite corner.
        resolution: [m] cell size.
    """

    def __init__(self, obstacles: ArrayLike, lower: ArrayLike, upper: ArrayLike, resolution: float) -> None:
        self.resolution = float(resolution)
        self.lower = np.asarray(lower, dtype=np.float64).reshape(2)
        upper_arr = np.asarray(upper, dtype=np.float64).reshape(2)
        self.shape = tuple(
            int(v) for v in np.ceil((upper_arr - self.lower) / self.resolution).astype(int) + 1
        )
        self.obstacles = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        self.occupied = np.zeros(self.shape, dtype=bool)
        self._mark(self.obstacles)
        self._update()

    @classmethod
    def from_points(
        cls, points: ArrayLike, config: NavigationConfig, keep: Sequence[ArrayLike] = ()
    ) -> FloorMap:
        """Map of cloud ``points`` (N, 3) [m] covering them and the ``keep`` positions (2,) [m]."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        band = pts[(pts[:, 2] > config.min_height) & (pts[:, 2] < config.max_height), :2]
        extent = [band] + [np.asarray(k, dtype=np.float64).reshape(1, 2) for k in keep]
        allpts = np.vstack(extent) if any(len(e) for e in extent) else np.zeros((1, 2))
        lower = allpts.min(axis=0) - config.margin
        upper = allpts.max(axis=0) + config.margin
        return cls(band, lower, upper, config.resolution)

    def _cells(self, xy: F64) -> NDArray[np.int64]:
        return np.asarray(np.rint((xy - self.lower) / self.resolution), dtype=np.int64)

    def _mark(self, xy: F64) -> None:
        cells = self._cells(xy)
        ok = np.all((cells >= 0) & (cells < np.asarray(self.shape)), axis=1)
        self.occupied[cells[ok, 0], cells[ok, 1]] = True

    def _update(self) -> None:
        if self.occupied.any():
            edt = np.asarray(distance_transform_edt(~self.occupied), dtype=np.float64)
            self.clearance_grid = edt * self.resolution - 0.5 * math.sqrt(2.0) * self.resolution
        else:
            self.clearance_grid = np.full(self.shape, np.inf)

    def with_segments(self, segments: Sequence[ArrayLike]) -> FloorMap:
        """A copy with extra obstacle segments, each (2, 2) [m] (e.g. a door leaf on the floor)."""
        extra = [self.obstacles]
        for seg in segments:
            a, b = np.asarray(seg, dtype=np.float64).reshape(2, 2)
            n = max(2, int(np.ceil(np.linalg.norm(b - a) / (0.5 * self.resolution))) + 1)
            extra.append(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a))
        upper = self.lower + (np.asarray(self.shape) - 1) * self.resolution
        return FloorMap(np.vstack(extra), self.lower, upper, self.resolution)

    def clearance(self, xy: ArrayLike) -> F64:
        """(N,) [m] clearance at floor positions ``xy`` (N, 2) (outside the map: +inf)."""
        pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        cells = self._cells(pts)
        ok = np.all((cells >= 0) & (cells < np.asarray(self.shape)), axis=1)
        out = np.full(len(pts), np.inf)
        out[ok] = self.clearance_grid[cells[ok, 0], cells[ok, 1]]
        return out

    def cell_centres(self) -> F64:
        """(H, W, 2) [m] floor position of every cell."""
        ii, jj = np.meshgrid(np.arange(self.shape[0]), np.arange(self.shape[1]), indexing="ij")
        return np.stack([ii, jj], axis=-1) * self.resolution + self.lower

    def segment_clear(self, a: ArrayLike, b: ArrayLike, radius: float) -> bool:
        """Whether the straight floor segment a → b (2,) [m] keeps ``radius`` [m] of clearance."""
        pa, pb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        n = max(2, int(np.ceil(np.linalg.norm(pb - pa) / (0.5 * self.resolution))) + 1)
        pts = pa + np.linspace(0.0, 1.0, n)[:, None] * (pb - pa)
        return bool((self.clearance(pts) >= radius).all())


def approach_cost(cells: F64, goal: F64, heading: F64, config: NavigationConfig) -> F64:
    """Eq. 23 cost c(x) [-] at floor positions ``cells`` (..., 2) [m] for ``goal`` (2,) and the stance's
    ``heading`` (2,)."""
    rel = cells - goal
    dist = np.linalg.norm(rel, axis=-1)
    back = -np.asarray(heading, dtype=np.float64) / max(float(np.linalg.norm(heading)), 1e-12)
    cos = np.einsum("...k,k->...", rel, back) / np.maximum(dist, 1e-9)
    near = dist < config.approach_length
    return np.asarray(1.0 + np.where(near, config.approach_weight * 0.5 * (1.0 - cos), 0.0))


def plan_root_path(
    floor: FloorMap,
    start: ArrayLike,
    goal: ArrayLike,
    heading: ArrayLike,
    *,
    radius: float,
    config: NavigationConfig,
) -> F64:
    """(N, 2) [m] collision-free root path from ``start`` to ``goal`` (2,) by fast marching (Eq. 23).

    ``heading`` (2,) is the facing of the standing pose at the goal; ``radius`` [m] the body radius.

    Raises:
        PlanningError: start or goal not clear, or no free path between them.
    """
    s, g = np.asarray(start, dtype=np.float64).reshape(2), np.asarray(goal, dtype=np.float64).reshape(2)
    start_clear = float(floor.clearance(s[None])[0])
    for label, p, c, slack in (
        ("start", s, start_clear, config.start_slack),
        ("goal", g, float(floor.clearance(g[None])[0]), 0.0),
    ):
        if c < radius - slack - 1e-9:
            more = f" (a start may have {slack} m less)" if slack > 0.0 else ""
            raise PlanningError(
                f"the root {label} {np.round(p, 3).tolist()} has {c:.3f} m clearance, less than the body "
                f"radius {radius} m{more}"
            )
    if np.linalg.norm(g - s) < 0.5 * floor.resolution:
        return np.vstack([s, g])
    centres = floor.cell_centres()
    free = floor.clearance_grid >= radius
    if start_clear < radius:  # out of a tight start through cells at least as clear, within the deficit
        near = np.linalg.norm(centres - s, axis=-1) <= radius - start_clear + 2.0 * floor.resolution
        free |= near & (floor.clearance_grid >= start_clear - 0.5 * floor.resolution)
    gi = tuple(floor._cells(g[None])[0])
    si = tuple(floor._cells(s[None])[0])
    for idx in (gi, si):
        if not (0 <= idx[0] < floor.shape[0] and 0 <= idx[1] < floor.shape[1]):
            raise PlanningError(
                f"{np.round(s, 3).tolist()} or {np.round(g, 3).tolist()} lies outside the floor map"
            )
        free[idx] = True
    phi = np.linalg.norm(centres - g, axis=-1) - 0.75 * floor.resolution
    phi = np.ma.MaskedArray(phi, mask=~free)
    speed = 1.0 / approach_cost(centres, g, np.asarray(heading, dtype=np.float64), config)
    travel = skfmm.travel_time(phi, speed, dx=floor.resolution)
    T = np.ma.filled(travel, np.inf).astype(np.float64)
    T[gi] = 0.0
    if not np.isfinite(T[si]):
        raise PlanningError(
            f"no collision-free root path from {np.round(s, 2).tolist()} to {np.round(g, 2).tolist()} "
            f"for a body radius of {radius} m"
        )
    cells = [si]
    while cells[-1] != gi and len(cells) < T.size:
        i, j = cells[-1]
        best, best_t = cells[-1], T[i, j]
        for di, dj in _NEIGHBOURS:
            ni, nj = i + di, j + dj
            if 0 <= ni < T.shape[0] and 0 <= nj < T.shape[1] and T[ni, nj] < best_t:
                best, best_t = (ni, nj), T[ni, nj]
        if best == cells[-1]:
            raise PlanningError(
                f"the fast-marching descent stalled at {np.round(centres[cells[-1]], 2).tolist()} on the way "
                f"to {np.round(g, 2).tolist()}"
            )
        cells.append(best)
    path = np.vstack(
        [s, centres[tuple(np.asarray(cells[1:-1]).T)] if len(cells) > 2 else np.zeros((0, 2)), g]
    )
    return _smooth(floor, path, radius, config.smooth_window)


def _smooth(floor: FloorMap, path: F64, radius: float, window: int) -> F64:
    if len(path) < 3 or window < 2:
        return path
    smooth = uniform_filter1d(path, size=window, axis=0, mode="nearest")
    smooth[0], smooth[-1] = path[0], path[-1]
    ok = all(floor.segment_clear(a, b, radius) for a, b in itertools.pairwise(smooth))
    return smooth if ok else path


def resample_path(path: ArrayLike, spacing: float) -> F64:
    """(M, 2) [m] the path resampled at about ``spacing`` [m] (ends kept)."""
    p = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    if arc[-1] < 1e-9:
        return p[[0, -1]]
    n = max(2, int(np.ceil(arc[-1] / spacing)) + 1)
    s = np.linspace(0.0, arc[-1], n)
    return np.stack([np.interp(s, arc, p[:, k]) for k in range(2)], axis=1)
