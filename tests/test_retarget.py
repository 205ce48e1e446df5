"""Retargeting: mapping (scale about the shoulders, unreachable goals reported), timed output within the
velocity/acceleration limits, schedules and planned wrist segments, a real HDM05 clip at >= real-time rate,
the ``hsi retarget`` CLI and the retarget node."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hsi_nodes.executor import Executor
from hsi_nodes.msgs import make_header, make_pose, msg_class
from hsi_nodes.node import Node
from hsi_nodes.nodes import load_executable
from hsi_nodes.nodes.retarget_node import RetargetNode, joint_trajectory_from_msg
from hsi_nodes.transport import make_transport
from hsi_nodes.transport.base import QoS, Transport
from hsi_planning.errors import ConfigError, RetargetError
from hsi_planning.mocap import load_amc, load_asf
from hsi_planning.mocap.skeleton import Motion
from hsi_planning.scheduler.schedule import Keyframe, Schedule
from hsi_planning.trajectory import WristTrajectory
from hsi_retarget.human_motion import HumanMotion
from hsi_retarget.joint_trajectory import ContactEvent, JointTrajectory
from hsi_retarget.mapping import MappingConfig, map_to_robot, robot_reach
from hsi_retarget.retarget import RetargetConfig, retarget
from hsi_retarget.robots import RobotModel
from hsi_retarget.sources import human_motion_from_mocap
from hsi_retarget.timing import time_parameterize

CLIP = "HDM_bd_grabHighR_001_120.amc"


@pytest.fixture(scope="module")
def dual() -> RobotModel:
    return RobotModel("dual_ur5e")


def _limits(robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    v, a = np.full(robot.nq, np.inf), np.full(robot.nq, np.inf)
    for name in robot.joint_names:
        v[robot.q_index(name)] = robot.v_max[robot.v_index(name)]
        a[robot.q_index(name)] = robot.a_max[robot.v_index(name)]
    return v, a


def _motion(n: int, rate: float, right: np.ndarray, left: np.ndarray | None = None) -> HumanMotion:
    """Standing human at the origin facing +x; wrist positions (n, 3), identity wrist orientation."""
    left = np.tile([0.3, 0.25, 1.0], (n, 1)) if left is None else left
    eye = np.tile(np.eye(3), (n, 1, 1))
    return HumanMotion(
        t=np.arange(n) / rate,
        wrist_position={"left": left, "right": right},
        wrist_rotation={"left": eye, "right": eye},
        active={"left": np.ones(n, bool), "right": np.ones(n, bool)},
        hip_position=np.tile([0.0, 0.0, 0.95], (n, 1)),
        hip_yaw=np.zeros(n),
    )


def test_joint_trajectory_sample_renormalizes_and_roundtrips(tmp_path: Path) -> None:
    q0 = np.r_[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.5]
    q1 = np.r_[1.0, 0.0, 1.0, *Rotation.from_euler("z", 170, degrees=True).as_quat(), 1.5]
    traj = JointTrajectory(
        "humanoid",
        [0.0, 1.0],
        [q0, q1],
        ("j",),
        (ContactEvent(0.5, "left", "grasp", "can1"),),
        {"a": np.ones(2)},
    )
    assert traj.root_index == 0
    mid = traj.sample(0.5)
    assert abs(np.linalg.norm(mid[3:7]) - 1.0) < 1e-12
    assert mid[0] == pytest.approx(0.5) and mid[7] == pytest.approx(1.0)
    back = JointTrajectory.read_json(traj.write_json(tmp_path / "t.json"))
    assert np.allclose(back.q, traj.q) and back.events == traj.events and back.meta == {"a": [1.0, 1.0]}
    fixed = JointTrajectory("dual_ur5e", [0.0, 1.0], np.zeros((2, 2)), ("a", "b"))
    assert fixed.root_index == -1
    with pytest.raises(RetargetError, match="malformed"):
        JointTrajectory.from_dict({"robot": "x"})


def test_time_parameterize_meets_limits_and_leaves_slow_paths_alone() -> None:
    t = np.arange(241) / 120.0
    q = np.column_stack([0.8 * np.sin(2 * np.pi * 2.0 * t), 0.05 * t])
    v_max, a_max = np.array([3.0, 3.0]), np.array([10.0, 10.0])
    res = time_parameterize(t, q, v_max, a_max)
    v = np.diff(q, axis=0) / np.diff(res.t)[:, None]
    a = np.diff(v, axis=0) / (0.5 * (np.diff(res.t)[1:] + np.diff(res.t)[:-1]))[:, None]
    assert np.all(np.abs(v) <= v_max * (1 + 1e-9)) and np.all(np.abs(a) <= a_max * (1 + 1e-9))
    assert res.acceleration_ratio_in > 10.0 and res.t[-1] > 3.0 * t[-1]
    slow = time_parameterize(t, 0.01 * q, v_max, a_max)
    assert np.allclose(slow.t, t) and slow.segments(t) == []


def test_mapping_scales_wrist_offsets_about_the_shoulders(dual: RobotModel) -> None:
    n = 5
    shoulder = {"left": np.tile([0.0, 0.18, 1.4], (n, 1)), "right": np.tile([0.0, -0.18, 1.4], (n, 1))}
    offset = np.array([0.3, -0.1, -0.2])
    motion = _motion(n, 60.0, shoulder["right"] + offset, shoulder["left"] + offset)
    motion = HumanMotion(**{**motion.__dict__, "shoulder_position": shoulder, "arm_length": 0.55})
    goals = map_to_robot(motion, dual, MappingConfig(anchor="shoulder"))
    reach = robot_reach(dual)
    assert goals.scale == pytest.approx(0.85 * np.mean(list(reach.values())) / 0.55)
    for side in ("left", "right"):
        expected = goals.shoulder[side] + goals.scale * offset
        assert np.allclose(goals.tcp[side][:, :3, 3], expected)
        assert goals.reachable[side].all()
    # identity wrist orientation = the dual arm's home TCP orientation (z forward, y left)
    home = dual.frame_pose(dual.q_home, "right_tcp")[:3, :3]
    assert np.allclose(goals.tcp["right"][0, :3, :3], home, atol=1e-4)
    # the torso lift brings the robot's shoulders to the human's height (within the lift range)
    assert np.allclose(goals.shoulder["right"][:, 2], 1.4 * 1.35 / 1.4, atol=1e-3)


def test_unreachable_goals_are_reported_not_clipped(dual: RobotModel) -> None:
    n = 60
    right = np.tile([0.45, -0.25, 1.0], (n, 1))
    right[20:40] = [2.5, -0.25, 1.0]  # 2.5 m ahead of a base that follows the hip
    motion = _motion(n, 60.0, right)
    goals = map_to_robot(motion, dual, MappingConfig(anchor="world"))
    assert np.allclose(goals.tcp["right"][:, :3, 3], right)  # not clipped
    assert not goals.reachable["right"][20:40].any() and goals.reachable["right"][:20].all()
    traj = retarget(motion, dual, config=RetargetConfig(mapping=MappingConfig(anchor="world")))
    flags = np.array(traj.meta["reachable"]["right"])
    assert flags.shape == (n,) and not flags[20:40].any() and flags[40:].all()
    (interval,) = traj.meta["unreachable"]
    assert interval["side"] == "right" and interval["t_start"] == pytest.approx(20 / 60.0)
    assert interval["max_excess_m"] > 0.5
    assert any(r["side"] == "right" for r in traj.meta["ik_unreached"])
    assert all(dual.within_limits(q) for q in traj.q)


def test_timed_output_respects_velocity_and_acceleration_limits(dual: RobotModel) -> None:
    n, rate = 240, 120.0
    t = np.arange(n) / rate
    right = np.column_stack(
        [0.5 + 0.15 * np.sin(2 * np.pi * 2.0 * t), -0.25 + 0.1 * np.cos(2 * np.pi * 2.0 * t), 1.0 + 0 * t]
    )
    traj = retarget(
        _motion(n, rate, right), dual, config=RetargetConfig(mapping=MappingConfig(anchor="world"))
    )
    v_max, a_max = _limits(dual)
    v = np.diff(traj.q, axis=0) / np.diff(traj.t)[:, None]
    h = np.diff(traj.t)
    a = np.diff(v, axis=0) / (0.5 * (h[1:] + h[:-1]))[:, None]
    assert np.all(np.abs(v) <= v_max * (1 + 1e-6))
    assert np.all(np.abs(a) <= a_max * (1 + 1e-6))
    scaling = traj.meta["time_scaling"]
    assert scaling["max_scale"] > 1.0 and traj.duration > t[-1]  # it had to slow down, and says so
    assert scaling["segments"] and scaling["velocity_ratio"] <= 1.0 and scaling["acceleration_ratio"] <= 1.0
    assert traj.meta["tracking"]["right"]["max_position_error_m"] < 0.01
    assert all(dual.within_limits(q) for q in traj.q)


def test_schedule_retargets_with_base_following_the_hip(dual: RobotModel) -> None:
    def key(time_s: float, joint: str, pos: list[float], **kw: Any) -> Keyframe:
        return Keyframe(
            time_s, joint, np.array(pos), np.array([0.0, 0.0, 0.0, 1.0]), kw.pop("action", "reach"), **kw
        )  # type: ignore[arg-type]

    frames = []
    for time_s, hip_x, right, event in (
        (0.0, 0.0, [0.45, -0.25, 1.0], ""),
        (1.5, 0.2, [0.8, -0.2, 0.9], "grasp"),
        (3.0, 0.3, [0.65, -0.25, 1.1], ""),
    ):
        frames += [
            key(time_s, "hip", [hip_x, 0.0, 0.95]),
            key(time_s, "root", [hip_x, 0.0, 0.0]),
            key(time_s, "left_wrist", [hip_x + 0.45, 0.25, 1.0]),
            key(
                time_s,
                "right_wrist",
                right,
                contact_event=event,
                hand="right",
                object_name="can1" if event else "",
            ),
        ]
    traj = retarget(Schedule("t1", tuple(frames)), dual)
    assert traj.meta["anchor"] == "world"
    (event,) = traj.events
    assert (event.hand, event.kind, event.object_name) == ("right", "grasp", "can1")
    k = int(np.argmin(np.abs(np.array(traj.meta["goal_time"]) - 1.5)))
    assert traj.t[k] == pytest.approx(event.time)
    tcp = dual.frame_pose(traj.q[k], "right_tcp")[:3, 3]
    assert np.linalg.norm(tcp - [0.8, -0.2, 0.9]) < 0.01
    assert traj.q[-1][dual.q_index("base_x_joint")] == pytest.approx(0.3, abs=0.05)


def test_a_carry_from_a_grasp_the_ik_ended_short_of_is_reaimed_in_one_pass(dual: RobotModel) -> None:
    def key(time_s: float, joint: str, pos: list[float], **kw: Any) -> Keyframe:
        return Keyframe(time_s, joint, np.array(pos), np.array([0.0, 0.0, 0.0, 1.0]), "reach", **kw)  # type: ignore[arg-type]

    frames = []
    for time_s, right, event in (
        (0.0, [0.45, -0.25, 1.0], ""),
        (1.5, [0.8, -0.2, 2.6], "grasp"),  # ~0.2 m above the arm's reach
        (3.0, [0.65, -0.25, 1.1], ""),
        (4.0, [0.65, -0.25, 1.1], "release"),
    ):
        frames += [key(time_s, "hip", [0.0, 0.0, 0.95]), key(time_s, "root", [0.0, 0.0, 0.0])]
        frames += [key(time_s, "left_wrist", [0.45, 0.25, 1.0])]
        name = "can1" if event else ""
        frames += [key(time_s, "right_wrist", right, contact_event=event, hand="right", object_name=name)]
    traj = retarget(Schedule("t1", tuple(frames)), dual)
    (record,) = traj.meta["carry_corrections"]
    assert (record["hand"], record["object"]) == ("right", "can1") and record["position_m"] > 0.1
    t, goal = np.array(traj.meta["goal_time"]), np.array(traj.meta["goal_position"]["right"])
    k = int(np.argmin(np.abs(t - 3.0)))
    # the carry's end goal is no longer the planned one (world anchor: mapped as planned) ...
    assert np.linalg.norm(goal[k] - goal[-1]) < 1e-9 and np.linalg.norm(goal[k] - [0.65, -0.25, 1.1]) > 0.05
    reached = dual.frame_pose(traj.q[-1], "right_tcp")[:3, 3]  # ... and the IK followed the re-aimed carry
    assert np.linalg.norm(reached - goal[-1]) < 0.005


def test_wrist_segments_become_one_trajectory_with_events(dual: RobotModel) -> None:
    t = np.linspace(0.0, 1.0, 31)
    path = np.column_stack([0.4 + 0.3 * t, -0.25 + 0 * t, 1.0 - 0.1 * t])
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (31, 1))
    approach = WristTrajectory(t, path, quat, "right", "grasp", "approach", object_name="can1")
    leave = WristTrajectory(
        t, path[::-1], quat, "right", "grasp", "leave", contact_index=0, object_name="can1"
    )
    traj = retarget([approach, leave], dual)
    assert [(e.kind, e.object_name) for e in traj.events] == [("grasp", "can1")]
    assert traj.meta["tracking"]["right"]["max_position_error_m"] < 0.005
    with pytest.raises(RetargetError, match="no wrist"):
        retarget([], dual)


def test_humanoid_retarget_keeps_feet_and_normalized_root() -> None:
    robot = RobotModel("humanoid")
    n = 60
    right = np.tile([0.3, -0.25, 1.0], (n, 1)) + np.outer(np.sin(np.linspace(0, np.pi, n)), [0.15, 0.0, 0.1])
    traj = retarget(
        _motion(n, 60.0, right), robot, config=RetargetConfig(mapping=MappingConfig(anchor="world"))
    )
    assert traj.root_index == 0
    assert np.allclose(np.linalg.norm(traj.q[:, 3:7], axis=1), 1.0)
    soles = np.array([[robot.frame_pose(q, f"{s}_sole")[:3, 3] for s in ("left", "right")] for q in traj.q])
    assert np.abs(soles - soles[0]).max() < 1e-3
    assert traj.meta["tracking"]["right"]["max_position_error_m"] < 0.01


def test_humanoid_smoothing_leaves_legs_and_root_alone() -> None:
    """On a floating robot the low-pass takes the arms and the waist that carries them, never the root
    or the legs (the soles stay in place); on the dual arm the arms, base and lift."""
    from hsi_retarget.smoothing import smooth_joints, smoothed_joints

    robot = RobotModel("humanoid")
    names = smoothed_joints(robot)
    assert {"waist_yaw", "waist_roll", "waist_pitch"} <= set(names)
    assert set(robot.arm_joints["left"]) <= set(names) and not any("hip" in j or "knee" in j for j in names)
    rng = np.random.default_rng(5)
    n = 120
    t = np.arange(n) / 60.0
    raw = np.tile(robot.q_home, (n, 1))
    raw[:, 7:] += 0.02 * rng.standard_normal((n, robot.nq - 7))
    raw[:, :3] += 0.01 * rng.standard_normal((n, 3))
    path = smooth_joints(robot, t, raw, 8.0)
    idx = np.array([robot.q_index(j) for j in names])
    rest = np.setdiff1d(np.arange(robot.nq), idx)
    np.testing.assert_array_equal(path[:, rest], raw[:, rest])  # root (and its quaternion) and legs
    assert np.abs(np.diff(path[:, idx], axis=0)).max() < 0.5 * np.abs(np.diff(raw[:, idx], axis=0)).max()
    dual_names = smoothed_joints(RobotModel("dual_ur5e"))
    assert "torso_lift_joint" in dual_names and "base_x_joint" in dual_names


def test_hdm05_clip_retargets_with_mm_tracking(hdm05_dir: Path, dual: RobotModel) -> None:
    """An HDM05 reach on the dual-arm robot: scaled up, tracked within 1 cm, limits kept. The frame rate
    is printed, not asserted (speed targets live in ``benchmarks/pick_place.py``, not in timed tests)."""
    skeleton = load_asf(hdm05_dir / "HDM_bd.asf")
    motion = load_amc(hdm05_dir / CLIP, skeleton)
    part = Motion(motion.channels, motion.values[40:160], motion.fps)  # 1 s of the reach
    wall = time.perf_counter()
    human = human_motion_from_mocap(skeleton, part)
    traj = retarget(human, dual)
    wall = time.perf_counter() - wall
    rate, ik_rate = 120 / wall, traj.meta["ik_rate_fps"]
    print(f"HDM05 {CLIP} frames 40-160 on dual_ur5e: {rate:.0f} frames/s overall, {ik_rate:.0f} IK frames/s")
    assert ik_rate > 0.0 and traj.q.shape[0] == 120
    assert traj.meta["scale"] > 1.2  # the UR5e arm is longer than a human arm
    right = traj.meta["tracking"]["right"]
    assert right["rms_position_error_m"] < 0.01, right
    assert all(dual.within_limits(q) for q in traj.q)


def _cli(argv: list[str]) -> int:
    from hsi_nodes.cli import retarget as command

    parser = argparse.ArgumentParser()
    command.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["retarget", *argv])
    return int(args.func(args))


def test_cli_writes_valid_json_and_plays_it(
    hdm05_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "traj.json"
    code = _cli(
        [
            str(hdm05_dir / CLIP),
            "--robot",
            "dual_arm",
            "--out",
            str(out),
            "--start",
            "60",
            "--frames",
            "48",
            "--sim",
        ]
    )
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 48 and summary["retarget_rate_fps"] > 0
    data = json.loads(out.read_text())
    traj = JointTrajectory.from_dict(data)
    assert traj.robot == "dual_ur5e" and traj.q.shape == (48, 20)
    sim = traj.meta["sim"]
    assert 0.0 <= sim["tracking_max_m"]["right"] < 0.1, sim


def test_cli_rejects_bad_inputs(tmp_path: Path) -> None:
    lonely = tmp_path / "clip.amc"
    lonely.write_text(":DEGREES\n")
    with pytest.raises(ConfigError, match="skeleton"):
        _cli([str(lonely)])
    other = tmp_path / "clip.txt"
    other.write_text("x")
    with pytest.raises(ConfigError, match=r"\.amc or \.bvh"):
        _cli([str(other)])


class _Probe(Node[Any]):
    def __init__(self, transport: Transport) -> None:
        super().__init__("probe", transport=transport)
        self.trajs: list[Any] = []
        self.reports: list[Any] = []
        self.create_subscription(
            "/robot/joint_trajectory", "trajectory_msgs/msg/JointTrajectory", self.trajs.append, QoS(depth=10)
        )
        self.create_subscription("/hsi/report", "hsi/msg/TaskReport", self.reports.append, QoS(depth=10))


def _wrist_msg(task: str, segment: str, stamp: float, path: np.ndarray) -> Any:
    n = path.shape[0]
    return msg_class("hsi/msg/WristTrajectory")(
        header=make_header(stamp, "world"),
        task_id=task,
        hand="right",
        action="grasp",
        segment=segment,
        planner="minjerk",
        object_name="can1",
        time_from_start=np.linspace(0.0, 1.0, n),
        poses=[make_pose(p) for p in path],
        contact_index=n - 1 if segment == "approach" else 0,
    )


def test_retarget_node_turns_wrist_segments_into_a_joint_trajectory() -> None:
    assert load_executable("retarget_node") is RetargetNode
    transport = make_transport("inproc")
    executor = Executor(transport, use_sim_time=True)
    node = RetargetNode(transport=transport, parameters={"settle_s": 0.2})
    probe = _Probe(transport)
    for n in (node, probe):
        executor.add_node(n)
    pub = transport.publisher("/hsi/wrist_trajectory", "hsi/msg/WristTrajectory")
    path = np.column_stack([np.linspace(0.4, 0.7, 21), np.full(21, -0.25), np.linspace(1.0, 0.9, 21)])
    pub.publish(_wrist_msg("t1", "approach", 0.0, path))
    pub.publish(_wrist_msg("t1", "leave", 1.0, path[::-1]))
    bad = _wrist_msg("t1", "leave", 1.0, path)
    bad.time_from_start = np.zeros(3)  # 3 times for 21 poses: ignored
    pub.publish(bad)
    executor.spin(duration_s=2.0, until=lambda: bool(probe.reports))
    executor.shutdown()
    assert node.ignored == 1
    (msg,) = probe.trajs
    traj = joint_trajectory_from_msg(msg, "dual_ur5e")
    assert traj.q.shape[1] == 20 and traj.duration >= 2.0 - 1e-6
    report = probe.reports[-1]
    assert report.stage == "retarget" and report.success and report.task_id == "t1"
    details = json.loads(report.details_json)
    assert details["events"][0]["kind"] == "grasp" and report.max_tracking_error_m < 0.01
    with pytest.raises(ConfigError, match="anchor"):
        RetargetNode(transport=make_transport("inproc"), parameters={"anchor": "moon"})


# --------------------------------------------------------------------------------- grip turn, carry


def test_grippers_close_across_handle_bars_and_narrow_sides() -> None:
    from hsi_planning.scene_paths import load_scene
    from hsi_retarget.grasp_windows import GraspWindow
    from hsi_retarget.grip_turn import (
        GripTurnConfig,
        across_bar_angle,
        handle_bar_axes,
        narrow_side_angle,
        object_prims,
        turn_grips,
    )

    spec = load_scene("kitchen")
    bars = handle_bar_axes(spec)
    assert abs(bars["drawer_unit1/drawer1"][2]) < 1e-9 and abs(abs(bars["cabinet1/door1"][2]) - 1.0) < 1e-9
    front = np.eye(3)  # wrist x into the front, z up: the fingers close along world y
    drawer = across_bar_angle(front, bars["drawer_unit1/drawer1"])
    assert abs(abs(drawer) - np.pi / 2) < 1e-9
    y_turned = np.cos(drawer) * front[:, 1] + np.sin(drawer) * front[:, 2]
    assert abs(y_turned @ bars["drawer_unit1/drawer1"]) < 1e-9
    assert across_bar_angle(front, bars["cabinet1/door1"]) == 0.0  # a vertical bar: already across
    assert across_bar_angle(front, np.array([1.0, 0.0, 0.0])) == 0.0  # a bar along the approach

    top = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # x down, fingers along world y
    prims = object_prims(spec)
    cfg = GripTurnConfig()
    assert narrow_side_angle(top, prims["can1"], cfg) == 0.0  # a can fits between the open fingers
    mug = narrow_side_angle(top, prims["mug2"], cfg)  # mug2's handle points along world y
    assert abs(abs(mug) - np.pi / 2) < 1e-9

    n = 61
    t = np.linspace(0.0, 3.0, n)
    motion = HumanMotion(
        t=t,
        wrist_position={"right": np.tile([0.5, -1.3, 0.7], (n, 1))},
        wrist_rotation={"right": np.tile(front, (n, 1, 1))},
        active={"right": np.ones(n, bool)},
        hip_position=np.tile([0.0, -1.3, 0.95], (n, 1)),
        hip_yaw=np.zeros(n),
    )
    part = "drawer_unit1/drawer1"
    windows = [
        GraspWindow("right", "grasp", part, False, 1.0, (0.5, 1.0), (1.0, 1.5)),
        GraspWindow("right", "release", part, False, 2.0, (1.5, 2.0), (2.0, 2.5)),
    ]
    turned, records = turn_grips(motion, windows, bars, prims, GripTurnConfig(turn_s=0.5))
    rot = turned.wrist_rotation["right"]
    assert records == [{"hand": "right", "target": part, "time_s": 1.0, "angle_deg": pytest.approx(-90.0)}]
    np.testing.assert_allclose(rot[:, :, 0], np.tile([1.0, 0.0, 0.0], (n, 1)), atol=1e-9)  # approach kept
    held = (t >= 1.0) & (t <= 2.0)
    assert np.abs(rot[held, :, 1] @ bars[part]).max() < 1e-9  # fingers across the bar while held
    outside = (t <= 0.5) | (t >= 2.5)
    np.testing.assert_allclose(rot[outside], motion.wrist_rotation["right"][outside], atol=1e-9)
    assert np.all(np.isfinite(turned.wrist_position["right"]))


def _left_carry(t: np.ndarray, tcp: np.ndarray) -> tuple[Any, tuple[ContactEvent, ...]]:
    """Left-hand goals ``tcp`` (T, 4, 4) at ``t`` (T,) [s] carrying can1 from a grasp at 1 s to a release
    at 3 s (the base at the origin)."""
    from hsi_retarget.mapping import RobotGoals

    n = t.shape[0]
    goals = RobotGoals(
        t=t,
        tcp={"left": tcp},
        active={"left": np.ones(n, bool)},
        reachable={"left": np.ones(n, bool)},
        reach_excess={"left": np.zeros(n)},
        root=np.tile(np.eye(4), (n, 1, 1)),
        lift=np.full(n, np.nan),
        shoulder={"left": np.zeros((n, 3))},
        scale=1.0,
    )
    return goals, (ContactEvent(1.0, "left", "grasp", "can1"), ContactEvent(3.0, "left", "release", "can1"))


def test_carry_is_reaimed_from_the_reached_grasp_pose(dual: RobotModel) -> None:
    from hsi_retarget.carry_correction import carry_frames, correct_carry

    n = 121
    t = np.linspace(0.0, 4.0, n)
    qs = np.tile(dual.q_home, (n, 1))
    reached = dual.frame_pose(dual.q_home, dual.tcp_frames["left"])
    planned = np.array(reached)
    planned[:3, 3] += [0.02, -0.01, 0.015]  # the IK ended 2.7 cm and 10 deg short of the grasp goal
    planned[:3, :3] = Rotation.from_rotvec([0.0, 0.0, np.radians(10.0)]).as_matrix() @ reached[:3, :3]
    release = np.array(planned)
    release[:3, 3] += [0.3, 0.2, 0.1]
    tcp = np.tile(planned, (n, 1, 1))
    tcp[t >= 2.0] = release
    goals, events = _left_carry(t, tcp)
    fixed, records, first = correct_carry(goals, qs, dual, events, ease_s=0.5)
    i_grasp = int(np.searchsorted(t, 1.0 - 1e-9))
    assert carry_frames(t, events) == {i_grasp: events}  # where an IK pass re-aims it, with its release
    assert carry_frames(t, events[:1]) == {i_grasp: events[:1]} and carry_frames(t, events[1:]) == {}
    assert first == i_grasp and len(records) == 1
    assert records[0]["position_m"] == pytest.approx(np.linalg.norm([0.02, -0.01, 0.015]), abs=1e-9)
    assert records[0]["angle_deg"] == pytest.approx(10.0, abs=1e-6)
    out = fixed.tcp["left"]
    np.testing.assert_allclose(out[:i_grasp], tcp[:i_grasp])  # nothing before the grasp
    np.testing.assert_allclose(out[i_grasp], reached, atol=1e-9)  # the reached pose from the grasp on
    delta = np.linalg.inv(planned) @ reached
    at_release = int(np.searchsorted(t, 3.0 - 1e-9))
    np.testing.assert_allclose(out[at_release], release @ delta, atol=1e-9)  # placed as planned
    np.testing.assert_allclose(out[t > 3.5 + 1e-9], tcp[t > 3.5 + 1e-9], atol=1e-9)  # eased out after
    unchanged, none, start = correct_carry(fixed, qs, dual, events[1:])  # no grasp: nothing to do
    assert none == [] and start is None and unchanged.tcp["left"] is not fixed.tcp["left"]


def test_a_carry_is_moved_to_put_the_object_on_its_placement(dual: RobotModel) -> None:
    from hsi_retarget.carry_correction import place_carries

    n = 121
    t = np.linspace(0.0, 4.0, n)
    grasp = dual.frame_pose(dual.q_home, dual.tcp_frames["left"])
    bottom = grasp[:3, 3] + grasp[:3, :3] @ np.array([0.03, 0.02, 0.0])  # held 3.6 cm off the TCP
    release = np.array(grasp)  # planned 30 cm further, the gripper turned half round its approach axis
    release[:3, :3] = grasp[:3, :3] @ Rotation.from_rotvec([0.0, 0.0, np.pi]).as_matrix()
    release[:3, 3] += [0.3, 0.0, 0.0]
    tcp = np.tile(grasp, (n, 1, 1))
    tcp[t >= 2.0] = release
    goals, events = _left_carry(t, tcp)
    place = bottom + np.array([0.3, 0.0, 0.0])  # where the planner meant it: the turn was not accounted for
    carries = [{"object": "can1", "hands": ["left"], "grasp": bottom.tolist(), "place": place.tolist()}]
    moved, records = place_carries(goals, events, carries, ease_s=0.5)
    out = moved.tcp["left"]
    i, r = (int(np.searchsorted(t, x - 1e-9)) for x in (1.0, 3.0))
    held = np.linalg.solve(out[i], np.append(bottom, 1.0))
    np.testing.assert_allclose((out[r] @ held)[:3], place, atol=1e-9)  # the object lands on its placement
    before = np.linalg.solve(tcp[i], np.append(bottom, 1.0))
    np.testing.assert_allclose(held, before, atol=1e-12)  # the grasp itself is not moved
    np.testing.assert_allclose(out[: i + 1], tcp[: i + 1], atol=1e-12)
    np.testing.assert_allclose(out[:, :3, :3], tcp[:, :3, :3])  # only translated
    np.testing.assert_allclose(out[t > 3.5 + 1e-9], tcp[t > 3.5 + 1e-9], atol=1e-12)  # eased out after
    shift = out[:, :3, 3] - tcp[:, :3, 3]
    assert np.all(np.diff(np.linalg.norm(shift[i : r + 1], axis=1)) >= -1e-12)  # eased in along the carry
    assert len(records) == 1
    assert np.linalg.norm(records[0]["shift_m"]) == pytest.approx(2 * np.hypot(0.03, 0.02))
    same, none = place_carries(goals, events, [{**carries[0], "place": (tcp[r] @ before)[:3].tolist()}])
    assert none == [] and np.array_equal(same.tcp["left"], tcp)  # consistent already: nothing to do
    assert place_carries(goals, events, [{"object": "can1", "hands": ["left"], "grasp": [0, 0, 0]}])[1] == []


def test_smoothing_keeps_the_path_where_it_costs_no_clearance(dual: RobotModel) -> None:
    from hsi_retarget.ik import IKSolver
    from hsi_retarget.smoothing import keep_clearance, smooth_joints

    rng = np.random.default_rng(3)
    n = 120
    t = np.arange(n) / 60.0
    raw = np.tile(dual.q_home, (n, 1))
    arm = dual.arm_q_indices("right")
    raw[:, arm] += 0.02 * rng.standard_normal((n, arm.shape[0]))  # chatter far from the other arm
    solver = IKSolver(dual)
    path, restored = keep_clearance(solver, dual, t, raw, 8.0)
    np.testing.assert_allclose(path, smooth_joints(dual, t, raw, 8.0))
    assert restored == 0
    assert np.abs(np.diff(path[:, arm], axis=0)).max() < np.abs(np.diff(raw[:, arm], axis=0)).max()


def test_smoothing_restores_the_frames_where_it_cuts_into_an_opened_part(dual: RobotModel) -> None:
    """Raw IK chatter between two poses of the right arm next to a door panel (a part layer): the smoothed
    mean pose lies 3 mm inside the panel's margin, 2 mm closer than the farther raw pose. Measured with the
    part's layer, those frames go back to the raw path; without it nothing is restored."""
    import trimesh

    from hsi_retarget.ik import IKSolver
    from hsi_retarget.scene_distance import SceneDistance
    from hsi_retarget.smoothing import keep_clearance, smooth_joints

    n = 120
    t = np.arange(n) / 60.0
    elbow = dual.q_index("right_elbow_joint")
    near, far = np.array(dual.q_home), np.array(dual.q_home)
    near[elbow] += 0.03
    far[elbow] -= 0.03
    raw = np.where((np.arange(n) % 2 == 0)[:, None], near, far)  # chatter at 30 Hz
    solver = IKSolver(dual)
    tips = solver.sphere_centers(near) - solver.sphere_centers(far)
    moving = int(np.argmax(np.linalg.norm(tips, axis=1)))  # the sphere the elbow moves most
    direction = tips[moving] / np.linalg.norm(tips[moving])
    middle = solver.sphere_centers(dual.q_home)[moving]

    def panel(offset: float) -> SceneDistance:
        box = trimesh.creation.box(extents=(0.01, 0.4, 0.4))
        frame = np.eye(4)
        frame[:3, 0] = direction
        frame[:3, 1] = np.cross(direction, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(direction, [0, 0, 1.0]))
        frame[:3, 2] = np.cross(frame[:3, 0], frame[:3, 1])
        frame[:3, 3] = middle + (offset + 0.005) * direction
        box.apply_transform(frame)
        return SceneDistance({"door": box}, ground=())

    def clearance(scene: SceneDistance, q: np.ndarray) -> float:
        solver.set_part_scene(scene, "left")
        try:
            return solver.clearance(q)
        finally:
            solver.set_part_scene(None)

    lo, hi = 0.0, 0.3  # the panel offset that puts the mean pose 3 mm inside its margin
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if clearance(panel(mid), dual.q_home) < -0.003 else (lo, mid)
    door = panel(hi)
    assert clearance(door, far) > clearance(door, dual.q_home) + 0.002
    layers = [(door, "left")] * n
    smooth = smooth_joints(dual, t, raw, 8.0)
    path, restored = keep_clearance(solver, dual, t, raw, 8.0, layers=layers)
    assert restored > n // 4
    assert np.abs(path - raw).max(axis=1)[n // 4 : 3 * n // 4].max() < 1e-9  # the raw path in the middle
    ignored, none = keep_clearance(solver, dual, t, raw, 8.0)
    assert none == 0 and np.allclose(ignored, smooth)
    assert solver._layer is None  # the check leaves no part scene behind


def test_frames_stop_at_the_task_residual_with_the_same_tracking(
    dual: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Away from contacts a frame's IK stops once more steps would not reduce its TCP errors (the weighted
    tasks' residual): far fewer steps, the same tracking within a millimetre; ``settle_*`` 0 turns it off."""
    from hsi_retarget.ik import IKSolver

    n, rate = 180, 60.0
    t = np.arange(n) / rate
    right = np.column_stack(
        [0.5 + 0.1 * np.sin(np.pi * t), -0.25 + 0.1 * np.cos(np.pi * t), 1.0 + 0.05 * np.sin(2 * np.pi * t)]
    )
    steps = [0]
    original = IKSolver.step

    def counted(self: IKSolver, *args: Any, **kwargs: Any) -> Any:
        steps[0] += 1
        return original(self, *args, **kwargs)

    monkeypatch.setattr(IKSolver, "step", counted)
    runs = {}
    for settle in ((5e-4, 5e-3), (0.0, 0.0)):
        steps[0] = 0
        cfg = RetargetConfig(
            mapping=MappingConfig(anchor="world"), settle_position=settle[0], settle_orientation=settle[1]
        )
        traj = retarget(_motion(n, rate, right), dual, config=cfg)
        runs[settle[0]] = (steps[0], traj.meta["tracking"]["right"])
    (fast, track_fast), (full, track_full) = runs[5e-4], runs[0.0]
    assert fast < 0.75 * full, (fast, full)
    assert abs(track_fast["rms_position_error_m"] - track_full["rms_position_error_m"]) < 1e-3
    assert track_fast["max_position_error_m"] < 1e-3
    with pytest.raises(ConfigError, match="settle_position"):
        RetargetConfig(settle_position=-1e-3)


def test_planned_orientations_lose_their_jitter_but_keep_their_turn_and_ends() -> None:
    """A 90 deg turn over 1.2 s with seeded 40 deg single-sample spikes (the learned planner's jitter):
    smoothed, the spikes are gone, the turn and both end orientations stay."""
    from hsi_retarget.rotation_filter import smooth_rotations

    rng = np.random.default_rng(11)
    t = np.arange(151) * 0.008
    turn = Rotation.from_euler("z", 90.0 * t[:, None] / t[-1], degrees=True)
    spikes = rng.choice(np.arange(5, 145), size=12, replace=False)
    kick = np.zeros((t.shape[0], 3))
    kick[spikes] = Rotation.random(12, random_state=3).as_rotvec()
    kick[spikes] *= np.radians(40.0) / np.linalg.norm(kick[spikes], axis=1, keepdims=True)
    noisy = turn * Rotation.from_rotvec(kick)
    quats = noisy.as_quat()
    quats[1::2] *= -1.0  # the same orientations with flipped quaternion signs
    out = Rotation.from_quat(smooth_rotations(t, quats, 3.0))
    assert (out[[0, -1]].inv() * noisy[[0, -1]]).magnitude().max() < 1e-9  # ends exact
    step = np.degrees((out[:-1].inv() * out[1:]).magnitude())
    assert step.max() < 4.0, step.max()  # was 40 deg within one 8 ms step
    assert np.degrees((out.inv() * turn).magnitude()).max() < 8.0  # the turn itself is kept
    np.testing.assert_allclose(smooth_rotations(t, quats, 0.0), quats)  # 0 Hz: as planned
    with pytest.raises(RetargetError, match="quats"):
        smooth_rotations(t, quats[:, :3], 3.0)
    with pytest.raises(RetargetError, match="increasing"):
        smooth_rotations(t[::-1], quats, 3.0)
    with pytest.raises(ConfigError, match="rotation_cutoff_hz"):
        RetargetConfig(rotation_cutoff_hz=-1.0)
