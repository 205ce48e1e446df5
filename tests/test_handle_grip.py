"""A handle held in the gripper by a pivot pair (hsi_retarget.sim_check.handle_grip): the bar turns about
its own axis and about nothing else, moves with the gripper, and the kitchen's doors and drawers are held
that way at the TCP."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.sim_check import WorldConfig, build_world
from hsi_retarget.sim_check.grasp import GraspController
from hsi_retarget.sim_check.handle_grip import PIVOT_HALF_SPAN, pivot

_TWO_BODIES = """
<mujoco>
  <option gravity="0 0 0" timestep="0.002"/>
  <worldbody>
    <body name="gripper" pos="0 0 1"><freejoint/><geom type="box" size="0.03 0.03 0.03" mass="1"/></body>
    <body name="bar" pos="0.1 0 1">
      <freejoint/><geom type="capsule" fromto="0 0 -0.1 0 0 0.1" size="0.02" mass="0.5"/>
    </body>
  </worldbody>
  <equality>
    <connect name="p0" body1="gripper" body2="bar" anchor="0 0 0" active="false" solref="0.01 1"/>
    <connect name="p1" body1="gripper" body2="bar" anchor="0 0 0" active="false" solref="0.01 1"/>
  </equality>
</mujoco>
"""


def _relative(m: mujoco.MjModel, d: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """The bar's rotation and position in the gripper's frame."""
    g, b = m.body("gripper").id, m.body("bar").id
    rg = d.xmat[g].reshape(3, 3)
    return rg.T @ d.xmat[b].reshape(3, 3), rg.T @ (d.xpos[b] - d.xpos[g])


@pytest.mark.parametrize("torque_axis, turns", [((0.0, 0.0, 1.0), True), ((1.0, 0.0, 0.0), False)])
def test_the_bar_turns_about_its_axis_only(torque_axis: tuple[float, float, float], turns: bool) -> None:
    m = mujoco.MjModel.from_xml_string(_TWO_BODIES)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    pins = (m.equality("p0").id, m.equality("p1").id)
    bodies = (m.body("gripper").id, m.body("bar").id)
    pivot(
        m, d, pins=pins, bodies=bodies, tcp=d.xpos[bodies[1]].copy(), axis=np.array([0.0, 0.0, 1.0])
    )  # the bar's axis: z
    assert all(d.eq_active[e] == 1 for e in pins)
    rot0, pos0 = _relative(m, d)
    d.xfrc_applied[bodies[1], 3:] = 0.002 * np.asarray(torque_axis)  # [N m] on the bar
    d.xfrc_applied[bodies[0], :3] = (2.0, 1.0, 0.0)  # [N] the gripper pulled: the bar comes along
    for _ in range(250):  # 0.5 s
        mujoco.mj_step(m, d)
    rot, pos = _relative(m, d)
    turn = np.degrees(_rotvec(rot0.T @ rot))  # [deg] the bar's turn in the gripper's frame
    assert np.linalg.norm(d.xpos[bodies[0]] - (0.0, 0.0, 1.0)) > 0.1  # the gripper moved
    assert np.linalg.norm(pos - pos0) < 0.005  # the bar stayed in the gripper (its axis through the TCP)
    assert np.linalg.norm(turn[:2]) < 1.0  # never about the axes across the bar
    if turns:
        assert abs(turn[2]) > 20.0  # the torque about the bar turns it in the grip


def _rotvec(r: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_matrix(r).as_rotvec())


def test_a_kitchen_part_is_held_by_its_pivot_pair_at_the_tcp_along_its_bar() -> None:
    world = build_world(WorldConfig(base_pose=(0.0, -0.75, 0.0), handle_pivot=True))
    part, hand = "drawer_unit1/drawer1", "right"
    assert set(world.bar_axes) == set(world.parts)
    for axis in world.bar_axes.values():
        assert np.linalg.norm(axis) == pytest.approx(1.0)
    m, d = world.model, world.data
    pins = world.pivots[(hand, part)]
    assert all(d.eq_active[e] == 0 for e in pins)
    grasp = GraspController(world)
    assert grasp._weld(hand, part) == "pivot"
    assert grasp.held[hand] == part and d.eq_active[world.welds[(hand, part)]] == 0
    b1, b2 = world.gripper_body[hand], world.body_ids[part]
    tcp = d.geom_xpos[world.tcp_probe[hand]]
    bar = d.xmat[b2].reshape(3, 3) @ world.bar_axes[part]
    ends = []
    for e in pins:
        assert d.eq_active[e] == 1
        on_gripper = d.xmat[b1].reshape(3, 3) @ m.eq_data[e, 0:3] + d.xpos[b1]
        on_part = d.xmat[b2].reshape(3, 3) @ m.eq_data[e, 3:6] + d.xpos[b2]
        np.testing.assert_allclose(on_gripper, on_part, atol=1e-9)  # no jump when it is made
        ends.append(on_gripper)
    np.testing.assert_allclose((ends[0] + ends[1]) / 2.0, tcp, atol=1e-9)  # centred on the TCP
    np.testing.assert_allclose(ends[1] - ends[0], 2.0 * PIVOT_HALF_SPAN * bar, atol=1e-9)  # along the bar
    grasp.command(ContactEvent(0.0, hand, "release", part), 0.0)
    assert all(d.eq_active[e] == 0 for e in pins) and hand not in grasp.held
    world.reset()


def test_by_default_only_the_floating_robot_holds_handles_by_pivots() -> None:
    humanoid = build_world(WorldConfig(robot="humanoid"))
    assert {p for _, p in humanoid.pivots} == set(humanoid.parts) and len(humanoid.pivots) == 2 * len(
        humanoid.parts
    )
    assert build_world(WorldConfig()).pivots == {}  # the dual arm: welded
