"""Dual UR5e on a holonomic base with a torso lift (``dual_ur5e``).

Base: planar x/y slides and a yaw hinge on ``base_link`` (wheels not modelled; the base floats 4 cm
above the floor), a prismatic ``torso_lift_joint`` (0–0.45 m) moving ``torso_link``. Two UR5e arms
hang from a V-shaped bracket: each arm base is tilted 45° outwards about x, so the shoulder-pan axes
point up and out, the shoulder points (``{side}_shoulder``) are 0.40 m apart at 1.125 + lift [m] above the
floor (1.35 m at mid lift), and the singular cylinder around each pan axis lies outside the workspace in
front. Each arm ends in a Robotiq 2F-140-like gripper (140 mm opening: mugs and bottles fit across their
body with room to spare) with a ``{side}_tcp`` frame 0.145 m out of the flange.
"""

from __future__ import annotations

import math

import numpy as np

from hsi_retarget.robots.description import (
    Frame,
    Geom,
    Inertial,
    Joint,
    Link,
    RobotDescription,
    box_inertia,
    rot_x,
    rot_z,
    transform,
)
from hsi_retarget.robots.gripper import ROBOTIQ_2F140, parallel_gripper
from hsi_retarget.robots.ur5e import JOINTS, UR5E_D, ur5e_arm

NAME = "dual_ur5e"
BASE_SIZE = (0.6, 0.5, 0.28)  #: base box full extents [m]
BASE_CLEARANCE = 0.04  #: gap between the base box and the floor [m]
BASE_MASS = 90.0  #: base with column [kg]
TORSO_ORIGIN_Z = 0.7  #: torso frame height at lift 0 [m]
LIFT_RANGE = (0.0, 0.45)  #: torso lift travel [m]
TORSO_MASS = 25.0  #: [kg]
SHOULDER_Z = 0.425  #: shoulder points above the torso frame [m]
SHOULDER_HALF_SPAN = 0.2  #: lateral offset of each shoulder point [m]
MOUNT_TILT = math.pi / 4  #: outward tilt of each arm base about x [rad]
#: Home: torso at mid lift, TCPs at (0.45, +/-0.25, 1.0) m pointing forward (z_tcp = +x, y_tcp = +y), elbows
#: forward and out (the most manipulable of the 8 UR inverse-kinematics branches; the arms are not mirror
#: images, a UR cannot be mirrored, so the right arm uses the shoulder-flipped branch).
HOME_ARM = {
    "left": (0.528, -0.1673, 1.9597, 1.3492, -2.0988, 2.3562),
    "right": (2.6136, -2.9743, -1.9597, 1.7924, 2.0988, 0.7854),
}
_COLOR = (0.55, 0.57, 0.6, 1.0)


def _base_links() -> list[Link]:
    bx, by, bz = BASE_SIZE
    planar = (
        Joint("base_x_joint", "prismatic", (1.0, 0.0, 0.0), -5.0, 5.0, 1.0, 1.0, 2000.0, 2.0e4, 3600.0),
        Joint("base_y_joint", "prismatic", (0.0, 1.0, 0.0), -5.0, 5.0, 1.0, 1.0, 2000.0, 2.0e4, 3600.0),
        Joint(
            "base_yaw_joint",
            "revolute",
            (0.0, 0.0, 1.0),
            -2 * math.pi,
            2 * math.pi,
            1.5,
            2.0,
            1000.0,
            2.0e4,
            1100.0,
        ),
    )
    base_geoms = (
        Geom(
            "base_link:chassis",
            "box",
            (bx / 2, by / 2, bz / 2),
            transform((0.0, 0.0, BASE_CLEARANCE + bz / 2)),
            _COLOR,
        ),
        Geom(
            "base_link:column",
            "box",
            (0.08, 0.12, 0.32),
            transform((-0.02, 0.0, BASE_CLEARANCE + bz + 0.32)),
            _COLOR,
        ),
    )
    base_inertial = Inertial.solid(
        BASE_MASS, np.array([0.0, 0.0, 0.25]), box_inertia(BASE_MASS, (bx, by, 0.5))
    )
    lift = Joint(
        "torso_lift_joint",
        "prismatic",
        (0.0, 0.0, 1.0),
        *LIFT_RANGE,
        0.2,
        0.5,
        3000.0,
        2.0e5,
        7500.0,
        armature=5.0,
        damping=100.0,
    )
    chest = (0.2, 0.3, 0.5)
    torso_geoms = (
        Geom("torso_link:chest", "box", (0.1, 0.13, 0.25), transform((-0.02, 0.0, 0.25)), _COLOR),
        Geom("torso_link:bracket", "box", (0.06, 0.1, 0.04), transform((0.0, 0.0, 0.3)), _COLOR),
        Geom("torso_link:head", "sphere", (0.09,), transform((-0.02, 0.0, 0.62)), _COLOR),
    )
    torso_inertial = Inertial.solid(TORSO_MASS, np.array([-0.02, 0.0, 0.25]), box_inertia(TORSO_MASS, chest))
    return [
        Link("base_footprint", None),
        Link("base_link", "base_footprint", joints=planar, inertial=base_inertial, geoms=base_geoms),
        Link(
            "torso_link",
            "base_link",
            transform((0.0, 0.0, TORSO_ORIGIN_Z)),
            (lift,),
            torso_inertial,
            torso_geoms,
        ),
    ]


def arm_mount(side: str) -> np.ndarray:
    """DH base frame of the ``side`` arm in ``torso_link``: (4, 4); q = 0 stretches the arm forward."""
    sign = 1.0 if side == "left" else -1.0
    rot = rot_x(-sign * MOUNT_TILT) @ rot_z(math.pi)
    shoulder = np.array([0.0, sign * SHOULDER_HALF_SPAN, SHOULDER_Z])
    return transform(shoulder - rot[:, 2] * UR5E_D[0], rot)


def dual_ur5e_description() -> RobotDescription:
    """The ``dual_ur5e`` robot."""
    links = _base_links()
    frames: list[Frame] = []
    home: dict[str, float] = {"torso_lift_joint": 0.5 * (LIFT_RANGE[0] + LIFT_RANGE[1])}
    for side in ("left", "right"):
        arm_links, arm_frames = ur5e_arm(side, "torso_link", arm_mount(side), side)  # type: ignore[arg-type]
        grip_links, grip_frames = parallel_gripper(
            side,
            arm_links[-1].name,
            arm_frames[-1].pose,
            ROBOTIQ_2F140,
            side,  # type: ignore[arg-type]
        )
        links += arm_links + grip_links
        frames += arm_frames + grip_frames
        home.update({f"{side}_{j}_joint": v for j, v in zip(JOINTS, HOME_ARM[side], strict=True)})
        home.update(
            {f"{side}_finger_a_joint": ROBOTIQ_2F140.stroke, f"{side}_finger_b_joint": ROBOTIQ_2F140.stroke}
        )
    return RobotDescription(
        name=NAME,
        links=tuple(links),
        frames=tuple(frames),
        home=home,
        arm_joints={s: tuple(f"{s}_{j}_joint" for j in JOINTS) for s in ("left", "right")},
        gripper_joints={s: (f"{s}_finger_a_joint", f"{s}_finger_b_joint") for s in ("left", "right")},
        tcp_frames={"left": "left_tcp", "right": "right_tcp"},
        shoulder_frames={"left": "left_shoulder", "right": "right_shoulder"},
    )
