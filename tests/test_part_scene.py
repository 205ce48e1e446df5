"""The opened part as the robot left it: the opening a holder's TCP reached, the part posed there, the IK
tracking posing it once as its hand got there, and a resumed second pass taking that pose from the trace."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from hsi_planning.errors import RetargetError
from hsi_planning.scene_paths import load_scene
from hsi_planning.scheduler.world import SceneWorld
from hsi_retarget.arm_branch import ArmBranch
from hsi_retarget.ik import IKSolver
from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.mapping import RobotGoals
from hsi_retarget.part_scene import PartPhase, follow_part, opened_part
from hsi_retarget.retarget import RetargetConfig
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance
from hsi_retarget.tracking import track

DRAWER = "drawer_unit1/drawer1"
DOOR = "cabinet1/door1"
#: TCP orientation pulling the drawer: approach +x into the unit, fingers closing along z
SIDE = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _phase(part: str) -> PartPhase:
    """The phase of a schedule whose right hand reaches ``part``'s handle by 1 s, opens it by 2 s, holds
    it to 2.5 s while the left hand grasps mug1 at 3 s, closes it from 4 s and lets go at 4.8 s."""

    def key(t: float, hand: str, action: str, obj: str = "", event: str = "") -> SimpleNamespace:
        return SimpleNamespace(time=t, hand=hand, action=action, object_name=obj, contact_event=event)

    keys = [key(0.0, "right", "idle"), key(1.0, "right", "reach", part), key(1.5, "right", "open", part)]
    keys += [key(2.0, "right", "open", part), key(2.5, "right", "hold", part)]
    keys += [key(3.0, "left", "grasp", "mug1")]
    keys += [key(4.0, "right", "close", part), key(4.8, "right", "release", part, "release")]
    keys += [key(5.0, "right", "idle")]
    schedule = SimpleNamespace(info={"part": part, "door_hand": "right"}, keyframes=keys)
    phase = opened_part(schedule, load_scene("kitchen"), exclude=("mug1",))  # type: ignore[arg-type]
    assert phase is not None
    return phase


@pytest.mark.parametrize("part", [DRAWER, DOOR])
def test_the_reached_opening_is_the_one_that_carries_the_grasp_to_the_tcp(part: str) -> None:
    phase = _phase(part)
    world = SceneWorld(load_scene("kitchen"))
    closed = world.handle_at(part, 0.0)
    assert phase.t_grasp == 1.0 and phase.fraction == 1.0 and phase.t_release == 4.8
    assert phase.reached(closed, world.handle_at(part, 0.6)) == pytest.approx(0.6, abs=0.002)
    assert phase.reached(closed, closed) == pytest.approx(0.0, abs=1e-9)
    assert phase.reached(closed, world.handle_at(part, 1.0)) == pytest.approx(1.0, abs=1e-9)
    off = world.handle_at(part, 0.3) + np.array([0.0, 0.0, 0.05])  # 5 cm above the arc: nearest point
    assert phase.reached(closed, off) == pytest.approx(0.3, abs=0.01)
    assert phase.reached(closed, np.array([np.nan, 0.0, 0.0])) == 1.0  # unknown: as it stands


def test_the_part_posed_where_it_was_taken_is_the_obstacle_there() -> None:
    phase = _phase(DRAWER)
    world = SceneWorld(load_scene("kitchen"))
    short = phase.posed(0.6)
    assert short.fraction == 0.6 and short.scene is not phase.scene and short.t_open == phase.t_open
    assert phase.posed(1.0) is phase and phase.posed(1.7).fraction == 1.0  # clipped to fully open
    handle = world.handle_at(DRAWER, 0.6)[None]
    assert abs(float(short.scene.query(handle)[0][0])) < 0.01  # the handle is where it was left
    assert float(phase.scene.query(handle)[0][0]) > 0.03  # fully opened, the front stands beyond it


def _pull(robot: RobotModel, fraction: float, n: int = 120) -> RobotGoals:
    """Goals of a right hand that takes the drawer's handle by 1 s and pulls it to ``fraction`` of its
    travel by 2 s, then holds it (frames every 1/24 s), the base in front of the drawer unit."""
    world = SceneWorld(load_scene("kitchen"))
    t = np.arange(n) / 24.0
    f = np.clip(t - 1.0, 0.0, 1.0) * fraction
    right = np.repeat(np.eye(4)[None], n, 0)
    right[:, :3, :3] = SIDE
    right[:, :3, 3] = [world.handle_at(DRAWER, float(v)) for v in f]
    right[t < 1.0, :3, 3] += np.outer(1.0 - t[t < 1.0], [-0.12, 0.0, 0.0])  # the approach
    root = np.eye(4)
    root[:3, 3] = (0.0, -0.75, 0.0)
    one = np.ones(n, dtype=bool)
    return RobotGoals(
        t=t,
        tcp={"right": right},
        active={"right": one},
        reachable={"right": one},
        reach_excess={"right": np.zeros(n)},
        root=np.repeat(root[None], n, 0),
        lift=np.zeros(n),
        shoulder={"right": np.zeros((n, 3))},
        scale=1.0,
        contact={},
    )


def _pulled_drawer() -> tuple[RobotModel, PartPhase, RobotGoals, IKSolver]:
    """The dual arm, the drawer's phase (held from 1 s to 4.8 s), goals pulling it to 0.6 of its travel
    between 1 s and 2 s (:func:`_pull`) and a solver of the kitchen without the drawer and mug1."""
    robot = RobotModel("dual_ur5e")
    spec = load_scene("kitchen")
    solver = IKSolver(robot, scene=SceneDistance.from_spec(spec, exclude=[DRAWER, "mug1"]))
    return robot, _phase(DRAWER), _pull(robot, 0.6), solver


def test_tracking_poses_the_part_as_the_holder_took_it_and_a_resume_takes_that_pose() -> None:
    robot, phase, goals, solver = _pulled_drawer()
    cfg = RetargetConfig()
    first = track(goals, robot, solver, cfg, part=phase, trace=True)
    assert first[1]["right"][30:].max() < 0.01  # the hand followed the handle
    assert first[3]["part_fraction"] == pytest.approx(0.6, abs=0.03)
    trace = first[3]["trace"]
    assert trace.posed is not None and trace.posed[0] == int(np.argmax(goals.t >= phase.t_open))
    fixed = track(goals, robot, solver, dataclasses.replace(cfg, reached_part=False), part=phase)
    assert fixed[3]["part_fraction"] == 1.0
    # an arm task from frame 60 on: resumed there from the trace, the part keeps the pose found at frame 48
    goal_q = np.array(first[0][80])
    goal_q[robot.arm_q_indices("left")] += 0.2
    arm = [ArmBranch("left", float(goals.t[90]), goal_q, np.where(np.arange(120) >= 60, 0.05, 0.0), 0.0)]
    full = track(goals, robot, solver, cfg, part=phase, arm=arm)
    resumed = track(goals, robot, solver, cfg, part=phase, arm=arm, resume=(60, trace))
    np.testing.assert_array_equal(resumed[0], full[0])
    assert resumed[3]["part"] is trace.posed[1] and resumed[3]["part_fraction"] == full[3]["part_fraction"]


def test_a_grasp_of_what_the_drawer_holds_follows_the_drawer_as_it_was_pulled() -> None:
    phase = _phase(DRAWER)
    assert set(phase.contents) == {"mug2", "box2"} and _phase(DOOR).contents == ()
    short = phase.posed(0.6)
    world = SceneWorld(load_scene("kitchen"))
    moved = world.handle_at(DRAWER, 0.6) - world.handle_at(DRAWER, 1.0)  # the contents, 40% less pulled
    np.testing.assert_allclose(short.shift()[:3, 3], moved, atol=1e-9)
    np.testing.assert_allclose(short.shift()[:3, :3], np.eye(3), atol=1e-12)
    goals = _pull(RobotModel("dual_ur5e"), 1.0)
    left = np.array(goals.tcp["right"])
    goals = dataclasses.replace(
        goals, tcp={**goals.tcp, "left": left}, active={**goals.active, "left": goals.active["right"]}
    )
    grasp = [ContactEvent(3.0, "left", "grasp", "mug2"), ContactEvent(3.0, "right", "grasp", "can1")]
    out = follow_part(goals, short, grasp)
    shift = out.tcp["left"][:, :3, 3] - left[:, :3, 3]
    t = goals.t
    np.testing.assert_allclose(shift[t <= phase.t_open], 0.0, atol=1e-12)  # before the drawer stood open
    np.testing.assert_allclose(shift[np.argmin(np.abs(t - 3.0))], moved, atol=1e-9)  # at the grasp: all of it
    np.testing.assert_allclose(shift[t >= 3.5], 0.0, atol=1e-12)  # eased out over 0.5 s of the carry
    assert np.all(np.linalg.norm(np.diff(shift, axis=0), axis=1) < 0.2 * np.linalg.norm(moved))  # no jumps
    np.testing.assert_array_equal(out.tcp["right"], goals.tcp["right"])  # can1 is not in the drawer
    assert follow_part(goals, phase, grasp) is goals  # pulled as scheduled: nothing moves


def test_the_part_keeps_its_padding_wherever_it_is_posed() -> None:
    """The opened part is grown by ``padding`` (where the holder's hand put it is known only that well):
    every distance and lower bound is that much smaller, posed anywhere; a bad padding is refused."""
    spec = load_scene("kitchen")
    plain = _phase(DRAWER)
    schedule = SimpleNamespace(
        info={"part": DRAWER, "door_hand": "right"},
        keyframes=[
            SimpleNamespace(time=t, hand="right", action=a, object_name=DRAWER, contact_event="")
            for t, a in ((1.0, "reach"), (2.0, "open"), (4.0, "close"))
        ],
    )
    padded = opened_part(schedule, spec, padding=0.005)  # type: ignore[arg-type]
    assert padded is not None and padded.scene.padding == 0.005 and plain.scene.padding == 0.0
    points = np.random.default_rng(5).uniform([0.0, -0.6, 0.3], [0.8, 0.6, 1.0], (50, 3))
    for f in (1.0, 0.4):
        a, b = plain.posed(f).scene, padded.posed(f).scene
        assert b.padding == 0.005
        np.testing.assert_allclose(b.query(points)[0], a.query(points)[0] - 0.005, atol=1e-6)
        np.testing.assert_allclose(b.query(points)[1], a.query(points)[1], atol=1e-6)
        np.testing.assert_allclose(b.lower_bound(points), a.lower_bound(points) - 0.005, atol=1e-6)
        assert np.all(b.lower_bound(points) <= b.query(points)[0] + 1e-9)  # still a lower bound
    for bad in (-0.001, float("nan"), float("inf")):
        with pytest.raises(RetargetError, match="padding"):
            SceneDistance(dict(plain.meshes or {}), padding=bad)
