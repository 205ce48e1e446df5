"""``click_player``: plays the demo's scripted clicks as pick-and-place goals, one task at a time.

The tasks come from :mod:`hsi_nodes.demo.tasks` (``variant``, optionally only the ``tasks`` named); those
of another scene than ``scene`` are left out. Each task goes out on ``/hsi/goal`` as one
``hsi/msg/PickPlaceGoal`` (``task_id`` = the task name): ``pick_point`` = the pick click (``object_name``
empty, the scheduler resolves the click against the cloud) or the object's name for an object the cameras
cannot see; ``has_place`` with ``place_pose.position`` = the place click (the placed object's bottom
centre). The first goal goes out ``start_delay_s`` after the start (the cloud reaches the scheduler
first); the next when the current task ends: its ``sim`` report arrives on ``/hsi/report``, or a
``schedule`` / ``retarget`` report says it failed before a trajectory was sent, or ``task_timeout_s``
passed. Every report of a task is kept in :attr:`ClickPlayerNode.reports`; the node is done when every
task has ended.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from hsi_nodes.msgs import make_header, make_pose, msg_class
from hsi_nodes.node import Node
from hsi_planning.errors import ConfigError

__all__ = ["ClickPlayerConfig", "ClickPlayerNode", "goal_msg"]

_GOAL = "hsi/msg/PickPlaceGoal"
_REPORT = "hsi/msg/TaskReport"


@dataclass(frozen=True)
class ClickPlayerConfig:
    """Parameters of :class:`ClickPlayerNode`."""

    scene: str = "kitchen"  #: scene of the launch; tasks of other scenes are skipped [-]
    variant: str = "kitchen"  #: task list of :mod:`hsi_nodes.demo.tasks` [-]
    tasks: tuple[str, ...] = ()  #: only these task names (empty = the whole variant) [-]
    start_delay_s: float = 0.5  #: clock time before the first goal [s]
    task_timeout_s: float = 600.0  #: clock time after which a task without a final report ends [s]
    frame_id: str = "world"  #: frame of the goals [-]
    goal_topic: str = "/hsi/goal"  #: output goals [-]
    report_topic: str = "/hsi/report"  #: task reports [-]

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start_delay_s) and self.start_delay_s >= 0.0):
            raise ConfigError(f"ClickPlayerConfig.start_delay_s must be >= 0 s, got {self.start_delay_s}")
        if not self.task_timeout_s > 0.0:
            raise ConfigError(f"ClickPlayerConfig.task_timeout_s must be > 0 s, got {self.task_timeout_s}")


def goal_msg(task: Any, stamp_s: float, frame_id: str) -> Any:
    """``hsi/msg/PickPlaceGoal`` of a :class:`~hsi_nodes.demo.tasks.DemoTask`."""
    point = msg_class("geometry_msgs/msg/Point")
    pick = task.click if task.click is not None else (math.nan, math.nan, math.nan)
    return msg_class(_GOAL)(
        header=make_header(stamp_s, frame_id),
        task_id=task.name,
        object_name=task.object_name,
        pick_point=point(x=float(pick[0]), y=float(pick[1]), z=float(pick[2])),
        has_place=True,
        place_pose=make_pose(task.place_click),
        hand=task.hand,
        planner="",
    )


def _ends_task(msg: Any) -> bool:
    """Whether a report is the last one its task will get."""
    stage = str(msg.stage)
    if stage == "sim":
        return True
    if stage == "schedule":
        return not bool(msg.success)
    if stage == "retarget" and not bool(msg.success):
        try:
            details = json.loads(str(msg.details_json) or "{}")
        except ValueError:
            return True
        return "events" not in details  # no trajectory was sent
    return False


class ClickPlayerNode(Node[ClickPlayerConfig]):
    """Publishes the scripted goals one after the other (see the module docstring)."""

    config_class = ClickPlayerConfig

    def __init__(self, name: str = "click_player", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        from hsi_nodes.demo.tasks import demo_tasks
        from hsi_planning.scene_paths import load_scene

        cfg = self.config
        scene = load_scene(cfg.scene).name
        chosen = demo_tasks(cfg.variant, cfg.tasks)
        self.queue = [t for t in chosen if load_scene(t.scene).name == scene]
        skipped = [t.name for t in chosen if t not in self.queue]
        if skipped:
            self.get_logger().info("tasks of other scenes than %s skipped: %s", scene, skipped)
        #: task name -> {stage: report fields}.
        self.reports: dict[str, dict[str, dict[str, Any]]] = {}
        self.current: str = ""
        self.sent_at = 0.0
        self.finished: list[str] = []
        self._started = False
        self.goal_pub = self.create_publisher(cfg.goal_topic, _GOAL, 10)
        self.create_subscription(cfg.report_topic, _REPORT, self._on_report, 50)
        self.create_timer(max(cfg.start_delay_s, 1e-3), self._tick)

    def _tick(self) -> None:
        if not self._started:
            self._started = True
            self._next()
        elif self.current and self.now() - self.sent_at > self.config.task_timeout_s:
            self.get_logger().warning("task %s timed out without a final report", self.current)
            self._end()

    def _next(self) -> None:
        if not self.queue:
            self.current = ""
            return
        task = self.queue.pop(0)
        self.current, self.sent_at = task.name, self.now()
        self.get_logger().info("goal %s: %s", task.name, task.description or task.label)
        self.goal_pub.publish(goal_msg(task, self.now(), self.config.frame_id))

    def _end(self) -> None:
        self.finished.append(self.current)
        self._next()

    def _on_report(self, msg: Any) -> None:
        task_id = str(msg.task_id)
        fields = ("success", "message", "object_name", "robot", "planner", "placement_error_m")
        entry = {f: getattr(msg, f) for f in fields}
        entry |= {
            "duration_s": float(msg.duration_s),
            "collisions": int(msg.collisions),
            "max_tracking_error_m": float(msg.max_tracking_error_m),
            "details_json": str(msg.details_json),
        }
        self.reports.setdefault(task_id, {})[str(msg.stage)] = entry
        if task_id == self.current and _ends_task(msg):
            self._end()

    def is_done(self) -> bool:
        """All tasks ended (a run with no task of this scene is done at once)."""
        return self._started and not self.current and not self.queue
