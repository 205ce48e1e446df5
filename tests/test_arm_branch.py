"""Arm configurations for missed grasps: the static search finds one that reaches into a shelf compartment
where the nominal arm pose gets stuck, a humanoid's search from its tracked stance keeps its footholds, the
IK's arm task pulls to it, the task's weight profile, the missed-contact list, the second tracking resumed
where the arm task starts, its escalation while a grasp still misses, and config validation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hsi_planning.errors import ConfigError
from hsi_planning.scene import LayoutConfig, generate_layouts
from hsi_planning.scene_paths import load_scene
from hsi_retarget import retrack
from hsi_retarget.arm_branch import (
    ArmBranch,
    ArmBranchConfig,
    Missed,
    _profile,
    find_branches,
    missed_contacts,
    scaled,
)
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.ik import IKSolver, IKTargets
from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.mapping import RobotGoals, nominal_configuration
from hsi_retarget.retarget import RetargetConfig
from hsi_retarget.retrack import retrack_missed
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance
from hsi_retarget.tracking import track

# A grasp of can1 deep in a compartment of the narrow shelf (benchmark case narrow_shelf_can/reshape/3 at
# 8.6 s of its schedule): TCP goals [m], base pose and torso lift [m] as the mapping gave them.
_LEFT = np.array([[0.0, 0.0, 1.0, 0.8759], [0.0, 1.0, 0.0, 0.2502], [-1.0, 0.0, 0.0, 0.9725], [0, 0, 0, 1]])
_RIGHT = np.array(
    [[0.0, 0.1261, 0.992, 0.372], [0.0, 0.992, -0.1261, -0.1832], [-1.0, 0.0, 0.0, 1.02], [0, 0, 0, 1]]
)
_ROOT = np.array([[0.992, 0.1261, 0.0, 0.1493], [-0.1261, 0.992, 0.0, 0.0467], [0, 0, 1, 0], [0, 0, 0, 1]])
_LIFT = 0.2382


@pytest.fixture(scope="module")
def robot() -> RobotModel:
    return RobotModel("dual_ur5e")


def _goals(n: int = 5) -> RobotGoals:
    one = np.ones(n, dtype=bool)
    return RobotGoals(
        t=np.linspace(0.0, 2.0, n),
        tcp={"left": np.repeat(_LEFT[None], n, 0), "right": np.repeat(_RIGHT[None], n, 0)},
        active={"left": one, "right": one},
        reachable={"left": one, "right": one},
        reach_excess={"left": np.zeros(n), "right": np.zeros(n)},
        root=np.repeat(_ROOT[None], n, 0),
        lift=np.full(n, _LIFT),
        shoulder={"left": np.zeros((n, 3)), "right": np.zeros((n, 3))},
        scale=1.0,
        contact={"left": np.ones(n)},
    )


def test_a_seeded_configuration_reaches_into_the_shelf_where_the_nominal_pose_sticks(
    robot: RobotModel,
) -> None:
    config = LayoutConfig(reshape=True, target="can1")
    spec = generate_layouts(load_scene("narrow_shelf"), 4, 100007, config)[3]
    solver = IKSolver(robot, scene=SceneDistance.from_spec(spec, exclude=("can1", "bottle1")))
    targets = IKTargets(tcp={"left": _LEFT, "right": _RIGHT}, root=_ROOT, lift=_LIFT, contact={"left": 1.0})
    start = nominal_configuration(robot, _ROOT, _LIFT)
    stuck = solver.solve(start, targets, 200)
    assert stuck.position_error["left"] > 0.02  # the arm from its nominal pose stops between the boards
    goals = _goals()
    search = ArmBranchConfig(seeds=16)
    missed = [Missed("left", 4, 2.0, stuck.position_error["left"], "can1")]
    branches = find_branches(goals, robot, solver, missed, lambda i: targets, config=search)
    assert len(branches) == 1
    b = branches[0]
    assert b.side == "left" and b.error <= search.tolerance
    reached = solver.solve(b.q, targets, 1)  # one more step from it: still there, clear of the shelf
    assert reached.position_error["left"] <= search.tolerance
    assert solver.clearance(b.q) >= search.clearance
    assert robot.within_limits(b.q)
    arm = robot.arm_q_indices("left")
    turnable = (b.q[arm] - 2 * np.pi >= robot.q_lower[arm]) | (b.q[arm] + 2 * np.pi <= robot.q_upper[arm])
    assert np.all(np.abs(b.q[arm] - start[arm])[turnable] <= np.pi + 1e-9)  # no needless whole turns
    again = find_branches(goals, robot, solver, missed, lambda i: targets, config=search)
    np.testing.assert_array_equal(again[0].q, b.q)  # seeded: the same search, the same answer
    np.testing.assert_allclose(b.weight, search.weight * _profile(goals.t, 2.0, search))


def test_a_floating_base_searches_from_the_tracked_stance_on_its_footholds() -> None:
    """The humanoid's solves start from the configuration ``start_at`` gives (crouched here, as the first
    tracking had it) with the arm at its nominal pose, and keep the soles where the targets put them."""
    human = RobotModel("humanoid")
    solver = IKSolver(human)
    start = np.array(human.q_home)
    start[2] -= 0.05  # the first tracking's pelvis, 5 cm lower than the nominal one
    feet = human.fk(start, ("left_sole", "right_sole"))
    tcp = human.fk(start, (human.tcp_frames["left"],))[human.tcp_frames["left"]].copy()
    tcp[:3, 3] += [0.15, 0.05, 0.1]
    pelvis = np.eye(4)
    pelvis[:3, 3] = human.q_home[:3]
    n = 5
    one = np.ones(n, dtype=bool)
    goals = RobotGoals(
        t=np.linspace(0.0, 2.0, n),
        tcp={"left": np.repeat(tcp[None], n, 0)},
        active={"left": one},
        reachable={"left": one},
        reach_excess={"left": np.zeros(n)},
        root=np.repeat(pelvis[None], n, 0),
        lift=np.full(n, np.nan),
        shoulder={"left": np.zeros((n, 3))},
        scale=1.0,
        contact={"left": np.ones(n)},
    )
    soles = {"left": feet["left_sole"], "right": feet["right_sole"]}
    targets = IKTargets(tcp={"left": tcp}, root=pelvis, feet=soles, contact={"left": 1.0})
    asked: list[int] = []

    def start_at(i: int) -> np.ndarray:
        asked.append(i)
        return start

    missed = [Missed("left", 4, 2.0, 0.1, "mug1")]
    config = ArmBranchConfig(seeds=2)
    branches = find_branches(
        goals, human, solver, missed, lambda i: targets, config=config, start_at=start_at
    )
    assert asked == [4] and len(branches) == 1 and branches[0].error <= config.tolerance
    q = branches[0].q
    reached = human.fk(q, ("left_sole", "right_sole"))
    for side in ("left", "right"):
        np.testing.assert_allclose(reached[f"{side}_sole"], soles[side], atol=2e-3)
    assert human.within_limits(q)


def test_no_branch_for_a_goal_out_of_reach(robot: RobotModel) -> None:
    far = _LEFT.copy()
    far[:3, 3] = [2.5, 0.25, 1.0]
    targets = IKTargets(tcp={"left": far}, root=_ROOT, lift=_LIFT, contact={"left": 1.0})
    solver = IKSolver(robot)
    missed = [Missed("left", 4, 2.0, 1.5, "can1")]
    config = ArmBranchConfig(seeds=2, iterations=60)
    assert find_branches(_goals(), robot, solver, missed, lambda i: targets, config=config) == []


def test_a_static_solve_stops_once_its_error_stalls(robot: RobotModel) -> None:
    """Out of reach the error stops falling long before the step limit: the stall rule ends the solve
    there; a reachable goal is still reached."""
    far = _LEFT.copy()
    far[:3, 3] = [2.5, 0.25, 1.0]
    solver = IKSolver(robot)
    start = nominal_configuration(robot, _ROOT, _LIFT)
    stuck = IKTargets(tcp={"left": far}, root=_ROOT, lift=_LIFT, contact={"left": 1.0})
    full = solver.solve(start, stuck, 200)
    stalled = solver.solve(start, stuck, 200, stall=(20, 1e-3))
    assert full.iterations == 200 and stalled.iterations < 100
    assert stalled.position_error["left"] < full.position_error["left"] + 1e-3
    near = _RIGHT.copy()
    near[:3, 3] = [0.45, -0.3, 0.95]
    reach = IKTargets(tcp={"right": near}, root=_ROOT, lift=_LIFT, contact={"right": 1.0})
    assert solver.solve(start, reach, 200, stall=(20, 1e-3)).position_error["right"] < 1e-3
    # giving up once the error, falling at its recent rate, cannot get within 1 cm by the step limit
    hopeless = solver.solve(start, stuck, 200, stall=(20, 1e-4), give_up=0.01)
    assert hopeless.iterations < solver.solve(start, stuck, 200, stall=(20, 1e-4)).iterations
    assert hopeless.position_error["left"] > 0.1  # far from within 1 cm
    assert solver.solve(start, reach, 200, stall=(20, 1e-3), give_up=0.01).position_error["right"] < 1e-3
    with pytest.raises(ConfigError, match="stall_steps"):
        ArmBranchConfig(stall_steps=0)


def test_the_arm_task_pulls_the_arm_to_its_configuration(robot: RobotModel) -> None:
    solver = IKSolver(robot)
    goal_q = np.array(robot.q_home)
    arm = robot.arm_q_indices("right")
    goal_q[arm] += np.array([0.3, -0.2, 0.25, -0.3, 0.2, 0.4])
    root = np.eye(4)
    free = solver.solve(robot.q_home, IKTargets(root=root, lift=0.225), 50)
    pulled = solver.solve(robot.q_home, IKTargets(root=root, lift=0.225, arm={"right": (goal_q, 1.0)}), 100)
    assert np.abs(free.q[arm] - robot.q_home[arm]).max() < 1e-3  # the posture holds it at home
    np.testing.assert_allclose(pulled.q[arm], goal_q[arm], atol=1e-3)
    left = robot.arm_q_indices("left")
    np.testing.assert_allclose(pulled.q[left], robot.q_home[left], atol=1e-3)


def test_a_second_tracking_resumed_where_the_arm_task_starts_is_the_full_one(robot: RobotModel) -> None:
    """The frames before the arm task weighs in have the first pass's targets: resumed from the first
    pass's trace there, the second pass is bitwise the full second pass (carry re-aimed on the way)."""
    n = 90
    goals = _goals(n)
    t = goals.t
    right = np.repeat(np.eye(4)[None], n, 0)
    right[:, :3, :3] = _RIGHT[:3, :3]
    right[:, :3, 3] = np.column_stack([0.45 + 0.1 * np.sin(t), -0.25 + 0.1 * t, 1.0 + 0.05 * np.cos(2 * t)])
    left = np.repeat(_LEFT[None], n, 0)
    left[:, 0, 3] = 0.55
    goals = dataclasses.replace(goals, tcp={"left": left, "right": right}, contact={})
    events = (ContactEvent(0.5, "right", "grasp", "box1"), ContactEvent(1.5, "right", "release", "box1"))
    solver, cfg = IKSolver(robot), RetargetConfig()
    first = track(goals, robot, solver, cfg, events=events, trace=True)
    trace = first[3]["trace"]
    goal_q = np.array(first[0][60])
    goal_q[robot.arm_q_indices("left")] += 0.2
    weight = np.where(np.arange(n) >= 50, 0.05, 0.0)
    arm = [ArmBranch("left", float(t[70]), goal_q, weight, 0.0)]
    full = track(goals, robot, solver, cfg, events=events, arm=arm)
    resumed = track(goals, robot, solver, cfg, events=events, arm=arm, resume=(50, trace))
    np.testing.assert_array_equal(resumed[0], full[0])
    assert not np.array_equal(full[0][50:], first[0][50:])  # the arm task changed the frames from 50
    np.testing.assert_array_equal(full[0][:50], first[0][:50])
    for s in ("left", "right"):
        np.testing.assert_array_equal(resumed[1][s], full[1][s])
    for key in ("qp_fallbacks", "min_collision_slack_m", "carry_corrections"):
        assert resumed[3][key] == full[3][key]
    np.testing.assert_array_equal(resumed[3]["goals"].tcp["right"], full[3]["goals"].tcp["right"])
    assert full[3]["carry_corrections"]  # the carry was re-aimed before frame 50: the resume takes that
    # stopped after frame 69 and resumed there (the staged search's tries): again the full pass
    part = track(goals, robot, solver, cfg, events=events, arm=arm, resume=(50, trace), trace=True, stop=70)
    assert np.isnan(part[1]["right"][70:]).all() and not part[0][70:].any()
    np.testing.assert_array_equal(part[0][:70], full[0][:70])
    ended = track(goals, robot, solver, cfg, events=events, arm=arm, resume=(70, part[3]["trace"]))
    np.testing.assert_array_equal(ended[0], full[0])
    for key in ("qp_fallbacks", "min_collision_slack_m", "carry_corrections"):
        assert ended[3][key] == full[3][key]


