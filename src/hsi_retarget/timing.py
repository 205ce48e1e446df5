"""Time-parameterization: stretch the time axis of a configuration path until it respects the robot's joint
velocity and acceleration limits.

Finite differences (the same definitions the checks use): with ``h_k = t_{k+1} - t_k``,
``v_k = (q_{k+1} - q_k) / h_k`` (per interval) and ``a_k = (v_k - v_{k-1}) / ((h_{k-1} + h_k) / 2)``
(per interior sample). Stretching interval k by ``s_k`` divides ``v_k`` by ``s_k``, and a uniform stretch
``s`` divides accelerations by ``s^2``. The scale profile starts at 1, is raised where a limit is exceeded
(by the velocity ratio or the square root of the acceleration ratio), widened and smoothed over
``window`` so that the time warp itself adds little acceleration, and the check is repeated; if that does
not converge in ``iterations`` rounds, a uniform stretch finishes the job (exact by the scaling law).
Joints with an infinite limit (a floating base) and ``exclude`` d indices are not limited.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter1d, uniform_filter1d

from hsi_planning.errors import ConfigError, RetargetError

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class TimingConfig:
    """Limits usage and smoothing of :func:`time_parameterize`."""

    velocity_fraction: float = 0.95  #: [-] fraction of each joint velocity limit used
    acceleration_fraction: float = 0.95  #: [-] fraction of each joint acceleration limit used
    window: float = 0.25  #: [s] width over which a local stretch is spread (and smoothed)
    iterations: int = 40  #: [-] local stretching rounds before the uniform fallback

    def __post_init__(self) -> None:
        for name in ("velocity_fraction", "acceleration_fraction"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ConfigError(f"TimingConfig.{name} must be in (0, 1], got {getattr(self, name)}")
        if not self.window >= 0.0 or self.iterations < 0:
            raise ConfigError("TimingConfig.window must be >= 0 s and iterations >= 0")


@dataclass(frozen=True, eq=False)
class TimingResult:
    """A re-timed path: ``t`` (T,) [s] new sample times, ``scale`` (T-1,) [-] stretch of every interval,
    the worst velocity / acceleration ratios (value / limit) before and after, and the stretched segments."""

    t: F64
    scale: F64
    velocity_ratio_in: float
    acceleration_ratio_in: float
    velocity_ratio: float
    acceleration_ratio: float
    uniform_fallback: bool

    def segments(self, t_in: F64, threshold: float = 1.001) -> list[dict[str, float]]:
        """Stretched runs: original ``t_start``/``t_end`` [s] and ``max_scale`` [-]."""
        mask = np.concatenate([[False], self.scale > threshold, [False]]).astype(np.int8)
        d = np.diff(mask)
        out = []
        for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
            out.append(
                {
                    "t_start": float(t_in[a]),
                    "t_end": float(t_in[b]),
                    "max_scale": float(self.scale[a:b].max()),
                }
            )
        return out

    def summary(self, t_in: F64) -> dict[str, Any]:
        """Plain dict for trajectory metadata."""
        return {
            "duration_in_s": float(t_in[-1] - t_in[0]),
            "duration_out_s": float(self.t[-1] - self.t[0]),
            "max_scale": float(self.scale.max()) if self.scale.size else 1.0,
            "velocity_ratio_in": self.velocity_ratio_in,
            "acceleration_ratio_in": self.acceleration_ratio_in,
            "velocity_ratio": self.velocity_ratio,
            "acceleration_ratio": self.acceleration_ratio,
            "uniform_fallback": self.uniform_fallback,
            "segments": self.segments(t_in),
        }


def finite_differences(t: F64, q: F64) -> tuple[F64, F64]:
    """Velocities (T-1, n) per interval and accelerations (T-2, n) per interior sample (module docstring)."""
    h = np.diff(np.asarray(t, dtype=np.float64))
    v = np.diff(np.asarray(q, dtype=np.float64), axis=0) / h[:, None]
    a = np.diff(v, axis=0) / (0.5 * (h[:-1] + h[1:]))[:, None]
    return v, a


def limit_ratios(t: F64, q: F64, v_max: F64, a_max: F64) -> tuple[F64, F64]:
    """Worst |v| / v_max per interval (T-1,) and |a| / a_max per interior sample (T-2,) [-] (0 where no
    limit applies: infinite limits)."""
    v, a = finite_differences(t, q)
    inv_v = np.where(np.isfinite(v_max), 1.0 / np.asarray(v_max), 0.0)
    inv_a = np.where(np.isfinite(a_max), 1.0 / np.asarray(a_max), 0.0)
    rv = np.max(np.abs(v) * inv_v, axis=1) if v.size else np.zeros(v.shape[0])
    ra = np.max(np.abs(a) * inv_a, axis=1) if a.size else np.zeros(a.shape[0])
    return rv, ra


def time_parameterize(
    t: F64,
    q: F64,
    v_max: F64,
    a_max: F64,
    *,
    config: TimingConfig | None = None,
    exclude: NDArray[np.int64] | None = None,
) -> TimingResult:
    """Stretch the times ``t`` (T,) [s] of the path ``q`` (T, n) (1-DoF coordinates: [rad] or [m]) until
    ``|v| <= velocity_fraction * v_max`` and ``|a| <= acceleration_fraction * a_max`` (n,) hold.

    Raises:
        RetargetError: mismatched shapes, non-increasing times or non-positive limits.
    """
    cfg = config or TimingConfig()
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    q = np.asarray(q, dtype=np.float64)
    vm = np.array(v_max, dtype=np.float64).reshape(-1) * cfg.velocity_fraction
    am = np.array(a_max, dtype=np.float64).reshape(-1) * cfg.acceleration_fraction
    if q.ndim != 2 or q.shape[0] != t.shape[0] or vm.shape != (q.shape[1],) or am.shape != vm.shape:
        raise RetargetError(
            f"time_parameterize needs t (T,), q (T, n), limits (n,); got {t.shape}, {q.shape}"
        )
    if t.shape[0] > 1 and np.any(np.diff(t) <= 0.0):
        raise RetargetError("time_parameterize needs strictly increasing times")
    if np.any(vm <= 0.0) or np.any(am <= 0.0):
        raise RetargetError("joint velocity and acceleration limits must be > 0")
    if exclude is not None and len(exclude):
        vm[exclude], am[exclude] = np.inf, np.inf
    h0 = np.diff(t)
    scale = np.ones(h0.shape[0])
    if t.shape[0] < 3:
        rv, _ = limit_ratios(t, q, vm, am)
        worst = float(rv.max()) if rv.size else 0.0
        scale *= max(1.0, worst)
        t_new = t[0] + np.concatenate([[0.0], np.cumsum(h0 * scale)])
        frac = cfg.velocity_fraction
        return TimingResult(t_new, scale, worst * frac, 0.0, worst / max(1.0, worst) * frac, 0.0, False)

    def times(s: F64) -> F64:
        return np.asarray(t[0] + np.concatenate([[0.0], np.cumsum(h0 * s)]))

    rv, ra = limit_ratios(t, q, vm, am)
    rv_in, ra_in = float(rv.max()), float(ra.max())
    median_h = float(np.median(h0))
    width = max(1, round(cfg.window / median_h)) if median_h > 0 else 1
    fallback = False
    for _ in range(cfg.iterations):
        rv, ra = limit_ratios(times(scale), q, vm, am)
        if rv.max() <= 1.0 and ra.max() <= 1.0:
            break
        need = np.maximum(rv, 1.0)
        acc = np.sqrt(np.maximum(ra, 1.0))
        need[:-1] = np.maximum(need[:-1], acc)
        need[1:] = np.maximum(need[1:], acc)
        need = np.where(need > 1.0, need * 1.02, 1.0)  # a little extra: converge in fewer rounds
        spread = maximum_filter1d(need, size=2 * width + 1, mode="nearest")
        scale = scale * np.maximum(uniform_filter1d(spread, size=width, mode="nearest"), need)
    rv, ra = limit_ratios(times(scale), q, vm, am)
    worst = max(float(rv.max()), float(np.sqrt(ra.max())))
    if worst > 1.0:
        fallback = True
        scale = scale * worst * (1.0 + 1e-9)
        rv, ra = limit_ratios(times(scale), q, vm, am)
    return TimingResult(
        times(scale),
        scale,
        rv_in * cfg.velocity_fraction,
        ra_in * cfg.acceleration_fraction,
        float(rv.max()) * cfg.velocity_fraction,
        float(ra.max()) * cfg.acceleration_fraction,
        fallback,
    )
