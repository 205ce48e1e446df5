"""Hand/hip trajectories from forward kinematics, low-pass filtering, and reach segmentation.

A *reach* is an approach movement that ends with the hand stopping at a target (the contact: grasp or
release), followed by a withdrawal that takes the hand back. :func:`segment_reaches` finds them in a
hand path from speed alone (no object geometry):

1. Low-pass the path (Butterworth, zero-phase ``filtfilt``, 6 Hz by default — the usual choice for
   optical mocap of arm movements) and differentiate: speed v(t).
2. *Stops* are the minima of the rest intervals where v < ``stop_fraction`` · max v; the clip ends are
   boundaries too. Consecutive boundaries delimit sub-movements.
3. A stop c is a *contact* when the hand travelled at least ``min_distance_m`` from the preceding
   boundary s to c (the approach), and later moves back against the approach direction by
   ``return_fraction`` of that distance (the withdrawal). Small movements near the contact
   (adjusting the object) stay inside the dwell. When the clip ends before the hand has come back
   and the hand never comes to rest elsewhere, the reach is kept (``end_truncated`` if it is still
   moving at the last frame).
4. Onset, contact and withdrawal end are refined with a threshold of ``onset_fraction`` (5 %) of the
   respective movement's peak speed — the common convention for reach onset/offset.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, filtfilt

from hsi_planning.errors import ConfigError, MotionDataError
from hsi_planning.mocap.skeleton import JointTrajectories

FloatArray = NDArray[np.float64]
Side = Literal["right", "left"]
HandPoint = Literal["wrist", "hand", "fingers"]

# Candidate joint names per convention; the first one present is used. For a BVH written by
# :func:`hsi_planning.mocap.bvh.save_bvh` from an ASF, joint ``rhand`` sits at the anatomical wrist
# (the end of the Acclaim ``rwrist`` bone), ``rfingers`` at the end of ``rhand``, and so on.
_HAND_NAMES: dict[tuple[str, str], tuple[str, ...]] = {
    ("acclaim", "wrist"): ("{s}wrist",),
    ("acclaim", "hand"): ("{s}hand",),
    ("acclaim", "fingers"): ("{s}fingers",),
    ("bvh", "wrist"): ("{s}hand", "{S}Hand", "{S}Wrist", "{S}_Wrist", "{side}_wrist"),
    ("bvh", "hand"): ("{s}fingers", "{S}HandMiddle1", "{S}HandEnd", "{S}Hand_end"),
    ("bvh", "fingers"): ("{s}fingers_end", "{S}HandMiddle4", "{S}HandEnd_end"),
}
_HIP_NAMES = ("root", "Hips", "hips", "Hip", "hip", "pelvis", "Pelvis")


def _find(fk: JointTrajectories, candidates: tuple[str, ...], what: str) -> str:
    for name in candidates:
        if name in fk.positions:
            return name
    raise MotionDataError(f"no {what} joint: tried {list(candidates)}; joints: {sorted(fk.positions)}")


def hand_joint_name(fk: JointTrajectories, side: Side = "right", point: HandPoint = "wrist") -> str:
    """Name of the joint whose point is the ``side`` wrist / hand centre / fingers in ``fk``."""
    if side not in ("right", "left") or point not in ("wrist", "hand", "fingers"):
        raise MotionDataError(
            f"side must be right|left and point wrist|hand|fingers, got {side!r}, {point!r}"
        )
    fmt = {"s": side[0], "S": side.capitalize(), "side": side}
    names = tuple(n.format(**fmt) for n in _HAND_NAMES[(fk.convention, point)])
    return _find(fk, names, f"{side} {point}")


def wrist_trajectory(fk: JointTrajectories, side: Side = "right", point: HandPoint = "wrist") -> FloatArray:
    """World wrist (or hand / fingers) positions (T, 3) [m] — a copy."""
    return np.array(fk.positions[hand_joint_name(fk, side, point)])


def wrist_rotations(fk: JointTrajectories, side: Side = "right") -> FloatArray:
    """World orientation (T, 3, 3) of the hand segment (the frame of the joint distal to the wrist)."""
    name = hand_joint_name(fk, side, "wrist")
    if fk.convention == "acclaim":
        name = hand_joint_name(fk, side, "hand")
    return np.array(fk.rotations[name])


def hip_trajectory(fk: JointTrajectories) -> FloatArray:
    """World pelvis/root positions (T, 3) [m] — a copy (Acclaim ``root``, BVH ``Hips``)."""
    return np.array(fk.positions[_find(fk, _HIP_NAMES, "hip/root")])


@dataclass(frozen=True)
class ReachConfig:
    """Parameters of :func:`segment_reaches`."""

    cutoff_hz: float = 6.0  #: [Hz] low-pass cut-off applied before differentiation
    filter_order: int = 2  #: [-] Butterworth order (run forward and backward: zero phase)
    stop_fraction: float = 0.2  #: [-] rest intervals: speed below this fraction of the clip's peak speed
    onset_fraction: float = 0.05  #: [-] onset/contact/end threshold, fraction of the movement's peak speed
    min_distance_m: float = 0.2  #: [m] minimum straight-line amplitude of an approach
    return_fraction: float = 0.3  #: [-] the withdrawal brings the hand back by this fraction of the approach

    def __post_init__(self) -> None:
        if not self.cutoff_hz > 0:
            raise ConfigError(f"cutoff_hz must be > 0 [Hz], got {self.cutoff_hz}")
        if not 1 <= self.filter_order <= 8:
            raise ConfigError(f"filter_order must be in 1..8, got {self.filter_order}")
        for name in ("stop_fraction", "onset_fraction", "return_fraction"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ConfigError(f"{name} must be in (0, 1), got {value}")
        if not self.min_distance_m > 0:
            raise ConfigError(f"min_distance_m must be > 0 [m], got {self.min_distance_m}")


@dataclass(frozen=True)
class ReachSegment:
    """One reach: approach ``onset → contact``, dwell, withdrawal ``withdrawal_start → end`` (indices).

    Attributes:
        onset: first sample of the approach.
        peak: sample of the approach's peak speed.
        contact: the hand stops at the target (grasp/release instant).
        withdrawal_start: the hand leaves the target.
        end: end of the withdrawal.
        fps: [Hz] sample rate.
        onset_speed_ratio: [-] speed at onset / approach peak speed (≤ onset_fraction unless the clip
            starts mid-movement).
        end_truncated: the clip ends before the withdrawal does.
        approach_distance: [m] straight-line distance onset → contact.
    """

    onset: int
    peak: int
    contact: int
    withdrawal_start: int
    end: int
    fps: float
    onset_speed_ratio: float
    end_truncated: bool
    approach_distance: float

    @property
    def approach(self) -> slice:
        """Slice of the approach samples, onset..contact inclusive."""
        return slice(self.onset, self.contact + 1)

    @property
    def withdrawal(self) -> slice:
        """Slice of the withdrawal samples, withdrawal_start..end inclusive."""
        return slice(self.withdrawal_start, self.end + 1)

    @property
    def approach_duration(self) -> float:
        """[s] contact − onset."""
        return (self.contact - self.onset) / self.fps


def lowpass(pos: FloatArray, fps: float, cutoff_hz: float = 6.0, order: int = 2) -> FloatArray:
    """Zero-phase Butterworth low-pass of ``pos: (T, D)`` sampled at ``fps`` [Hz]; returns (T, D)."""
    p = np.asarray(pos, dtype=np.float64)
    if not fps > 0 or not 0 < cutoff_hz < fps / 2:
        raise MotionDataError(f"need fps > 0 and 0 < cutoff_hz < fps/2 [Hz], got {fps}, {cutoff_hz}")
    b, a = butter(order, cutoff_hz / (fps / 2))
    padlen = 3 * max(len(a), len(b))
    if p.shape[0] <= padlen:
        raise MotionDataError(f"need more than {padlen} samples to filter, got {p.shape[0]}")
    return np.asarray(filtfilt(b, a, p, axis=0))


def _stops(speed: FloatArray, threshold: float) -> list[int]:
    """Index of the minimum of every run of samples with speed < threshold."""
    below = speed < threshold
    stops: list[int] = []
    i, n = 0, speed.shape[0]
    while i < n:
        if below[i]:
            j = i
            while j + 1 < n and below[j + 1]:
                j += 1
            stops.append(i + int(np.argmin(speed[i : j + 1])))
            i = j + 1
        else:
            i += 1
    return stops


def segment_reaches(pos: FloatArray, fps: float, config: ReachConfig | None = None) -> list[ReachSegment]:
    """Find the reaches in a hand path.

    Args:
        pos: (T, 3) [m] hand positions (raw mocap is fine: it is low-passed here).
        fps: [Hz] sample rate.
        config: thresholds; defaults to :class:`ReachConfig`.

    Returns:
        The reaches in time order (possibly none).
    """
    cfg = config or ReachConfig()
    p = np.asarray(pos, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
        raise MotionDataError(f"pos must be finite (T, 3) [m], got shape {p.shape}")
    x = lowpass(p, fps, cfg.cutoff_hz, cfg.filter_order)
    v = np.linalg.norm(np.gradient(x, 1.0 / fps, axis=0), axis=1)
    vmax = float(np.max(v))
    if vmax <= 0:
        return []
    last = v.shape[0] - 1
    stops = [s for s in _stops(v, cfg.stop_fraction * vmax) if 0 < s < last]
    bounds = [0, *stops, last]
    reaches: list[ReachSegment] = []
    k = 1
    while k < len(bounds) - 1:
        s, c = bounds[k - 1], bounds[k]
        amplitude = float(np.linalg.norm(x[c] - x[s]))
        if amplitude < cfg.min_distance_m:
            k += 1
            continue
        end_k = _withdrawal_end(x, bounds, k, amplitude, cfg)
        if end_k is None:
            k += 1
            continue
        reaches.append(_refine(v, x, (s, c, bounds[end_k]), fps, cfg))
        k = end_k + 1
    return reaches


def _withdrawal_end(
    x: FloatArray, bounds: list[int], k: int, amplitude: float, cfg: ReachConfig
) -> int | None:
    """Index into ``bounds`` where the withdrawal from contact ``bounds[k]`` ends, or None (no reach).

    The withdrawal reverses the approach: the hand's displacement from the contact, projected on the
    approach direction, reaches −``return_fraction`` · amplitude (walking while reaching makes a plain
    "back to the start point" test fail, the projection does not).
    """
    s, c = bounds[k - 1], bounds[k]
    direction = (x[c] - x[s]) / amplitude
    for m in range(k + 1, len(bounds)):
        b = bounds[m]
        left = float(np.linalg.norm(x[b] - x[c])) >= cfg.min_distance_m
        back = float((x[b] - x[c]) @ direction) <= -cfg.return_fraction * amplitude
        if left and back:
            return m
    later_rest = any(
        float(np.linalg.norm(x[bounds[m]] - x[c])) >= cfg.min_distance_m
        for m in range(k + 1, len(bounds) - 1)
    )
    if not later_rest and float(np.linalg.norm(x[bounds[-1]] - x[c])) >= cfg.min_distance_m:
        return len(bounds) - 1
    return None


def _refine(
    v: FloatArray, x: FloatArray, marks: tuple[int, int, int], fps: float, cfg: ReachConfig
) -> ReachSegment:
    """Threshold-refined reach from approach start ``s``, contact stop ``c``, withdrawal end ``e``."""
    s, c, e = marks
    peak = s + int(np.argmax(v[s : c + 1]))
    thr = cfg.onset_fraction * v[peak]
    before = np.flatnonzero(v[s : peak + 1] < thr)
    onset = s + int(before[-1]) if before.size else s
    after = np.flatnonzero(v[peak : c + 1] < thr)
    contact = peak + int(after[0]) if after.size else c
    wpeak = c + int(np.argmax(v[c : e + 1]))
    wthr = cfg.onset_fraction * v[wpeak]
    leave = np.flatnonzero(v[c : wpeak + 1] < wthr)
    wstart = c + int(leave[-1]) if leave.size else c
    stop = np.flatnonzero(v[wpeak : e + 1] < wthr)
    end = wpeak + int(stop[0]) if stop.size else e
    truncated = end == v.shape[0] - 1 and bool(v[end] >= wthr)
    return ReachSegment(
        onset=onset,
        peak=peak,
        contact=contact,
        withdrawal_start=max(wstart, contact),
        end=end,
        fps=float(fps),
        onset_speed_ratio=float(v[onset] / v[peak]),
        end_truncated=truncated,
        approach_distance=float(np.linalg.norm(x[contact] - x[onset])),
    )
