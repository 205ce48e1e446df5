"""Human-like wrist orientation along a reach: slerp with a minimum-jerk phase, most rotation mid-reach.

Quaternions are ``[x y z w]`` (scipy's scalar-last convention, as in :class:`WristTrajectory`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation, Slerp

from hsi_planning.errors import PlanningError


def unit_quaternion(q: ArrayLike, name: str = "quaternion") -> NDArray[np.float64]:
    """(4,) unit quaternion [x y z w] from ``q``; raises :class:`PlanningError` for a zero or bad one."""
    arr = np.asarray(q, dtype=np.float64).reshape(-1)
    norm = float(np.linalg.norm(arr)) if arr.shape == (4,) else 0.0
    if arr.shape != (4,) or not np.isfinite(arr).all() or norm < 1e-9:
        raise PlanningError(f"{name} must be a finite non-zero quaternion [x y z w], got {q!r}")
    return arr / norm


def rotation_phase(tau: NDArray[np.float64], start: float, end: float) -> NDArray[np.float64]:
    """(T,) rotation fraction in [0, 1] at normalized times ``tau`` (T,): 0 before ``start``, 1 after
    ``end``, minimum-jerk ``10 x³ - 15 x⁴ + 6 x⁵`` in between (most rotation mid-way)."""
    if not 0.0 <= start < end <= 1.0:
        raise PlanningError(f"rotation phase needs 0 <= start < end <= 1, got {start}, {end}")
    x = np.clip((np.asarray(tau, dtype=np.float64) - start) / (end - start), 0.0, 1.0)
    return np.asarray(x**3 * (10.0 - 15.0 * x + 6.0 * x**2), dtype=np.float64)


def interpolate_orientation(
    q_start: NDArray[np.float64],
    q_end: NDArray[np.float64],
    phase: NDArray[np.float64],
    noise: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """(T, 4) unit quaternions [x y z w] slerped from ``q_start`` to ``q_end`` (4,) along the shortest arc.

    Args:
        q_start: (4,) start orientation.
        q_end: (4,) end orientation.
        phase: (T,) rotation fraction in [0, 1] per sample.
        noise: optional (T, 3) [rad] rotation vectors applied on top (world frame); must vanish where the
            orientation has to be exact (first and last sample).
    """
    rots = Rotation.from_quat(np.vstack([q_start, q_end]))
    slerp = Slerp([0.0, 1.0], rots)
    out = slerp(np.clip(phase, 0.0, 1.0))
    if noise is not None:
        out = Rotation.from_rotvec(np.asarray(noise, dtype=np.float64)) * out
    quat = np.asarray(out.as_quat(), dtype=np.float64)
    # keep a continuous sign (no hemisphere jumps between samples)
    flips = np.einsum("ij,ij->i", quat[1:], quat[:-1]) < 0.0
    sign = np.concatenate([[1.0], np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)])
    quat *= sign[:, None]
    if np.dot(quat[0], q_start) < 0.0:
        quat = -quat
    return np.asarray(quat / np.linalg.norm(quat, axis=1, keepdims=True), dtype=np.float64)


def smooth_rotation_noise(
    tau: NDArray[np.float64], amplitude: float, rng: np.random.Generator, modes: int = 2
) -> NDArray[np.float64]:
    """(T, 3) [rad] smooth random rotation vectors with standard deviation ``amplitude`` [rad] mid-reach,
    vanishing (value and slope) at ``tau = 0`` and ``tau = 1``."""
    tau = np.asarray(tau, dtype=np.float64)
    envelope = np.sin(np.pi * tau) ** 2
    coeff = rng.normal(0.0, amplitude, size=(modes, 3))
    basis = np.stack([np.sin((k + 1) * np.pi * tau) for k in range(modes)], axis=1)
    return np.asarray(envelope[:, None] * (basis @ coeff), dtype=np.float64)
