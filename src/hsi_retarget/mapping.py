"""Human wrist/hip goals -> robot goals: TCP poses, base pose + torso lift (dual arm) or pelvis (humanoid).

Conventions (world z up, x forward, y left):

- **Human wrist frame** (the planner's, :func:`hsi_planning.scheduler.body.wrist_quaternion`): x along the
  hand, pointing out of the fingers (the approach direction), z "up" (the thumb side in a side grasp of an
  upright object), y = z x x (the palm normal, the axis a pinch closes along).
- **Robot TCP frame** (:mod:`hsi_retarget.robots`): z out of the gripper (approach), y along which the
  fingers slide. The default ``wrist_to_tcp_rotvec`` = (0, pi/2, 0) maps wrist x -> TCP z, wrist y -> TCP y
  (so an identity wrist orientation is the dual arm's home TCP orientation).
- **Hip**: position (3,) [m] and heading ``yaw`` [rad]; the robot root (dual-arm base x, y, yaw; humanoid
  pelvis) takes the hip's floor position and heading. Dual arm: the torso lift puts the robot's shoulders
  at the (scaled) human shoulder height, clipped to the lift range. Humanoid: pelvis height = hip height
  times the robot/human standing height ratio, between ``pelvis_drop_max`` below and the home height (flat
  feet limit the squat; straight knees are singular); the pelvis stays upright (the waist leans).

Anchors (``MappingConfig.anchor``):

- ``shoulder`` (teleoperation, recorded motion): ``tcp = S_r + s (w - S_h)`` with the human shoulder
  ``S_h`` (from mocap, or from the hip with adult offsets), the robot's nominal shoulder ``S_r`` and the
  arm-length ratio ``s = robot reach / human arm length``.
- ``world`` (planned pick-and-place: the contact poses are on real objects): ``tcp = w``.

A goal farther from the robot's shoulder than its reach is flagged per sample (``RobotGoals.reachable``,
``reach_excess``) and kept as is: nothing is clipped; the IK then reports the residual it cannot close.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError
from hsi_retarget.human_motion import SIDES, HumanMotion
from hsi_retarget.robots import RobotModel

F64 = NDArray[np.float64]
BASE_JOINTS = ("base_x_joint", "base_y_joint", "base_yaw_joint")  #: planar base of the dual-arm robot
LIFT_JOINT = "torso_lift_joint"  #: torso lift of the dual-arm robot
Anchor = Literal["shoulder", "world"]
_REACH_CACHE: dict[str, dict[str, float]] = {}


@dataclass(frozen=True)
class MappingConfig:
    """How human goals become robot goals."""

    anchor: Anchor = "shoulder"  #: [-] ``shoulder`` (scaled about the shoulders) or ``world`` (as given)
    arm_scale: float = 0.0  #: [-] wrist-offset scale; 0 = reach_fraction x robot reach / human arm length
    reach_fraction: float = 0.85  #: [-] share of the robot's reach a straight human arm maps to (singularity)
    human_arm_length: float = 0.6  #: [m] shoulder-wrist length when the source does not measure it
    shoulder_lateral: float = 0.18  #: [m] human shoulder offset to the side of the hip (adult)
    shoulder_height: float = 0.45  #: [m] human shoulder height above the hip along the trunk (adult)
    standing_hip_height: float = 0.95  #: [m] human hip height standing (when the source has none)
    wrist_to_tcp_rotvec: tuple[float, float, float] = (0.0, np.pi / 2, 0.0)  #: [rad] TCP in the wrist frame
    reach_margin: float = 0.0  #: [m] goals beyond ``reach - reach_margin`` are flagged unreachable
    pelvis_drop_max: float = 0.15  #: [m] deepest pelvis goal below home (flat feet limit the squat)

    def __post_init__(self) -> None:
        if self.anchor not in ("shoulder", "world"):
            raise ConfigError(f"MappingConfig.anchor={self.anchor!r}: 'shoulder' or 'world'")
        if not 0.3 <= self.reach_fraction <= 1.0:
            raise ConfigError(f"MappingConfig.reach_fraction must be in [0.3, 1], got {self.reach_fraction}")
        if not 0.0 <= self.arm_scale <= 5.0:
            raise ConfigError(f"MappingConfig.arm_scale must be in [0, 5] (0 = auto), got {self.arm_scale}")
        for name in ("human_arm_length", "shoulder_lateral", "shoulder_height", "standing_hip_height"):
            if not 0.0 < getattr(self, name) < 3.0:
                raise ConfigError(f"MappingConfig.{name} must be in (0, 3) m, got {getattr(self, name)}")
        if len(self.wrist_to_tcp_rotvec) != 3 or not np.all(np.isfinite(self.wrist_to_tcp_rotvec)):
            raise ConfigError("MappingConfig.wrist_to_tcp_rotvec must be 3 finite numbers [rad]")
        if not 0.0 <= self.pelvis_drop_max <= 1.0:
            raise ConfigError(
                f"MappingConfig.pelvis_drop_max must be in [0, 1] m, got {self.pelvis_drop_max}"
            )
        if not 0.0 <= self.reach_margin < 0.5:
            raise ConfigError(f"MappingConfig.reach_margin must be in [0, 0.5) m, got {self.reach_margin}")


@dataclass(frozen=True, eq=False)
class RobotGoals:
    """Robot goals over time (world frame), ready for the IK.

    Attributes:
        t: (T,) [s].
        tcp: side -> (T, 4, 4) TCP goal poses [m].
        active: side -> (T,) bool: track this side's TCP goal.
        reachable: side -> (T,) bool: the goal is within the robot's reach (False: reported, not clipped).
        reach_excess: side -> (T,) [m] how far the goal lies beyond the reach (0 when reachable).
        root: (T, 4, 4) base (dual arm: floor pose) or pelvis (humanoid) goal poses [m].
        lift: (T,) [m] torso lift goal (NaN for robots without a lift).
        shoulder: side -> (T, 3) [m] the robot's nominal shoulder positions the goals were mapped about.
        scale: [-] the wrist-offset scale used.
        contact: side -> (T,) [0..1] closeness to a contact (:attr:`HumanMotion.contact`; empty: none).
        finger: side -> (T,) [m] opening of each finger joint of its gripper (NaN or no entry: as it is;
            :mod:`hsi_retarget.finger_room`).
    """

    t: F64
    tcp: dict[str, F64]
    active: dict[str, NDArray[np.bool_]]
    reachable: dict[str, NDArray[np.bool_]]
    reach_excess: dict[str, F64]
    root: F64
    lift: F64
    shoulder: dict[str, F64]
    scale: float
    contact: dict[str, F64] = field(default_factory=dict)
    finger: dict[str, F64] = field(default_factory=dict)

    def unreachable_intervals(self) -> list[dict[str, float | str]]:
        """Contiguous runs of active, unreachable samples: ``side``, ``t_start``/``t_end`` [s],
        ``max_excess_m`` [m]."""
        out: list[dict[str, float | str]] = []
        for side in sorted(self.tcp):
            bad = self.active[side] & ~self.reachable[side]
            for i0, i1 in _runs(bad):
                out.append(
                    {
                        "side": side,
                        "t_start": float(self.t[i0]),
                        "t_end": float(self.t[i1]),
                        "max_excess_m": float(self.reach_excess[side][i0 : i1 + 1].max()),
                    }
                )
        return out


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """(first, last) index of every run of True in ``mask``."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(padded)
    return [
        (int(a), int(b) - 1) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True)
    ]


