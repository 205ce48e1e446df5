"""Human goals from their sources, as a :class:`~hsi_retarget.mapping.HumanMotion`: a recorded motion
(ASF/AMC or BVH skeleton + channels), a scheduler :class:`~hsi_planning.scheduler.schedule.Schedule`, or
planned :class:`~hsi_planning.trajectory.WristTrajectory` segments.

Recorded motion: wrist = the anatomical wrist point (:func:`hsi_planning.mocap.wrist_trajectory`), hip = the
root; the arm length is measured on the skeleton's rest pose (arms out), the standing hip and shoulder
heights as the 90th percentile of their height above the lowest body point over the clip. The wrist frame
(planner convention: x along the hand, z to the thumb side) is calibrated once on the rest pose, assuming
a T-pose with the palms down (so the thumbs point forward, world +x): the hand segment's orientation is
then carried through the clip by the mocap rotations. Heading: the root's rotation relative to the rest
pose applied to world +x.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from hsi_planning.errors import MotionDataError, RetargetError
from hsi_planning.mocap import Motion, Skeleton, forward_kinematics, hip_trajectory, lowpass, wrist_trajectory
from hsi_planning.mocap.reach import wrist_rotations
from hsi_planning.trajectory import WristTrajectory
from hsi_retarget.human_motion import SIDES, HumanMotion
from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.rotation_filter import smooth_rotations

if TYPE_CHECKING:  # the scheduler package is imported only when a schedule is retargeted
    from hsi_planning.scheduler.schedule import Schedule

F64 = NDArray[np.float64]
#: [Hz] low-pass of the planned wrist orientations (the learned planner's jitter; a reach's own turning
#: stays below it)
ROTATION_CUTOFF_HZ = 3.0
_SHOULDER_NAMES = {
    "acclaim": ("{s}clavicle",),
    "bvh": ("{s}humerus", "{S}Arm", "{S}UpArm", "{S}Shoulder", "{side}_shoulder"),
}


def _shoulder_name(names: set[str], convention: str, side: str) -> str:
    fmt = {"s": side[0], "S": side.capitalize(), "side": side}
    for pattern in _SHOULDER_NAMES[convention]:
        if pattern.format(**fmt) in names:
            return pattern.format(**fmt)
    raise MotionDataError(f"no {side} shoulder joint among {sorted(names)}")


def _smooth_rotations(rot: F64, fps: float, cutoff_hz: float) -> F64:
    """Low-pass (T, 3, 3) rotations through sign-continuous quaternions."""
    quat = Rotation.from_matrix(rot).as_quat()
    flips = np.cumsum(np.concatenate([[0], (np.einsum("ij,ij->i", quat[1:], quat[:-1]) < 0).astype(int)]))
    quat[flips % 2 == 1] *= -1.0
    quat = lowpass(quat, fps, cutoff_hz)
    return np.asarray(Rotation.from_quat(quat / np.linalg.norm(quat, axis=1, keepdims=True)).as_matrix())


def human_motion_from_mocap(
    skeleton: Skeleton, motion: Motion, lowpass_hz: float = 6.0, source: str = "mocap"
) -> HumanMotion:
    """Wrists, hip, shoulders and body measures of a recorded motion (see the module docstring).

    Args:
        lowpass_hz: [Hz] zero-phase low-pass of the positions and orientations (0: none; needs more than
            ~9 frames); the robot's acceleration limits make raw 120 Hz marker jitter costly.
    """
    fk = forward_kinematics(skeleton, motion)
    rest = forward_kinematics(
        skeleton, Motion(motion.channels, np.zeros((1, len(motion.channels))), motion.fps)
    )
    names = set(fk.positions)
    n, fps = fk.n_frames, fk.fps
    smooth = lowpass_hz > 0.0 and n > 12

    def pos(p: F64) -> F64:
        return lowpass(p, fps, lowpass_hz) if smooth else np.array(p)

    wrist_p: dict[str, F64] = {}
    wrist_r: dict[str, F64] = {}
    shoulders: dict[str, F64] = {}
    arm = []
    for side in SIDES:
        sh = _shoulder_name(names, fk.convention, side)
        w_rest = wrist_trajectory(rest, side)[0]
        x = wrist_trajectory(rest, side, "hand")[0] - w_rest
        x /= np.linalg.norm(x)
        z = np.array([1.0, 0.0, 0.0]) - x[0] * x
        z /= np.linalg.norm(z)
        frame_rest = np.column_stack([x, np.cross(z, x), z])
        offset = wrist_rotations(rest, side)[0].T @ frame_rest
        rot = wrist_rotations(fk, side) @ offset
        wrist_p[side] = pos(wrist_trajectory(fk, side))
        wrist_r[side] = _smooth_rotations(rot, fps, lowpass_hz) if smooth else rot
        shoulders[side] = pos(fk.positions[sh])
        arm.append(float(np.linalg.norm(w_rest - rest.positions[sh][0])))
    hip = pos(hip_trajectory(fk))
    root_name = skeleton.joints[0].name
    rel = fk.rotations[root_name] @ rest.rotations[root_name][0].T
    yaw = np.unwrap(np.arctan2(rel[:, 1, 0], rel[:, 0, 0]))
    floor = np.min(np.stack([p[:, 2] for p in fk.positions.values()]), axis=0)  # lowest point per frame
    mid_shoulder = 0.5 * (shoulders["left"][:, 2] + shoulders["right"][:, 2])
    return HumanMotion(
        t=fk.t,
        wrist_position=wrist_p,
        wrist_rotation=wrist_r,
        active={str(s): np.ones(n, dtype=bool) for s in SIDES},
        hip_position=hip,
        hip_yaw=lowpass(yaw[:, None], fps, lowpass_hz)[:, 0] if smooth else yaw,
        shoulder_position=shoulders,
        arm_length=float(np.mean(arm)),
        standing_hip_height=float(np.percentile(hip[:, 2] - floor, 90)),
        standing_shoulder_height=float(np.percentile(mid_shoulder - floor, 90)),
        source=source,
    )


def _min_jerk(u: F64) -> F64:
    u = np.clip(u, 0.0, 1.0)
    return np.asarray(10 * u**3 - 15 * u**4 + 6 * u**5)


def _keyframe_path(times: F64, positions: F64, quats: F64, t: F64) -> tuple[F64, F64]:
    """Positions (T, 3) and rotations (T, 3, 3) at ``t`` through keyframes: min-jerk in position, slerp with
    the same timing in orientation, held before the first and after the last keyframe."""
    if times.shape[0] == 1:
        rot = Rotation.from_quat(quats[0]).as_matrix()
        return np.tile(positions[0], (t.shape[0], 1)), np.tile(rot, (t.shape[0], 1, 1))
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.shape[0] - 2)
    u = _min_jerk((t - times[k]) / np.maximum(times[k + 1] - times[k], 1e-12))
    p = positions[k] + u[:, None] * (positions[k + 1] - positions[k])
    slerp = Slerp(times, Rotation.from_quat(quats))
    phase = times[k] + u * (times[k + 1] - times[k])
    return p, np.asarray(slerp(np.clip(phase, times[0], times[-1])).as_matrix())


def _overlay(
    t: F64, pos: F64, rot: F64, start: float, traj: WristTrajectory, *, cutoff_hz: float = ROTATION_CUTOFF_HZ
) -> None:
    """Replace the samples of ``t`` inside a planned segment (starting at ``start`` [s]) by the segment, its
    orientations low-passed at ``cutoff_hz`` [Hz] (:func:`~hsi_retarget.rotation_filter.smooth_rotations`;
    0: as planned)."""
    inside = (t >= start + traj.t[0]) & (t <= start + traj.t[-1])
    if not inside.any():
        return
    local = t[inside] - start
    pos[inside] = np.column_stack([np.interp(local, traj.t, traj.position[:, i]) for i in range(3)])
    quats = smooth_rotations(traj.t, traj.quaternion, cutoff_hz)
    rot[inside] = Slerp(traj.t, Rotation.from_quat(quats))(local).as_matrix()


def human_motion_from_schedule(
    schedule: Schedule, rate: float = 60.0, rotation_cutoff_hz: float = ROTATION_CUTOFF_HZ
) -> HumanMotion:
    """Samples at ``rate`` [Hz] of a schedule: hip and wrist keyframes (min-jerk between them) with the
    planned wrist segments laid over their time spans, their orientations low-passed at
    ``rotation_cutoff_hz`` [Hz] (0: as planned; :mod:`hsi_retarget.rotation_filter`); grasp/release
    keyframes become events."""
    hips = schedule.of("hip")
    if not hips:
        raise RetargetError(f"schedule {schedule.task_id!r} has no hip keyframes")
    duration = schedule.duration
    t = np.arange(math.floor(duration * rate) + 1) / rate
    if t[-1] < duration - 1e-9:
        t = np.append(t, duration)
    hip_t = np.array([k.time for k in hips])
    hip_p, hip_r = _keyframe_path(
        hip_t, np.array([k.position for k in hips]), np.array([k.quaternion for k in hips]), t
    )
    euler = Rotation.from_matrix(hip_r).as_euler("ZYX")
    wrist_p: dict[str, F64] = {}
    wrist_r: dict[str, F64] = {}
    active: dict[str, NDArray[np.bool_]] = {}
    for side in SIDES:
        keys = schedule.of(f"{side}_wrist")
        if not keys:
            continue
        kt = np.array([k.time for k in keys])
        p, r = _keyframe_path(
            kt, np.array([k.position for k in keys]), np.array([k.quaternion for k in keys]), t
        )
        for seg in schedule.segments:
            if seg.trajectory.hand == side:
                _overlay(t, p, r, seg.start_time, seg.trajectory, cutoff_hz=rotation_cutoff_hz)
        wrist_p[side], wrist_r[side], active[side] = p, r, np.ones(t.shape[0], dtype=bool)
    events = []
    for k in schedule.events():
        if k.contact_event in ("grasp", "release"):
            hands = ("left", "right") if k.hand == "both" else (k.hand,)
            events += [ContactEvent(k.time, h, k.contact_event, k.object_name) for h in hands if h in SIDES]
    return HumanMotion(
        t=t,
        wrist_position=wrist_p,
        wrist_rotation=wrist_r,
        active=active,
        hip_position=hip_p,
        hip_yaw=np.unwrap(euler[:, 0]),
        hip_pitch=euler[:, 1],
        events=tuple(events),
        source=f"schedule {schedule.task_id}",
    )


def human_motion_from_wrists(
    segments: Sequence[WristTrajectory],
    hip: tuple[float, float, float] = (0.0, 0.0, 0.0),
    hip_height: float = 0.95,
    rate: float = 60.0,
) -> HumanMotion:
    """Planned wrist segments played one after the other per hand (each hand's segments in the given order),
    the hip standing still at ``hip`` = (x [m], y [m], yaw [rad]) and ``hip_height`` [m]. The contact of a
    grasp approach becomes a grasp event, that of a place approach a release event."""
    if not segments:
        raise RetargetError("no wrist trajectories to retarget")
    starts: list[float] = []
    ends = {s: 0.0 for s in SIDES}
    for seg in segments:
        starts.append(ends[seg.hand])
        ends[seg.hand] += seg.duration
    duration = max(ends.values())
    t = np.arange(math.floor(duration * rate) + 1) / rate
    if t[-1] < duration - 1e-9:
        t = np.append(t, duration)
    wrist_p: dict[str, F64] = {}
    wrist_r: dict[str, F64] = {}
    active: dict[str, NDArray[np.bool_]] = {}
    events: list[ContactEvent] = []
    for side in SIDES:
        own = [(s0, seg) for s0, seg in zip(starts, segments, strict=True) if seg.hand == side]
        if not own:
            continue
        first, last = own[0][1], own[-1][1]
        p = np.where(t[:, None] < own[0][0] + first.t[-1], first.position[0], last.position[-1])
        r = np.tile(Rotation.from_quat(last.quaternion[-1]).as_matrix(), (t.shape[0], 1, 1))
        for s0, seg in own:
            _overlay(t, p, r, s0, seg)
            if seg.segment == "approach":
                kind = "grasp" if seg.action == "grasp" else "release"
                events.append(ContactEvent(s0 + float(seg.t[seg.contact_index]), side, kind, seg.object_name))
        wrist_p[side], wrist_r[side], active[side] = p, r, np.ones(t.shape[0], dtype=bool)
    n = t.shape[0]
    return HumanMotion(
        t=t,
        wrist_position=wrist_p,
        wrist_rotation=wrist_r,
        active=active,
        hip_position=np.tile([hip[0], hip[1], hip_height], (n, 1)),
        hip_yaw=np.full(n, hip[2]),
        standing_hip_height=hip_height,
        events=tuple(events),
        source=f"{len(segments)} wrist trajectories",
    )
