"""The demo's pick-and-place pipeline: scripted clicks, grasp depth, gripper dwell, one task end to end on
each robot in MuJoCo, honest failure reports, and the node path (sim_check_node after the real
retarget_node, click_player sequencing, the launch file).

Planner used: ``reach_model`` (the human-reach model; deterministic and fast). The implicit planner's
results are in the demo's report (``hsi demo``), not asserted here.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hsi_nodes.demo.pipeline import (
    ROBOT_BODY_RADIUS,
    ROBOT_WRIST_CLEARANCE,
    PipelineConfig,
    TaskOutcome,
    make_demo_planner,
    resolve_task,
    robot_trajectory,
    run_task,
)
from hsi_nodes.demo.runner import scene_cloud
from hsi_nodes.demo.summary import REQUIRED_KEYS
from hsi_nodes.demo.tasks import VARIANTS, DemoTask, demo_tasks
from hsi_nodes.executor import Executor
from hsi_nodes.msgs import make_header, msg_class
from hsi_nodes.node import Node
from hsi_nodes.nodes import load_executable
from hsi_nodes.nodes.click_player_node import ClickPlayerConfig, ClickPlayerNode, goal_msg
from hsi_nodes.nodes.planner_node import trajectory_msg
from hsi_nodes.nodes.retarget_node import RetargetNode
from hsi_nodes.nodes.scheduler_node import schedule_msg
from hsi_nodes.nodes.sim_check_node import SimCheckNode, SimCheckNodeConfig
from hsi_nodes.transport import make_transport
from hsi_nodes.transport.base import QoS, Transport
from hsi_planning.config import from_mapping
from hsi_planning.errors import ConfigError, PlanningError, RetargetError
from hsi_planning.perception import LabelledCloud
from hsi_planning.scene import SceneSpec
from hsi_planning.scene.model import support_surface
from hsi_planning.scene_paths import load_scene
from hsi_planning.scheduler import ReachModelPlanner, SceneWorld, find_blockers
from hsi_planning.scheduler.auxiliary import AuxiliaryConfig
from hsi_planning.scheduler.world import WorldState
from hsi_retarget.grasp_depth import GraspDepthConfig, shape_grasps
from hsi_retarget.grasp_windows import container_rims, grasp_windows
from hsi_retarget.gripper_dwell import DwellConfig, add_gripper_dwell
from hsi_retarget.joint_trajectory import ContactEvent, JointTrajectory
from hsi_retarget.retarget import RetargetConfig, retarget
from hsi_retarget.sources import human_motion_from_schedule

_REPORT = "hsi/msg/TaskReport"
_GOAL = "hsi/msg/PickPlaceGoal"
COUNTER = demo_tasks("test")[0]


@pytest.fixture(scope="module")
def kitchen_cloud() -> LabelledCloud:
    return scene_cloud("kitchen", 0.01)


@pytest.fixture(scope="module")
def dual_arm(kitchen_cloud: LabelledCloud) -> TaskOutcome:
    """The counter can task on the dual arm, end to end."""
    config = PipelineConfig(robot="dual_arm", planner="reach_model")
    return run_task(COUNTER, load_scene("kitchen"), kitchen_cloud, make_demo_planner("reach_model"), config)


# ------------------------------------------------------------------------------------------ the tasks


def test_variants_hold_the_scripted_scenarios() -> None:
    kitchen = {t.name: t for t in demo_tasks("kitchen")}
    assert set(kitchen) == {"counter_can", "cabinet_bottle", "drawer_mug", "narrow_shelf_can"}
    spec = load_scene("kitchen")
    assert spec.object_by_name(kitchen["cabinet_bottle"].object_name).on.startswith("cabinet1")
    assert spec.object_by_name(kitchen["drawer_mug"].object_name).on.startswith("drawer_unit1/drawer")
    assert kitchen["narrow_shelf_can"].scene == "narrow_shelf"
    assert [t.name for t in demo_tasks("kitchen", ("drawer_mug",))] == ["drawer_mug"]
    assert demo_tasks("test") == VARIANTS["test"]
    with pytest.raises(ConfigError, match="available"):
        demo_tasks("moon")
    with pytest.raises(ConfigError, match="unknown demo task"):
        demo_tasks("kitchen", ("nope",))
    with pytest.raises(ConfigError, match="exactly one"):
        DemoTask("x", "kitchen", (0.0, 0.0, 0.9), click=(1.0, 0.0, 1.0), object_name="can1")
    with pytest.raises(ConfigError, match="hand"):
        DemoTask("x", "kitchen", (0.0, 0.0, 0.9), object_name="can1", hand="third")
    with pytest.raises(ConfigError, match="door_hand must be '', left or right, got 'both'"):
        DemoTask("x", "kitchen", (0.0, 0.0, 0.9), object_name="can1", door_hand="both")
    with pytest.raises(ConfigError, match="finite"):
        DemoTask("x", "kitchen", (0.0, float("nan"), 0.9), object_name="can1")


def test_clicks_resolve_against_the_cloud(kitchen_cloud: LabelledCloud) -> None:
    spec = load_scene("kitchen")
    world = SceneWorld(spec, kitchen_cloud)
    config = PipelineConfig().scheduler_config()
    supports = {"counter_can": "counter1", "cabinet_bottle": "shelf1/board2", "drawer_mug": "counter1"}
    for task in demo_tasks("kitchen"):
        if task.scene != "kitchen":
            continue
        request = resolve_task(task, world, config)
        assert request.place_support == supports[task.name]
        assert request.place is not None
        np.testing.assert_allclose(request.place, task.place_click, atol=0.03)
    assert resolve_task(COUNTER, world, config).target == "can1"  # the click on the can's top
    on_floor = dataclasses.replace(COUNTER, click=(0.3, -1.0, 0.0))
    with pytest.raises(PlanningError, match="floor"):
        resolve_task(on_floor, world, config)
    occupied = dataclasses.replace(COUNTER, place_click=(0.95, 0.04, 0.9))  # beside the teapot
    with pytest.raises(PlanningError, match="not free"):
        resolve_task(occupied, world, config)


def test_a_robot_hand_needs_more_room_past_a_neighbour_than_a_human_hand() -> None:
    """The narrow shelf's bottle moved 8 cm aside of the can's way out: a human hand (the scheduler's
    default 3.5 cm sphere) passes it, the robot's gripper (the pipeline's hand sphere) does not, so the
    demo's scheduler moves the bottle first."""
    doc = load_scene("narrow_shelf").to_dict()
    for obj in doc["objects"]:
        if obj["name"] == "bottle1":
            obj["xy"] = [obj["xy"][0], obj["xy"][1] + 0.08]
    world = SceneWorld(SceneSpec.from_dict(doc))
    planner = ReachModelPlanner()
    for robot in ("dual_ur5e", "humanoid"):
        aux = PipelineConfig(robot=robot).scheduler_config().auxiliary
        assert aux.hand_radius > AuxiliaryConfig().hand_radius
        assert find_blockers(world, planner, "can1", WorldState(), hand="right", config=aux) == ["bottle1"]
    assert find_blockers(world, planner, "can1", WorldState(), hand="right", config=AuxiliaryConfig()) == []