def robot_reach(robot: RobotModel, waist: bool = False, samples: int = 4000) -> dict[str, float]:
    """[m] largest TCP distance from each shoulder frame at home, sampled over the arm joint ranges (with
    ``waist``: also the waist joints' ranges) with a seeded generator; cached per robot name."""
    key = f"{robot.name}:{waist}"
    if key in _REACH_CACHE:
        return dict(_REACH_CACHE[key])
    rng = np.random.default_rng(0)
    out: dict[str, float] = {}
    waist_joints = [j for j in robot.joint_names if waist and j.startswith("waist_")]
    for side in SIDES:
        idx = np.concatenate([robot.arm_q_indices(side), [robot.q_index(j) for j in waist_joints]]).astype(
            int
        )
        shoulder = robot.frame_pose(robot.q_home, robot.shoulder_frames[side])[:3, 3]
        best = 0.0
        for _ in range(samples):
            q = np.array(robot.q_home)
            q[idx] = rng.uniform(robot.q_lower[idx], robot.q_upper[idx])
            tcp = robot.frame_pose(q, robot.tcp_frames[side])[:3, 3]
            best = max(best, float(np.linalg.norm(tcp - shoulder)))
        out[side] = best
    _REACH_CACHE[key] = out
    return dict(out)


def nominal_configuration(robot: RobotModel, root: F64, lift: float = float("nan")) -> F64:
    """Home configuration (nq,) moved to the root goal ``root`` (4, 4) [m] (dual arm: base x, y, yaw from
    its floor pose; floating robots: the free flyer) and the torso ``lift`` [m] when given."""
    q = np.array(robot.q_home)
    pose = np.asarray(root, dtype=np.float64)
    if robot.floating:
        q[:3] = pose[:3, 3]
        q[3:7] = Rotation.from_matrix(pose[:3, :3]).as_quat()
    elif all(j in robot.joint_names for j in BASE_JOINTS):
        yaw = float(np.arctan2(pose[1, 0], pose[0, 0]))
        for name, value in zip(BASE_JOINTS, (pose[0, 3], pose[1, 3], yaw), strict=True):
            q[robot.q_index(name)] = value
    if np.isfinite(lift) and LIFT_JOINT in robot.joint_names:
        q[robot.q_index(LIFT_JOINT)] = lift
    return q


