"""Room for the fingers at a free-object grasp (:mod:`hsi_retarget.finger_room`): the aperture and the
turn about the approach axis, on the dual arm's real gripper and the kitchen's can."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from hsi_planning.errors import ConfigError
from hsi_planning.scene_paths import load_scene
from hsi_retarget.finger_room import FingerRoomConfig, make_finger_room
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.grip_turn import object_prims
from hsi_retarget.ik import IKSolver
from hsi_retarget.mapping import RobotGoals
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance

N = 61
T = np.linspace(0.0, 3.0, N)
TOP = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])  # TCP z down, fingers along world y
SIDE = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # TCP z along world x
WINDOWS = [
    GraspWindow("left", "grasp", "can1", True, 1.0, (0.5, 1.0), (1.0, 1.5)),
    GraspWindow("left", "release", "can1", True, 2.0, (1.5, 2.0), (2.0, 2.5)),
]


@pytest.fixture(scope="module")
def dual() -> RobotModel:
    return RobotModel("dual_ur5e")


@pytest.fixture(scope="module")
def can() -> tuple[list, np.ndarray]:
    prims = object_prims(load_scene("kitchen"))["can1"]
    center = np.asarray(prims[0].matrix[:3, 3])
    return prims, center + np.array([0.0, 0.0, prims[0].size[1] - 0.03])  # the TCP 3 cm below the top


def _goals(rotation: np.ndarray, at: np.ndarray) -> RobotGoals:
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rotation, at
    ones = np.ones(N, bool)
    return RobotGoals(
        t=T,
        tcp={"left": np.tile(pose, (N, 1, 1))},
        active={"left": ones},
        reachable={"left": ones},
        reach_excess={"left": np.zeros(N)},
        root=np.tile(np.eye(4), (N, 1, 1)),
        lift=np.zeros(N),
        shoulder={"left": np.zeros((N, 3))},
        scale=1.0,
    )


def _neighbours(grip: np.ndarray, axis: np.ndarray, gap: float) -> SceneDistance:
    """Two 8 cm wide cylinders as tall as the can, ``gap`` [m] from its 3.3 cm radius on both sides along
    ``axis`` (``grip``: the grasp point, 3 cm below the can's top)."""
    meshes = {}
    for sign, name in ((1.0, "a"), (-1.0, "b")):
        mesh = trimesh.creation.cylinder(radius=0.04, height=0.122)
        mesh.apply_translation(grip - (0.0, 0.0, 0.031) + sign * (0.033 + gap + 0.04) * axis)
        meshes[name] = mesh
    return SceneDistance(meshes)


def test_fingers_turn_away_from_close_neighbours_and_open_only_as_far_as_the_can_needs(
    dual: RobotModel, can: tuple[list, np.ndarray]
) -> None:
    prims, center = can
    scene = _neighbours(center, np.array([0.0, 1.0, 0.0]), 0.025)  # along the planned finger axis
    goals = _goals(TOP, center)
    out, records = make_finger_room(goals, WINDOWS, {"can1": prims}, IKSolver(dual, scene=scene))
    (rec,) = records
    assert abs(rec["turn_deg"]) >= 45.0
    assert rec["room_m"][0] < 0.0 <= rec["room_m"][1]  # no room as planned, room after the turn
    assert rec["aperture_m"] == pytest.approx(0.033 + 0.015, abs=2e-3)  # the can's radius + clearance
    tcp = out.tcp["left"]
    np.testing.assert_allclose(tcp[:, :3, 2], np.tile([0.0, 0.0, -1.0], (N, 1)), atol=1e-9)  # approach kept
    np.testing.assert_allclose(tcp[:, :3, 3], goals.tcp["left"][:, :3, 3])  # positions kept
    held = (T >= 1.0) & (T <= 2.0)
    rel = np.einsum("ji,tjk->tik", TOP, tcp[held, :3, :3])  # planned^T turned = Rz(turn)
    angle = np.degrees(np.arctan2(rel[:, 1, 0], rel[:, 0, 0]))
    np.testing.assert_allclose(angle, rec["turn_deg"], atol=1e-6)  # turned while held
    outside = (T <= 0.0) | (T >= 3.0)
    np.testing.assert_allclose(tcp[outside], goals.tcp["left"][outside], atol=1e-9)
    finger = out.finger["left"]
    assert np.allclose(finger[held], rec["aperture_m"]) and np.isnan(finger[0])
    assert np.all(np.isnan(finger) | ((finger >= rec["aperture_m"] - 1e-9) & (finger <= 0.07 + 1e-9)))
    assert "left" not in goals.finger  # the input is not changed


def test_no_turn_with_room_and_none_for_a_side_grasp(dual: RobotModel, can: tuple[list, np.ndarray]) -> None:
    prims, center = can
    roomy = _neighbours(center, np.array([0.0, 1.0, 0.0]), 0.15)
    _, records = make_finger_room(_goals(TOP, center), WINDOWS, {"can1": prims}, IKSolver(dual, scene=roomy))
    assert records[0]["turn_deg"] == 0.0 and records[0]["room_m"][0] >= 0.0
    tight = _neighbours(center, np.array([0.0, 1.0, 0.0]), 0.025)
    side, records = make_finger_room(
        _goals(SIDE, center), WINDOWS, {"can1": prims}, IKSolver(dual, scene=tight)
    )
    assert records[0]["turn_deg"] == 0.0 and records[0]["room_m"] == [None, None]  # not searched
    np.testing.assert_allclose(side.tcp["left"][:, :3, :3], np.tile(SIDE, (N, 1, 1)), atol=1e-12)
    full, records = make_finger_room(
        _goals(TOP, center),
        WINDOWS,
        {"can1": prims},
        IKSolver(dual, scene=tight),
        config=FingerRoomConfig(aperture=False, turn=False),
    )
    assert records[0]["aperture_m"] == pytest.approx(0.07)  # the full stroke: the fingers stay as planned
    assert np.all(np.isnan(full.finger["left"]))


def test_finger_room_config_rejects_bad_values() -> None:
    for bad in ({"clearance": -0.01}, {"step_deg": 0.0}, {"top_down_deg": 120.0}, {"turn_s": 0.0}):
        with pytest.raises(ConfigError, match="FingerRoomConfig"):
            FingerRoomConfig(**bad)