def test_re_tracking_escalates_only_while_a_grasp_still_misses(robot: RobotModel) -> None:
    """The left hand's approach into the shelf compartment misses its grasp by ~3 cm; the re-tracking
    reaches within ~1 cm. With a 5 mm trigger that is still a miss: each escalation factor is tracked in
    turn and the least total miss kept; with a 1 cm trigger the first re-tracking ends the search."""
    spec = generate_layouts(load_scene("narrow_shelf"), 4, 100007, LayoutConfig(reshape=True, target="can1"))[
        3
    ]
    n = 150
    t = np.linspace(0.0, 2.5, n)
    u = np.clip(t / 2.0, 0.0, 1.0)
    left = np.repeat(_LEFT[None], n, 0)
    left[:, 0, 3] = 0.45 + (_LEFT[0, 3] - 0.45) * u * u * (3.0 - 2.0 * u)  # in from in front of the shelf
    goals = _goals(n)
    goals = dataclasses.replace(
        goals,
        t=t,
        tcp={"left": left, "right": goals.tcp["right"]},
        contact={"left": np.clip(4 * t - 6, 0, 1)},
    )
    events = (ContactEvent(2.0, "left", "grasp", "can1"),)
    windows = [GraspWindow("left", "grasp", "can1", True, 2.0, (1.5, 2.0), (2.0, 2.5))]
    reports = {}
    for trigger, escalation in ((0.005, ()), (0.005, (4.0, 16.0)), (0.01, (4.0, 16.0))):
        solver = IKSolver(robot, scene=SceneDistance.from_spec(spec, exclude=("can1", "bottle1")))
        cfg = RetargetConfig(arm_branch=ArmBranchConfig(trigger=trigger, escalation=escalation))
        qs, pos, _, diag = track(goals, robot, solver, cfg, events=events, trace=True)
        assert pos["left"][119] > 0.02  # the first pass stops short of the can
        _, out = retrack_missed(
            goals, robot, solver, cfg, (qs, pos, diag), part=None, events=events, windows=windows
        )
        reports[trigger, escalation] = out["arm_branches"]
    plain, escalated, reached = reports.values()
    assert plain["factors_tried"] == [1.0] and plain["kept"]
    assert escalated["factors_tried"] == [1.0, 4.0, 16.0]  # 1 cm off each time: never within 5 mm
    assert escalated["contact_error_after_m"] <= plain["contact_error_after_m"] + 1e-12
    assert escalated["factor"] in escalated["factors_tried"]
    assert reached["factors_tried"] == [1.0] and reached["contact_error_after_m"] <= 0.01


