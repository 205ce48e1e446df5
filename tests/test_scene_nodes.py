"""sim_node and scene_cloud_node: topics, cloud round trip, /tf vs MuJoCo, bad input, launch file, scenes."""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

from hsi_nodes.executor import Executor
from hsi_nodes.launch import parse_launch_file, run_launch
from hsi_nodes.msgs import make_header, msg_class
from hsi_nodes.node import Node
from hsi_nodes.nodes import load_executable
from hsi_nodes.nodes.scene_cloud_node import SceneCloudNode
from hsi_nodes.nodes.sim_node import SimNode
from hsi_nodes.pointcloud2 import msg_to_cloud
from hsi_nodes.transport import make_transport
from hsi_nodes.transport.base import QoS, Transport
from hsi_planning.errors import ConfigError, LaunchError, SceneError
from hsi_planning.scene import articulated_parts, object_names, object_pose, scene_labels, scene_meshes
from hsi_planning.scene_paths import builtin_scenes, load_scene, resolve_scene

SMALL_CLOUD = {"width": 160, "height": 120, "voxel_size": 0.02}
_TF = "tf2_msgs/msg/TFMessage"
_JS = "sensor_msgs/msg/JointState"


class _Probe(Node[Any]):
    """Collects every message of the given topics (latched subscriptions)."""

    def __init__(self, transport: Transport, topics: dict[str, str]) -> None:
        super().__init__("probe", transport=transport)
        self.got: dict[str, list[Any]] = {t: [] for t in topics}
        for topic, typename in topics.items():
            self.create_subscription(topic, typename, self.got[topic].append, QoS(depth=1000, latched=True))


def _transform(
    child: str, xyz: tuple[float, float, float], quat_xyzw: tuple[float, ...] = (0, 0, 0, 1)
) -> Any:
    stamped, tf = msg_class("geometry_msgs/msg/TransformStamped"), msg_class("geometry_msgs/msg/Transform")
    vec, quat = msg_class("geometry_msgs/msg/Vector3"), msg_class("geometry_msgs/msg/Quaternion")
    x, y, z, w = quat_xyzw
    return stamped(
        header=make_header(0.0, "world"),
        child_frame_id=child,
        transform=tf(translation=vec(x=xyz[0], y=xyz[1], z=xyz[2]), rotation=quat(x=x, y=y, z=z, w=w)),
    )


@pytest.fixture(scope="module")
def sim_run() -> Iterator[dict[str, Any]]:
    """sim_node + scene_cloud_node on the kitchen, 0.2 s of simulated time, everything collected."""
    transport = make_transport("inproc")
    executor = Executor(transport, use_sim_time=True)
    sim = SimNode(
        transport=transport, parameters={"scene": "kitchen", "duration_s": 0.2, "publish_rate": 50.0}
    )
    cloud = SceneCloudNode(transport=transport, parameters={**SMALL_CLOUD, "period_s": 0.1})
    topics = {
        "/robot/joint_states": _JS,
        "/scene/joint_states": _JS,
        "/tf": _TF,
        "/scene/points": "sensor_msgs/msg/PointCloud2",
        "/scene/labels": "std_msgs/msg/String",
    }
    probe = _Probe(transport, topics)
    for node in (sim, cloud, probe):
        executor.add_node(node)
    executor.spin(1.0, until=executor.all_done)
    executor.spin_once(0.0)  # deliver the last messages
    run = {"sim": sim, "cloud": cloud, "got": probe.got, "now": transport.clock.now()}
    yield run
    executor.shutdown()
    transport.close()


def test_scene_paths_resolve_names_and_paths(repo_root: Path) -> None:
    assert {"kitchen", "narrow_shelf", "cluttered_drawer"} <= set(builtin_scenes())
    assert resolve_scene("kitchen") == repo_root / "sim" / "scenes" / "kitchen.yaml"
    path = repo_root / "sim" / "scenes" / "narrow_shelf.yaml"
    assert resolve_scene(str(path)) == path and load_scene(path).name == "narrow_shelf"
    with pytest.raises(SceneError, match=r"unknown scene 'kichen'.*kitchen"):
        resolve_scene("kichen")
    with pytest.raises(SceneError, match="does not exist"):
        resolve_scene("nowhere/kitchen.yaml")


