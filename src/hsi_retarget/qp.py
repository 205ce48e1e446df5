"""Small dense convex QPs with box and row bounds, solved by DAQP (a dual active-set solver: ~10 us for
the IK's 16-variable, 24-row problems, warm-startable, no setup)."""

from __future__ import annotations

import daqp
import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
QP_INF = 1e30  #: [-] DAQP's infinite bound
_EQUALITY = 5  #: DAQP's constraint sense of an equality row


def solve_qp(
    hess: F64, grad: F64, rows: F64, *, row_bounds: tuple[F64, F64], box: tuple[F64, F64]
) -> tuple[F64, bool]:
    """``min 0.5 x^T H x + g^T x`` s.t. ``lo <= rows x <= hi`` (``row_bounds``; a row with ``lo == hi`` is
    an equality) and ``lbx <= x <= ubx`` (``box``). ``hess`` (n, n) positive definite, ``grad`` (n,),
    ``rows`` (m, n). Returns x (n,) and whether DAQP found the optimum (else x is its last iterate)."""
    lo, hi = row_bounds
    lbx, ubx = box
    upper = np.concatenate([ubx, np.minimum(hi, QP_INF)])
    lower = np.concatenate([lbx, np.maximum(lo, -QP_INF)])
    sense = np.zeros(upper.shape[0], dtype=np.int32)
    sense[lbx.shape[0] :][lo == hi] = _EQUALITY
    h, g, a = (np.ascontiguousarray(m, dtype=np.float64) for m in (hess, grad, rows))
    x, _, flag, _ = daqp.solve(h, g, a, upper, lower, sense)
    return np.asarray(x, dtype=np.float64).reshape(-1), int(flag) >= 1  # 1 optimal, 2 soft optimal
