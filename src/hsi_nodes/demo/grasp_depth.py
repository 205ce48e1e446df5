"""Human palm contacts -> gripper contacts: move the planned wrist goals of object grasps into the object.

The planners place a grasp's wrist ``palm_offset`` [m] beyond the object's box along the approach axis
(the palm touches the object; :func:`hsi_planning.scheduler.reach_planner.contact_from_points`), and the
retargeter maps the wrist onto the robot's TCP one to one (``MappingConfig(anchor="world")``). A parallel
gripper has to close *around* the object, so its TCP must go ``palm_offset + grasp_depth`` further along
the wrist's x axis (the approach direction; the TCP's z axis). :func:`deepen_grasps` applies that offset
to a :class:`~hsi_planning.scheduler.Schedule` per hand as a function of time: 0 when free, rising over
the planned approach of a grasp of a free object to the full offset at the grasp, held while the object
is carried, and falling back to 0 over the withdrawal after its release. Door and drawer handles are not
touched (the scheduler's handle goals are the handle bar itself).

This belongs with the wrist-to-TCP mapping (:mod:`hsi_retarget.mapping`); it lives here until the
mapping has a grasp-depth option.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError
from hsi_planning.scheduler import Keyframe, PlannedSegment, Schedule

__all__ = ["GraspDepthConfig", "deepen_grasps", "grasp_offsets"]

F64 = NDArray[np.float64]
_EPS = 1e-3  #: [s] tolerance matching keyframe and segment times


@dataclass(frozen=True)
class GraspDepthConfig:
    """How far a gripper's TCP goes beyond the planned wrist contact of an object grasp."""

    #: Wrist distance beyond the object's box used by the planners (scheduler ``palm_offset``) [m].
    palm_offset: float = 0.06
    #: Depth of the TCP inside the object's box past its near face [m].
    grasp_depth: float = 0.03
    #: Ramp time of the offset when no planned segment precedes a grasp or follows a release [s].
    ramp_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("palm_offset", "grasp_depth"):
            if not 0.0 <= getattr(self, name) <= 0.3:
                raise ConfigError(f"GraspDepthConfig.{name} must be in [0, 0.3] m, got {getattr(self, name)}")
        if not self.ramp_s > 0.0:
            raise ConfigError(f"GraspDepthConfig.ramp_s must be > 0 s, got {self.ramp_s}")

    @property
    def offset(self) -> float:
        """[m] full TCP offset along the wrist's x axis while an object is grasped."""
        return self.palm_offset + self.grasp_depth


def _hands(hand: str) -> tuple[str, ...]:
    return ("left", "right") if hand == "both" else (hand,)


def grasp_offsets(
    schedule: Schedule, hand: str, objects: Collection[str], config: GraspDepthConfig
) -> tuple[F64, F64]:
    """Breakpoints (times (K,) [s], offsets (K,) [m]) of ``hand``'s TCP offset (linear in between, 0
    before the first and after the last): 0 -> full over the approach to each grasp of one of ``objects``,
    full until its release, full -> 0 over the withdrawal."""
    segments = sorted((s for s in schedule.segments if s.trajectory.hand == hand), key=lambda s: s.start_time)
    full = config.offset
    times: list[float] = [0.0]
    values: list[float] = [0.0]
    for k in schedule.events():
        if hand not in _hands(k.hand) or k.object_name not in objects:
            continue
        if k.contact_event == "grasp":
            before = [s for s in segments if s.end_time <= k.time + _EPS]
            start = before[-1].start_time if before else k.time - config.ramp_s
            if before and k.time - before[-1].end_time > config.ramp_s:
                start = k.time - config.ramp_s
            times += [max(start, times[-1]), k.time]
            values += [0.0, full]
        elif k.contact_event == "release":
            after = [s for s in segments if s.start_time >= k.time - _EPS]
            end = after[0].end_time if after else k.time + config.ramp_s
            times += [k.time, max(end, k.time + 1e-6)]
            values += [full, 0.0]
    return np.asarray(times, dtype=np.float64), np.asarray(values, dtype=np.float64)


def _offset_at(breaks: tuple[F64, F64], t: F64) -> F64:
    times, values = breaks
    order = np.argsort(times, kind="stable")
    return np.asarray(np.interp(t, times[order], values[order]), dtype=np.float64)


def deepen_grasps(
    schedule: Schedule, objects: Collection[str], config: GraspDepthConfig | None = None
) -> Schedule:
    """A copy of ``schedule`` whose wrist keyframes and planned segments are moved along each wrist's x
    axis by the grasp offset of :func:`grasp_offsets` (only grasps of ``objects``, the free objects)."""
    cfg = config if config is not None else GraspDepthConfig()
    names = set(objects)
    breaks = {h: grasp_offsets(schedule, h, names, cfg) for h in ("left", "right")}
    frames = []
    for key in schedule.keyframes:
        k = key
        if k.key_joint.endswith("_wrist"):
            hand = k.key_joint.removesuffix("_wrist")
            axis = Rotation.from_quat(k.quaternion).as_matrix()[:, 0]
            depth = float(_offset_at(breaks[hand], np.array([k.time]))[0])
            k = Keyframe(
                k.time,
                k.key_joint,
                k.position + depth * axis,
                k.quaternion,
                k.action,
                k.contact_event,
                k.hand,
                k.object_name,
            )
        frames.append(k)
    segments = []
    for s in schedule.segments:
        tr = s.trajectory
        axes = Rotation.from_quat(tr.quaternion).as_matrix()[:, :, 0]
        shift = _offset_at(breaks[tr.hand], s.start_time + tr.t)
        moved = dataclasses.replace(tr, position=tr.position + shift[:, None] * axes)
        segments.append(PlannedSegment(s.start_time, moved, s.step))
    info = {**schedule.info, "grasp_offset_m": cfg.offset}
    return Schedule(
        schedule.task_id, tuple(frames), tuple(segments), schedule.steps, schedule.root_path, info
    )
