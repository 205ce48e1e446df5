"""Piecewise quintic Hermite curves: the trajectory parameterization of the minimum-jerk optimizer.

K knots at uniform times ``t_k = k·h``, ``h = T / (K − 1)``, each with a position p_k, velocity v_k and
acceleration a_k (all (3,)). On segment k the curve is the unique quintic matching (p, v, a) at both of
its knots::

    x(t_k + σh) = H0(σ) p_k + h H1(σ) v_k + h² H2(σ) a_k + H3(σ) p_{k+1} + h H4(σ) v_{k+1} + h² H5(σ) a_{k+1}

so the curve is C² (continuous acceleration) and its jerk is piecewise quadratic. Every quantity the
optimizer needs is **linear** in the stacked knot values ``Z = [P; V; A]`` ((3K, 3), one column per axis):
positions, velocities and accelerations at check points (:func:`value_operator`) and the jerk at Gauss
points, whose squared norm integrates the cost exactly (:func:`jerk_cost_root`: ∫|x'''|² dt = ‖R Z‖²_F).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import PlanningError

F64 = NDArray[np.float64]

#: Coefficients (powers σ⁰..σ⁵) of the quintic Hermite basis H0..H5 on σ ∈ [0, 1].
_BASIS = np.array(
    [
        [1.0, 0.0, 0.0, -10.0, 15.0, -6.0],
        [0.0, 1.0, 0.0, -6.0, 8.0, -3.0],
        [0.0, 0.0, 0.5, -1.5, 1.5, -0.5],
        [0.0, 0.0, 0.0, 10.0, -15.0, 6.0],
        [0.0, 0.0, 0.0, -4.0, 7.0, -3.0],
        [0.0, 0.0, 0.0, 0.5, -1.0, 0.5],
    ]
)
#: Powers of h multiplying each basis function's knot value (p: 0, v: 1, a: 2).
_H_POWER = np.array([0, 1, 2, 0, 1, 2])
#: 3-point Gauss–Legendre nodes and weights on [0, 1] (exact for the quartic |jerk|²).
_GAUSS_X = 0.5 + 0.5 * np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)])
_GAUSS_W = 0.5 * np.array([5.0, 8.0, 5.0]) / 9.0


def basis(sigma: ArrayLike, derivative: int = 0) -> F64:
    """(S, 6) values of the ``derivative``-th σ-derivative of H0..H5 at ``sigma`` (S,) in [0, 1]."""
    s = np.asarray(sigma, dtype=np.float64).reshape(-1)
    coeffs = _BASIS.copy()
    powers = np.arange(6, dtype=np.float64)
    for _ in range(derivative):
        coeffs = coeffs[:, 1:] * powers[1 : coeffs.shape[1]]
        powers = np.arange(coeffs.shape[1], dtype=np.float64)
    if coeffs.shape[1] == 0:
        return np.zeros((s.shape[0], 6))
    return np.asarray(np.vander(s, coeffs.shape[1], increasing=True) @ coeffs.T, dtype=np.float64)


def _rows(knots: int, h: float, segments: NDArray[np.int64], sigma: F64, derivative: int) -> F64:
    """(S, 3K) rows mapping Z = [P; V; A] to the derivative at (segment, σ) pairs."""
    out = np.zeros((segments.shape[0], 3 * knots))
    values = basis(sigma, derivative) * (h ** (_H_POWER - derivative))[None, :]
    rows = np.arange(segments.shape[0])
    for j in range(6):
        knot = segments + (1 if j >= 3 else 0)
        block = _H_POWER[j]  # 0: positions, 1: velocities, 2: accelerations
        np.add.at(out, (rows, block * knots + knot), values[:, j])
    return out


def check_points(knots: int, per_segment: int) -> tuple[NDArray[np.int64], F64]:
    """(segment index, σ) of the check points: ``per_segment`` evenly spaced per segment (σ = j / m,
    starting at the knot), then the last knot: ``(K − 1)·m + 1`` points in time order."""
    if knots < 2 or per_segment < 1:
        raise PlanningError(f"need knots >= 2 and per_segment >= 1, got {knots}, {per_segment}")
    seg = np.repeat(np.arange(knots - 1, dtype=np.int64), per_segment)
    sig = np.tile(np.arange(per_segment, dtype=np.float64) / per_segment, knots - 1)
    return np.append(seg, knots - 2), np.append(sig, 1.0)


def value_operator(knots: int, duration: float, per_segment: int, derivative: int = 0) -> F64:
    """((K − 1)·m + 1, 3K) matrix: Z ↦ the ``derivative``-th time derivative at :func:`check_points`."""
    seg, sig = check_points(knots, per_segment)
    return _rows(knots, duration / (knots - 1), seg, sig, derivative)


def jerk_cost_root(knots: int, duration: float) -> F64:
    """(3(K − 1), 3K) matrix R with ∫₀ᵀ |x'''(t)|² dt = ‖R Z‖²_F exactly [m²/s⁵]."""
    h = duration / (knots - 1)
    seg = np.repeat(np.arange(knots - 1, dtype=np.int64), 3)
    sig = np.tile(_GAUSS_X, knots - 1)
    weights = np.sqrt(np.tile(_GAUSS_W, knots - 1) * h)
    return weights[:, None] * _rows(knots, h, seg, sig, 3)


@dataclass(frozen=True, eq=False)
class QuinticSpline:
    """A piecewise quintic Hermite curve over uniform knots (see the module doc).

    Attributes:
        duration: [s] total time T; knots at ``linspace(0, T, K)``.
        position: (K, 3) [m]; velocity: (K, 3) [m/s]; acceleration: (K, 3) [m/s²] at the knots.
    """

    duration: float
    position: F64
    velocity: F64
    acceleration: F64

    def __post_init__(self) -> None:
        arrays = [
            np.array(getattr(self, n), dtype=np.float64, copy=True)
            for n in ("position", "velocity", "acceleration")
        ]
        k = arrays[0].shape[0] if arrays[0].ndim == 2 else 0
        if k < 2 or any(a.shape != (k, 3) or not np.isfinite(a).all() for a in arrays):
            raise PlanningError("position, velocity and acceleration must be finite (K >= 2, 3) arrays")
        if not (np.isfinite(self.duration) and self.duration > 0.0):
            raise PlanningError(f"duration must be > 0 [s], got {self.duration}")
        for name, arr in zip(("position", "velocity", "acceleration"), arrays, strict=True):
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "duration", float(self.duration))

    @property
    def knots(self) -> int:
        """Number of knots K."""
        return int(self.position.shape[0])

    @property
    def knot_times(self) -> F64:
        """(K,) [s] knot times."""
        return np.linspace(0.0, self.duration, self.knots)

    def stacked(self) -> F64:
        """(3K, 3) Z = [P; V; A]."""
        return np.vstack([self.position, self.velocity, self.acceleration])

    def evaluate(self, times: ArrayLike, derivative: int = 0) -> F64:
        """(N, 3) the ``derivative``-th time derivative [m/s^d] at ``times`` (N,) [s] (clamped to [0, T])."""
        t = np.clip(np.asarray(times, dtype=np.float64).reshape(-1), 0.0, self.duration)
        h = self.duration / (self.knots - 1)
        seg = np.minimum(np.floor(t / h).astype(np.int64), self.knots - 2)
        sig = np.clip(t / h - seg, 0.0, 1.0)
        return np.asarray(_rows(self.knots, h, seg, sig, derivative) @ self.stacked(), dtype=np.float64)

    def jerk_cost(self) -> float:
        """∫₀ᵀ |x'''|² dt [m²/s⁵] (exact)."""
        r = jerk_cost_root(self.knots, self.duration) @ self.stacked()
        return float(np.sum(r * r))


def resample_uniform(positions: ArrayLike, count: int) -> F64:
    """(count, 3) [m] positions linearly resampled at ``count`` uniform times from (N, 3) positions
    that are themselves uniform in time (N >= 2)."""
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 2 or not np.isfinite(p).all():
        raise PlanningError(f"an initial path must be finite (N >= 2, 3) positions [m], got {p.shape}")
    src = np.linspace(0.0, 1.0, p.shape[0])
    dst = np.linspace(0.0, 1.0, count)
    return np.stack([np.interp(dst, src, p[:, a]) for a in range(3)], axis=1)


def rest_to_rest(
    start: Sequence[float] | F64, goal: Sequence[float] | F64, duration: float, knots: int
) -> QuinticSpline:
    """The free-space minimum-jerk motion (straight, ``10τ³ − 15τ⁴ + 6τ⁵``) as a :class:`QuinticSpline`."""
    a = np.asarray(start, dtype=np.float64).reshape(3)
    b = np.asarray(goal, dtype=np.float64).reshape(3)
    tau = np.linspace(0.0, 1.0, knots)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = (30.0 * tau**2 - 60.0 * tau**3 + 30.0 * tau**4) / duration
    dds = (60.0 * tau - 180.0 * tau**2 + 120.0 * tau**3) / duration**2
    d = b - a
    return QuinticSpline(duration, a + np.outer(s, d), np.outer(ds, d), np.outer(dds, d))


def initial_spline(
    initial: ArrayLike | None, start: F64, goal: F64, duration: float, *, knots: int, smoothing: float
) -> QuinticSpline:
    """Warm start: the curve minimizing ``jerk / jerk_line + smoothing · mean |p_k − initial_k|² / m²``
    over the interior knot values (linear least squares, ends fixed at rest); ``initial_k`` are the
    ``initial`` path's (N, 3) [m] positions (uniform in time) resampled at the knot times. None = the
    straight minimum-jerk line."""
    if initial is None:
        return rest_to_rest(start, goal, duration, knots)
    target = resample_uniform(initial, knots)
    scale = 720.0 * max(float(np.linalg.norm(goal - start)), 0.05) ** 2 / duration**5
    root = jerk_cost_root(knots, duration) / math.sqrt(scale)
    fixed = np.zeros((3 * knots, 3))
    fixed[0], fixed[knots - 1] = start, goal
    free = np.r_[1 : knots - 1, knots + 1 : 2 * knots - 1, 2 * knots + 1 : 3 * knots - 1]
    weight = math.sqrt(smoothing / knots)
    fit = np.zeros((knots - 2, free.size))
    fit[:, : knots - 2] = weight * np.eye(knots - 2)
    rows = sp.csc_matrix(np.vstack([root[:, free], fit]))
    rhs = np.vstack([-root @ fixed, weight * target[1:-1]])
    # Sparse normal equations (SuperLU): no multi-threaded dense LAPACK for a banded problem.
    sol = np.asarray(spla.spsolve((rows.T @ rows).tocsc(), rows.T @ rhs), dtype=np.float64).reshape(-1, 3)
    z = fixed.copy()
    z[free] = sol
    return QuinticSpline(duration, z[:knots], z[knots : 2 * knots], z[2 * knots :])
