"""The holder's goals while it holds a handle move as the part does (hsi_retarget.handle_hold): on the
door's arc, turning with it, back to the plan after the release; the goal slides only further open, and
only while the part stands open."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_part_scene import DOOR, DRAWER, SIDE, _phase, _pull

from hsi_planning.errors import ConfigError
from hsi_planning.scene_paths import load_scene
from hsi_planning.scheduler.world import SceneWorld
from hsi_retarget.handle_hold import hold_handle
from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.robots import RobotModel


def _events(part: str) -> list[ContactEvent]:
    return [ContactEvent(1.0, "right", "grasp", part), ContactEvent(4.8, "right", "release", part)]


def _door_goals() -> tuple[object, np.ndarray]:
    """Goals of a right hand that opens the door from 1 s to 2 s, holds it, closes it from 4 s to 4.8 s,
    up to 2 cm above the handle's arc (on it at the grasp) and never turning (frames every 1/24 s to 6 s);
    the planned openings."""
    goals = _pull(RobotModel("dual_ur5e"), 1.0, n=144)
    world = SceneWorld(load_scene("kitchen"))
    t = goals.t
    f = np.clip(t - 1.0, 0.0, 1.0) - np.clip((t - 4.0) / 0.8, 0.0, 1.0)
    right = np.array(goals.tcp["right"])
    right[:, :3, :3] = SIDE
    lift = 0.02 * np.sin(np.pi * np.clip((t - 1.0) / 3.8, 0.0, 1.0))
    right[:, :3, 3] = [
        world.handle_at(DOOR, float(v)) + np.array([0.0, 0.0, z]) for v, z in zip(f, lift, strict=True)
    ]
    return dataclasses.replace(goals, tcp={"right": right}), f


def test_the_held_goal_rides_on_the_door_and_turns_with_it() -> None:
    goals, f = _door_goals()
    phase = _phase(DOOR)
    world = SceneWorld(load_scene("kitchen"))
    held, holds, records = hold_handle(goals, _events(DOOR), phase)
    t, before, after = goals.t, goals.tcp["right"], held.tcp["right"]
    assert len(holds) == 1 and holds[0].hand == "right" and records[0]["part"] == DOOR
    np.testing.assert_array_equal(after[t <= 1.0], before[t <= 1.0])  # up to the grasp: as planned
    start = before[int(np.searchsorted(t, 1.0))]
    for i in np.flatnonzero((t > 1.05) & (t < 4.8)):
        motion = world.part_transform(DOOR, float(f[i]))
        expected = motion @ start  # the grasp pose carried by the door
        assert np.linalg.norm(after[i, :3, 3] - expected[:3, 3]) < 0.005
        turn = Rotation.from_matrix(after[i, :3, :3] @ expected[:3, :3].T).magnitude()
        assert np.degrees(turn) < 0.5
    open_turn = Rotation.from_matrix(after[int(np.argmax(t >= 3.0)), :3, :3] @ SIDE.T).magnitude()
    assert np.degrees(open_turn) > 60.0  # the planned hand did not turn, the door's does
    assert records[0]["max_turn_deg"] > 60.0 and records[0]["max_shift_m"] > 0.015
    np.testing.assert_allclose(after[t >= 5.2], before[t >= 5.2], atol=1e-12)  # back to the plan after


def test_the_goal_slides_only_further_open_and_only_while_the_part_stands_open() -> None:
    robot = RobotModel("dual_ur5e")
    goals = _pull(robot, 0.6)  # the drawer pulled to 0.6 of its travel by 2 s, held to the end (5 s)
    phase = _phase(DRAWER)  # stands open from 2 s to 4 s
    world = SceneWorld(load_scene("kitchen"))
    _, (hold,), _ = hold_handle(goals, _events(DRAWER), phase, slack=0.1)
    t = goals.t

    def opening(pose: np.ndarray) -> float:
        return float(np.linalg.norm(pose[:3, 3] - world.handle_at(DRAWER, 0.0))) / float(
            np.linalg.norm(world.handle_at(DRAWER, 1.0) - world.handle_at(DRAWER, 0.0))
        )

    standing = int(np.argmax(t >= 3.0))
    assert hold.slack[standing] == pytest.approx(0.1)
    for tcp_at, expected in ((0.65, 0.65), (0.9, 0.7), (0.5, 0.6)):  # further: up to 0.1; less: as planned
        target = hold.target(standing, world.handle_at(DRAWER, tcp_at))
        assert target is not None and opening(target) == pytest.approx(expected, abs=0.005)
    pulling = int(np.argmax(t >= 1.5))  # on the opening arc: the plan, wherever the hand is
    assert hold.slack[pulling] == 0.0
    target = hold.target(pulling, world.handle_at(DRAWER, 0.9))
    assert target is not None and opening(target) == pytest.approx(0.3, abs=0.005)
    assert hold.target(int(np.argmax(t >= 0.5)), world.handle_at(DRAWER, 0.0)) is None  # before the grasp


def test_without_a_part_or_hold_the_goals_are_left_alone_and_bad_settings_are_refused() -> None:
    goals = _pull(RobotModel("dual_ur5e"), 0.6)
    assert hold_handle(goals, _events(DRAWER), None) == (goals, [], [])
    other = [ContactEvent(1.0, "right", "grasp", "mug1")]
    assert hold_handle(goals, other, _phase(DRAWER))[0] is goals
    with pytest.raises(ConfigError, match="slack"):
        hold_handle(goals, _events(DRAWER), _phase(DRAWER), slack=1.5)
    with pytest.raises(ConfigError, match="ease_s"):
        hold_handle(goals, _events(DRAWER), _phase(DRAWER), ease_s=-1.0)