def test_nodes_publish_expected_topics(sim_run: dict[str, Any]) -> None:
    got, sim = sim_run["got"], sim_run["sim"]
    spec = sim.spec
    assert sim.sim_time == pytest.approx(0.2, abs=1e-9) and sim.steps == 100 and sim.resets == 0
    assert math.isclose(sim_run["now"], 0.2, abs_tol=1e-6)
    for topic in ("/robot/joint_states", "/scene/joint_states", "/tf"):
        assert len(got[topic]) == 10, topic  # 50 Hz for 0.2 s
    robot = got["/robot/joint_states"][-1]
    assert robot.name == [] and robot.position.size == 0  # no robot in the scenes yet
    scene_js = got["/scene/joint_states"][-1]
    assert scene_js.name == articulated_parts(spec) and scene_js.position.shape == (4,)
    assert np.all(np.isfinite(scene_js.position)) and np.all(np.abs(scene_js.position) < 0.01)  # closed
    stamps = [m.transforms[0].header.stamp for m in got["/tf"]]
    assert [s.sec + s.nanosec * 1e-9 for s in stamps] == pytest.approx(np.arange(1, 11) * 0.02)
    assert [t.child_frame_id for t in got["/tf"][-1].transforms] == object_names(spec)
    assert all(t.header.frame_id == "world" for t in got["/tf"][-1].transforms)
    # a cloud at start, then every 0.1 s; latched label table once
    assert len(got["/scene/points"]) >= 2 and sim_run["cloud"].published == len(got["/scene/points"])
    assert len(got["/scene/labels"]) == 1
    table = json.loads(got["/scene/labels"][0].data)
    labels = scene_labels(spec)
    assert [table[str(i)]["name"] for i in range(len(labels))] == list(labels.names)
    assert table[str(labels.by_name("mug1").id)] == {
        "name": "mug1",
        "semantic_class": "mug",
        "kind": "object",
        "parent": None,
    }


def test_tf_matches_mujoco_body_poses(sim_run: dict[str, Any]) -> None:
    sim = sim_run["sim"]
    last = sim_run["got"]["/tf"][-1]
    for tf in last.transforms:
        bid = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_BODY, tf.child_frame_id)
        t, r = tf.transform.translation, tf.transform.rotation
        np.testing.assert_allclose([t.x, t.y, t.z], sim.data.xpos[bid], atol=1e-12)
        np.testing.assert_allclose([r.w, r.x, r.y, r.z], sim.data.xquat[bid], atol=1e-12)
        # physics is sane: resting objects stay within 1 cm of their spec pose after 0.2 s
        spec_pos = object_pose(sim.spec, tf.child_frame_id)[:3, 3]
        assert np.linalg.norm(np.array([t.x, t.y, t.z]) - spec_pos) < 0.01, tf.child_frame_id


def test_cloud_round_trips_and_labels_match_geometry(sim_run: dict[str, Any]) -> None:
    cloud_node = sim_run["cloud"]
    msg = sim_run["got"]["/scene/points"][-1]
    assert msg.header.frame_id == "world" and [f.name for f in msg.fields] == ["x", "y", "z", "label"]
    points, labels, dropped = msg_to_cloud(msg)
    rendered = cloud_node.last_cloud
    assert dropped == 0 and labels is not None and len(points) > 5000
    np.testing.assert_array_equal(labels, rendered.labels)
    np.testing.assert_allclose(points, rendered.points, atol=1e-5)  # float32 on the wire
    meshes = scene_meshes(cloud_node.spec)
    table = scene_labels(cloud_node.spec)
    seen = set(np.unique(labels).tolist())
    assert {table.by_name(n).id for n in ("floor", "counter1", "shelf1", "mug1", "teapot1")} <= seen
    for label in seen:  # every point lies on (the bounding box of) the body its label names
        name = table.by_id(int(label)).name
        lo, hi = meshes[name].bounds
        pts = points[labels == label]
        inside = np.all((pts >= lo - 0.03) & (pts <= hi + 0.03), axis=1)
        assert inside.mean() > 0.99, (name, inside.mean())


