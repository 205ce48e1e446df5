"""Movement smoothness: spectral arc length (SPARC) and log dimensionless jerk (LDLJ).

References:
    - S. Balasubramanian, A. Melendez-Calderon, A. Roby-Brami, E. Burdet (2015), *On the analysis of
      movement smoothness*, J. NeuroEng. Rehabil. 12:112 — SPARC and LDLJ definitions and values.
    - N. Hogan, D. Sternad (2009), *Sensitivity of smoothness measures to movement duration, amplitude,
      and arrests*, J. Motor Behavior 41(6) — dimensionless jerk.

Sign convention (both measures): values are negative and **closer to zero is smoother**. A
minimum-jerk reach gives SPARC ≈ −1.40 (with the published defaults fc = 10 Hz, amplitude threshold
0.05, padding level 4; −1.64 with threshold 0.01) and LDLJ = −ln(204.8) ≈ −5.32.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import MotionDataError

FloatArray = NDArray[np.float64]


def sparc(speed: FloatArray, fs: float, fc: float = 10.0, amp_th: float = 0.05, padlevel: int = 4) -> float:
    """Spectral arc length of a speed profile [-] (Balasubramanian et al. 2015).

    The magnitude spectrum of the zero-padded speed (FFT length 2^(ceil(log2 T) + padlevel)) is
    normalized by its DC value; it is cut at the adaptive frequency: the last frequency below ``fc``
    where the spectrum is still at least ``amp_th``; SPARC is minus the arc length of that curve with the
    frequency axis normalized by the cut-off.

    Args:
        speed: (T,) [m/s] speed samples (any units: the measure is dimensionless).
        fs: [Hz] sampling frequency.
        fc: [Hz] maximum cut-off frequency (10 Hz is the published default).
        amp_th: [-] amplitude threshold of the adaptive cut-off (0.05).
        padlevel: [-] zero-padding level (4).
    """
    v = np.asarray(speed, dtype=np.float64).reshape(-1)
    if v.shape[0] < 3 or not np.all(np.isfinite(v)):
        raise MotionDataError(f"speed must be (T>=3,) finite samples, got shape {np.shape(speed)}")
    if not (fs > 0 and fc > 0 and 0 < amp_th < 1 and padlevel >= 0):
        raise MotionDataError(
            "need fs > 0 [Hz], fc > 0 [Hz], 0 < amp_th < 1, padlevel >= 0; "
            f"got {fs}, {fc}, {amp_th}, {padlevel}"
        )
    nfft = int(2 ** (np.ceil(np.log2(v.shape[0])) + padlevel))
    freq = np.arange(nfft) * fs / nfft
    mag = np.abs(np.fft.fft(v, nfft))
    if mag.max() <= 0:
        raise MotionDataError("speed is identically zero: SPARC is undefined")
    mag = mag / mag.max()
    keep = freq <= fc
    f_sel, m_sel = freq[keep], mag[keep]
    above = np.flatnonzero(m_sel >= amp_th)
    f_sel = f_sel[above[0] : above[-1] + 1]
    m_sel = m_sel[above[0] : above[-1] + 1]
    if f_sel.shape[0] < 2:
        return 0.0
    df = np.diff(f_sel) / (f_sel[-1] - f_sel[0])
    return float(-np.sum(np.sqrt(df**2 + np.diff(m_sel) ** 2)))


def dimensionless_jerk(signal: FloatArray, fs: float) -> float:
    """Dimensionless jerk DJ = (D³ / v_peak²) ∫ |d²v/dt²|² dt [-] (positive; 204.8 for minimum jerk).

    Args:
        signal: (T,) speed [m/s] — then d²v/dt² is the second derivative of speed — or (T, D) positions
            [m] — then v is the velocity vector and d²v/dt² the jerk vector (Balasubramanian 2015, LDLJ-V).
        fs: [Hz] sampling frequency.

    D = (T − 1) / fs is the movement duration [s].
    """
    x = np.asarray(signal, dtype=np.float64)
    if not fs > 0:
        raise MotionDataError(f"fs must be > 0 [Hz], got {fs}")
    if x.ndim not in (1, 2) or x.shape[0] < 5 or not np.all(np.isfinite(x)):
        raise MotionDataError(f"need (T>=5,) speed or (T>=5, D) positions, finite; got shape {x.shape}")
    dt = 1.0 / fs
    vel = x[:, None] if x.ndim == 1 else np.gradient(x, dt, axis=0)
    vpeak = float(np.max(np.linalg.norm(vel, axis=1)))
    if vpeak <= 0:
        raise MotionDataError("the movement has zero peak speed: dimensionless jerk is undefined")
    second = np.diff(vel, 2, axis=0) / dt**2
    # Central differences live at samples 1..T-2; extrapolate linearly to both ends and integrate with
    # the trapezoidal rule over the whole duration (a plain sum misses the large end values).
    second = np.concatenate([2 * second[:1] - second[1:2], second, 2 * second[-1:] - second[-2:-1]])
    duration = (x.shape[0] - 1) * dt
    integral = float(np.trapezoid(np.sum(second**2, axis=1), dx=dt))
    return float(duration**3 / vpeak**2 * integral)


def log_dimensionless_jerk(signal: FloatArray, fs: float) -> float:
    """LDLJ = −ln(DJ) [-] (negative; closer to 0 is smoother). See :func:`dimensionless_jerk`.

    Minimum-jerk reach: −ln(204.8) ≈ −5.32.
    """
    return float(-np.log(dimensionless_jerk(signal, fs)))
