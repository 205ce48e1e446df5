"""Zero-phase low-pass of an orientation path, its end orientations kept exactly.

The learned planner's wrist orientations jitter from sample to sample (drawer and shelf cases: up to 80 deg
within one 8 ms step, a 95th-percentile rate of 400-1400 deg/s; the minimum-jerk planner's stay below
100 deg/s). The gripper goals put the TCP up to 9 cm along the planned wrist axis
(:mod:`hsi_retarget.grasp_depth`), so that jitter became TCP goal jumps of up to 10 cm between two frames,
which the humanoid's IK followed with its pelvis (a jolt in MuJoCo that put a finger on a shelf board).
:func:`smooth_rotations` filters the quaternion components (signs made continuous, zero-phase Butterworth,
renormalized) and then turns the result back onto the path's first and last orientation with a
correction that eases linearly between the two (the contact orientations at a segment's ends stay as
planned).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import RetargetError
from hsi_planning.mocap import lowpass

__all__ = ["smooth_rotations"]

F64 = NDArray[np.float64]
_MIN_SAMPLES = 16  #: [-] shorter paths are returned as they are (too short to filter)


def smooth_rotations(t: F64, quats: F64, cutoff_hz: float) -> F64:
    """Quaternions (T, 4) (scalar last) of ``quats`` (T, 4) sampled at ``t`` (T,) [s] low-passed at
    ``cutoff_hz`` [Hz] with the first and last orientation unchanged; ``cutoff_hz`` 0, fewer than 16 samples
    or a cut-off at or above the Nyquist rate: a copy of ``quats``.

    Raises:
        RetargetError: mismatched shapes, non-finite values or non-increasing times.
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    q = np.array(quats, dtype=np.float64)
    if q.ndim != 2 or q.shape != (t.shape[0], 4) or not (np.isfinite(q).all() and np.isfinite(t).all()):
        raise RetargetError(
            f"smooth_rotations needs finite t (T,) and quats (T, 4), got {t.shape}, {q.shape}"
        )
    if t.shape[0] > 1 and np.any(np.diff(t) <= 0.0):
        raise RetargetError("smooth_rotations needs strictly increasing times")
    if cutoff_hz < 0.0:
        raise RetargetError(f"smooth_rotations: cutoff_hz must be >= 0 Hz, got {cutoff_hz}")
    n = t.shape[0]
    if cutoff_hz == 0.0 or n < _MIN_SAMPLES:
        return q
    fs = (n - 1) / float(t[-1] - t[0])
    if cutoff_hz >= 0.5 * fs:
        return q
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    flip = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=1) < 0.0, -1.0, 1.0))
    q[1:] *= flip[:, None]  # one hemisphere along the path
    filtered = lowpass(q, fs, cutoff_hz)
    filtered /= np.linalg.norm(filtered, axis=1, keepdims=True)
    smooth = Rotation.from_quat(filtered)
    exact = Rotation.from_quat(q[[0, -1]])
    ends = (smooth[[0, -1]].inv() * exact).as_rotvec()  # (2, 3) corrections at the ends
    s = ((t - t[0]) / (t[-1] - t[0]))[:, None]
    out = smooth * Rotation.from_rotvec((1.0 - s) * ends[0] + s * ends[1])
    return np.asarray(out.as_quat())
