"""planner_node in an executor: goals → one WristTrajectory per segment and a TaskReport; bad input."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from planner_fixture import START, scene_cloud, shared_checkpoint

from hsi_nodes.executor import Executor
from hsi_nodes.msgs import make_header, make_pose, msg_class, pose_to_arrays
from hsi_nodes.node import Node
from hsi_nodes.nodes import load_executable
from hsi_nodes.nodes.planner_node import PlannerNode
from hsi_nodes.pointcloud2 import cloud_to_msg
from hsi_nodes.transport import make_transport
from hsi_nodes.transport.base import QoS, Transport
from hsi_planning.errors import ConfigError

_GOAL = "hsi/msg/PickPlaceGoal"
_TRAJ = "hsi/msg/WristTrajectory"
_REPORT = "hsi/msg/TaskReport"
_STRING = "std_msgs/msg/String"
_CLOUD = "sensor_msgs/msg/PointCloud2"


class _Probe(Node[Any]):
    """Collects trajectories and reports."""

    def __init__(self, transport: Transport) -> None:
        super().__init__("probe", transport=transport)
        self.trajs: list[Any] = []
        self.reports: list[Any] = []
        self.create_subscription("/hsi/wrist_trajectory", _TRAJ, self.trajs.append, QoS(depth=100))
        self.create_subscription("/hsi/report", _REPORT, self.reports.append, QoS(depth=100))


def _goal(task: str, obj: str = "can", hand: str = "right", **kw: Any) -> Any:
    point = msg_class("geometry_msgs/msg/Point")
    return msg_class(_GOAL)(
        header=make_header(0.0, "world"),
        task_id=task,
        object_name=obj,
        pick_point=kw.get("pick_point", point(x=0.0, y=0.0, z=0.0)),
        has_place=kw.get("has_place", False),
        place_pose=kw.get("place_pose", make_pose([0.0, 0.0, 0.0])),
        hand=hand,
        planner=kw.get("planner", ""),
    )


@pytest.fixture(scope="module")
def run() -> Any:
    transport = make_transport("inproc")
    executor = Executor(transport, use_sim_time=True)
    node = PlannerNode(
        transport=transport,
        parameters={"checkpoint": str(shared_checkpoint()), "start_right": START["right"], "fit_steps": 5},
    )
    probe = _Probe(transport)
    for n in (node, probe):
        executor.add_node(n)
    pubs = {
        "cloud": transport.publisher("/scene/points", _CLOUD, QoS(depth=1, latched=True)),
        "labels": transport.publisher("/scene/labels", _STRING, QoS(depth=1, latched=True)),
        "goal": transport.publisher("/hsi/goal", _GOAL),
    }
    yield executor, node, probe, pubs
    executor.shutdown()
    transport.close()


def _spin(executor: Executor) -> None:
    for _ in range(20):
        if executor.spin_once(0.0) == 0:
            break


def test_registered_and_needs_a_checkpoint(tmp_path: Path) -> None:
    assert load_executable("planner_node") is PlannerNode
    with pytest.raises(ConfigError, match="checkpoint"):
        PlannerNode(transport=make_transport("inproc"), parameters={"checkpoint": str(tmp_path / "no.pt")})
    with pytest.raises(ConfigError, match="planner"):
        PlannerNode(transport=make_transport("inproc"), parameters={"planner": "rrt"})


def test_goal_before_the_cloud_is_reported_as_failure(run: Any) -> None:
    executor, _node, probe, pubs = run
    pubs["goal"].publish(_goal("early"))
    _spin(executor)
    report = probe.reports[-1]
    assert report.task_id == "early" and not report.success and "no labelled cloud" in report.message
    assert report.stage == "plan"


def test_goal_is_planned_into_two_segments(run: Any, caplog: pytest.LogCaptureFixture) -> None:
    executor, node, probe, pubs = run
    cloud = scene_cloud()
    with caplog.at_level(logging.WARNING, logger="hsi.planner_node"):
        pubs["labels"].publish(msg_class(_STRING)(data="not json"))
        pubs["cloud"].publish(cloud_to_msg(cloud.points))  # no labels: ignored
        _spin(executor)
    assert node.ignored == 2 and "label table" in caplog.text
    table = {
        str(k): {"name": v, "semantic_class": v, "kind": "object", "parent": None}
        for k, v in cloud.label_names.items()
    }
    pubs["labels"].publish(msg_class(_STRING)(data=json.dumps(table)))
    pubs["cloud"].publish(cloud_to_msg(cloud.points, cloud.labels))
    n_traj = len(probe.trajs)
    pubs["goal"].publish(_goal("t1"))
    _spin(executor)
    new = probe.trajs[n_traj:]
    assert [(m.action, m.segment) for m in new] == [("grasp", "approach"), ("grasp", "leave")]
    report = probe.reports[-1]
    assert report.task_id == "t1" and report.success, report.message
    assert report.planner == "implicit" and report.duration_s > 0.0
    assert json.loads(report.details_json)["target"] == "can"
    approach, leave = new
    assert approach.task_id == "t1" and approach.hand == "right" and approach.object_name == "can"
    assert approach.contact_index == len(approach.poses) - 1 and leave.contact_index == 0
    t = np.asarray(approach.time_from_start)
    assert t[0] == 0.0 and np.all(np.diff(t) > 0.0) and len(t) == len(approach.poses)
    start, _ = pose_to_arrays(approach.poses[0])
    np.testing.assert_allclose(start, START["right"], atol=1e-9)
    end, _ = pose_to_arrays(approach.poses[-1])
    first, _ = pose_to_arrays(leave.poses[0])
    np.testing.assert_allclose(end, first, atol=1e-9)


def test_pick_point_place_and_bad_goals(run: Any) -> None:
    executor, node, probe, pubs = run
    assert node.points is not None  # cloud from the previous test (latched)
    point = msg_class("geometry_msgs/msg/Point")
    n_traj = len(probe.trajs)
    pubs["goal"].publish(_goal("t2", obj="", pick_point=point(x=0.78, y=0.0, z=0.86)))
    _spin(executor)
    assert probe.reports[-1].success and json.loads(probe.reports[-1].details_json)["target"] == "can"
    assert len(probe.trajs) == n_traj + 2
    failures = [
        (_goal("t3", obj="teapot"), "teapot"),
        (_goal("t4", hand="both"), "both"),
        (_goal("t5", planner="minjerk"), "minjerk"),
    ]
    for goal, word in failures:
        pubs["goal"].publish(goal)
        _spin(executor)
        report = probe.reports[-1]
        assert report.task_id == goal.task_id and not report.success and word in report.message
    # pick and place: the can set down 5 cm to the right on the table -> four segments
    n_traj = len(probe.trajs)
    pubs["goal"].publish(_goal("t6", has_place=True, place_pose=make_pose([0.78, -0.05, 0.75])))
    _spin(executor)
    assert probe.reports[-1].task_id == "t6" and probe.reports[-1].success, probe.reports[-1].message
    got = [(m.action, m.segment) for m in probe.trajs[n_traj:]]
    assert got == [("grasp", "approach"), ("grasp", "leave"), ("place", "approach"), ("place", "leave")]
    assert node.callback_errors == 0 and node.failed == 4 and node.planned >= 3
