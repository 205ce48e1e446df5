"""The minimum-jerk ease with which the retargeting's corrections fade in and out (carries re-aimed, grips
turned, grasp depths, a drawer's contents followed, clearance blends)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["ease"]

F64 = NDArray[np.float64]


def ease(u: F64) -> F64:
    """Minimum-jerk ease 0 -> 1 (``10 u^3 - 15 u^4 + 6 u^5``) of ``u`` (any shape) clipped to [0, 1]."""
    u = np.clip(u, 0.0, 1.0)
    return np.asarray(10 * u**3 - 15 * u**4 + 6 * u**5)