def test_a_missed_grasp_is_searched_for_the_grasp_not_for_the_carry_re_aimed_from_the_miss(
    robot: RobotModel,
) -> None:
    """The first pass re-aims the carry from where the hand closed, 3 cm short of the can, from the grasp
    frame on; the search at the missed grasp solves for the can's grasp pose (the goals as that frame was
    tracked), not for the pose the hand already had."""
    spec = generate_layouts(load_scene("narrow_shelf"), 4, 100007, LayoutConfig(reshape=True, target="can1"))[
        3
    ]
    n = 150
    t = np.linspace(0.0, 2.5, n)
    u = np.clip(t / 2.0, 0.0, 1.0)
    left = np.repeat(_LEFT[None], n, 0)
    left[:, 0, 3] = 0.45 + (_LEFT[0, 3] - 0.45) * u * u * (3.0 - 2.0 * u)
    goals = dataclasses.replace(
        _goals(n),
        t=t,
        tcp={"left": left, "right": _goals(n).tcp["right"]},
        contact={"left": np.clip(4 * t - 6, 0, 1)},
    )
    # the grasp nearest the frame the carry is re-aimed from (its first at or after the grasp)
    events = (ContactEvent(2.01, "left", "grasp", "can1"), ContactEvent(2.4, "left", "release", "can1"))
    windows = [GraspWindow("left", "grasp", "can1", True, 2.01, (1.5, 2.01), (2.01, 2.5))]
    solver = IKSolver(robot, scene=SceneDistance.from_spec(spec, exclude=("can1", "bottle1")))
    cfg = RetargetConfig(arm_branch=ArmBranchConfig(seeds=16, escalation=(), trigger=0.01))
    qs, pos, _, diag = track(goals, robot, solver, cfg, events=events, trace=True)
    g = int(np.searchsorted(t, 2.01 - 1e-9))
    assert g == int(np.argmin(np.abs(t - 2.01)))
    assert pos["left"][g] > 0.02  # the first pass stops short of the can ...
    aimed = diag["goals"].tcp["left"]
    assert np.linalg.norm(aimed[g, :3, 3] - _LEFT[:3, 3]) > 0.02  # ... and carries from there
    trace = diag["trace"]
    np.testing.assert_array_equal(retrack.tracked_goals(goals, trace, g).tcp["left"][g], left[g])
    np.testing.assert_array_equal(retrack.tracked_goals(goals, trace, g + 1).tcp["left"][g + 1], aimed[g + 1])
    found: list[ArmBranch] = []
    real = retrack.find_branches

    def spy(*args: object, **kwargs: object) -> list[ArmBranch]:
        found.extend(real(*args, **kwargs))  # type: ignore[arg-type]
        return found

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(retrack, "find_branches", spy)
        retrack_missed(goals, robot, solver, cfg, (qs, pos, diag), part=None, events=events, windows=windows)
    assert len(found) == 1
    tcp = robot.frame_pose(found[0].q, robot.tcp_frames["left"])
    assert np.linalg.norm(tcp[:3, 3] - _LEFT[:3, 3]) <= cfg.arm_branch.tolerance  # the can's grasp pose


