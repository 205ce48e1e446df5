"""Kinematic metrics of a hand/wrist path: speed, timing, path shape, curvature, acceleration, jerk.

All functions take positions ``pos: (T, D) [m]`` (D = 2 or 3) sampled at times ``t: (T,) [s]``
(strictly increasing, not necessarily uniform) and differentiate with second-order central
differences (:func:`numpy.gradient`). Filter noisy data first (e.g.
:func:`hsi_planning.mocap.reach.lowpass`).

References:
    - Flash & Hogan (1985), *The coordination of arm movements*, J. Neurosci. 5(7) — bell-shaped speed.
    - Lacquaniti, Terzuolo & Viviani (1983), *The law relating the kinematic and figural aspects of
      drawing movements*, Acta Psychol. 54 — two-thirds power law, v = k κ^(−1/3).
    - Huang et al. (2024), CHOICE — unsmoothness as mean acceleration, RMS curvature, path length.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.stats import theilslopes

from hsi_planning.errors import MotionDataError

FloatArray = NDArray[np.float64]


def _check(
    pos: FloatArray, t: FloatArray | None = None, min_samples: int = 3
) -> tuple[FloatArray, FloatArray]:
    p = np.asarray(pos, dtype=np.float64)
    if p.ndim == 1:
        p = p[:, None]
    if p.ndim != 2 or p.shape[0] < min_samples or p.shape[1] not in (1, 2, 3):
        raise MotionDataError(f"positions must be (T>={min_samples}, D<=3) [m], got shape {np.shape(pos)}")
    if not np.all(np.isfinite(p)):
        raise MotionDataError("positions contain NaN or infinity")
    if t is None:
        return p, np.arange(p.shape[0], dtype=np.float64)
    tt = np.asarray(t, dtype=np.float64).reshape(-1)
    if tt.shape[0] != p.shape[0]:
        raise MotionDataError(f"t has {tt.shape[0]} samples but positions have {p.shape[0]}")
    if not np.all(np.diff(tt) > 0):
        raise MotionDataError("t must be strictly increasing [s]")
    return p, tt


def _pad3(x: FloatArray) -> FloatArray:
    return np.pad(x, ((0, 0), (0, 3 - x.shape[1]))) if x.shape[1] < 3 else x


def velocity(pos: FloatArray, t: FloatArray) -> FloatArray:
    """Velocity (T, D) [m/s] of ``pos: (T, D) [m]`` at times ``t: (T,) [s]``."""
    p, tt = _check(pos, t)
    return np.gradient(p, tt, axis=0)


def acceleration(pos: FloatArray, t: FloatArray) -> FloatArray:
    """Acceleration (T, D) [m/s²]."""
    p, tt = _check(pos, t)
    return np.gradient(np.gradient(p, tt, axis=0), tt, axis=0)


def jerk(pos: FloatArray, t: FloatArray) -> FloatArray:
    """Jerk (T, D) [m/s³] (needs T >= 4)."""
    p, tt = _check(pos, t, min_samples=4)
    return np.gradient(acceleration(p, tt), tt, axis=0)


def speed_profile(pos: FloatArray, t: FloatArray) -> FloatArray:
    """Speed |v| (T,) [m/s] of ``pos: (T, D) [m]`` sampled at ``t: (T,) [s]``."""
    return np.asarray(np.linalg.norm(velocity(pos, t), axis=1))


def normalized_peak_speed_time(pos: FloatArray, t: FloatArray) -> float:
    """Time of peak speed as a fraction of the duration, (t_peak − t_0) / (t_end − t_0) [-].

    0.5 for a symmetric (minimum-jerk) profile; human grasping reaches peak earlier (≈ 0.3–0.45).
    """
    p, tt = _check(pos, t)
    v = speed_profile(p, tt)
    return float((tt[int(np.argmax(v))] - tt[0]) / (tt[-1] - tt[0]))


def path_length(pos: FloatArray) -> float:
    """Length of the polyline through ``pos: (T, D) [m]``, in [m]."""
    p, _ = _check(pos, None, min_samples=2)
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def chord_length(pos: FloatArray) -> float:
    """Straight-line distance [m] from the first to the last sample."""
    p, _ = _check(pos, None, min_samples=2)
    return float(np.linalg.norm(p[-1] - p[0]))


def path_deviation(pos: FloatArray) -> FloatArray:
    """Perpendicular distance (T,) [m] of every sample from the line through the first and last sample."""
    p, _ = _check(pos, None, min_samples=2)
    chord = p[-1] - p[0]
    length = float(np.linalg.norm(chord))
    if length < 1e-9:
        raise MotionDataError("start and end coincide: the chord (and the deviation ratio) is undefined")
    rel = p - p[0]
    along = rel @ (chord / length)
    return np.asarray(np.linalg.norm(rel - along[:, None] * (chord / length)[None, :], axis=1))


def max_path_deviation_ratio(pos: FloatArray) -> float:
    """Maximum perpendicular distance from the start–end chord divided by the chord length [-].

    0 for a straight path; human reaches ≈ 0.05–0.15 (HDM05 ``grabHighR``).
    """
    return float(np.max(path_deviation(pos)) / chord_length(pos))


def curvature(pos: FloatArray, t: FloatArray, min_speed: float = 1e-6) -> FloatArray:
    """Path curvature κ = |v × a| / |v|³ (T,) [1/m]; NaN where the speed is below ``min_speed`` [m/s].

    2D paths are treated as lying in the x–y plane. A circle of radius r gives κ = 1/r.
    """
    p, tt = _check(pos, t)
    v = _pad3(np.gradient(p, tt, axis=0))
    a = _pad3(np.gradient(np.gradient(p, tt, axis=0), tt, axis=0))
    speed = np.linalg.norm(v, axis=1)
    kappa = np.full(speed.shape, np.nan)
    ok = speed > min_speed
    kappa[ok] = np.linalg.norm(np.cross(v[ok], a[ok]), axis=1) / speed[ok] ** 3
    return kappa


def _moving(speed: FloatArray, fraction: float) -> FloatArray:
    """Boolean mask of the samples moving at least ``fraction`` of the peak speed."""
    if not 0.0 <= fraction < 1.0:
        raise MotionDataError(f"speed fraction must be in [0, 1), got {fraction}")
    return np.asarray(speed >= fraction * np.max(speed))


def rms_curvature(pos: FloatArray, t: FloatArray, min_speed_fraction: float = 0.05) -> float:
    """Root-mean-square curvature [1/m] over the samples moving faster than ``min_speed_fraction`` of peak."""
    p, tt = _check(pos, t)
    speed = speed_profile(p, tt)
    if np.max(speed) <= 0:
        raise MotionDataError("the path does not move: curvature is undefined")
    kappa = curvature(p, tt)
    sel = _moving(speed, min_speed_fraction) & np.isfinite(kappa)
    return float(np.sqrt(np.mean(kappa[sel] ** 2)))


def speed_curvature_exponent(
    pos: FloatArray,
    t: FloatArray,
    min_speed_fraction: float = 0.2,
    min_curvature: float = 1e-3,
) -> float:
    """Exponent β of the speed–curvature power law v = k κ^β [-].

    β is the Theil–Sen (robust) slope of log v against log κ over the samples whose speed is at least
    ``min_speed_fraction`` of the peak (this drops the slow, ill-defined ends of a reach) and whose
    curvature is at least ``min_curvature`` [1/m] (drops near-straight stretches, where κ is noise).
    The two-thirds power law (Lacquaniti et al. 1983) gives β = −1/3.

    Raises:
        MotionDataError: fewer than 10 usable samples.
    """
    p, tt = _check(pos, t)
    speed = speed_profile(p, tt)
    if np.max(speed) <= 0:
        raise MotionDataError("the path does not move: the speed–curvature exponent is undefined")
    kappa = curvature(p, tt)
    sel = _moving(speed, min_speed_fraction) & np.isfinite(kappa) & (kappa >= min_curvature)
    if np.count_nonzero(sel) < 10:
        raise MotionDataError(
            f"only {np.count_nonzero(sel)} samples with speed >= {min_speed_fraction} of peak and "
            f"curvature >= {min_curvature} 1/m; need 10 for the speed–curvature regression"
        )
    result = theilslopes(np.log(speed[sel]), np.log(kappa[sel]))
    return float(result[0])


def mean_acceleration(pos: FloatArray, t: FloatArray) -> float:
    """Unsmoothness as in CHOICE: time-average of |a| [m/s²] (trapezoidal in time)."""
    p, tt = _check(pos, t)
    acc = np.linalg.norm(acceleration(p, tt), axis=1)
    return float(np.trapezoid(acc, tt) / (tt[-1] - tt[0]))


def integrated_squared_jerk(pos: FloatArray, t: FloatArray) -> float:
    """∫ |d³x/dt³|² dt [m²/s⁵] (trapezoidal); the quantity a minimum-jerk trajectory minimizes."""
    p, tt = _check(pos, t, min_samples=4)
    jj = np.sum(jerk(p, tt) ** 2, axis=1)
    return float(np.trapezoid(jj, tt))
