"""``retarget_node``: planned wrist trajectories (+ the task's schedule) -> a robot joint trajectory.

Inputs: ``/hsi/wrist_trajectory`` (``hsi/msg/WristTrajectory``, one per planned segment) and ``/hsi/schedule``
(``hsi/msg/Schedule``: hip/root and wrist keyframes). Inputs are collected per ``task_id``; a task is
retargeted once nothing new arrived for it for ``settle_s`` (and, with ``require_schedule``, once its schedule
is known). With a schedule, the wrist segments are placed at ``segment stamp - schedule stamp`` and the hip
keyframes drive the base/pelvis; without one, the segments play one after the other per hand from a hip
standing at ``hip``. With ``deepen_grasps``, the wrist goals around the grasps of a schedule become
gripper goals (:mod:`hsi_retarget.grasp_depth`, as in the demo's function path): the TCP goes
``palm_offset + grasp_depth`` into a free object of the scene, the last ``standoff`` of an approach and the
first of a retreat are straight along the approach axis, and a carried object turns smoothly.
Output: ``/robot/joint_trajectory`` (``trajectory_msgs/msg/JointTrajectory``; a floating root appears as
seven pseudo-joints ``root_joint/x`` ... ``root_joint/qw``) and a ``hsi/msg/TaskReport``
(stage ``retarget``) whose ``details_json`` carries the gripper events, unreachable goals and time scaling.
Malformed messages are logged and ignored.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hsi_nodes.msgs import make_header, msg_class, pose_to_arrays, stamp_to_seconds
from hsi_nodes.node import Node
from hsi_planning.errors import ConfigError, HsiError
from hsi_planning.trajectory import WristTrajectory
from hsi_retarget.grasp_depth import GraspDepthConfig
from hsi_retarget.joint_trajectory import JointTrajectory, plain

__all__ = ["RetargetNode", "RetargetNodeConfig", "joint_trajectory_from_msg", "joint_trajectory_msg"]

_WRIST = "hsi/msg/WristTrajectory"
_SCHEDULE = "hsi/msg/Schedule"
_JOINT_TRAJ = "trajectory_msgs/msg/JointTrajectory"
_REPORT = "hsi/msg/TaskReport"
ROOT_COORDS = ("x", "y", "z", "qx", "qy", "qz", "qw")  #: pseudo-joint suffixes of a floating root


@dataclass(frozen=True)
class RetargetNodeConfig:
    """Parameters of :class:`RetargetNode`."""

    robot: str = "dual_ur5e"  #: robot name (``dual_ur5e``/``dual_arm`` or ``humanoid``) [-]
    scene: str = ""  #: scene spec (name or YAML) for collision margins; empty: none [-]
    anchor: str = "world"  #: goal mapping anchor (``world`` or ``shoulder``) [-]
    settle_s: float = 0.5  #: quiet time after a task's last input before it is retargeted [s]
    require_schedule: bool = False  #: wait for the task's schedule [-]
    deepen_grasps: bool = False  #: gripper goals around the grasps of a schedule (needs ``scene``) [-]
    palm_offset: float = 0.06  #: planners' wrist distance beyond an object's box at a grasp [m]
    grasp_depth: float = 0.03  #: gripper TCP depth inside the object's box past its near face [m]
    standoff: float = 0.08  #: straight final approach / first retreat along the approach axis [m]
    sample_rate: float = 60.0  #: sampling of the plans [Hz]
    hip: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: hip x [m], y [m], yaw [rad] without a schedule
    period_s: float = 0.1  #: check period of the settle timer [s]
    frame_id: str = "world"  #: frame of the output header [-]
    wrist_topic: str = "/hsi/wrist_trajectory"  #: input wrist segments [-]
    schedule_topic: str = "/hsi/schedule"  #: input schedules [-]
    trajectory_topic: str = "/robot/joint_trajectory"  #: output joint trajectories [-]
    report_topic: str = "/hsi/report"  #: output reports [-]

    def __post_init__(self) -> None:
        from hsi_retarget.robots import robot_name

        robot_name(self.robot)
        if self.anchor not in ("world", "shoulder"):
            raise ConfigError(f"RetargetNodeConfig.anchor={self.anchor!r}: 'world' or 'shoulder'")
        if not (self.settle_s >= 0.0 and self.sample_rate > 0.0 and self.period_s > 0.0):
            raise ConfigError("RetargetNodeConfig: settle_s >= 0 s, sample_rate > 0 Hz, period_s > 0 s")
        if self.deepen_grasps and not self.scene:
            raise ConfigError("RetargetNodeConfig.deepen_grasps needs the scene (its object names)")
        self.grasp()  # validates palm_offset, grasp_depth and standoff

    def grasp(self) -> GraspDepthConfig:
        """The gripper-goal config of ``palm_offset``, ``grasp_depth`` and ``standoff`` [m]."""
        return GraspDepthConfig(
            palm_offset=self.palm_offset, grasp_depth=self.grasp_depth, standoff=self.standoff
        )


def joint_trajectory_msg(traj: JointTrajectory, stamp_s: float, frame_id: str) -> Any:
    """``trajectory_msgs/msg/JointTrajectory`` of ``traj`` (positions and finite-difference velocities)."""
    names = list(traj.joint_names)
    if traj.root_index >= 0:
        names = [f"root_joint/{c}" for c in ROOT_COORDS] + names
    vel = traj.velocities()
    point = msg_class("trajectory_msgs/msg/JointTrajectoryPoint")
    duration = msg_class("builtin_interfaces/msg/Duration")
    points = []
    for k in range(traj.t.shape[0]):
        ns = round(float(traj.t[k]) * 1e9)
        points.append(
            point(
                positions=np.array(traj.q[k]),
                velocities=np.array(vel[k]),
                accelerations=np.zeros(0),
                effort=np.zeros(0),
                time_from_start=duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000),
            )
        )
    return msg_class(_JOINT_TRAJ)(header=make_header(stamp_s, frame_id), joint_names=names, points=points)


def joint_trajectory_from_msg(msg: Any, robot: str) -> JointTrajectory:
    """Inverse of :func:`joint_trajectory_msg` (events and meta are not carried by the message)."""
    names = [str(n) for n in msg.joint_names]
    floating = bool(names) and names[0] == "root_joint/x"
    t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points])
    q = np.array([np.asarray(p.positions, dtype=np.float64) for p in msg.points])
    return JointTrajectory(
        robot, t, q, tuple(names[7:] if floating else names), floating_index=0 if floating else -1
    )


def _wrist_from_msg(msg: Any) -> WristTrajectory:
    poses = [pose_to_arrays(p) for p in msg.poses]
    return WristTrajectory(
        t=np.asarray(msg.time_from_start, dtype=np.float64),
        position=np.array([p for p, _ in poses]).reshape(-1, 3),
        quaternion=np.array([q for _, q in poses]).reshape(-1, 4),
        hand=str(msg.hand),  # type: ignore[arg-type]
        action=str(msg.action),  # type: ignore[arg-type]
        segment=str(msg.segment),  # type: ignore[arg-type]
        contact_index=int(msg.contact_index),
        planner=str(msg.planner),
        object_name=str(msg.object_name),
    )


@dataclass
class _Task:
    segments: list[tuple[float, WristTrajectory]] = field(default_factory=list)  # (stamp [s], segment)
    schedule: Any = None  # (stamp [s], keyframe msgs, steps)
    updated: float = 0.0


class RetargetNode(Node[RetargetNodeConfig]):
    """Retargets planned tasks onto the robot (see the module docstring)."""

    config_class = RetargetNodeConfig

    def __init__(self, name: str = "retarget_node", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        from hsi_retarget.robots import RobotModel

        cfg = self.config
        self.robot = RobotModel(cfg.robot)
        self.spec: Any = None
        if cfg.scene:
            from hsi_planning.scene_paths import load_scene

            self.spec = load_scene(cfg.scene)
        self.tasks: dict[str, _Task] = {}
        #: Messages ignored as malformed; tasks retargeted / failed.
        self.ignored = 0
        self.retargeted = 0
        self.failed = 0
        self.create_subscription(cfg.wrist_topic, _WRIST, self._on_wrist, 50)
        self.create_subscription(cfg.schedule_topic, _SCHEDULE, self._on_schedule, 10)
        self.traj_pub = self.create_publisher(cfg.trajectory_topic, _JOINT_TRAJ, 10)
        self.report_pub = self.create_publisher(cfg.report_topic, _REPORT, 10)
        self.create_timer(cfg.period_s, self._tick)

    def _ignore(self, what: str, exc: Exception | str) -> None:
        self.ignored += 1
        self.get_logger().warning("ignored %s: %s", what, exc)

    def _on_wrist(self, msg: Any) -> None:
        try:
            traj = _wrist_from_msg(msg)
        except (HsiError, ValueError, TypeError) as exc:
            self._ignore("wrist trajectory", exc)
            return
        task = self.tasks.setdefault(str(msg.task_id), _Task())
        task.segments.append((stamp_to_seconds(msg.header.stamp), traj))
        task.updated = self.now()

    def _on_schedule(self, msg: Any) -> None:
        task = self.tasks.setdefault(str(msg.task_id), _Task())
        task.schedule = (stamp_to_seconds(msg.header.stamp), list(msg.keyframes), [str(s) for s in msg.steps])
        task.updated = self.now()

    def _tick(self) -> None:
        now = self.now()
        for task_id in list(self.tasks):
            task = self.tasks[task_id]
            if now - task.updated < self.config.settle_s or not task.segments:
                continue
            if self.config.require_schedule and task.schedule is None:
                continue
            del self.tasks[task_id]
            self._retarget(task_id, task)

    def _source(self, task_id: str, task: _Task) -> Any:
        if task.schedule is None:
            return [seg for _, seg in task.segments]
        from hsi_planning.scheduler.schedule import Keyframe, PlannedSegment, Schedule

        stamp, keyframes, steps = task.schedule
        frames = []
        for k in keyframes:
            position, quat = pose_to_arrays(k.pose)
            fields = {
                "time": k.time,
                "key_joint": str(k.key_joint),
                "action": str(k.action),
                "hand": str(k.hand),
            }
            fields |= {"position": position, "quaternion": quat, "contact_event": str(k.contact_event)}
            frames.append(Keyframe.from_dict({**fields, "object": str(k.object_name)}))
        segments = tuple(PlannedSegment(max(0.0, s - stamp), seg, seg.segment) for s, seg in task.segments)
        return Schedule(task_id, tuple(frames), segments, tuple(steps))

    def _retarget(self, task_id: str, task: _Task) -> None:
        from hsi_retarget.mapping import MappingConfig
        from hsi_retarget.retarget import RetargetConfig, retarget

        cfg = self.config
        t0 = time.perf_counter()
        objects = sorted({seg.object_name for _, seg in task.segments if seg.object_name})
        try:
            config = RetargetConfig(
                mapping=MappingConfig(anchor=cfg.anchor),  # type: ignore[arg-type]
                sample_rate=cfg.sample_rate,
                hip=cfg.hip,
                grasp=cfg.grasp() if cfg.deepen_grasps and self.spec is not None else None,
            )
            traj = retarget(self._source(task_id, task), self.robot, self.spec, config)
        except HsiError as exc:
            self.failed += 1
            self.get_logger().warning("task %r not retargeted: %s", task_id, exc)
            seconds = time.perf_counter() - t0
            self._report(
                task_id, False, str(exc), objects=objects, seconds=seconds, error=float("nan"), details={}
            )
            return
        self.traj_pub.publish(joint_trajectory_msg(traj, self.now(), cfg.frame_id))
        self.retargeted += 1
        meta = traj.meta
        worst = max((v["max_position_error_m"] for v in meta["tracking"].values()), default=float("nan"))
        details = {
            "events": [dict(e.__dict__) for e in traj.events],
            "unreachable": meta["unreachable"],
            "ik_unreached": meta["ik_unreached"],
            "time_scaling": meta["time_scaling"],
            "ik_rate_fps": meta["ik_rate_fps"],
            "compute_s": time.perf_counter() - t0,
        }
        ok = not meta["unreachable"] and not meta["ik_unreached"]
        message = f"{traj.t.shape[0]} samples, {traj.duration:.2f} s" + (
            "" if ok else "; some goals not reached"
        )
        self._report(
            task_id, ok, message, objects=objects, seconds=traj.duration, error=worst, details=details
        )

    def _report(
        self,
        task_id: str,
        ok: bool,
        message: str,
        *,
        objects: list[str],
        seconds: float,
        error: float,
        details: Any,
    ) -> None:
        report = msg_class(_REPORT)(
            header=make_header(self.now(), self.config.frame_id),
            task_id=task_id,
            stage="retarget",
            success=ok,
            message=message,
            object_name=objects[0] if objects else "",
            robot=self.robot.name,
            planner="",
            placement_error_m=float("nan"),
            duration_s=float(seconds),
            collisions=0,
            max_tracking_error_m=float(error),
            details_json=json.dumps(plain(details)),
        )
        self.report_pub.publish(report)
