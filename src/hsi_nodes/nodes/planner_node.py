"""``planner_node``: plans timed 6D wrist trajectories for pick(-and-place) goals from the scene cloud.

Inputs: the labelled cloud ``/scene/points`` (``sensor_msgs/PointCloud2`` with a ``label`` field), its
label table ``/scene/labels`` (``std_msgs/String`` JSON ``{"<id>": {"name": ...}}``, as published by
``scene_cloud_node``) and goals ``/hsi/goal`` (``hsi/msg/PickPlaceGoal``). For each goal it plans with
the configured planner (the goal's ``planner`` field overrides it when set) the grasp's approach and
leave, and with ``has_place`` also the place's approach and leave (the object set down with the bottom
centre of its box at ``place_pose.position``). Each segment goes out as one ``hsi/msg/WristTrajectory``
on ``/hsi/wrist_trajectory``; the outcome as ``hsi/msg/TaskReport`` (stage ``plan``) on ``/hsi/report``,
``success`` false with the reason when the request cannot be planned. Malformed messages are logged and
ignored; the node keeps running.

The wrist starts from ``start_left`` / ``start_right`` (world frame). With ``scene`` set, the approach
axis of a target comes from the scene spec (as in training); otherwise it is estimated from the cloud.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from hsi_nodes.msgs import make_header, make_pose, msg_class
from hsi_nodes.node import Node
from hsi_nodes.pointcloud2 import msg_to_cloud
from hsi_nodes.transport.base import QoS
from hsi_planning.errors import ConfigError, HsiError, PlanningError
from hsi_planning.trajectory import Action, Hand, WristTrajectory

__all__ = ["PlannerNode", "PlannerNodeConfig", "trajectory_msg"]

_CLOUD = "sensor_msgs/msg/PointCloud2"
_STRING = "std_msgs/msg/String"
_GOAL = "hsi/msg/PickPlaceGoal"
_TRAJ = "hsi/msg/WristTrajectory"
_REPORT = "hsi/msg/TaskReport"


@dataclass(frozen=True)
class PlannerNodeConfig:
    """Parameters of :class:`PlannerNode`."""

    #: Planner used when a goal leaves ``planner`` empty (``implicit``) [-].
    planner: str = "implicit"
    #: Checkpoint of the implicit planner (relative paths: to the working directory) [path].
    checkpoint: str = "models/planner.pt"
    #: Scene spec name or path for approach axes; empty = estimate them from the cloud [-].
    scene: str = ""
    #: Hand used when a goal leaves ``hand`` empty (``left`` / ``right``) [-].
    default_hand: str = "right"
    #: Wrist position of the left hand before the reach (world frame) [m].
    start_left: tuple[float, float, float] = (0.2, 0.25, 1.0)
    #: Wrist position of the right hand before the reach (world frame) [m].
    start_right: tuple[float, float, float] = (0.2, -0.25, 1.0)
    #: Latent-fit steps of the implicit planner [steps]; 0 = its benchmarked default
    #: (``ImplicitPlannerConfig.fit_steps``).
    fit_steps: int = 0
    #: Frame of the published trajectories (the cloud's frame) [-].
    frame_id: str = "world"
    #: Labelled cloud topic [-].
    points_topic: str = "/scene/points"
    #: Label table topic (JSON) [-].
    labels_topic: str = "/scene/labels"
    #: Goal topic [-].
    goal_topic: str = "/hsi/goal"
    #: Output trajectory topic [-].
    trajectory_topic: str = "/hsi/wrist_trajectory"
    #: Report topic [-].
    report_topic: str = "/hsi/report"

    def __post_init__(self) -> None:
        from hsi_planning.planning import PLANNER_NAMES

        if self.planner not in PLANNER_NAMES:
            raise ConfigError(f"PlannerNodeConfig.planner={self.planner!r}; available: {list(PLANNER_NAMES)}")
        if self.default_hand not in ("left", "right"):
            raise ConfigError(f"PlannerNodeConfig.default_hand={self.default_hand!r}: 'left' or 'right'")
        for name in ("start_left", "start_right"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != (3,) or not np.isfinite(value).all():
                raise ConfigError(f"PlannerNodeConfig.{name} must be 3 finite numbers [m], got {value}")
        if self.fit_steps < 0:
            raise ConfigError(f"PlannerNodeConfig.fit_steps={self.fit_steps} must be ≥ 0 (0 = default)")


def trajectory_msg(traj: WristTrajectory, task_id: str, stamp_s: float, frame_id: str) -> Any:
    """``hsi/msg/WristTrajectory`` of a planned segment."""
    return msg_class(_TRAJ)(
        header=make_header(stamp_s, frame_id),
        task_id=task_id,
        hand=traj.hand,
        action=traj.action,
        segment=traj.segment,
        planner=traj.planner,
        object_name=traj.object_name,
        time_from_start=np.array(traj.t, dtype=np.float64),
        poses=[make_pose(p, q) for p, q in zip(traj.position, traj.quaternion, strict=True)],
        contact_index=int(traj.contact_index),
    )


class PlannerNode(Node[PlannerNodeConfig]):
    """Plans wrist trajectories for goals (see the module docstring)."""

    config_class = PlannerNodeConfig

    def __init__(self, name: str = "planner_node", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        from hsi_planning.planning import make_planner

        cfg = self.config
        path = Path(cfg.checkpoint)
        if not path.is_file():
            raise ConfigError(f"planner_node: checkpoint {path} not found (parameter 'checkpoint')")
        options = {"fit_steps": cfg.fit_steps} if cfg.fit_steps and cfg.planner == "implicit" else {}
        self.planners = {cfg.planner: make_planner(cfg.planner, path, **options)}
        self.spec: Any = None
        if cfg.scene:
            from hsi_planning.scene_paths import load_scene

            self.spec = load_scene(cfg.scene)
        self.points: np.ndarray | None = None
        self.labels: np.ndarray | None = None
        self.label_names: dict[int, str] = {}
        #: Messages ignored as malformed; goals planned / failed.
        self.ignored = 0
        self.planned = 0
        self.failed = 0
        latched = QoS(depth=1, latched=True)
        self.create_subscription(cfg.points_topic, _CLOUD, self._on_cloud, latched)
        self.create_subscription(cfg.labels_topic, _STRING, self._on_labels, latched)
        self.create_subscription(cfg.goal_topic, _GOAL, self._on_goal, 10)
        self.traj_pub = self.create_publisher(cfg.trajectory_topic, _TRAJ, 10)
        self.report_pub = self.create_publisher(cfg.report_topic, _REPORT, 10)

    # ------------------------------------------------------------------------------------- inputs

    def _ignore(self, what: str, exc: Exception | str) -> None:
        self.ignored += 1
        self.get_logger().warning("ignored %s: %s", what, exc)

    def _on_cloud(self, msg: Any) -> None:
        try:
            points, labels, _ = msg_to_cloud(msg)
        except HsiError as exc:
            self._ignore("malformed point cloud", exc)
            return
        if labels is None:
            self._ignore("point cloud", "it has no 'label' field; the planner needs a labelled cloud")
            return
        self.points, self.labels = points, labels

    def _on_labels(self, msg: Any) -> None:
        try:
            table = json.loads(str(msg.data))
            names = {int(k): str(v["name"]) for k, v in table.items()}
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            self._ignore("label table", f"not JSON {{id: {{name: ...}}}} ({exc})")
            return
        self.label_names = names

    # -------------------------------------------------------------------------------------- goals

    def _report(
        self, goal: Any, success: bool, message: str, *, planner: str, seconds: float, details: Any
    ) -> None:
        report = msg_class(_REPORT)(
            header=make_header(self.now(), self.config.frame_id),
            task_id=str(goal.task_id),
            stage="plan",
            success=success,
            message=message,
            object_name=str(goal.object_name),
            robot="",
            planner=planner,
            placement_error_m=float("nan"),
            duration_s=float(seconds),
            collisions=0,
            max_tracking_error_m=float("nan"),
            details_json=json.dumps(details, default=float),
        )
        self.report_pub.publish(report)

    def _target(self, goal: Any) -> str:
        if str(goal.object_name):
            return str(goal.object_name)
        assert self.points is not None and self.labels is not None
        p = goal.pick_point
        pick = np.array([p.x, p.y, p.z], dtype=np.float64)
        if not np.isfinite(pick).all():
            raise PlanningError("the goal names no object and its pick_point is not finite")
        known = np.isin(self.labels, list(self.label_names))
        if not known.any():
            raise PlanningError("no labelled point in the cloud matches the label table")
        idx = np.flatnonzero(known)[np.argmin(np.linalg.norm(self.points[known] - pick, axis=1))]
        return self.label_names[int(self.labels[idx])]

    def _on_goal(self, goal: Any) -> None:
        t0 = time.perf_counter()
        planner_name = str(goal.planner) or self.config.planner
        try:
            segments, details = self._plan_goal(goal, planner_name)
        except HsiError as exc:
            self.failed += 1
            self.get_logger().warning("goal %r not planned: %s", str(goal.task_id), exc)
            self._report(
                goal, False, str(exc), planner=planner_name, seconds=time.perf_counter() - t0, details={}
            )
            return
        stamp = self.now()
        for traj in segments:
            self.traj_pub.publish(trajectory_msg(traj, str(goal.task_id), stamp, self.config.frame_id))
        self.planned += 1
        message = f"planned {len(segments)} segments for {segments[0].object_name!r}"
        self._report(
            goal, True, message, planner=planner_name, seconds=time.perf_counter() - t0, details=details
        )

    def _plan_goal(self, goal: Any, planner_name: str) -> tuple[list[WristTrajectory], dict[str, Any]]:
        from hsi_planning.implicit.problem import approach_axis_for
        from hsi_planning.planning import PlanRequest

        if planner_name not in self.planners:
            raise PlanningError(
                f"planner {planner_name!r} is not available here; have {sorted(self.planners)}"
            )
        if self.points is None or self.labels is None or not self.label_names:
            raise PlanningError("no labelled cloud and label table received yet on the scene topics")
        hand = str(goal.hand) or self.config.default_hand
        if hand not in ("left", "right"):
            raise PlanningError(f"hand {hand!r} cannot be planned as one wrist; use 'left' or 'right'")
        target = self._target(goal)
        cloud = _cloud(self.points, self.labels, self.label_names)
        axis = None
        if self.spec is not None and target in {o.name for o in self.spec.objects}:
            axis = approach_axis_for(self.spec, target)
        start = np.asarray(self.config.start_left if hand == "left" else self.config.start_right)
        planner = self.planners[planner_name]
        actions = ["grasp", "place"] if bool(goal.has_place) else ["grasp"]
        out: list[WristTrajectory] = []
        timings: dict[str, float] = {}
        for action in actions:
            place = None
            if action == "place":
                pp = goal.place_pose.position
                place = np.array([pp.x, pp.y, pp.z], dtype=np.float64)
            request = PlanRequest(
                cloud=cloud,
                target=target,
                hand=cast(Hand, hand),
                action=cast(Action, action),
                start_position=start,
                approach_axis=axis,
                place_position=place,
            )
            result = planner.plan(request)
            out += [result.approach, result.leave]
            timings.update({f"{action}_{k}": v for k, v in result.timings.items()})
        return out, {"target": target, "hand": hand, "timings": timings}


def _cloud(points: np.ndarray, labels: np.ndarray, names: dict[int, str]) -> Any:
    from hsi_planning.errors import CloudError
    from hsi_planning.perception.cloud import LabelledCloud

    try:
        return LabelledCloud(points, labels, label_names=names)
    except CloudError as exc:
        raise PlanningError(f"invalid cloud: {exc}") from exc
