"""Grasps of objects moved after planning, re-aimed (:mod:`hsi_retarget.moved_target`)."""

from __future__ import annotations

import numpy as np
import pytest

from hsi_planning.errors import RetargetError
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.human_motion import HumanMotion
from hsi_retarget.moved_target import MAX_SHIFT, shift_grasps

_RATE = 100.0  #: [Hz]
_WINDOWS = [
    GraspWindow("right", "grasp", "can1", True, 1.0, (0.5, 1.0), (1.0, 1.3)),
    GraspWindow("right", "release", "can1", True, 2.5, (2.0, 2.5), (2.5, 2.8)),
    GraspWindow("left", "grasp", "cabinet1/door1", False, 0.2, (0.0, 0.2), (0.2, 0.5)),
]


def _motion(n: int = 301) -> HumanMotion:
    t = np.arange(n) / _RATE
    right = np.column_stack([0.3 + 0.1 * t, -0.2 + 0.05 * np.sin(t), np.full(n, 1.0)])
    eye = np.tile(np.eye(3), (n, 1, 1))
    return HumanMotion(
        t=t,
        wrist_position={"left": np.tile([0.3, 0.25, 1.0], (n, 1)), "right": right},
        wrist_rotation={"left": eye, "right": eye.copy()},
        active={"left": np.ones(n, bool), "right": np.ones(n, bool)},
        hip_position=np.tile([0.0, 0.0, 0.95], (n, 1)),
        hip_yaw=np.zeros(n),
    )


def test_the_grasp_moves_with_the_object_and_the_release_stays() -> None:
    motion = _motion()
    before = {s: p.copy() for s, p in motion.wrist_position.items()}
    d = np.array([0.03, -0.02, 0.0])
    out, records = shift_grasps(motion, _WINDOWS, {"can1": d})
    t, moved = motion.t, out.wrist_position["right"] - before["right"]
    np.testing.assert_array_equal(motion.wrist_position["right"], before["right"])  # the input is kept
    np.testing.assert_array_equal(out.wrist_position["left"], before["left"])  # the other hand is not moved
    np.testing.assert_allclose(moved[t <= 0.5], 0.0, atol=1e-12)  # before the approach: as planned
    np.testing.assert_allclose(moved[(t >= 1.0) & (t <= 1.3)], np.tile(d, (31, 1)), atol=1e-12)  # the grasp
    np.testing.assert_allclose(moved[t >= 2.0 - 1e-9], 0.0, atol=1e-12)  # the release: where it was planned
    share = moved @ d / (d @ d)
    assert np.all(np.diff(share[(t >= 0.5) & (t <= 1.0)]) >= -1e-12)  # eased in, monotonically
    assert np.all(np.diff(share[(t >= 1.3) & (t <= 2.0)]) <= 1e-12)  # eased out over the carry
    np.testing.assert_allclose(np.cross(moved, d), 0.0, atol=1e-12)  # only along the displacement
    assert records == [{"hand": "right", "object": "can1", "time_s": 1.0, "shift_m": [0.03, -0.02, 0.0]}]


def test_bad_displacements_and_unknown_objects_are_rejected() -> None:
    motion = _motion()
    with pytest.raises(RetargetError, match="finite"):
        shift_grasps(motion, _WINDOWS, {"can1": [0.01, np.nan, 0.0]})
    with pytest.raises(RetargetError, match="at most"):
        shift_grasps(motion, _WINDOWS, {"can1": [MAX_SHIFT + 0.01, 0.0, 0.0]})
    with pytest.raises(RetargetError, match=r"\(3,\)"):
        shift_grasps(motion, _WINDOWS, {"can1": [0.01, 0.0]})
    with pytest.raises(RetargetError, match=r"never grasped; grasped: \['can1'\]"):
        shift_grasps(motion, _WINDOWS, {"mug2": [0.01, 0.0, 0.0]})
    with pytest.raises(RetargetError, match="never grasped"):  # a door is no free object
        shift_grasps(motion, _WINDOWS, {"cabinet1/door1": [0.01, 0.0, 0.0]})
