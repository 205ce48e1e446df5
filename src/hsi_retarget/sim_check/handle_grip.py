"""A door's or drawer's handle held in the gripper: the bar held, free to turn about its own axis.

Parallel fingers closed on a handle bar hold it against every push and pull and against tilting it across
the fingers, but the bar's round section can turn between the pads about the bar's own axis (the friction
of two narrow pads resists little torque there). A full weld (the free objects' grasp) instead also locks
that turn: in humanoid ``cabinet_bottle/reshape/1`` the hand holding the door open turned 11 deg about the
vertical bar while the other hand reached for a bottle, the weld fought the arm, and the strained body
shook the reaching hand 3 cm off the bottle.

:func:`pivot` holds the handle with two ``connect`` constraints (MuJoCo equality: one point of the gripper
kept on one point of the part), at the TCP +- :data:`PIVOT_HALF_SPAN` along the bar's axis: together a hinge
about the bar. :func:`bar_axes` gives each part's bar axis in its body frame (the longest side of its
``handle`` box, :func:`~hsi_retarget.grip_turn.handle_bar_axes`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np
from numpy.typing import NDArray

from hsi_retarget.grip_turn import handle_bar_axes

if TYPE_CHECKING:
    from hsi_planning.scene import SceneSpec

__all__ = ["PIVOT_HALF_SPAN", "bar_axes", "pivot"]

F64 = NDArray[np.float64]
PIVOT_HALF_SPAN = 0.03  #: [m] the two pivot points lie this far from the TCP along the bar


def bar_axes(model: mujoco.MjModel, spec: SceneSpec, bodies: dict[str, int]) -> dict[str, F64]:
    """Part name -> (3,) unit axis of its handle bar in its MuJoCo body frame, for the ``bodies`` (name ->
    body id) that have a handle bar (at the model's rest configuration)."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    out = {}
    for name, axis in handle_bar_axes(spec).items():
        if name in bodies:
            local = data.xmat[bodies[name]].reshape(3, 3).T @ axis
            out[name] = local / np.linalg.norm(local)
    return out


def pivot(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    *,
    pins: tuple[int, int],
    bodies: tuple[int, int],
    tcp: F64,
    axis: F64,
) -> None:
    """Switch on the pivot pair ``pins`` (two connect equality ids) between the gripper and part
    ``bodies`` (body ids), about the bar ``axis`` (3,) (part body frame) through the TCP ``tcp`` (3,) [m]
    (world), at their current poses (``data``'s kinematics must be current)."""
    b1, b2 = bodies
    rot1, rot2 = data.xmat[b1].reshape(3, 3), data.xmat[b2].reshape(3, 3)
    direction = rot2 @ np.asarray(axis, dtype=np.float64)
    for eq, sign in zip(pins, (-1.0, 1.0), strict=True):
        point = np.asarray(tcp, dtype=np.float64) + sign * PIVOT_HALF_SPAN * direction
        model.eq_data[eq, 0:3] = rot1.T @ (point - data.xpos[b1])  # the point in body1's (gripper) frame
        model.eq_data[eq, 3:6] = rot2.T @ (point - data.xpos[b2])  # the same point in body2's (part) frame
        data.eq_active[eq] = 1
