"""scheduler_node in an executor (clicks and goals → Schedule + TaskReport, refusals keep it running), its
parameter file and registry entry, and the ``hsi schedule`` command.

Planner used: ``reach_model`` (the human-reach model), as in tests/test_scheduler.py.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hsi_nodes.cli import schedule as schedule_cli
from hsi_nodes.executor import Executor
from hsi_nodes.msgs import make_header, make_pose, msg_class, pose_to_arrays
from hsi_nodes.node import Node
from hsi_nodes.nodes import NODE_EXECUTABLES, load_executable
from hsi_nodes.nodes.scheduler_node import SchedulerNode
from hsi_nodes.pointcloud2 import cloud_to_msg
from hsi_nodes.transport import make_transport
from hsi_nodes.transport.base import QoS, Transport
from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.perception import scene_cloud
from hsi_planning.scene import object_pose
from hsi_planning.scene_paths import load_scene
from hsi_planning.scheduler import Schedule

_CLOUD = "sensor_msgs/msg/PointCloud2"
_CLICK = "geometry_msgs/msg/PointStamped"
_GOAL = "hsi/msg/PickPlaceGoal"
_SCHEDULE = "hsi/msg/Schedule"
_REPORT = "hsi/msg/TaskReport"


class _Probe(Node[Any]):
    def __init__(self, transport: Transport) -> None:
        super().__init__("probe", transport=transport)
        self.schedules: list[Any] = []
        self.reports: list[Any] = []
        self.create_subscription("/hsi/schedule", _SCHEDULE, self.schedules.append, QoS(depth=100))
        self.create_subscription("/hsi/report", _REPORT, self.reports.append, QoS(depth=100))


@pytest.fixture(scope="module")
def run() -> Iterator[tuple[Executor, SchedulerNode, _Probe, dict[str, Any]]]:
    transport = make_transport("inproc")
    executor = Executor(transport, use_sim_time=True)
    node = SchedulerNode(transport=transport, parameters={"scene": "kitchen", "planner": "reach_model"})
    probe = _Probe(transport)
    for n in (node, probe):
        executor.add_node(n)
    pubs = {
        "cloud": transport.publisher("/scene/points", _CLOUD, QoS(depth=1, latched=True)),
        "click": transport.publisher("/clicked_point", _CLICK),
        "goal": transport.publisher("/hsi/goal", _GOAL),
    }
    yield executor, node, probe, pubs
    executor.shutdown()
    transport.close()


def _spin(executor: Executor) -> None:
    for _ in range(20):
        if executor.spin_once(0.0) == 0:
            break


def _click(xyz: Any) -> Any:
    point = msg_class("geometry_msgs/msg/Point")
    x, y, z = (float(v) for v in xyz)
    return msg_class(_CLICK)(header=make_header(0.0, "world"), point=point(x=x, y=y, z=z))


def _goal(task: str, obj: str, place: Any = None) -> Any:
    point = msg_class("geometry_msgs/msg/Point")
    return msg_class(_GOAL)(
        header=make_header(0.0, "world"),
        task_id=task,
        object_name=obj,
        pick_point=point(x=0.0, y=0.0, z=0.0),
        has_place=place is not None,
        place_pose=make_pose(place if place is not None else [0.0, 0.0, 0.0]),
        hand="",
        planner="",
    )


def test_node_schedules_clicks_and_goals_and_survives_bad_clicks(run: Any) -> None:
    executor, node, probe, pubs = run
    pubs["click"].publish(_click([0.8, 0.8, 1.3]))  # before any cloud
    _spin(executor)
    assert probe.reports[-1].success is False and "no point cloud received" in probe.reports[-1].message
    spec = load_scene("kitchen")
    cloud = scene_cloud(spec)
    pubs["cloud"].publish(cloud_to_msg(cloud.points, cloud.labels, "world"))
    _spin(executor)
    bad = {
        "air": ([0.3, 0.0, 1.5], "hits nothing"),
        "far floor": ([2.5, -2.0, 0.0], "beyond max_distance"),
        "cabinet door": ([0.6, -0.45, 0.3], "fixed furniture"),
        "place with empty hands": ([0.72, -0.2, 0.9], "no hand holds an object"),
    }
    for point, _ in bad.values():
        pubs["click"].publish(_click(point))
    _spin(executor)
    assert probe.schedules == []
    failed = probe.reports[-len(bad) :]
    for report, (name, (_, text)) in zip(failed, bad.items(), strict=True):
        assert report.stage == "schedule" and report.success is False, name
        assert text in report.message, (name, report.message)
    # a click on the bottle: a pick schedule; then a click on the free counter: place it there
    bottle = object_pose(spec, "bottle1")[:3, 3] + [-0.04, 0.0, 0.1]
    pubs["click"].publish(_click(bottle))
    _spin(executor)
    assert len(probe.schedules) == 1 and probe.reports[-1].success is True
    pick = probe.schedules[0]
    assert pick.task_id == probe.reports[-1].task_id and pick.header.frame_id == "world"
    assert {k.key_joint for k in pick.keyframes} == {"left_wrist", "right_wrist", "hip", "root"}
    times = [k.time for k in pick.keyframes]
    assert times == sorted(times) and len(pick.steps) >= 3
    grasps = [k for k in pick.keyframes if k.contact_event == "grasp"]
    assert [k.object_name for k in grasps] == ["bottle1"]
    assert node.hands.holding(grasps[0].hand) == "bottle1"  # type: ignore[arg-type]
    details = json.loads(probe.reports[-1].details_json)
    assert details["strategy"] == "single" and details["blockers"] == []
    pubs["click"].publish(_click([0.72, -0.2, 0.9]))
    _spin(executor)
    assert len(probe.schedules) == 2 and probe.reports[-1].success is True, probe.reports[-1].message
    releases = [k for k in probe.schedules[1].keyframes if k.contact_event == "release"]
    assert [k.object_name for k in releases] == ["bottle1"]
    assert node.hands.held() == ()
    # an explicit goal: can1 on the counter, placed on the shelf's free board spot
    pubs["goal"].publish(_goal("g1", "can1", place=[0.72, -0.25, 0.9]))
    _spin(executor)
    assert probe.reports[-1].task_id == "g1" and probe.reports[-1].success is True, probe.reports[-1].message
    assert probe.schedules[-1].task_id == "g1"
    assert node.callback_errors == 0 and node.scheduled == 3 and node.failed == len(bad) + 1
    pose, _ = pose_to_arrays(probe.schedules[-1].keyframes[0].pose)
    assert np.isfinite(pose).all()


def test_parameter_file_and_registry(repo_root: Path) -> None:
    params = Node.load_parameter_file(repo_root / "config" / "scheduler_node.yaml", "scheduler_node")
    assert params["scene"] == "kitchen" and params["scheduler"]["hands"]["deviation_weight"] == 2.0
    assert NODE_EXECUTABLES["scheduler_node"] == "hsi_nodes.nodes.scheduler_node:SchedulerNode"
    assert load_executable("scheduler_node") is SchedulerNode
    transport = make_transport("inproc")
    try:
        node = SchedulerNode(transport=transport, parameters=params)
        assert node.scheduler_config.navigation.approach_length == 0.4
        assert node.scheduler_config.body.arm_reach == 0.75
        with pytest.raises(ConfigError, match="planner='fancy'"):
            SchedulerNode(transport=transport, parameters={"planner": "fancy"})
        with pytest.raises(ConfigError, match="unknown parameter"):
            SchedulerNode(transport=transport, parameters={"scheduler": {"body": {"arms": 3}}})
        with pytest.raises(ConfigError, match="holding"):
            SchedulerNode(transport=transport, parameters={"holding": ["mug1"]})
    finally:
        transport.close()


def _cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="hsi")
    schedule_cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return int(args.func(args))


def test_cli_writes_schedule_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "schedule.json"
    bottle = object_pose(load_scene("narrow_shelf"), "mug2")[:3, 3] + [0.0, 0.0, 0.05]
    click = ",".join(f"{v:.3f}" for v in bottle)
    assert (
        _cli(["schedule", "narrow_shelf", "--click", click, "--holding", "left:bowl1", "--out", str(out)])
        == 0
    )
    text = capsys.readouterr().out
    assert "reach and grasp mug2 with the right hand" in text and "keyframes" in text
    doc = json.loads(out.read_text())
    assert set(doc["keyframes"][0]) == {
        "time",
        "key_joint",
        "position",
        "quaternion",
        "hand",
        "action",
        "contact_event",
        "object",
    }
    schedule = Schedule.from_dict(doc)
    assert schedule.info["grasp_hand"] == "right" and all(
        k.object_name == "bowl1" for k in schedule.of("left_wrist")
    )
    with pytest.raises(PlanningError, match="on the floor"):
        _cli(["schedule", "narrow_shelf", "--click", "0,1.2,0", "--out", str(out)])
    with pytest.raises(SystemExit):
        _cli(["schedule", "narrow_shelf", "--click", "0,1", "--out", str(out)])
