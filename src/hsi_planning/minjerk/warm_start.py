"""Initial guesses for the minimum-jerk optimizer: the straight line when it is clear, else a corridor.

IPOPT is a local method: started on a straight line through a shelf board it converges to a local
infeasibility. When the straight minimum-jerk line violates a clearance constraint, a collision-free
**corridor** is searched on the distance grid: fast marching (scikit-fmm) of the geodesic distance to the
goal through the nodes where every sphere has its (relaxed) clearance, steepest descent over the 26
neighbours from the start, greedy shortcuts along free straight segments, and minimum-jerk timing along
the resulting polyline (``s(τ) = 10τ³ − 15τ⁴ + 6τ⁵`` of the arc length), sampled uniformly in time.
"""

from __future__ import annotations

import itertools
import logging

import numpy as np
import skfmm
from numpy.typing import NDArray

from hsi_planning.minjerk.clearance import ClearanceSphere
from hsi_planning.minjerk.optimizer import MinJerkConfig, margins
from hsi_planning.minjerk.quintic import initial_spline

_LOG = logging.getLogger(__name__)

F64 = NDArray[np.float64]
_NEIGHBOURS = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if d != (0, 0, 0)], dtype=np.int64)


def straight_is_clear(
    start: F64, goal: F64, duration: float, spheres: tuple[ClearanceSphere, ...], config: MinJerkConfig
) -> bool:
    """Whether the free-space minimum-jerk line meets every clearance constraint at the check points."""
    return path_is_clear(None, start, goal, duration, spheres, config=config)


def path_is_clear(
    path: F64 | None,
    start: F64,
    goal: F64,
    duration: float,
    spheres: tuple[ClearanceSphere, ...],
    *,
    config: MinJerkConfig,
    tolerance: float = 0.0,
) -> bool:
    """Whether the optimizer's initial curve from ``path`` (N, 3) [m] (uniform in time; None = the
    straight minimum-jerk line) meets every clearance constraint at the check points, less ``tolerance``
    [m]."""
    curve = initial_spline(
        path, start, goal, duration, knots=config.knots, smoothing=config.warm_start_smoothing
    )
    worst = margins(curve, spheres, config)
    return bool(worst.size == 0 or worst.min() >= -tolerance)


def _free(
    points: F64,
    spheres: tuple[ClearanceSphere, ...],
    ends: list[F64],
    config: MinJerkConfig,
    cushion: float = 0.0,
    *,
    cubic: bool = True,
) -> NDArray[np.bool_]:
    """(N,) whether wrist positions (N, 3) meet every sphere's (relaxed) requirement + ``cushion`` (not
    near the ends), each sphere offset at the normalized time guessed by :func:`_progress`."""
    ok = np.ones(points.shape[0], dtype=bool)
    tau = _progress(points, ends)
    for s in spheres:
        relaxed = s.relaxed_ends(ends[0], ends[1], config.relax_slack)
        centres = s.centres(points, tau)
        need = s.requirement(centres, relaxed, config.relax_slope)
        ok &= s.field.contains(centres)
        ok &= s.field.interpolate(centres, cubic=cubic) >= need + cushion * (need >= s.required - 1e-9)
    return ok


def _progress(points: F64, ends: list[F64]) -> F64:
    """(N,) [-] normalized time guessed for wrist positions (N, 3) [m]: the share of the way from the
    start, |p − start| / (|p − start| + |p − goal|), so a turning held object is checked in the pose it
    has there (at the start in its start pose, near the goal in its goal pose)."""
    d0 = np.linalg.norm(points - ends[0], axis=1)
    d1 = np.linalg.norm(points - ends[1], axis=1)
    return np.asarray(d0 / np.maximum(d0 + d1, 1e-12), dtype=np.float64)


def _shortcut(
    path: F64, spheres: tuple[ClearanceSphere, ...], ends: list[F64], config: MinJerkConfig, step: float
) -> F64:
    """Greedy shortcuts: from each kept vertex, walk forward while the straight segment to the next
    vertex stays free, keep the last vertex reached (O(vertices) segment checks)."""

    def clear(p: F64, q: F64) -> bool:
        n = max(2, int(np.ceil(np.linalg.norm(q - p) / step)) + 1)
        seg = p + np.linspace(0.0, 1.0, n)[:, None] * (q - p)
        return bool(_free(seg, spheres, ends, config, cubic=False).all())

    out = [path[0]]
    i = 0
    while i < len(path) - 1:
        j = i + 1
        while j + 1 < len(path) and clear(path[i], path[j + 1]):
            j += 1
        out.append(path[j])
        i = j
    return np.asarray(out)