def test_tries_that_miss_more_are_not_tracked_to_the_end(
    robot: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An arm task pulling the right arm away from its grasp: each try (weight x1, x4) misses the grasp by
    more than the first pass, so the search stops at the grasp frame, tracks nothing further and keeps the
    first pass (its configurations, the very array)."""
    n = 90
    goals = _goals(n)
    t = goals.t
    right = np.repeat(_RIGHT[None], n, 0)
    right[:, 0, 3] = 0.45 + 0.05 * t
    goals = dataclasses.replace(goals, tcp={"left": goals.tcp["left"], "right": right}, contact={})
    events = (ContactEvent(float(t[45]), "right", "grasp", "box1"),)
    solver, cfg = IKSolver(robot), RetargetConfig()
    qs, pos, _, diag = track(goals, robot, solver, cfg, events=events, trace=True)
    away = np.array(qs[45])
    away[robot.arm_q_indices("right")] += np.array([0.8, -0.6, 0.7, 0.5, -0.6, 0.4])
    branch = ArmBranch("right", float(t[45]), away, np.where(np.arange(n) >= 20, 5.0, 0.0), 0.0)
    missed = [Missed("right", 45, float(t[45]), 0.05, "box1")]  # as if missed by 5 cm
    contacts = [Missed("right", 45, float(t[45]), float(pos["right"][45]), "box1")]
    report: dict[str, object] = {"contact_error_before_m": contacts[0].error, "kept": False}
    stops: list[object] = []

    def counting(*args: object, **kwargs: object) -> object:
        stops.append(kwargs.get("stop"))
        return track(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(retrack, "track", counting)
    out, _ = retrack._retrack(
        goals,
        robot,
        solver,
        cfg,
        (qs, diag, diag["trace"]),
        branches=[branch],
        branch_cfg=ArmBranchConfig(),
        missed=missed,
        contacts=contacts,
        report=report,
        part=None,
        events=events,
        objects=None,
    )
    assert out is qs and report["kept"] is False and report["contact_error_after_m"] is None
    assert report["factors_tried"] == [1.0, 4.0] and stops == [46, 46]  # both tries end at the grasp


def test_scaled_branches_are_copies_with_scaled_weights() -> None:
    b = ArmBranch("left", 1.0, np.zeros(3), np.array([0.0, 0.5, 1.0]), 0.002)
    (s,) = scaled([b], 4.0)
    np.testing.assert_array_equal(s.weight, [0.0, 2.0, 4.0])
    s.q[0] = 1.0
    assert b.q[0] == 0.0 and b.weight[2] == 1.0  # the original is untouched


def test_weight_profile_eases_in_before_and_out_after_the_contact() -> None:
    cfg = ArmBranchConfig(lead_s=1.5, settle_s=0.5, hold_s=0.3, release_s=0.5)
    t = np.linspace(0.0, 10.0, 1001)
    w = _profile(t, 5.0, cfg)
    assert np.all(w[t <= 3.0] == 0.0) and np.all(w[t >= 5.8] == 0.0)
    assert np.all(w[(t >= 4.5) & (t <= 5.3)] == 1.0)
    rising, falling = (t >= 3.0) & (t <= 4.5), (t >= 5.3) & (t <= 5.8)
    assert np.all(np.diff(w[rising]) >= 0.0) and np.all(np.diff(w[falling]) <= 0.0)
    assert np.all((w >= 0.0) & (w <= 1.0))


def test_missed_contacts_are_the_free_objects_beyond_the_tolerance() -> None:
    t = np.arange(0.0, 3.0, 0.5)
    windows = [
        GraspWindow("left", "grasp", "can1", True, 1.0, (0.5, 1.0), (1.0, 1.5)),
        GraspWindow("right", "grasp", "cabinet1/door1", False, 1.0, (0.5, 1.0), (1.0, 1.5)),
        GraspWindow("left", "release", "can1", True, 2.1, (1.5, 2.1), (2.1, 2.5)),
    ]
    err = {"left": np.array([0, 0, 0.05, 0, 0.005, 0]), "right": np.full(6, 0.3)}
    missed = missed_contacts(t, windows, err, 0.01)
    assert [(m.side, m.index, m.target) for m in missed] == [("left", 2, "can1")]
    assert missed[0].error == pytest.approx(0.05)
    err["left"][4] = np.nan  # inactive: not missed
    assert len(missed_contacts(t, windows, err, 0.001)) == 1


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("seeds", -1),
        ("iterations", 0),
        ("weight", -0.1),
        ("lead_s", float("nan")),
        ("tolerance", 0.0),
        ("trigger", -0.01),
        ("escalation", (0.0,)),
        ("escalation", (float("nan"),)),
    ],
)
def test_config_rejects_bad_values(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match="ArmBranchConfig"):
        ArmBranchConfig(**{field: value})
