"""Small dense convex QPs with box and row bounds, solved by DAQP (a dual active-set solver: ~10 us for
the IK's 16-variable, 24-row problems, warm-startable, no setup)."""

from __future__ import annotations

import daqp
import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
QP_INF = 1e30  #: [-] DAQP's infinite bound
_EQUALITY = 5  #: DAQP's constraint sense of an equality row
_STIFF = 1e4  #: [-] weight of the equality rows turned into tasks (:func:`solve_cascade`)


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


def solve_cascade(
    hess: F64, grad: F64, rows: F64, row_bounds: tuple[F64, F64], box: tuple[F64, F64]
) -> tuple[F64, bool, int]:
    """The IK step's QP ``min 1/2 dx^T hess dx + grad^T dx`` with rows ``lo <= rows dx <= hi`` (equality rows:
    ``lo == hi``; inequality rows: ``hi = inf``) and ``box`` (lbx, ubx), retried while infeasible: level 1
    with the inequality rows relaxed to ``lo <= 0`` ("do not get closer"), level 2 also with the equality rows
    as stiff tasks (skipped without equality rows), level 3 without any row.

    Returns:
        (dx, solved, level).
    """
    row_lo, row_hi = row_bounds
    eq = np.isfinite(row_hi)
    dx, ok, level = np.zeros(grad.shape[0]), False, 0
    for level in range(4):
        if level == 2 and not eq.any():  # level 2 would repeat level 1
            continue
        lo, hi = np.array(row_lo, dtype=np.float64), np.array(row_hi, dtype=np.float64)
        if level in (1, 2):
            lo[~eq] = np.minimum(lo[~eq], 0.0)
        h, g, a = hess, grad, rows
        if level >= 2:
            h = hess + _STIFF * rows[eq].T @ rows[eq]
            g = grad - _STIFF * rows[eq].T @ hi[eq]
            keep = ~eq if level == 2 else np.zeros(eq.shape, dtype=bool)
            a, lo, hi = rows[keep], lo[keep], hi[keep]
        dx, ok = solve_qp(h, g, a, row_bounds=(lo, hi), box=box)
        if ok:
            break
    return dx, ok, level