def _pose(position: F64, yaw: float) -> F64:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
    out[:3, 3] = position
    return out


def human_shoulders(motion: HumanMotion, config: MappingConfig) -> dict[str, F64]:
    """side -> (T, 3) [m] human shoulders: measured, or from the hip pose with the adult offsets."""
    if motion.shoulder_position:
        return {s: np.array(p) for s, p in motion.shoulder_position.items()}
    pitch = motion.hip_pitch if motion.hip_pitch is not None else np.zeros(motion.n_samples)
    rot = Rotation.from_euler("ZY", np.column_stack([motion.hip_yaw, pitch]))
    out: dict[str, F64] = {}
    for side in SIDES:
        sign = 1.0 if side == "left" else -1.0
        local = np.array([0.0, sign * config.shoulder_lateral, config.shoulder_height])
        out[side] = motion.hip_position + rot.apply(local)
    return out


def map_to_robot(motion: HumanMotion, robot: RobotModel, config: MappingConfig | None = None) -> RobotGoals:
    """Robot goals for ``motion`` (see the module docstring for the mapping)."""
    cfg = config or MappingConfig()
    n = motion.n_samples
    reach = robot_reach(robot)
    reach_check = robot_reach(robot, waist=True) if robot.floating else reach
    human_arm = motion.arm_length or cfg.human_arm_length
    scale = cfg.arm_scale or cfg.reach_fraction * float(np.mean([reach[s] for s in SIDES])) / human_arm
    if cfg.anchor == "world" and cfg.arm_scale == 0.0:
        scale = 1.0
    shoulders_h = human_shoulders(motion, cfg)
    stand_hip = motion.standing_hip_height or cfg.standing_hip_height
    stand_shoulder = motion.standing_shoulder_height or (stand_hip + cfg.shoulder_height)
    home = {s: robot.frame_pose(robot.q_home, robot.shoulder_frames[s])[:3, 3] for s in SIDES}
    lift = np.full(n, np.nan)
    has_lift = LIFT_JOINT in robot.joint_names
    roots = np.zeros((n, 4, 4))
    if robot.floating:
        pelvis_ratio = float(robot.q_home[2]) / stand_hip
        top = float(robot.q_home[2])
        for i in range(n):  # straight knees are singular: the pelvis rises no higher than at home
            position = np.array(motion.hip_position[i])
            position[2] = float(np.clip(position[2] * pelvis_ratio, top - cfg.pelvis_drop_max, top))
            roots[i] = _pose(position, float(motion.hip_yaw[i]))
    else:
        for i in range(n):
            roots[i] = _pose(np.array([*motion.hip_position[i, :2], 0.0]), float(motion.hip_yaw[i]))
    lift_lo = lift_hi = 0.0
    if has_lift:
        il = robot.q_index(LIFT_JOINT)
        lift_lo, lift_hi, lift_home = (
            float(robot.q_lower[il]),
            float(robot.q_upper[il]),
            float(robot.q_home[il]),
        )
        z_at_zero = float(np.mean([home[s][2] for s in SIDES])) - lift_home
        ratio = 1.0 if cfg.anchor == "world" else float(np.mean([home[s][2] for s in SIDES])) / stand_shoulder
        mid_h = 0.5 * (shoulders_h["left"][:, 2] + shoulders_h["right"][:, 2])
        lift = np.clip(ratio * mid_h - z_at_zero, lift_lo, lift_hi)
    shoulder_r = _robot_shoulders(
        robot,
        motion,
        cfg=cfg,
        roots=roots,
        lift=lift,
        shoulders_h=shoulders_h,
        human_trunk=stand_shoulder - stand_hip,
    )
    wrist_to_tcp = Rotation.from_rotvec(np.asarray(cfg.wrist_to_tcp_rotvec, dtype=float)).as_matrix()
    tcp: dict[str, F64] = {}
    reachable: dict[str, NDArray[np.bool_]] = {}
    excess: dict[str, F64] = {}
    for side in motion.wrist_position:
        w = motion.wrist_position[side]
        goal = w if cfg.anchor == "world" else shoulder_r[side] + scale * (w - shoulders_h[side])
        poses = np.tile(np.eye(4), (n, 1, 1))
        poses[:, :3, :3] = motion.wrist_rotation[side] @ wrist_to_tcp
        poses[:, :3, 3] = goal
        tcp[side] = poses
        if has_lift:  # the lift moves the shoulder vertically over its range
            low = shoulder_r[side].copy()
            low[:, 2] += lift_lo - lift
            dist = _segment_distance(goal, low, np.array([0.0, 0.0, lift_hi - lift_lo]))
        else:
            dist = np.linalg.norm(goal - shoulder_r[side], axis=1)
        excess[side] = np.maximum(dist - (reach_check[side] - cfg.reach_margin), 0.0)
        reachable[side] = excess[side] <= 0.0
    return RobotGoals(
        t=np.array(motion.t),
        tcp=tcp,
        active={s: np.array(a) for s, a in motion.active.items()},
        reachable=reachable,
        reach_excess=excess,
        root=roots,
        lift=lift,
        shoulder=shoulder_r,
        scale=float(scale),
        contact={s: np.array(c) for s, c in motion.contact.items()},
    )