def test_only_the_humanoid_keeps_its_resting_wrists_clear_at_a_stance() -> None:
    """The humanoid's hands start where the human's ready wrists are, the dual arm's at their home pose."""
    clear = {r: PipelineConfig(robot=r).scheduler_config().stance.wrist_clearance for r in ROBOT_BODY_RADIUS}
    assert clear == {"dual_ur5e": 0.0, "humanoid": ROBOT_WRIST_CLEARANCE["humanoid"]}
    assert clear["humanoid"] > 0.0


# ---------------------------------------------------------------------------- grasp depth and dwell


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[rad] rotation angles between (..., 3, 3) rotations."""
    rel = np.einsum("...ji,...jk->...ik", a, b)
    return np.asarray(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)))


def test_gripper_goals_around_the_grasps(dual_arm: TaskOutcome) -> None:
    schedule = dual_arm.schedule
    assert schedule is not None
    cfg = GraspDepthConfig(palm_offset=0.06, grasp_depth=0.03, standoff=0.08, top_standoff=0.0, lift=0.01)
    motion = human_motion_from_schedule(schedule, 60.0)
    windows = grasp_windows(schedule, ["can1"], cfg)
    assert [(w.kind, w.target, w.free) for w in windows] == [
        ("grasp", "can1", True),
        ("release", "can1", True),
    ]
    grasp, release = windows
    shaped = shape_grasps(motion, windows, cfg)
    side, t = grasp.hand, motion.t
    p0, r0 = motion.wrist_position[side], motion.wrist_rotation[side]
    p1, r1 = shaped.wrist_position[side], shaped.wrist_rotation[side]
    key = next(k for k in schedule.events() if k.contact_event == "grasp")
    axis = Rotation.from_quat(key.quaternion).as_matrix()[:, 0]
    assert axis[2] < -0.99  # a counter object is grasped from above: the TCP goes 9 cm further down
    i_g = int(np.argmin(np.abs(t - grasp.time)))
    goal = key.position + 0.09 * axis
    np.testing.assert_allclose(p1[i_g], goal, atol=1e-6)
    # the straight final approach: on the approach axis through the grasp, in the contact orientation
    start, end = grasp.before
    straight = min(max(cfg.straight_min_s, cfg.grasp_straight * (end - start)), 0.6 * (end - start))
    line = (t >= end - straight + 1e-9) & (t <= end)
    assert line.sum() >= 10
    off_axis = np.cross(p1[line] - goal, axis)
    assert np.abs(off_axis).max() < 1e-6
    along = (p1[line] - goal) @ axis
    assert -cfg.standoff - 1e-6 <= along.min() < -0.01 and np.all(np.diff(along) >= -1e-9)
    approach = (t >= start) & (t <= end)  # the line starts at the pre-grasp pose, standoff before the grasp
    assert np.linalg.norm(p1[approach] - (goal - cfg.standoff * axis), axis=1).min() < 1e-3
    assert _angle(r1[line], r0[i_g]).max() < 1e-6
    # a top-down approach comes down from higher up (above the walls of an open drawer), still straight
    high = shape_grasps(motion, windows, dataclasses.replace(cfg, top_standoff=0.2)).wrist_position[side]
    assert np.abs(np.cross(high[line] - goal, axis)).max() < 1e-6
    assert ((high[line] - goal) @ axis).min() < -0.1
    # out of an open container, it comes down from rim_clearance above the rim (not for the release)
    rim = float(goal[2]) + 0.1
    rimmed = grasp_windows(schedule, ["can1"], cfg, rims={"can1": rim})
    assert [w.rim for w in rimmed] == [rim, -np.inf]
    deep = shape_grasps(motion, rimmed, cfg).wrist_position[side]
    assert np.abs(np.cross(deep[line] - goal, axis)).max() < 1e-6
    pre = goal - (rim + cfg.rim_clearance - goal[2]) * axis  # axis: straight down
    assert np.linalg.norm(deep[approach] - pre, axis=1).min() < 1e-3
    np.testing.assert_allclose(deep[t > grasp.after[1]], p1[t > grasp.after[1]], atol=1e-12)
    # the kitchen's rims: the mug in the top drawer gets its walls' top, counter and shelf objects none
    kitchen = load_scene("kitchen")
    drawer = support_surface(kitchen, "drawer_unit1/drawer1")
    rim = pytest.approx(drawer.top_z + drawer.ceiling)
    assert container_rims(kitchen) == {"mug2": rim, "box2": rim}
    assert container_rims(None) == {}
    # the first retreat after the grasp lifts the object straight back along the axis (+ lift)
    a0, a1 = grasp.after
    post = goal - 0.08 * axis + [0.0, 0.0, 0.01]
    lifting = (t >= a0) & (t <= a1)
    reached = np.linalg.norm(p1[lifting] - post, axis=1)
    assert reached.min() < 1e-3
    k = int(np.argmin(reached))
    assert np.abs(np.cross(p1[lifting][: k + 1] - goal, axis)[:, :2]).max() < 0.011  # straight up first
    # carried: the gripper keeps the grasp orientation (grasp and release are both top-down here), while
    # the planned wrist turns more
    carry = (t > grasp.time) & (t < release.time)
    assert _angle(r1[carry], r1[i_g]).max() < _angle(r0[carry], r0[i_g]).max()
    # untouched before the approach and after the withdrawal of the release; smooth everywhere
    before = t < start - 1e-9
    np.testing.assert_array_equal(p1[before], p0[before])
    after = t > release.after[1] + 1e-9
    np.testing.assert_allclose(p1[after], p0[after], atol=1e-12)
    planned_step = np.linalg.norm(np.diff(p0, axis=0), axis=1).max()  # [m] per 1/60 s
    assert np.linalg.norm(np.diff(p1, axis=0), axis=1).max() < 1.5 * planned_step
    assert _angle(r1[1:], r1[:-1]).max() < 0.2
    other = "right" if side == "left" else "left"
    np.testing.assert_array_equal(shaped.wrist_position[other], motion.wrist_position[other])
    # a handle (not a free object): no depth
    handle = shape_grasps(motion, grasp_windows(schedule, [], cfg), cfg)
    np.testing.assert_allclose(handle.wrist_position[side][i_g], key.position, atol=1e-6)
    with pytest.raises(ConfigError, match="grasp_depth"):
        GraspDepthConfig(grasp_depth=-0.01)
    with pytest.raises(ConfigError, match="grasp_straight"):
        GraspDepthConfig(grasp_straight=0.9)


def test_gripper_dwell_holds_still_and_shifts_the_rest() -> None:
    t = np.linspace(0.0, 2.0, 21)
    q = np.column_stack([t, -t])
    events = (
        ContactEvent(1.0, "left", "grasp", "can1"),
        ContactEvent(1.0, "right", "grasp", "can1"),  # same time: one standstill
        ContactEvent(1.5, "left", "release", "can1"),
    )
    traj = JointTrajectory("x", t, q, ("a", "b"), events=events)
    out = add_gripper_dwell(traj, DwellConfig(after_s=0.8, before_release_s=0.3))
    assert out.duration == pytest.approx(2.0 + 0.8 + 1.1)
    assert out.meta["gripper_dwell_s"] == pytest.approx(1.9)
    assert [e.time for e in out.events] == pytest.approx([1.0, 1.0, 1.5 + 0.8 + 0.3])
    for s in np.linspace(1.0, 1.8, 9):  # standing still while the fingers close
        np.testing.assert_allclose(out.sample(s), [1.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(out.sample(2.0), traj.sample(1.2), atol=1e-12)  # the rest, shifted
    np.testing.assert_allclose(out.sample(out.duration), q[-1])
    assert np.all(np.diff(out.t) > 0.0)
    with pytest.raises(ConfigError):
        DwellConfig(after_s=-1.0)


# ---------------------------------------------------------------------------- end to end in MuJoCo


def _check_success(outcome: TaskOutcome) -> None:
    report = outcome.report
    assert outcome.stage == "done", outcome.error
    assert report.success, report.failures
    assert report.placement_error_m is not None and report.placement_error_m < 0.02
    assert report.collisions == 0
    assert [g.kind for g in report.grasps] == ["grasp", "release"]
    final = np.asarray(report.object_final_poses["can1"])
    assert outcome.placement is not None
    assert abs(final[2] - outcome.placement[2]) < 0.01  # standing on the counter, not lying
    entry = outcome.entry()
    assert set(REQUIRED_KEYS) <= set(entry)
    assert entry["task"] == "counter_can" and entry["stage"] == "done"


def test_counter_pick_and_place_succeeds_on_the_dual_arm(dual_arm: TaskOutcome) -> None:
    _check_success(dual_arm)
    report, traj = dual_arm.report, dual_arm.trajectory
    assert report.robot == "dual_ur5e" and report.planner == "reach_model"
    assert report.max_tracking_error_m < 0.05
    assert traj is not None and traj.meta["gripper_dwell_s"] == pytest.approx(2 * 0.8 + 0.3)
    base = traj.q[:, :3]  # base x, y, yaw follow the schedule's root: it moves towards the counter
    assert np.ptp(base[:, 0]) > 0.05
    assert "held" not in traj.meta  # held objects are off by default


def test_a_grasped_object_rides_with_its_hand_as_ik_geometry(dual_arm: TaskOutcome) -> None:
    schedule = dual_arm.schedule
    assert schedule is not None
    pipeline = PipelineConfig()
    config = RetargetConfig(sample_rate=pipeline.sample_rate, grasp=pipeline.grasp, hold_objects=True)
    traj = retarget(schedule, "dual_ur5e", load_scene("kitchen"), config)
    (held,) = traj.meta["held"]  # the can, from the frame its grasp was reached
    grasp = next(e for e in schedule.events() if e.contact_event == "grasp")
    assert (held["hand"], held["object"]) == (grasp.hand, "can1")
    assert held["time_s"] == pytest.approx(grasp.time, abs=0.1)


def test_a_moved_can_is_grasped_where_it_is_and_placed_where_planned(dual_arm: TaskOutcome) -> None:
    """The executed schedule retargeted with the can pushed 3 cm: the hand closes around it there (the
    grasp goal and the reached TCP moved by the push) and releases it where the first plan did."""
    from hsi_planning.scene import moved_object
    from hsi_retarget.robots import RobotModel

    schedule, first = dual_arm.schedule, dual_arm.trajectory
    assert schedule is not None and first is not None
    push = np.array([0.02, -0.025, 0.0])
    spec = moved_object(load_scene("kitchen"), "can1", push)
    config = PipelineConfig(robot="dual_arm", planner="reach_model")
    moved = robot_trajectory(schedule, spec, config, moved={"can1": push})
    (record,) = moved.meta["moved_grasps"]
    assert record["object"] == "can1"
    robot = RobotModel("dual_ur5e")

    def tcp_at(traj: Any, kind: str) -> np.ndarray:
        event = next(e for e in traj.events if e.kind == kind and e.object_name == "can1")
        return robot.frame_pose(traj.sample(event.time), robot.tcp_frames[event.hand])[:3, 3]

    np.testing.assert_allclose(tcp_at(moved, "grasp") - tcp_at(first, "grasp"), push, atol=0.01)
    np.testing.assert_allclose(tcp_at(moved, "release"), tcp_at(first, "release"), atol=0.01)
    with pytest.raises(RetargetError, match="never grasped"):
        robot_trajectory(schedule, spec, config, moved={"mug2": push})


def test_counter_pick_and_place_succeeds_on_the_humanoid(kitchen_cloud: LabelledCloud) -> None:
    config = PipelineConfig(robot="humanoid", planner="reach_model")
    outcome = run_task(
        COUNTER, load_scene("kitchen"), kitchen_cloud, make_demo_planner("reach_model"), config
    )
    _check_success(outcome)
    assert outcome.report.robot == "humanoid"


def test_failures_are_reported_with_their_stage(kitchen_cloud: LabelledCloud) -> None:
    spec, planner = load_scene("kitchen"), make_demo_planner("linear")
    config = PipelineConfig(planner="linear")
    lost = dataclasses.replace(COUNTER, click=None, object_name="unicorn")
    outcome = run_task(lost, spec, kitchen_cloud, planner, config)
    assert outcome.stage == "resolve" and not outcome.report.success
    assert "unicorn" in outcome.report.failures[0] and outcome.report.failures[0].startswith("resolve:")
    entry = outcome.entry()
    assert set(REQUIRED_KEYS) <= set(entry)
    assert entry["success"] is False and entry["max_tracking_error_m"] is None and entry["duration_s"] == 0.0
    with pytest.raises(ConfigError, match="available"):
        PipelineConfig(planner="teleport")
    with pytest.raises(ConfigError, match="unknown robot"):
        PipelineConfig(robot="octopus")


# -------------------------------------------------------------------------------------- node path


class _Probe(Node[Any]):
    def __init__(self, transport: Transport) -> None:
        super().__init__("probe", transport=transport)
        self.reports: list[Any] = []
        self.goals: list[Any] = []
        self.states: list[Any] = []
        self.create_subscription("/hsi/report", _REPORT, self.reports.append, QoS(depth=100))
        self.create_subscription("/hsi/goal", _GOAL, self.goals.append, QoS(depth=100))
        self.create_subscription(
            "/robot/joint_states", "sensor_msgs/msg/JointState", self.states.append, QoS(depth=5000)
        )


@pytest.fixture()
def bus() -> Iterator[tuple[Transport, Executor]]:
    transport = make_transport("inproc")
    executor = Executor(transport, use_sim_time=True)
    yield transport, executor
    executor.shutdown()
    transport.close()


def _report(task: str, stage: str, success: bool, obj: str = "", details: str = "") -> Any:
    return msg_class(_REPORT)(
        header=make_header(0.0, "world"),
        task_id=task,
        stage=stage,
        success=success,
        message="",
        object_name=obj,
        robot="",
        planner="reach_model",
        placement_error_m=float("nan"),
        duration_s=0.0,
        collisions=0,
        max_tracking_error_m=float("nan"),
        details_json=details,
    )


def test_sim_check_node_executes_the_retargeted_schedule(
    bus: tuple[Transport, Executor], dual_arm: TaskOutcome
) -> None:
    """The scheduler's side is played by the test (schedule, its segments, the report, the goal); the real
    retarget_node makes the joint trajectory and sim_check_node executes it."""
    transport, executor = bus
    params = {"scene": "kitchen", "require_schedule": True, "deepen_grasps": True}
    retarget = RetargetNode(transport=transport, parameters=params)
    sim = SimCheckNode(transport=transport, parameters={"scene": "kitchen", "joint_state_rate": 10.0})
    probe = _Probe(transport)
    for node in (retarget, sim, probe):
        executor.add_node(node)
    assert dual_arm.schedule is not None
    schedule = dual_arm.schedule  # the node makes the gripper goals, as the pipeline does
    transport.publisher("/hsi/goal", _GOAL).publish(goal_msg(COUNTER, 0.0, "world"))
    transport.publisher("/hsi/report", _REPORT).publish(_report("counter_can", "schedule", True, "can1"))
    transport.publisher("/hsi/schedule", "hsi/msg/Schedule").publish(schedule_msg(schedule, 1.0, "world"))
    wrist = transport.publisher("/hsi/wrist_trajectory", "hsi/msg/WristTrajectory")
    for seg in schedule.segments:
        wrist.publish(trajectory_msg(seg.trajectory, "counter_can", 1.0 + seg.start_time, "world"))
    executor.spin(5.0, until=lambda: any(str(r.stage) == "sim" for r in probe.reports))
    sim_reports = [r for r in probe.reports if str(r.stage) == "sim"]
    assert len(sim_reports) == 1 and sim.executed == 1
    report = sim_reports[0]
    assert report.task_id == "counter_can" and report.object_name == "can1" and report.robot == "dual_ur5e"
    assert bool(report.success), report.message
    assert report.placement_error_m < 0.02 and report.collisions == 0
    assert '"grasps"' in str(report.details_json)
    assert len(probe.states) > 50 and list(probe.states[0].name) == list(sim.world.robot.joint_names)
    stamps = [s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in probe.states]
    assert np.all(np.diff(stamps) > 0.0)


def test_click_player_sends_one_goal_per_finished_task(bus: tuple[Transport, Executor]) -> None:
    transport, executor = bus
    player = ClickPlayerNode(transport=transport, parameters={"variant": "kitchen", "start_delay_s": 0.1})
    probe = _Probe(transport)
    for node in (player, probe):
        executor.add_node(node)
    reports = transport.publisher("/hsi/report", _REPORT)
    executor.spin(0.5)
    assert [str(g.task_id) for g in probe.goals] == ["counter_can"]  # narrow_shelf_can: another scene
    first = probe.goals[0]
    assert first.object_name == "" and first.pick_point.x == pytest.approx(0.9) and first.has_place
    reports.publish(_report("counter_can", "retarget", True, details='{"events": []}'))  # not final
    executor.spin(0.5)
    assert len(probe.goals) == 1
    reports.publish(_report("counter_can", "sim", True))
    executor.spin(0.5)
    assert [str(g.task_id) for g in probe.goals] == ["counter_can", "cabinet_bottle"]
    assert probe.goals[1].object_name == "bottle2" and probe.goals[1].place_pose.position.z == 1.25
    reports.publish(_report("cabinet_bottle", "schedule", False))  # refused: next task at once
    executor.spin(0.5)
    reports.publish(_report("drawer_mug", "retarget", False, details="{}"))  # no trajectory was sent
    executor.spin(0.5)
    assert player.is_done() and player.finished == ["counter_can", "cabinet_bottle", "drawer_mug"]
    assert player.reports["counter_can"]["sim"]["success"] is True
    with pytest.raises(ConfigError, match="start_delay_s"):
        ClickPlayerConfig(start_delay_s=-1.0)


def test_click_player_times_out_a_silent_task(bus: tuple[Transport, Executor]) -> None:
    transport, executor = bus
    params = {"variant": "test", "start_delay_s": 0.1, "task_timeout_s": 2.0}
    player = ClickPlayerNode(transport=transport, parameters=params)
    executor.add_node(player)
    executor.spin(5.0, until=player.is_done)
    assert player.is_done() and player.finished == ["counter_can"]


def test_launch_file_and_parameter_files(repo_root: Path) -> None:
    from hsi_nodes.launch import parse_launch_file

    description = parse_launch_file(
        repo_root / "launch" / "sim_pick_place.launch.yaml",
        {"planner": "reach_model", "tasks": "[counter_can]"},
    )
    execs = [n.executable for n in description.nodes]
    assert execs == ["scene_cloud_node", "scheduler_node", "retarget_node", "sim_check_node", "click_player"]
    for spec in description.nodes:  # every node's parameters build its config
        cls = load_executable(spec.executable)
        config = from_mapping(cls.config_class, spec.parameters)
        if spec.executable == "scheduler_node":
            assert config.planner == "reach_model"
            assert config.scheduler["body"]["body_radius"] == pytest.approx(0.4)
        if spec.executable == "click_player":
            assert config.tasks == ("counter_can",)
    sim = from_mapping(
        SimCheckNodeConfig,
        Node.load_parameter_file(repo_root / "config" / "sim_check_node.yaml", "sim_check_node"),
    )
    assert sim == SimCheckNodeConfig()
    player = from_mapping(
        ClickPlayerConfig,
        Node.load_parameter_file(repo_root / "config" / "click_player.yaml", "click_player"),
    )
    assert player == ClickPlayerConfig()
    with pytest.raises(ConfigError, match="robot"):
        SimCheckNodeConfig(robot="octopus")


def test_counter_task_succeeds_through_the_launch_file(dual_arm: TaskOutcome, tmp_path: Path) -> None:
    """The node path (scheduler_node publishes its segments; retarget_node deepens the grasps;
    sim_check_node dwells) ends like the function path."""
    from hsi_nodes.demo.launch_path import run_launch_tasks
    from hsi_nodes.demo.runner import RunnerConfig

    config = RunnerConfig(pipeline=PipelineConfig(robot="dual_arm", planner="reach_model"), video=None)
    run = run_launch_tasks(demo_tasks("test", ("counter_can",)), tmp_path, config, echo=lambda _: None)
    assert len(run.outcomes) == 1
    outcome = run.outcomes[0]
    assert outcome.stage == "done", outcome.report.failures
    report = outcome.report
    assert report.success and report.object == "can1" and report.collisions == 0
    assert report.placement_error_m is not None and report.placement_error_m < 0.02
    assert dual_arm.report.success
    assert report.max_tracking_error_m == pytest.approx(dual_arm.report.max_tracking_error_m, abs=0.005)
    assert outcome.trajectory is not None and dual_arm.trajectory is not None
    dwell = dual_arm.trajectory.meta["gripper_dwell_s"]  # sim_check_node adds it after the topic
    assert outcome.trajectory.duration + dwell == pytest.approx(dual_arm.trajectory.duration, abs=0.1)
    assert (tmp_path / "plots" / "counter_can.png").exists()


def test_the_diagnosis_names_a_grasp_the_ik_ended_short_of() -> None:
    from hsi_nodes.demo.pipeline import failed_report
    from hsi_retarget.joint_trajectory import JointTrajectory

    task = DemoTask("x", "kitchen", (0.0, 0.0, 0.9), object_name="bottle2")
    meta = {
        "carry_corrections": [
            {"hand": "left", "object": "bottle2", "time_s": 7.2, "position_m": 0.062, "angle_deg": 24.0},
            {"hand": "right", "object": "can1", "time_s": 9.0, "position_m": 0.004, "angle_deg": 2.0},
        ]
    }
    trajectory = JointTrajectory("dual_ur5e", np.zeros(1), np.zeros((1, 2)), ("a", "b"), meta=meta)
    outcome = TaskOutcome(task, failed_report(task, "bottle2", PipelineConfig(), "x"), trajectory=trajectory)
    (line,) = outcome.diagnosis()  # a 4 mm correction is within the IK tolerance: not reported
    assert "left hand closed 0.062 m and 24 deg off its planned grasp of bottle2 at 7.2 s" in line
