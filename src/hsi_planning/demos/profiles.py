"""Timing of a geometric wrist path: bell-shaped speed, two-thirds power law, Fitts-like duration.

A reach is timed in two layers (Flash & Hogan 1985; Lacquaniti, Terzuolo & Viviani 1983):

- a global bell-shaped speed profile over normalized time tau in [0, 1]: the Beta-like shape
  ``v(tau) ∝ tau^a (1 - tau)^b`` whose peak lies at ``a / (a + b)`` (``a = b = 2`` is minimum jerk);
- a local modulation ``m(s) = ((kappa(s) + kappa_0) / kappa_ref)^beta`` of the speed along the path
  (speed ∝ curvature^beta, beta ≈ -1/3 for the two-thirds power law), applied by slowing the clock:
  ``dt/dtau = 1 / m``, so the path speed becomes ``v(tau) · m``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.special import betainc

from hsi_planning.errors import PlanningError

#: [-] smallest exponent of the bell: > 1 keeps the acceleration continuous (zero) at start and end
MIN_BELL_EXPONENT = 1.5


def bell_exponents(peak: float, sharpness: float) -> tuple[float, float]:
    """Exponents ``(a, b)`` of ``tau^a (1 - tau)^b`` with its maximum at ``peak`` (in (0, 1)) and
    ``a + b = sharpness`` (4 = minimum-jerk width), widened so that ``min(a, b) >= MIN_BELL_EXPONENT``
    (smooth start and stop: zero acceleration at both ends)."""
    if not 0.0 < peak < 1.0 or sharpness <= 0.0:
        raise PlanningError(f"bell profile needs 0 < peak < 1 and sharpness > 0, got {peak}, {sharpness}")
    total = max(sharpness, MIN_BELL_EXPONENT / peak, MIN_BELL_EXPONENT / (1.0 - peak))
    return total * peak, total * (1.0 - peak)


def bell_progress(tau: NDArray[np.float64], peak: float, sharpness: float) -> NDArray[np.float64]:
    """(T,) normalized distance travelled in [0, 1] at normalized times ``tau`` (T,) for the bell profile
    peaking at ``peak`` (the regularized incomplete beta function)."""
    a, b = bell_exponents(peak, sharpness)
    return np.asarray(betainc(a + 1.0, b + 1.0, np.clip(tau, 0.0, 1.0)), dtype=np.float64)


def fitts_duration(distance: float, intercept: float, slope: float, width: float) -> float:
    """Movement time [s] for a reach over ``distance`` [m] to a target of ``width`` [m]:
    ``intercept + slope · log2(1 + 2 distance / width)`` (Fitts 1954, Shannon form) [s]."""
    return intercept + slope * math.log2(1.0 + 2.0 * max(distance, 0.0) / width)


def arc_length(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) [m] cumulative arc length of a polyline ``points`` (N, 3) [m], starting at 0."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def path_curvature(points: NDArray[np.float64], smooth_length: float = 0.02) -> NDArray[np.float64]:
    """(N,) [1/m] geometric curvature of a densely sampled path ``points`` (N, 3) [m].

    The path is resampled uniformly in arc length, differentiated twice with respect to arc length
    (``kappa = |d²x/ds²|``) after a moving-average of ``smooth_length`` [m], and mapped back.
    """
    s = arc_length(points)
    total = float(s[-1])
    if total <= 0.0 or len(points) < 5:
        return np.zeros(len(points))
    n = max(len(points), 64)
    su = np.linspace(0.0, total, n)
    xu = np.column_stack([np.interp(su, s, points[:, k]) for k in range(3)])
    ds = su[1] - su[0]
    width = max(1, round(smooth_length / ds))
    if width > 1:
        kernel = np.ones(width) / width
        pad = np.pad(xu, ((width, width), (0, 0)), mode="reflect", reflect_type="odd")
        xu = np.column_stack([np.convolve(pad[:, k], kernel, mode="same") for k in range(3)])[width:-width]
    d2 = np.gradient(np.gradient(xu, ds, axis=0), ds, axis=0)
    kappa = np.linalg.norm(d2, axis=1)
    return np.asarray(np.interp(s, su, kappa), dtype=np.float64)


def power_law_modulation(
    kappa: NDArray[np.float64], exponent: float, offset: float, lower: float, upper: float
) -> NDArray[np.float64]:
    """(N,) speed factor ``((kappa + offset) / median(kappa + offset))^exponent`` clipped to
    ``[lower, upper]``; ``kappa`` (N,) [1/m], ``offset`` [1/m], ``exponent`` e.g. -1/3."""
    k = np.asarray(kappa, dtype=np.float64) + offset
    ref = float(np.median(k))
    if ref <= 0.0:
        return np.ones_like(k)
    return np.asarray(np.clip((k / ref) ** exponent, lower, upper), dtype=np.float64)


def time_path(
    arc: NDArray[np.float64],
    modulation: NDArray[np.float64],
    *,
    peak: float,
    sharpness: float,
    duration: float,
    rate: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Time a path given by its cumulative arc length ``arc`` (N,) [m].

    Args:
        arc: (N,) [m] increasing arc length of the dense path samples.
        modulation: (N,) [-] local speed factor per path sample (power law, slowing inside containers).
        peak: normalized time of the global speed peak, before modulation, in (0, 1).
        sharpness: ``a + b`` of the bell (4 = minimum jerk).
        duration: wanted total time [s] (quantized to whole samples).
        rate: sample rate [Hz].

    Returns:
        ``t`` (T,) [s] sample times ``k / rate`` and ``s`` (T,) [m] arc length at each sample, with
        ``s[0] = 0`` and ``s[-1] = arc[-1]`` exactly.
    """
    total = float(arc[-1])
    tau = np.linspace(0.0, 1.0, 4001)
    s_tau = total * bell_progress(tau, peak, sharpness)
    m_tau = np.interp(s_tau, arc, modulation)
    inv = 1.0 / np.maximum(m_tau, 1e-6)
    clock = np.concatenate([[0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(tau))])
    clock /= clock[-1]
    n = max(2, round(duration * rate))
    t = np.arange(n + 1, dtype=np.float64) / rate
    s = np.interp(t / t[-1], clock, s_tau)
    s[0], s[-1] = 0.0, total
    return t, np.maximum.accumulate(s)
