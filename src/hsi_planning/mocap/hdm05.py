"""HDM05 reach statistics: the human reference that generated and planned reaches are compared with.

Clips ``HDM_<actor>_<action>_<nnn>_120.amc`` with skeleton ``HDM_<actor>.asf`` (M. Müller et al.,
*Documentation Mocap Database HDM05*, Tech. Rep. CG-2007-2, Universität Bonn, 2007; CC BY-SA 3.0).
Each clip is segmented with :func:`~hsi_planning.mocap.reach.segment_reaches` on the right wrist and
the metrics of :mod:`hsi_planning.metrics` are computed on the low-passed approach (onset → contact).

Many clips start while the actor is still walking or already moving the arm: the approach onset is
then the first frame and ``onset_speed_ratio`` (speed at onset / peak speed) is large. Rows with
``complete`` (ratio ≤ :data:`COMPLETE_ONSET_RATIO`) have an observed onset; use those for timing.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import Any

import numpy as np

from hsi_planning.errors import MotionDataError
from hsi_planning.metrics.kinematics import (
    chord_length,
    max_path_deviation_ratio,
    normalized_peak_speed_time,
    path_length,
    speed_curvature_exponent,
    speed_profile,
)
from hsi_planning.metrics.smoothness import log_dimensionless_jerk, sparc
from hsi_planning.mocap.amc import load_amc
from hsi_planning.mocap.asf import load_asf
from hsi_planning.mocap.reach import ReachConfig, lowpass, segment_reaches, wrist_trajectory
from hsi_planning.mocap.skeleton import forward_kinematics

_LOG = logging.getLogger(__name__)
_CLIP = re.compile(r"^HDM_(?P<actor>[a-z]+)_(?P<action>[A-Za-z]+)_(?P<num>\d+)_(?P<fps>\d+)\.amc$")

#: [-] a reach whose speed at onset is at most this fraction of its peak speed has an observed onset.
COMPLETE_ONSET_RATIO = 0.3

#: numeric keys of every row of :func:`hdm05_reach_stats`, with units.
STAT_UNITS: dict[str, str] = {
    "duration": "s",
    "distance": "m",
    "path_length": "m",
    "peak_speed": "m/s",
    "peak_time_ratio": "-",
    "max_deviation_ratio": "-",
    "speed_curvature_exponent": "-",
    "sparc": "-",
    "ldlj": "-",
    "contact_height": "m",
    "onset_speed_ratio": "-",
}


def hdm05_clips(
    directory: str | Path, actions: tuple[str, ...] = ("grabHighR", "depositFloorR")
) -> list[Path]:
    """The ``.amc`` clips of ``actions`` in ``directory``, sorted by name."""
    root = Path(directory)
    if not root.is_dir():
        raise MotionDataError(f"{root}: HDM05 directory not found")
    clips = []
    for path in sorted(root.glob("HDM_*.amc")):
        match = _CLIP.match(path.name)
        if match and match["action"] in actions:
            clips.append(path)
    return clips


def reach_metrics(approach: np.ndarray, fps: float) -> dict[str, float]:
    """Metrics of one approach path ``(T, 3) [m]`` sampled at ``fps`` [Hz] (already low-passed).

    Keys and units as in :data:`STAT_UNITS` (duration [s], distance [m], peak speed [m/s], …); the
    speed–curvature exponent is NaN when too few samples are curved enough to fit it.
    """
    t = np.arange(approach.shape[0]) / fps
    speed = speed_profile(approach, t)
    try:
        beta = speed_curvature_exponent(approach, t)
    except MotionDataError:
        beta = float("nan")
    return {
        "duration": float(t[-1]),
        "distance": chord_length(approach),
        "path_length": path_length(approach),
        "peak_speed": float(np.max(speed)),
        "peak_time_ratio": normalized_peak_speed_time(approach, t),
        "max_deviation_ratio": max_path_deviation_ratio(approach),
        "speed_curvature_exponent": beta,
        "sparc": sparc(speed, fps),
        "ldlj": log_dimensionless_jerk(approach, fps),
    }


def hdm05_reach_stats(
    directory: str | Path,
    actions: tuple[str, ...] = ("grabHighR", "depositFloorR"),
    config: ReachConfig | None = None,
    side: str = "right",
) -> list[dict[str, Any]]:
    """Per-clip statistics of the right-wrist approach of every HDM05 reach clip.

    Returns:
        One dict per detected reach: ``actor``, ``clip`` (file stem), ``action``, ``reach`` (index in the
        clip), ``complete`` (observed onset), ``end_truncated`` and the numbers of :data:`STAT_UNITS`.
    """
    cfg = config or ReachConfig()
    rows: list[dict[str, Any]] = []
    skeletons: dict[str, Any] = {}
    for path in hdm05_clips(directory, actions):
        match = _CLIP.match(path.name)
        assert match is not None
        actor, action, fps = match["actor"], match["action"], float(match["fps"])
        if actor not in skeletons:
            skeletons[actor] = load_asf(path.parent / f"HDM_{actor}.asf")
        fk = forward_kinematics(skeletons[actor], load_amc(path, skeletons[actor], fps=fps))
        wrist = wrist_trajectory(fk, "left" if side == "left" else "right")
        smooth = lowpass(wrist, fps, cfg.cutoff_hz, cfg.filter_order)
        reaches = segment_reaches(wrist, fps, cfg)
        if len(reaches) != 1:
            _LOG.warning("%s: %d reaches found (expected 1)", path.name, len(reaches))
        for i, reach in enumerate(reaches):
            approach = smooth[reach.approach]
            row: dict[str, Any] = {
                "actor": actor,
                "clip": path.stem,
                "action": action,
                "reach": i,
                "complete": reach.onset_speed_ratio <= COMPLETE_ONSET_RATIO,
                "end_truncated": reach.end_truncated,
            }
            row.update(reach_metrics(approach, fps))
            row["contact_height"] = float(smooth[reach.contact, 2])
            row["onset_speed_ratio"] = reach.onset_speed_ratio
            rows.append(row)
    return rows


def median_stats(
    rows: list[dict[str, Any]], group_by: tuple[str, ...] = ("action", "actor"), complete_only: bool = False
) -> list[dict[str, Any]]:
    """Median of every numeric statistic per group (NaN ignored); each result row has ``n``."""
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for row in rows:
        if complete_only and not row["complete"]:
            continue
        groups.setdefault(tuple(row[k] for k in group_by), []).append(row)
    out = []
    for key, members in sorted(groups.items()):
        med: dict[str, Any] = dict(zip(group_by, key, strict=True))
        med["n"] = len(members)
        for name in STAT_UNITS:
            values = np.array([m[name] for m in members], dtype=np.float64)
            med[name] = float(np.nanmedian(values)) if np.any(np.isfinite(values)) else float("nan")
        out.append(med)
    return out
