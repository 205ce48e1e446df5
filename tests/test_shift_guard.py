"""The clearance guard of the in-hand placement correction: the dual UR5e's left hand held just above the
kitchen counter, shifts towards it, along it and away from it."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from hsi_retarget.sim_check import SimWorld, WorldConfig, build_world
from hsi_retarget.sim_check.shift_guard import ShiftGuard

TOP = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])  #: TCP pointing down
CLEARANCE = 0.003  #: [m]


@pytest.fixture(scope="module")
def low_hand() -> tuple[SimWorld, np.ndarray]:
    """The counter world and a configuration with the left TCP pointing down 4 cm above the counter top."""
    world = build_world(WorldConfig(base_pose=(0.2, 0.0, 0.0)))
    robot = world.robot
    frame = robot.model.getFrameId(robot.tcp_frames["left"])
    goal = pin.SE3(TOP, np.linalg.solve(world.base, [0.8, 0.1, 0.94, 1.0])[:3])
    q, iv = robot.q_home.copy(), robot.arm_v_indices("left")
    data = robot.model.createData()
    for _ in range(200):  # damped least squares on the arm's joints
        pin.framesForwardKinematics(robot.model, data, q)
        err = pin.log6(data.oMf[frame].actInv(goal)).vector
        if np.linalg.norm(err) < 1e-9:
            break
        jac = pin.computeFrameJacobian(robot.model, data, q, frame, pin.LOCAL)[:, iv]
        dv = np.zeros(robot.nv)
        dv[iv] = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), err)
        q = pin.integrate(robot.model, q, dv)
    return world, q


def _clearance(world: SimWorld, q: np.ndarray, shift: np.ndarray) -> float:
    """[m] smallest distance of the left hand's geoms, translated by ``shift`` (3,), to the counter."""
    m, probe = world.model, mujoco.MjData(world.model)
    probe.qpos[:] = world.map.q_to_qpos(q, world.data.qpos)
    mujoco.mj_kinematics(m, probe)
    hand = np.flatnonzero((world.geom_hand == 0) & ((m.geom_contype | m.geom_conaffinity) > 0))
    probe.geom_xpos[hand] += shift
    counter, fromto = m.geom("counter1:block").id, np.zeros(6)
    return float(min(mujoco.mj_geomDistance(m, probe, int(g), counter, 1.0, fromto) for g in hand))


def test_the_shifted_hand_keeps_its_clearance_to_the_counter(low_hand: tuple[SimWorld, np.ndarray]) -> None:
    world, q = low_hand
    guard = ShiftGuard(world, CLEARANCE)
    before = world.data.qpos.copy()
    gap = _clearance(world, q, np.zeros(3))
    assert 0.01 < gap < 0.05  # the fingers hang a few centimetres above the counter top

    down = guard.limit(q, ("left",), np.array([0.0, 0.0, -0.08]))
    assert down[2] == pytest.approx(-(gap - CLEARANCE), abs=2e-4)  # down to the clearance, no further
    assert _clearance(world, q, down) == pytest.approx(CLEARANCE, abs=2e-4)
    for free in ([0.03, -0.02, 0.0], [0.0, 0.0, 0.04]):  # along the top and away from it: untouched
        np.testing.assert_allclose(guard.limit(q, ("left",), np.array(free)), free, atol=1e-9)
    np.testing.assert_array_equal(world.data.qpos, before)  # measured on a probe, not the world's data

    rng = np.random.default_rng(7)
    for shift in rng.normal(scale=0.04, size=(40, 3)):
        kept = guard.limit(q, ("left",), shift)
        assert _clearance(world, q, kept) >= CLEARANCE - 2e-4
        assert np.linalg.norm(kept) <= np.linalg.norm(shift) + 1e-9  # a projection never lengthens it


def _arm_gap(world: SimWorld, q: np.ndarray, pairs: np.ndarray) -> float:
    """[m] smallest distance over geom ``pairs`` (P, 2) at ``q``."""
    m, probe = world.model, mujoco.MjData(world.model)
    probe.qpos[:] = world.map.q_to_qpos(q, world.data.qpos)
    mujoco.mj_kinematics(m, probe)
    return float(min(mujoco.mj_geomDistance(m, probe, int(a), int(b), 1.0, None) for a, b in pairs))


def test_the_shifted_arm_keeps_its_room_to_the_rest_of_the_robot() -> None:
    """The left arm turned towards the right arm at its shoulder: planned 2 cm from it, a shift that brings
    it 1 cm off (inside the 15 mm clearance) is refused, one away from it or none is kept."""
    world = build_world(WorldConfig())
    guard = ShiftGuard(world, 0.015)
    pairs = guard._arm_pairs["left"]
    m = world.model
    assert len(pairs) > 0 and all(world.geom_hand[a] in (-1, 0) for a, _ in pairs)
    names = {m.geom(int(b)).name for _, b in pairs}
    assert any(n.startswith("right_") for n in names) and not any(n.startswith("left_") for n in names)
    home = world.robot.q_home
    pan = world.robot.q_index(world.robot.arm_joints["left"][0])

    def turned(angle: float) -> np.ndarray:
        q = home.copy()
        q[pan] += angle
        return q

    sign = 1.0 if _arm_gap(world, turned(0.1), pairs) < _arm_gap(world, turned(-0.1), pairs) else -1.0
    angles = np.linspace(0.0, 3.0, 301) * sign
    gaps = np.array([_arm_gap(world, turned(a), pairs) for a in angles])
    assert gaps[0] > 0.05 and gaps.min() < 0.0  # at home well apart; turned far enough, it runs into it

    def at(gap: float) -> np.ndarray:
        k = int(np.argmax(gaps < gap))
        return turned(float(angles[k]))

    plan = at(0.02)
    assert (
        guard.arm_room(plan, at(0.01), ("left",)) is False
    )  # within the 15 mm clearance, closer than planned
    assert guard.arm_room(plan, turned(0.0), ("left",))  # away from it
    assert guard.arm_room(at(0.01), at(0.01), ("left",))  # as planned: not pushed in further, so kept
    assert guard.arm_room(plan, at(0.001), ()) and not guard.arm_room(plan, at(0.001), ("left",))