def _robot_shoulders(
    robot: RobotModel,
    motion: HumanMotion,
    *,
    cfg: MappingConfig,
    roots: F64,
    lift: F64,
    shoulders_h: dict[str, F64],
    human_trunk: float,
) -> dict[str, F64]:
    """side -> (T, 3) [m] nominal robot shoulders: FK at the root/lift goals; a robot with a waist
    (floating) also takes the human trunk lean, scaled by the trunk-length ratio."""
    n = motion.n_samples
    out: dict[str, F64] = {s: np.zeros((n, 3)) for s in SIDES}
    frames = tuple(robot.shoulder_frames[s] for s in SIDES)
    if robot.floating and cfg.anchor == "shoulder":
        home = robot.fk(robot.q_home, frames)
        pelvis = robot.q_home[:3]
        robot_trunk = float(np.linalg.norm(0.5 * sum(home[f][:3, 3] for f in frames) - pelvis))
        k = robot_trunk / human_trunk
        for side in SIDES:
            lateral = home[robot.shoulder_frames[side]][:3, 3] - pelvis
            mid_h = 0.5 * (shoulders_h["left"] + shoulders_h["right"])
            trunk = k * (mid_h - motion.hip_position)
            rot = Rotation.from_euler("z", motion.hip_yaw.reshape(-1, 1))
            lat = rot.apply(np.array([lateral[0], lateral[1], 0.0]))
            out[side] = roots[:, :3, 3] + trunk + lat
        return out
    for i in range(n):
        fk = robot.fk(nominal_configuration(robot, roots[i], float(lift[i])), frames)
        for side in SIDES:
            out[side][i] = fk[robot.shoulder_frames[side]][:3, 3]
    return out


def _segment_distance(points: F64, start: F64, direction: F64) -> F64:
    """(T,) [m] distance of points (T, 3) from the segments ``start + u direction``, u in [0, 1]."""
    dd = float(direction @ direction)
    u = np.clip(((points - start) @ direction) / dd, 0.0, 1.0) if dd > 0 else np.zeros(points.shape[0])
    return np.asarray(np.linalg.norm(points - start - u[:, None] * direction[None, :], axis=1))
