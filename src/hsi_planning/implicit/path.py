"""Geometry and timing of the implicit planner's wrist path.

- :class:`Clearance`: distance [m] from points to the observed obstacle points (KD-tree), segment tests.
- :func:`select_start` (Eq. 11): the entry point x_s = argmin_x (−φ̂(x) + |x − w| / v̄) among candidate
  nodes whose straight connection from the wrist w is clear.
- :func:`smooth_path`: arc-length resampling and Gaussian smoothing with both ends kept.
- :func:`time_path`: sample times from a speed profile (from the remaining-time field, v = 1/|∇φ̂|),
  limited by a maximum speed and acceleration so the hand starts and ends at rest.
- :func:`resample_uniform`: the timed path at a fixed rate (monotone cubic interpolation).
- :func:`estimate_approach_axis`: the container opening seen from the target when no scene spec is known.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import PchipInterpolator
from scipy.ndimage import gaussian_filter1d

from hsi_planning.errors import PlanningError
from hsi_planning.fields.nearest import NearestPoints

F64 = NDArray[np.float64]


class Clearance:
    """Euclidean distance [m] to the nearest of ``obstacle_points`` (M, 3) [m] (inf without points)."""

    def __init__(self, obstacle_points: ArrayLike) -> None:
        self._nearest = NearestPoints(obstacle_points)
        self.n_points = self._nearest.n_points

    def __call__(self, points: ArrayLike, bound: float = np.inf) -> F64:
        """(N,) [m] distance of each of ``points`` (N, 3) to the nearest obstacle point; distances beyond
        ``bound`` [m] come back as ``bound`` (a bounded search is several times faster)."""
        return self._nearest.distance(points, bound)

    def segments_clear(
        self, a: ArrayLike, ends: ArrayLike, radius: float, step: float = 0.01
    ) -> NDArray[np.bool_]:
        """(B,) whether each segment a (3,) → ends[b] (B, 3) [m] stays ``radius`` [m] from every obstacle."""
        pa = np.asarray(a, dtype=np.float64).reshape(1, 1, 3)
        pb = np.asarray(ends, dtype=np.float64).reshape(-1, 1, 3)
        if pb.shape[0] == 0:
            return np.zeros(0, dtype=bool)
        longest = float(np.linalg.norm(pb - pa, axis=2).max())
        u = np.linspace(0.0, 1.0, max(2, int(np.ceil(longest / step)) + 1)).reshape(1, -1, 1)
        samples = pa + u * (pb - pa)
        dist = self(samples.reshape(-1, 3), bound=radius + 1e-6).reshape(pb.shape[0], -1)
        return np.asarray((dist >= radius).all(axis=1))


def arc_length(points: ArrayLike) -> F64:
    """(N,) [m] cumulative arc length of a path (N, 3) [m], 0 at the first sample."""
    p = np.asarray(points, dtype=np.float64)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def required_clearance(
    distance_to_contact: ArrayLike, full: float, contact_clear: float, relax: float, tolerance: float = 1e-3
) -> F64:
    """(N,) [m] clearance required along a path: ``full`` [m] farther than ``relax`` [m] (arc length)
    from the contact, relaxing linearly to what the contact pose itself has (``contact_clear`` [m], less
    ``tolerance``; negative for a held object that still overlaps its support)."""
    d = np.asarray(distance_to_contact, dtype=np.float64)
    end = min(full, contact_clear - tolerance)
    return np.asarray(end + (full - end) * np.clip(d / max(relax, 1e-9), 0.0, 1.0), dtype=np.float64)


def select_start(
    candidates: ArrayLike,
    phi: ArrayLike,
    wrist: ArrayLike,
    mean_speed: float,
    connect_clear: Callable[[F64], NDArray[np.bool_]],
    *,
    batch: int = 128,
    max_checks: int = 4096,
) -> int:
    """Eq. 11: index of x_s = argmin (−φ̂(x) + |x − w| / v̄) over ``candidates`` whose connection is clear.

    Args:
        candidates: (K, 3) [m] candidate points (free grid nodes inside the prior's time corridor).
        phi: (K,) [s] remaining time φ̂ at the candidates.
        wrist: (3,) [m] current wrist position w.
        mean_speed: [m/s] v̄, the demonstration's mean speed.
        connect_clear: (B, 3) candidates → (B,) whether the straight connection w → x is free (called on
            batches of ``batch`` candidates in cost order).
        max_checks: [-] candidates tested before giving up.

    Raises:
        PlanningError: no candidate, or none of the ``max_checks`` cheapest has a clear connection.
    """
    pts = np.asarray(candidates, dtype=np.float64).reshape(-1, 3)
    val = np.asarray(phi, dtype=np.float64).reshape(-1)
    if pts.shape[0] == 0 or val.shape[0] != pts.shape[0]:
        raise PlanningError("no free grid node lies in the time corridor of the matched prior")
    if not mean_speed > 0.0:
        raise PlanningError(f"mean_speed must be > 0 [m/s], got {mean_speed}")
    w = np.asarray(wrist, dtype=np.float64).reshape(3)
    cost = -val + np.linalg.norm(pts - w, axis=1) / mean_speed
    order = np.argsort(cost, kind="stable")[:max_checks]
    for lo in range(0, order.shape[0], batch):
        idx = order[lo : lo + batch]
        ok = np.flatnonzero(connect_clear(pts[idx]))
        if ok.shape[0]:
            return int(idx[ok[0]])
    raise PlanningError(
        f"no start point reachable from the wrist at {w.round(3).tolist()} [m] along a collision-free "
        f"straight line among the {order.shape[0]} best candidates"
    )


def resample_arc(points: ArrayLike, step: float) -> F64:
    """(M, 3) [m] the path (N, 3) resampled at uniform arc-length ``step`` [m] (ends kept)."""
    p = np.asarray(points, dtype=np.float64)
    arc = arc_length(p)
    keep = np.concatenate([[True], np.diff(arc) > 1e-12])
    p, arc = p[keep], arc[keep]
    if p.shape[0] < 2:
        return np.array(p, copy=True)
    s = np.linspace(0.0, arc[-1], max(2, int(np.ceil(arc[-1] / step)) + 1))
    return np.stack([np.interp(s, arc, p[:, c]) for c in range(3)], axis=1)


def smooth_path(points: ArrayLike, sigma: float, step: float = 0.005) -> F64:
    """(M, 3) [m] path resampled at ``step`` [m] and Gaussian-smoothed over ``sigma`` [m] of arc length.

    Both end points are kept: the path is extended by its point reflections through them before filtering.
    """
    p = resample_arc(points, step)
    n = p.shape[0]
    if n < 3 or sigma <= 0.0:
        return p
    k = min(n - 1, int(np.ceil(4.0 * sigma / step)))
    head = 2.0 * p[0] - p[k:0:-1]
    tail = 2.0 * p[-1] - p[-2 : -k - 2 : -1]
    ext = np.vstack([head, p, tail])
    sm = gaussian_filter1d(ext, sigma=sigma / step, axis=0, mode="nearest")[k : k + n]
    # Remove the residual end offsets linearly (keeps the ends exact).
    u = np.linspace(0.0, 1.0, n)[:, None]
    sm = sm - (1.0 - u) * (sm[0] - p[0]) - u * (sm[-1] - p[-1])
    return np.asarray(sm, dtype=np.float64)


def time_path(
    points: ArrayLike,
    speed: ArrayLike,
    *,
    max_speed: float,
    min_speed: float,
    max_accel: float,
    smooth: float = 0.0,
) -> F64:
    """(N,) [s] sample times of a path (N, 3) [m] travelled at ``speed`` (N,) [m/s], from rest to rest.

    The speed is smoothed over ``smooth`` [m] of arc length, clipped to [min_speed, max_speed] and
    capped by the rest-to-rest envelope sqrt(v₀² + 2·a_max·s) from both ends (v₀ = min_speed / 4).
    """
    p = np.asarray(points, dtype=np.float64)
    v = np.asarray(speed, dtype=np.float64).reshape(-1)
    if v.shape[0] != p.shape[0] or p.shape[0] < 2:
        raise PlanningError(
            f"time_path needs (N, 3) points and (N,) speeds with N ≥ 2, got {p.shape}, {v.shape}"
        )
    if not (np.isfinite(v).all() and np.isfinite(p).all()):
        raise PlanningError("time_path got NaN or infinite points or speeds")
    arc = arc_length(p)
    total = float(arc[-1])
    if total < 1e-9:
        raise PlanningError("the path does not move (length below 1 nm)")
    step = total / (p.shape[0] - 1)
    if smooth > 0.0 and p.shape[0] > 2:
        v = gaussian_filter1d(v, sigma=max(smooth / step, 1e-3), mode="nearest")
    v = np.clip(v, min_speed, max_speed)
    v0 = 0.25 * min_speed
    env = np.sqrt(v0**2 + 2.0 * max_accel * np.minimum(arc, total - arc))
    v = np.minimum(v, env)
    ds = np.diff(arc)
    dt = ds / (0.5 * (v[1:] + v[:-1]))
    return np.concatenate([[0.0], np.cumsum(dt)])


def resample_uniform(times: ArrayLike, points: ArrayLike, rate: float) -> tuple[F64, F64]:
    """(t (M,) [s], positions (M, 3) [m]) of a timed path at ``rate`` [Hz] (monotone cubic, ends kept)."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    p = np.asarray(points, dtype=np.float64)
    keep = np.concatenate([[True], np.diff(t) > 1e-9])
    t, p = t[keep], p[keep]
    if t.shape[0] < 2:
        raise PlanningError("a timed path needs at least two distinct sample times")
    dt = 1.0 / rate
    n = max(2, int(np.floor((t[-1] - t[0]) / dt + 0.5)) + 1)
    tt = np.linspace(t[0], t[-1], n)
    pos = PchipInterpolator(t, p, axis=0)(tt)
    return tt - tt[0], np.asarray(pos, dtype=np.float64)


def estimate_approach_axis(
    target_points: ArrayLike,
    clearance: Clearance,
    toward: ArrayLike,
    *,
    probe: float = 0.5,
    radius: float = 0.04,
    snap_deg: float = 90.0,
) -> F64:
    """(3,) unit direction out of the opening in front of the target, from the observed obstacles.

    Straight up (+z) when the space above the target is free for ``probe`` [m] (counters, tables, pulled-
    out drawers, as in training); otherwise the mean of the horizontal directions (16 tested) that stay
    free longest, ties broken towards ``toward`` (3,) [m] (e.g. the wrist), its heading rounded to a
    multiple of ``snap_deg`` [deg] (furniture fronts face the world axes; 0 = no rounding).
    """
    pts = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    half = 0.5 * (pts.max(axis=0) - pts.min(axis=0))
    steps = np.linspace(0.0, probe, 26)[1:]

    def free_length(d: F64) -> float:
        start = centre + (float(np.abs(d) @ half) + radius) * d
        ok = clearance(start + steps[:, None] * d) >= radius
        return float(probe if ok.all() else steps[int(np.argmin(ok))] - steps[0])

    up = np.array([0.0, 0.0, 1.0])
    if free_length(up) >= probe:
        return up
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    lengths = np.array([free_length(d) for d in dirs])
    best = dirs[lengths >= lengths.max() - 1e-9]
    mean = best.mean(axis=0)
    if float(np.linalg.norm(mean)) < 1e-6:  # free all around: face the wrist
        to_w = np.asarray(toward, dtype=np.float64).reshape(3) - centre
        to_w[2] = 0.0
        mean = to_w if float(np.linalg.norm(to_w)) > 1e-6 else dirs[0]
    heading = float(np.arctan2(mean[1], mean[0]))
    if snap_deg > 0.0:
        step = np.radians(snap_deg)
        heading = step * round(heading / step)
    return np.array([np.cos(heading), np.sin(heading), 0.0])
