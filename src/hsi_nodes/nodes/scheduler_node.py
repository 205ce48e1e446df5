"""``scheduler_node``: turns clicks and pick-and-place goals into keyframe schedules (CHOICE §6).

Inputs: the labelled cloud ``/scene/points`` (``sensor_msgs/PointCloud2`` with a ``label`` field, label
ids of the scene's label table), clicks ``/clicked_point`` (``geometry_msgs/PointStamped``, RViz's
Publish Point) and goals ``/hsi/goal`` (``hsi/msg/PickPlaceGoal``). The scene spec (``scene``) is the
node's world knowledge: label names, what opens how, where hidden objects are.

- A click on an object schedules picking it (with the free hand(s)); a click on the top of a counter,
  table or shelf board while a hand holds an object schedules putting that object there.
- A goal names its object (or gives ``pick_point``) and, with ``has_place``, where the object's bottom
  centre goes (``place_pose.position``); its ``hand`` restricts the grasping hand.

Each schedule goes out as ``hsi/msg/Schedule`` on ``/hsi/schedule``, then each of its planned wrist segments
as ``hsi/msg/WristTrajectory`` on ``/hsi/wrist_trajectory`` (``segment_topic``; empty = none), stamped with
the schedule's stamp plus the segment's start time (what ``retarget_node`` places them by), and a
``hsi/msg/TaskReport`` (stage ``schedule``) on ``/hsi/report``. A click on nothing, on the floor or on fixed
furniture, an unreachable target, or any other planning failure produces a report with ``success`` false and
the reason, no schedule, and the node keeps running. The report's ``duration_s`` is the schedule's motion
time on success and the compute time on failure; ``details_json`` holds the assignment, strategy, opened
part, blockers, Eq. 24 cost and the step lines. The goal's ``planner`` field is not used (the node's
``planner`` parameter is). Label names come from the scene spec's label table, so the cloud must be rendered
from the same scene (``scene_cloud_node`` with the same ``scene``). The node assumes its schedules are
executed: it keeps track of what each hand holds (``holding``: the start state).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hsi_nodes.msgs import make_header, make_pose, msg_class
from hsi_nodes.node import Node
from hsi_nodes.nodes.planner_node import trajectory_msg
from hsi_nodes.pointcloud2 import msg_to_cloud
from hsi_nodes.transport.base import QoS
from hsi_planning.errors import ConfigError, HsiError, PlanningError

__all__ = ["SchedulerNode", "SchedulerNodeConfig", "schedule_msg"]

_CLOUD = "sensor_msgs/msg/PointCloud2"
_CLICK = "geometry_msgs/msg/PointStamped"
_GOAL = "hsi/msg/PickPlaceGoal"
_SCHEDULE = "hsi/msg/Schedule"
_KEYFRAME = "hsi/msg/Keyframe"
_WRIST = "hsi/msg/WristTrajectory"
_REPORT = "hsi/msg/TaskReport"


@dataclass(frozen=True)
class SchedulerNodeConfig:
    """Parameters of :class:`SchedulerNode`."""

    #: Scene: built-in name or spec path (world knowledge: labels, doors, drawers, supports) [-].
    scene: str = "kitchen"
    #: Wrist planner: ``reach_model``, ``linear`` or ``implicit`` [-].
    planner: str = "reach_model"
    #: Checkpoint of the implicit planner [path].
    checkpoint: str = "models/planner.pt"
    #: Objects in the hands at start, e.g. ``[left:mug1]`` [-].
    holding: tuple[str, ...] = ()
    #: Overrides of SchedulerConfig fields (nested mappings for body, navigation, ...) [-].
    scheduler: dict[str, Any] | None = None
    #: Voxel size of the predicted clouds (opened doors and drawers) [m].
    voxel_size: float = 0.01
    #: Frame of clicks, goals and keyframes [-].
    frame_id: str = "world"
    #: Labelled cloud topic [-].
    points_topic: str = "/scene/points"
    #: Click topic [-].
    click_topic: str = "/clicked_point"
    #: Goal topic [-].
    goal_topic: str = "/hsi/goal"
    #: Output schedule topic [-].
    schedule_topic: str = "/hsi/schedule"
    #: Output planned wrist segments, one message each; empty = not published [-].
    segment_topic: str = "/hsi/wrist_trajectory"
    #: Report topic [-].
    report_topic: str = "/hsi/report"

    def __post_init__(self) -> None:
        from hsi_planning.scheduler.planners import SCHEDULER_PLANNERS

        if not self.scene:
            raise ConfigError("SchedulerNodeConfig.scene: give a built-in scene name or a spec path")
        if self.planner not in SCHEDULER_PLANNERS:
            raise ConfigError(
                f"SchedulerNodeConfig.planner={self.planner!r}; available: {list(SCHEDULER_PLANNERS)}"
            )
        if not self.voxel_size > 0.0:
            raise ConfigError(f"SchedulerNodeConfig.voxel_size must be > 0 m, got {self.voxel_size}")


def schedule_msg(schedule: Any, stamp_s: float, frame_id: str) -> Any:
    """``hsi/msg/Schedule`` of a :class:`~hsi_planning.scheduler.Schedule`."""
    keyframe = msg_class(_KEYFRAME)
    frames = [
        keyframe(
            time=float(k.time),
            key_joint=k.key_joint,
            pose=make_pose(k.position, k.quaternion),
            action=k.action,
            contact_event=k.contact_event,
            hand=k.hand,
            object_name=k.object_name,
        )
        for k in schedule.keyframes
    ]
    return msg_class(_SCHEDULE)(
        header=make_header(stamp_s, frame_id),
        task_id=schedule.task_id,
        keyframes=frames,
        steps=list(schedule.steps),
    )


class SchedulerNode(Node[SchedulerNodeConfig]):
    """Schedules pick-and-place tasks from clicks and goals (see the module docstring)."""

    config_class = SchedulerNodeConfig

    def __init__(self, name: str = "scheduler_node", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        from hsi_planning.config import from_mapping
        from hsi_planning.scene import scene_labels
        from hsi_planning.scene_paths import load_scene
        from hsi_planning.scheduler import HandState, SchedulerConfig
        from hsi_planning.scheduler.planners import scheduler_planner

        cfg = self.config
        self.spec = load_scene(cfg.scene)
        self.labels = scene_labels(self.spec)
        self.scheduler_config = from_mapping(
            SchedulerConfig, cfg.scheduler or {}, where="scheduler_node.scheduler"
        )
        self.planner = scheduler_planner(cfg.planner, cfg.checkpoint)
        #: What the hands hold now (updated after each schedule).
        self.hands = HandState.parse(cfg.holding)
        self.world: Any = None
        #: Schedules published; requests refused; malformed messages ignored.
        self.scheduled = 0
        self.failed = 0
        self.ignored = 0
        self._count = 0
        self.create_subscription(cfg.points_topic, _CLOUD, self._on_cloud, QoS(depth=1, latched=True))
        self.create_subscription(cfg.click_topic, _CLICK, self._on_click, 10)
        self.create_subscription(cfg.goal_topic, _GOAL, self._on_goal, 10)
        self.schedule_pub = self.create_publisher(cfg.schedule_topic, _SCHEDULE, 10)
        self.segment_pub = self.create_publisher(cfg.segment_topic, _WRIST, 50) if cfg.segment_topic else None
        self.report_pub = self.create_publisher(cfg.report_topic, _REPORT, 10)

    # ------------------------------------------------------------------------------------- inputs

    def _on_cloud(self, msg: Any) -> None:
        from hsi_planning.perception import CloudConfig, LabelledCloud
        from hsi_planning.scheduler import SceneWorld

        try:
            points, labels, _ = msg_to_cloud(msg)
            if labels is None:
                raise PlanningError("the cloud has no 'label' field; the scheduler needs a labelled cloud")
            names = {lab.id: lab.name for lab in self.labels}
            classes = {lab.id: lab.semantic_class for lab in self.labels}
            cloud = LabelledCloud(points, labels, names, classes)
        except HsiError as exc:
            self.ignored += 1
            self.get_logger().warning("ignored a point cloud: %s", exc)
            return
        self.world = SceneWorld(self.spec, cloud, CloudConfig(voxel_size=self.config.voxel_size))

    def _on_click(self, msg: Any) -> None:
        self._count += 1
        task_id = f"click-{self._count}"
        p = msg.point
        point = np.array([p.x, p.y, p.z], dtype=np.float64)
        self._handle(task_id, "", lambda: self._click_task(point, task_id))

    def _on_goal(self, goal: Any) -> None:
        task_id = str(goal.task_id) or f"goal-{self._count + 1}"
        self._count += 1
        self._handle(task_id, str(goal.object_name), lambda: self._goal_task(goal, task_id))

    # ------------------------------------------------------------------------------------ tasks

    def _require_world(self) -> Any:
        if self.world is None:
            raise PlanningError(f"no point cloud received on {self.config.points_topic} yet")
        return self.world

    def _click_task(self, point: Any, task_id: str) -> Any:
        from hsi_planning.scheduler import PickGoal, Task, WorldState, resolve_click

        world = self._require_world()
        cloud = world.state_cloud(WorldState(held=frozenset(self.hands.held())))
        held = self.hands.held()
        footprint = self._footprint(held[0]) if held else None
        goal = resolve_click(point, cloud, self.spec, self.scheduler_config.goals, footprint=footprint)
        if isinstance(goal, PickGoal):
            return Task(target=goal.object_name, hands=self.hands, task_id=task_id)
        if not held:
            raise PlanningError(
                f"the click designates a place on {goal.support!r} but no hand holds an object; "
                "click an object"
            )
        return Task(
            target=held[0], place=goal.position, place_support=goal.support, hands=self.hands, task_id=task_id
        )

    def _goal_task(self, goal: Any, task_id: str) -> Any:
        from hsi_planning.scheduler import PickGoal, Task, WorldState, resolve_click

        world = self._require_world()
        target = str(goal.object_name)
        if not target:
            p = goal.pick_point
            pick = np.array([p.x, p.y, p.z], dtype=np.float64)
            cloud = world.state_cloud(WorldState(held=frozenset(self.hands.held())))
            resolved = resolve_click(pick, cloud, self.spec, self.scheduler_config.goals)
            if not isinstance(resolved, PickGoal):
                raise PlanningError(f"the goal's pick_point {pick.round(3).tolist()} is on no object")
            target = resolved.object_name
        place = None
        if bool(goal.has_place):
            q = goal.place_pose.position
            place = np.array([q.x, q.y, q.z], dtype=np.float64)
            if not np.isfinite(place).all():
                raise PlanningError("the goal's place_pose position is not finite")
        return Task(target=target, place=place, hands=self.hands, hand=str(goal.hand), task_id=task_id)

    def _footprint(self, obj: str) -> tuple[float, float]:
        size = self.world.object_size(obj)
        radius = 0.5 * (float(np.hypot(size[0], size[1])) if len(size) == 3 else float(size[0]))
        return radius, float(size[-1])

    def _handle(self, task_id: str, obj: str, make_task: Any) -> None:
        from hsi_planning.scheduler import Scheduler

        t0 = time.perf_counter()
        try:
            task = make_task()
            obj = task.target
            schedule = Scheduler(self._require_world(), self.planner, self.scheduler_config).schedule(task)
        except HsiError as exc:
            self.failed += 1
            self.get_logger().warning("task %s refused: %s", task_id, exc)
            error = {"error": type(exc).__name__}
            self._report(task_id, False, str(exc), obj=obj, seconds=time.perf_counter() - t0, details=error)
            return
        self._publish_schedule(schedule)
        self._update_hands(task, schedule)
        self.scheduled += 1
        keys = ("assignment", "strategy", "part", "blockers", "deviation_cost")
        details: dict[str, Any] = {k: schedule.info.get(k) for k in keys}
        details["steps"] = list(schedule.steps)
        assignment = schedule.info.get("assignment")
        message = f"{len(schedule.keyframes)} keyframes over {schedule.duration:.2f} s: {assignment}"
        self._report(task_id, True, message, obj=obj, seconds=schedule.duration, details=details)

    def _publish_schedule(self, schedule: Any) -> None:
        """The schedule, then its planned segments stamped ``schedule stamp + start time`` [s]."""
        stamp, frame = self.now(), self.config.frame_id
        self.schedule_pub.publish(schedule_msg(schedule, stamp, frame))
        if self.segment_pub is None:
            return
        for seg in schedule.segments:
            self.segment_pub.publish(
                trajectory_msg(seg.trajectory, schedule.task_id, stamp + seg.start_time, frame)
            )

    def _update_hands(self, task: Any, schedule: Any) -> None:
        from hsi_planning.scheduler import HandState

        hands = task.hands
        grasp = schedule.info.get("grasp_hand", "")
        used = ("left", "right") if grasp == "both" else (grasp,)
        if task.place is not None:
            left = "" if hands.left == task.target else hands.left
            right = "" if hands.right == task.target else hands.right
            self.hands = HandState(left, right)
        else:
            for h in used:
                hands = hands.with_object(h, task.target)
            self.hands = hands

    def _report(
        self, task_id: str, success: bool, message: str, *, obj: str, seconds: float, details: Any
    ) -> None:
        report = msg_class(_REPORT)(
            header=make_header(self.now(), self.config.frame_id),
            task_id=task_id,
            stage="schedule",
            success=success,
            message=message,
            object_name=obj,
            robot="",
            planner=self.planner.name,
            placement_error_m=float("nan"),
            duration_s=float(seconds),
            collisions=0,
            max_tracking_error_m=float("nan"),
            details_json=json.dumps(details, default=str),
        )
        self.report_pub.publish(report)
