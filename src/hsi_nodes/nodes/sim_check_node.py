"""``sim_check_node``: executes robot joint trajectories in the MuJoCo check and reports how they went.

Inputs: ``/robot/joint_trajectory`` (``trajectory_msgs/JointTrajectory`` from ``retarget_node``), the
task reports on ``/hsi/report`` (``hsi/msg/TaskReport``: the ``schedule`` stage names the task's object
and planner, the ``retarget`` stage carries the task id and the gripper events in ``details_json``) and
the goals on ``/hsi/goal`` (``hsi/msg/PickPlaceGoal``: the placement, ``place_pose.position`` = the
object's bottom centre). A trajectory is executed when the ``retarget`` report that follows it arrives.

Each task runs in the scene at rest (``reset_each_task``) with the robot snapped to the trajectory's
first configuration; the robot stands still ``dwell_after_s`` at every gripper event (and
``dwell_before_release_s`` before a release) while the fingers move (:mod:`hsi_retarget.gripper_dwell`).
During the execution ``/robot/joint_states`` (``sensor_msgs/JointState``, stamped with the node clock plus
the simulated execution time) goes out at ``joint_state_rate``; afterwards a ``TaskReport`` (stage
``sim``) with success, placement error, collisions, tracking error and the full report as
``details_json`` (plus ``opening_max``: the widest opening [rad or m] of a door or drawer the robot
grasped, ``null`` without one). With ``video`` set, every execution is rendered into that one file.
Malformed inputs and failed executions are reported, and the node keeps running.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hsi_nodes.msgs import make_header, msg_class, ns_to_time
from hsi_nodes.node import Node
from hsi_planning.errors import ConfigError, HsiError

__all__ = ["SimCheckNode", "SimCheckNodeConfig"]

_JOINT_TRAJ = "trajectory_msgs/msg/JointTrajectory"
_JOINT_STATE = "sensor_msgs/msg/JointState"
_REPORT = "hsi/msg/TaskReport"
_GOAL = "hsi/msg/PickPlaceGoal"


@dataclass(frozen=True)
class SimCheckNodeConfig:
    """Parameters of :class:`SimCheckNode`."""

    scene: str = "kitchen"  #: built-in scene name or spec path [-]
    robot: str = "dual_ur5e"  #: robot name (``dual_ur5e``/``dual_arm`` or ``humanoid``) [-]
    reset_each_task: bool = True  #: start every task from the scene at rest [-]
    dwell_after_s: float = 0.8  #: standstill after a gripper event [s]
    dwell_before_release_s: float = 0.3  #: standstill before a release [s]
    joint_state_rate: float = 25.0  #: /robot/joint_states rate during an execution; 0 = none [Hz]
    video: str = ""  #: video file of all executions ('' = none) [path]
    video_width: int = 320  #: video frame width [px]
    video_height: int = 240  #: video frame height [px]
    video_every: int = 8  #: render every k-th control step [-]
    video_fps: float = 25.0  #: video playback rate [frames/s]
    video_distance: float = 2.6  #: free camera distance from the task's target [m]
    video_azimuth: float = 160.0  #: free camera azimuth [deg]
    video_elevation: float = -35.0  #: free camera elevation [deg]
    frame_id: str = "world"  #: frame of the report headers [-]
    trajectory_topic: str = "/robot/joint_trajectory"  #: input joint trajectories [-]
    report_topic: str = "/hsi/report"  #: task reports (input: schedule/retarget; output: sim) [-]
    goal_topic: str = "/hsi/goal"  #: pick-and-place goals (placements) [-]
    joint_states_topic: str = "/robot/joint_states"  #: robot joint states during execution [-]

    def __post_init__(self) -> None:
        from hsi_retarget.robots import robot_name

        robot_name(self.robot)
        if not self.scene:
            raise ConfigError("SimCheckNodeConfig.scene: give a built-in scene name or a spec path")
        values = (self.dwell_after_s, self.dwell_before_release_s, self.joint_state_rate)
        if not all(math.isfinite(v) and v >= 0.0 for v in values):
            raise ConfigError(
                "SimCheckNodeConfig: dwell_after_s, dwell_before_release_s [s] and joint_state_rate [Hz] "
                f"must be finite and >= 0, got {values}"
            )
        if self.video_width < 16 or self.video_height < 16 or self.video_every < 1:
            raise ConfigError("SimCheckNodeConfig: video size >= 16 px and video_every >= 1")
        if not (math.isfinite(self.video_fps) and self.video_fps > 0.0 and self.video_distance > 0.0):
            raise ConfigError("SimCheckNodeConfig: video_fps > 0 frames/s and video_distance > 0 m")


@dataclass
class _TaskInfo:
    object_name: str = ""
    planner: str = ""
    placement: tuple[float, float, float] | None = None


class SimCheckNode(Node[SimCheckNodeConfig]):
    """Runs joint trajectories in MuJoCo and reports them (see the module docstring)."""

    config_class = SimCheckNodeConfig

    def __init__(self, name: str = "sim_check_node", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        from hsi_retarget.sim_check import WorldConfig, build_world

        cfg = self.config
        self.world = build_world(WorldConfig(scene=cfg.scene, robot=cfg.robot))
        self.tasks: dict[str, _TaskInfo] = {}
        self.pending: Any = None  #: the last joint trajectory not yet executed
        #: Executions run; inputs ignored as malformed.
        self.executed = 0
        self.ignored = 0
        self.video: Any = None
        self._last_recorder: Any = None
        if cfg.video:
            from pathlib import Path

            from hsi_nodes.demo.video import DemoVideo
            from hsi_retarget.sim_check import VideoConfig

            size = VideoConfig(
                width=cfg.video_width,
                height=cfg.video_height,
                every=cfg.video_every,
                fps=cfg.video_fps,
                distance=cfg.video_distance,
                azimuth=cfg.video_azimuth,
                elevation=cfg.video_elevation,
            )
            self.video = DemoVideo(Path(cfg.video), size)
        self.create_subscription(cfg.trajectory_topic, _JOINT_TRAJ, self._on_trajectory, 10)
        self.create_subscription(cfg.report_topic, _REPORT, self._on_report, 50)
        self.create_subscription(cfg.goal_topic, _GOAL, self._on_goal, 10)
        self.report_pub = self.create_publisher(cfg.report_topic, _REPORT, 10)
        self.state_pub = self.create_publisher(cfg.joint_states_topic, _JOINT_STATE, 100)

    # ------------------------------------------------------------------------------------- inputs

    def _on_goal(self, goal: Any) -> None:
        info = self.tasks.setdefault(str(goal.task_id), _TaskInfo())
        if str(goal.object_name):
            info.object_name = str(goal.object_name)
        if bool(goal.has_place):
            p = goal.place_pose.position
            info.placement = (float(p.x), float(p.y), float(p.z))

    def _on_trajectory(self, msg: Any) -> None:
        from hsi_nodes.nodes.retarget_node import joint_trajectory_from_msg

        try:
            self.pending = joint_trajectory_from_msg(msg, self.world.robot.name)
        except (HsiError, ValueError, TypeError) as exc:
            self.ignored += 1
            self.get_logger().warning("ignored a joint trajectory: %s", exc)

    def _on_report(self, msg: Any) -> None:
        stage, task_id = str(msg.stage), str(msg.task_id)
        if stage == "schedule" and bool(msg.success):
            info = self.tasks.setdefault(task_id, _TaskInfo())
            info.object_name = info.object_name or str(msg.object_name)
            info.planner = str(msg.planner)
        elif stage == "retarget" and self.pending is not None:
            traj, self.pending = self.pending, None
            try:
                details = json.loads(str(msg.details_json) or "{}")
                events = list(details.get("events", []))
            except (ValueError, AttributeError) as exc:
                self.ignored += 1
                self.get_logger().warning("task %s: unreadable retarget details: %s", task_id, exc)
                events = []
            self._execute(task_id, traj, events)

    # ---------------------------------------------------------------------------------- execution

    def _states(self) -> Any:
        cfg, world = self.config, self.world
        if cfg.joint_state_rate <= 0.0:
            return None
        joint_state = msg_class(_JOINT_STATE)
        names = list(world.robot.joint_names)
        index = [world.robot.q_index(n) for n in names]
        start, last = self.now_ns(), [-math.inf]

        def publish(w: Any) -> None:
            if w.time - last[0] < 1.0 / cfg.joint_state_rate - 1e-9:
                return
            last[0] = w.time
            q = w.robot_q()
            stamp = ns_to_time(start + round(w.time * 1e9))
            self.state_pub.publish(
                joint_state(
                    header=msg_class("std_msgs/msg/Header")(stamp=stamp, frame_id=cfg.frame_id),
                    name=names,
                    position=np.asarray(q[index], dtype=np.float64),
                    velocity=np.zeros(0),
                    effort=np.zeros(0),
                )
            )

        return publish

    def _execute(self, task_id: str, traj: Any, events: list[dict[str, Any]]) -> None:
        from hsi_retarget.gripper_dwell import DwellConfig, add_gripper_dwell
        from hsi_retarget.joint_trajectory import ContactEvent, JointTrajectory
        from hsi_retarget.sim_check import TaskGoal, execute

        cfg, world = self.config, self.world
        info = self.tasks.get(task_id, _TaskInfo())
        t0 = time.perf_counter()
        try:
            full = JointTrajectory(
                traj.robot,
                traj.t,
                traj.q,
                traj.joint_names,
                events=tuple(ContactEvent(**e) for e in events),
                floating_index=traj.floating_index,
            )
            full = add_gripper_dwell(full, DwellConfig(cfg.dwell_after_s, cfg.dwell_before_release_s))
            if cfg.reset_each_task:
                world.reset()
            placement = info.placement if info.object_name else None
            goal = TaskGoal(info.object_name, placement=placement, planner=info.planner)
            parts = sorted(
                {str(e.object_name) for e in full.events if e.kind == "grasp" and "/" in e.object_name}
            )
            opened = dict.fromkeys(parts, 0.0)

            def track_opening(w: Any) -> None:
                for part in parts:
                    opened[part] = max(opened[part], abs(float(w.opening(part))))

            hooks = [h for h in (self._states(), self._recorder(info), track_opening) if h is not None]

            def on_frame(w: Any) -> None:
                for hook in hooks:
                    hook(w)

            report = execute(world, full, goal=goal, on_frame=on_frame)
        except (HsiError, ValueError, TypeError) as exc:
            self.get_logger().warning("task %s not executed: %s", task_id, exc)
            self._publish(task_id, info, None, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0)
            return
        self.executed += 1
        if self.video is not None:
            verdict = "success" if report.success else "failure"
            self.video.add([f"{task_id}: {verdict}", info.object_name], self._last_recorder)
        opening_max = max(opened.values()) if opened else None
        self._publish(task_id, info, report, "", report.duration_s, opening_max=opening_max)

    def _recorder(self, info: _TaskInfo) -> Any:
        self._last_recorder = None
        if self.video is None:
            return None
        target = np.array([0.8, 0.0, 0.9])
        if info.placement is not None:
            target = np.array([*info.placement[:2], 0.9])
        self._last_recorder = self.video.recorder(self.world, tuple(float(v) for v in target))
        return self._last_recorder

    def _publish(
        self,
        task_id: str,
        info: _TaskInfo,
        report: Any,
        error: str,
        seconds: float,
        *,
        opening_max: float | None = None,
    ) -> None:
        nan = float("nan")
        if report is None:
            success, message, details = False, f"execution failed: {error}", {"error": error}
        else:
            success = bool(report.success)
            message = "success" if success else "; ".join(report.failures)
            details = report.to_dict()
            details["opening_max"] = opening_max  # the widest opening of a door or drawer held [rad or m]
        self.report_pub.publish(
            msg_class(_REPORT)(
                header=make_header(self.now(), self.config.frame_id),
                task_id=task_id,
                stage="sim",
                success=success,
                message=message,
                object_name=info.object_name,
                robot=self.world.robot.name,
                planner=info.planner,
                placement_error_m=nan
                if report is None or report.placement_error_m is None
                else float(report.placement_error_m),
                duration_s=float(seconds),
                collisions=0 if report is None else int(report.collisions),
                max_tracking_error_m=nan if report is None else float(report.max_tracking_error_m),
                details_json=json.dumps(details),
            )
        )

    def on_shutdown(self) -> None:
        """Finish the video file."""
        if self.video is not None:
            self.video.close()