def _densify(polyline: F64, step: float) -> F64:
    out = [polyline[:1]]
    for a, b in itertools.pairwise(polyline):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.vstack(out)


def _smooth(
    polyline: F64, spheres: tuple[ClearanceSphere, ...], ends: list[F64], config: MinJerkConfig, step: float
) -> F64:
    """Round the corners of ``polyline`` (Laplacian smoothing with pinned ends) as far as it stays free."""
    dense = _densify(polyline, step)
    if dense.shape[0] < 3:
        return dense
    best = dense
    current = dense.copy()
    for rounds in (25, 25, 50, 100):  # cumulative 25, 50, 100, 200 smoothing passes
        for _ in range(rounds):
            current[1:-1] += 0.5 * (current[:-2] + current[2:] - 2.0 * current[1:-1])
        if not _free(current, spheres, ends, config).all():
            break
        best = current.copy()
    return best


def _timed(polyline: F64, count: int) -> F64:
    """(count, 3) points along ``polyline`` uniform in time under minimum-jerk arc-length progress."""
    seg = np.linalg.norm(np.diff(polyline, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])
    poly = polyline[keep]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poly, axis=0), axis=1))])
    if arc[-1] <= 0.0:
        return np.repeat(poly[:1], count, axis=0)
    tau = np.linspace(0.0, 1.0, count)
    s = arc[-1] * tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    return np.stack([np.interp(s, arc, poly[:, a]) for a in range(3)], axis=1)


def corridor_path(
    start: F64,
    goal: F64,
    spheres: tuple[ClearanceSphere, ...],
    config: MinJerkConfig,
    *,
    samples: int = 200,
    cushion: float = 0.0,
) -> F64 | None:
    """(samples, 3) [m] a collision-free initial path from ``start`` to ``goal``, uniform in time, or
    None when the grid shows no free corridor (the optimizer then starts from the straight line).
    ``cushion`` [m] is extra clearance asked of the grid nodes away from the ends (an interior start
    converges faster; retry without it when no corridor is found)."""
    if not spheres:
        return None
    field = spheres[0].field
    ends = [start, goal]
    nodes = field.points()
    free = _free(nodes, spheres, ends, config, cushion, cubic=False).reshape(field.shape)
    res = field.resolution
    phi = np.linalg.norm(nodes - goal, axis=1).reshape(field.shape) - 1.5 * res
    # The ends may sit in relaxed pockets narrower than a cell: their balls are free by definition.
    free |= (phi <= 0.0) | (np.linalg.norm(nodes - start, axis=1).reshape(field.shape) <= 1.5 * res)
    if not (phi <= 0.0).any():
        return None
    try:
        travel = skfmm.distance(np.ma.MaskedArray(phi, mask=~free), dx=res)
    except ValueError:  # the goal ball is fully masked
        return None
    dist = np.ma.filled(travel, np.inf)
    idx = np.clip(np.rint((start - field.origin) / res).astype(np.int64), 0, np.asarray(field.shape) - 1)
    if not np.isfinite(dist[tuple(idx)]):
        return None
    shape = np.asarray(field.shape)
    path = [start]
    for _ in range(int(shape.sum()) * 3):
        if dist[tuple(idx)] <= 0.0:
            break
        cand = idx + _NEIGHBOURS
        inside = ((cand >= 0) & (cand < shape)).all(axis=1)
        cand = cand[inside]
        values = dist[cand[:, 0], cand[:, 1], cand[:, 2]]
        best = int(np.argmin(values))
        if not values[best] < dist[tuple(idx)]:
            return None  # stuck (should not happen on a fast-marching distance)
        idx = cand[best]
        path.append(field.origin + idx * res)
    else:
        return None
    path.append(goal)
    poly = _shortcut(np.asarray(path), spheres, ends, config, 0.5 * res)
    _LOG.debug("corridor warm start: %d grid steps, %d vertices after shortcuts", len(path), len(poly))
    return _timed(_smooth(poly, spheres, ends, config, 0.01), samples)
