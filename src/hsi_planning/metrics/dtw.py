"""Dynamic time warping of trajectories and the shape normalization used before comparing them.

References:
    - H. Sakoe, S. Chiba (1978), *Dynamic programming algorithm optimization for spoken word
      recognition*, IEEE Trans. ASSP 26(1) — DTW with the symmetric (1, 1, 1) step pattern.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import MotionDataError

FloatArray = NDArray[np.float64]


def _as_2d(x: FloatArray, name: str) -> FloatArray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] < 1 or not np.all(np.isfinite(arr)):
        raise MotionDataError(f"{name} must be a finite (N, D) array, got shape {np.shape(x)}")
    return arr


def dtw_distance(a: FloatArray, b: FloatArray, normalized: bool = True) -> float:
    """DTW distance between sequences ``a: (N, D)`` and ``b: (M, D)`` (same units, e.g. [m] or [-]).

    Local cost is the Euclidean distance; steps (1,0), (0,1), (1,1). The result is the cost of the
    optimal alignment, divided by the number of aligned pairs on that path when ``normalized`` (then it
    is a mean distance in the inputs' units). Symmetric; 0 for identical sequences.
    """
    x, y = _as_2d(a, "a"), _as_2d(b, "b")
    if x.shape[1] != y.shape[1]:
        raise MotionDataError(f"a and b must have the same dimension, got {x.shape[1]} and {y.shape[1]}")
    n, m = x.shape[0], y.shape[0]
    cost = np.sqrt(np.sum((x[:, None, :] - y[None, :, :]) ** 2, axis=2))
    acc = np.full((n + 1, m + 1), np.inf)
    steps = np.zeros((n + 1, m + 1))
    acc[0, 0] = 0.0
    # Sweep anti-diagonals k = i + j (1-based cell indices): each depends only on diagonals k-1, k-2.
    for k in range(2, n + m + 1):
        i = np.arange(max(1, k - m), min(n, k - 1) + 1)
        j = k - i
        cand = np.stack([acc[i - 1, j - 1], acc[i - 1, j], acc[i, j - 1]])
        cand_steps = np.stack([steps[i - 1, j - 1], steps[i - 1, j], steps[i, j - 1]])
        best = np.argmin(cand, axis=0)
        cols = np.arange(i.shape[0])
        acc[i, j] = cost[i - 1, j - 1] + cand[best, cols]
        steps[i, j] = cand_steps[best, cols] + 1.0
    total = float(acc[n, m])
    return total / float(steps[n, m]) if normalized else total


def _resample(points: FloatArray, param: FloatArray, n: int) -> FloatArray:
    u = (param - param[0]) / (param[-1] - param[0])
    grid = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(grid, u, points[:, d]) for d in range(points.shape[1])], axis=1)


def normalized_trajectory(
    pos: FloatArray, n: int = 100, t: FloatArray | None = None, by: Literal["time", "arc"] = "time"
) -> FloatArray:
    """Shape-normalize a 3D path for comparison: (n, 3) [-] in chord units.

    The start goes to the origin, the path is scaled by its chord length (start → end), rotated so the
    chord lies on +x and the point of maximum deviation from the chord lies in the x–y plane at y > 0,
    and resampled to ``n`` samples uniformly in time (``by="time"``; ``t: (T,) [s]`` or uniform sampling
    when omitted) or in arc length (``by="arc"``). The end is then at (1, 0, 0).

    Args:
        pos: (T, 3) [m] positions.
        n: number of output samples (>= 2).
        t: (T,) [s] sample times, strictly increasing (default: uniform).
        by: resampling parameter, ``"time"`` or ``"arc"``.
    """
    p = _as_2d(pos, "pos")
    if p.shape[1] != 3 or p.shape[0] < 2:
        raise MotionDataError(f"pos must be (T>=2, 3) [m], got shape {p.shape}")
    if n < 2:
        raise MotionDataError(f"n must be >= 2, got {n}")
    chord = p[-1] - p[0]
    length = float(np.linalg.norm(chord))
    if length < 1e-9:
        raise MotionDataError("start and end coincide: the chord used for normalization is zero")
    e1 = chord / length
    rel = p - p[0]
    perp = rel - (rel @ e1)[:, None] * e1[None, :]
    dev = np.linalg.norm(perp, axis=1)
    k = int(np.argmax(dev))
    if dev[k] > 1e-9 * length:
        e2 = perp[k] / dev[k]
    else:
        helper = np.eye(3)[int(np.argmin(np.abs(e1)))]
        e2 = helper - (helper @ e1) * e1
        e2 /= np.linalg.norm(e2)
    rot = np.stack([e1, e2, np.cross(e1, e2)])
    q = rel @ rot.T / length
    if by == "arc":
        param = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        if param[-1] <= 0:
            raise MotionDataError("the path has zero length")
        # Drop repeated points (zero arc increments) so the parameter is strictly increasing.
        keep = np.concatenate([[True], np.diff(param) > 0])
        return _resample(q[keep], param[keep], n)
    if by != "time":
        raise MotionDataError(f"by must be 'time' or 'arc', got {by!r}")
    tt = np.arange(p.shape[0], dtype=np.float64) if t is None else np.asarray(t, dtype=np.float64).reshape(-1)
    if tt.shape[0] != p.shape[0] or not np.all(np.diff(tt) > 0):
        raise MotionDataError("t must be (T,) strictly increasing [s], matching pos")
    return _resample(q, tt, n)
