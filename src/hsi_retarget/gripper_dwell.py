"""Gripper dwell: hold the robot still while its fingers close on a grasp or open on a release.

A schedule's ``grasp`` / ``release`` keyframe marks the *end* of the human hand's short closing time
(``SchedulerConfig.grasp_time``, 0.3 s); the MuJoCo check starts closing the gripper at the event, and a
2F-140-like gripper needs ``stroke / speed`` (0.7 s from fully open) to close. Without a pause the arm
pulls a door handle or lifts an object before the fingers hold it. :func:`add_gripper_dwell` inserts a
standstill of ``after_s`` at every grasp and release event (and ``before_release_s`` before a release,
so a carried object comes to rest before it is let go), shifting the rest of the trajectory and its events.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError
from hsi_retarget.joint_trajectory import ContactEvent, JointTrajectory

__all__ = ["DwellConfig", "add_gripper_dwell"]

_SAME_TIME = 1e-6  #: [s] events closer than this share one standstill


@dataclass(frozen=True)
class DwellConfig:
    """Standstill lengths around gripper events."""

    after_s: float = 0.8  #: standstill after a grasp or release event (fingers moving) [s]
    before_release_s: float = 0.3  #: standstill before a release event (object settles) [s]

    def __post_init__(self) -> None:
        if not (0.0 <= self.after_s <= 5.0 and 0.0 <= self.before_release_s <= 5.0):
            raise ConfigError(
                f"DwellConfig: after_s and before_release_s must be in [0, 5] s, got {self.after_s}, "
                f"{self.before_release_s}"
            )


def _append(times: list[float], poses: list[NDArray[np.float64]], t: float, q: NDArray[np.float64]) -> None:
    """Add sample (t, q) unless it does not come after the last one (a sample already at that time)."""
    if t > times[-1] + _SAME_TIME:
        times.append(t)
        poses.append(q)


def add_gripper_dwell(traj: JointTrajectory, config: DwellConfig | None = None) -> JointTrajectory:
    """A copy of ``traj`` standing still around each gripper event (see the module docstring); ``meta``
    gets ``gripper_dwell_s`` (the total time added [s])."""
    cfg = config if config is not None else DwellConfig()
    events = sorted(traj.events, key=lambda e: e.time)
    groups: list[list[ContactEvent]] = []
    for e in events:
        if groups and e.time - groups[-1][0].time <= _SAME_TIME:
            groups[-1].append(e)
        else:
            groups.append([e])
    times = [float(traj.t[0])]
    poses = [traj.q[0]]
    new_events: list[ContactEvent] = []
    offset, k = 0.0, 1
    n = traj.t.shape[0]
    for group in groups:
        te = min(max(group[0].time, float(traj.t[0])), float(traj.t[-1]))
        while k < n and traj.t[k] < te - _SAME_TIME:
            _append(times, poses, float(traj.t[k]) + offset, traj.q[k])
            k += 1
        pre = cfg.before_release_s if any(e.kind == "release" for e in group) else 0.0
        q_event = traj.sample(te)
        for stamp in (te + offset, te + offset + pre + cfg.after_s):
            _append(times, poses, stamp, q_event)
        new_events += [replace(e, time=te + offset + pre) for e in group]
        offset += pre + cfg.after_s
    while k < n:
        _append(times, poses, float(traj.t[k]) + offset, traj.q[k])
        k += 1
    meta = {**traj.meta, "gripper_dwell_s": offset}
    return JointTrajectory(
        robot=traj.robot,
        t=np.asarray(times),
        q=np.asarray(poses),
        joint_names=traj.joint_names,
        events=tuple(new_events),
        meta=meta,
        floating_index=traj.floating_index,
    )