def test_cloud_follows_tf_and_ignores_bad_transforms(caplog: pytest.LogCaptureFixture) -> None:
    transport = make_transport("inproc")
    executor = Executor(transport, use_sim_time=True)
    node = SceneCloudNode(transport=transport, parameters={**SMALL_CLOUD, "period_s": 0.05})
    executor.add_node(node)
    tf_pub = transport.publisher("/tf", _TF)
    js_pub = transport.publisher("/scene/joint_states", _JS)
    executor.spin(0.01)
    mug = scene_labels(node.spec).by_name("mug1").id
    before = node.last_cloud
    assert before is not None and np.any(before.labels == mug)
    target = (0.3, 0.0, 1.2)  # in free space between the cameras and the furniture
    bad = [
        _transform("ghost", (0.0, 0.0, 0.0)),
        _transform("can1", (math.nan, 0.0, 1.0)),
        _transform("bowl1", (0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 0.0)),
    ]
    js = msg_class(_JS)
    with caplog.at_level(logging.WARNING, logger="hsi.scene_cloud_node"):
        tf_pub.publish(msg_class(_TF)(transforms=[*bad, _transform("mug1", target)]))
        js_pub.publish(
            js(
                header=make_header(0.0, ""),
                name=["nothing"],
                position=np.zeros(1),
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
        )
        js_pub.publish(
            js(
                header=make_header(0.0, ""),
                name=["a", "b"],
                position=np.zeros(1),
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
        )
        published = node.published
        executor.spin(0.06)
    assert node.callback_errors == 0 and node.ignored == 5
    text = caplog.text
    for needle in ("ghost", "non-finite", "'nothing'", "2 names but 1 positions"):
        assert needle in text, needle
    assert node.published > published  # keeps rendering
    after = node.last_cloud
    assert after is not None
    mug_pts = after.points[after.labels == mug]
    assert len(mug_pts) > 20
    np.testing.assert_allclose(mug_pts.mean(axis=0), target, atol=0.06)  # the mug moved to the target
    # can1 (NaN) and bowl1 (zero quaternion) stayed where they were
    for name in ("can1", "bowl1"):
        lab = scene_labels(node.spec).by_name(name).id
        np.testing.assert_allclose(
            after.points[after.labels == lab].mean(axis=0),
            before.points[before.labels == lab].mean(axis=0),
            atol=0.02,
        )
    # the door follows /scene/joint_states: opened 80 degrees, its points leave the closed-door box
    door = scene_labels(node.spec).by_name("cabinet1/door1").id
    js_pub.publish(
        js(
            header=make_header(0.0, ""),
            name=["cabinet1/door1"],
            position=np.array([1.4]),
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
    )
    executor.spin(0.06)
    closed = scene_meshes(node.spec)["cabinet1/door1"].bounds
    door_pts = node.last_cloud.points[node.last_cloud.labels == door]
    outside = ~np.all((door_pts >= closed[0] - 0.03) & (door_pts <= closed[1] + 0.03), axis=1)
    assert outside.mean() > 0.5
    executor.shutdown()
    transport.close()


def test_sim_node_resets_nan_state_and_logs_once(caplog: pytest.LogCaptureFixture) -> None:
    transport = make_transport("inproc")
    executor = Executor(transport, use_sim_time=True)
    sim = SimNode(transport=transport, parameters={"scene": "narrow_shelf", "publish_rate": 100.0})
    executor.add_node(sim)
    executor.spin(0.05)
    sim.data.qvel[:] = math.nan
    with caplog.at_level(logging.WARNING, logger="hsi.sim_node"):
        executor.spin(0.05)
    assert sim.resets == 1 and sim.callback_errors == 0
    assert np.all(np.isfinite(sim.data.qpos)) and np.all(np.isfinite(sim.data.qvel))
    assert sim.sim_time == pytest.approx(0.1, abs=1e-9)  # physics time stays with the clock
    assert "reset" in caplog.text and caplog.text.count("MuJoCo warning") <= 1
    executor.shutdown()
    transport.close()


def test_sim_node_wall_clock_realtime_factor() -> None:
    transport = make_transport("inproc")
    executor = Executor(transport)
    sim = SimNode(transport=transport, parameters={"scene": "kitchen", "realtime_factor": 2.0})
    executor.add_node(sim)
    t0 = time.monotonic()
    executor.spin(0.25)
    wall = time.monotonic() - t0
    assert 2.0 * wall - 0.15 <= sim.sim_time <= 2.0 * wall + 0.01
    executor.shutdown()
    transport.close()


def test_bad_parameters_are_rejected() -> None:
    transport = make_transport("inproc")
    with pytest.raises(ConfigError, match="publish_rate"):
        SimNode(transport=transport, parameters={"publish_rate": 0.0})
    with pytest.raises(ConfigError, match="duration_s"):
        SimNode(transport=transport, parameters={"duration_s": -1.0})
    with pytest.raises(SceneError, match="built-in scenes"):
        SimNode(transport=transport, parameters={"scene": "moon_base"})
    with pytest.raises(ConfigError, match="cam_top"):
        SceneCloudNode(transport=transport, parameters={**SMALL_CLOUD, "cameras": ["cam_top"]})
    with pytest.raises(ConfigError, match="voxel_size"):
        SceneCloudNode(transport=transport, parameters={"voxel_size": -0.1})
    transport.close()


def test_sim_world_launch_file_runs(repo_root: Path) -> None:
    launch = repo_root / "launch" / "sim_world.launch.yaml"
    overrides = {
        "scene": "cluttered_drawer",
        "duration": "0.1",
        "width": "96",
        "height": "72",
        "voxel_size": "0.03",
    }
    desc = parse_launch_file(launch, overrides)
    sim_spec, cloud_spec = desc.nodes
    assert (sim_spec.executable, cloud_spec.executable) == ("sim_node", "scene_cloud_node")
    assert load_executable("sim_node") is SimNode and load_executable("scene_cloud_node") is SceneCloudNode
    # parameter file values, then the launch arguments on top
    assert sim_spec.parameters["publish_rate"] == 50.0 and sim_spec.parameters["duration_s"] == 0.1
    assert cloud_spec.parameters["topic"] == "/scene/points" and cloud_spec.parameters["width"] == 96
    summary = run_launch(desc, duration_s=1.0, use_sim_time=True)
    assert summary.stop_reason == "done" and summary.total_errors == 0
    counts = summary.message_counts
    assert counts["/tf"] == counts["/scene/joint_states"] == counts["/robot/joint_states"] == 5
    assert counts["/scene/points"] >= 1 and counts["/scene/labels"] == 1
    with pytest.raises(LaunchError, match="moon_base"):
        run_launch(parse_launch_file(launch, {"scene": "moon_base"}), duration_s=0.1, use_sim_time=True)
