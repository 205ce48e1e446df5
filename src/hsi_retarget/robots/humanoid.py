"""Adult humanoid (``humanoid``): 1.75 m, 70 kg, floating pelvis, 6-DoF legs, 3-DoF waist, 7-DoF arms.

Segment lengths are fractions of the height and masses fractions of the body mass from Winter's
anthropometric table (Biomechanics and Motor Control of Human Movement): thigh 0.245 H, shank 0.246 H,
ankle height 0.039 H, shoulder height 0.818 H, upper arm 0.186 H, forearm 0.146 H; masses head 0.081,
trunk 0.497 (thorax+abdomen 0.355, pelvis 0.142), upper arm 0.028, forearm 0.016, hand 0.006,
thigh 0.100, shank 0.0465, foot 0.0145. Every link frame is world-aligned at q = 0 (x forward, y left,
z up), except the wrists, turned a quarter about the forearm so that the forearm is neutral at
``wrist_yaw`` = 0. The hands are parallel two-finger grippers (opening 9 cm) whose ``{side}_tcp`` has z
pointing out of the hand and y to the left (the fingers close across the palm, as a human hand's pinch;
the mapping's human wrist frame lands on it with the forearm neutral) at home. Joint limits are human
ranges of motion, except the shoulder roll and yaw and the wrists, which have a robot's (Unitree G1's
published ranges: shoulder roll down to -1.59 rad, shoulder yaw +-2.618, forearm turn (``wrist_yaw``)
+-1.97, wrist pitch and roll +-1.61 rad): with a human's (wrist deviation +-0.6 rad) the two-finger
gripper cannot take the top-down and sideways grasps into drawers and cabinets. The arm servos are stiff
(shoulders 1200, elbow 900, wrists 200 N m/rad; within their effort limits): the largest arm joint error
before a release fell from 3.4 to 0.6 deg with them (drawer_mug/plain/0). In MuJoCo the pelvis can
be held by the ``pelvis_anchor`` mocap body (weld ``pelvis_anchor_weld``, inactive by default); the home
pose stands on its own with the position actuators.
"""

from __future__ import annotations

import math

import numpy as np

from hsi_retarget.robots.description import (
    CollisionGroup,
    Frame,
    Geom,
    Inertial,
    Joint,
    Link,
    RobotDescription,
    box_inertia,
    cylinder_inertia,
    transform,
)
from hsi_retarget.robots.gripper import GripperSpec, parallel_gripper

NAME = "humanoid"
HEIGHT = 1.75  #: standing height [m]
MASS = 70.0  #: body mass [kg]
THIGH, SHANK, ANKLE_H = 0.245 * HEIGHT, 0.246 * HEIGHT, 0.039 * HEIGHT  #: [m]
UPPER_ARM, FOREARM = 0.186 * HEIGHT, 0.146 * HEIGHT  #: [m]
HIP_HALF_WIDTH, HIP_DROP = 0.09, 0.03  #: hip joints relative to the pelvis frame [m]
WAIST_Z = 0.1  #: waist joints above the pelvis frame [m]
SHOULDER_HALF_WIDTH = 0.19  #: [m]
SHOULDER_Z = 0.818 * HEIGHT  #: shoulder joint height at home [m] (minus pelvis + waist -> torso offset)
HAND = GripperSpec(
    stroke=0.045,
    palm_size=(0.04, 0.11, 0.07),
    palm_mass=0.30,
    finger_size=(0.02, 0.012, 0.08),
    finger_mass=0.06,
    tcp_depth=0.02,
    speed=0.1,
    force=40.0,
    kp=500.0,
    kv=15.0,
    coupling=0.02,
)
X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
_SKIN = (0.85, 0.72, 0.6, 1.0)
_CLOTH = (0.3, 0.4, 0.55, 1.0)
#: name -> (axis, lower, upper, velocity, effort, kp, kv, armature) for the left side; right mirrors x/z.
_JOINTS: dict[str, tuple[tuple[float, float, float], float, float, float, float, float, float, float]] = {
    "waist_yaw": (Z, -0.8, 0.8, 4.0, 250.0, 1500.0, 80.0, 0.1),
    "waist_roll": (X, -0.5, 0.5, 4.0, 250.0, 1500.0, 80.0, 0.1),
    "waist_pitch": (Y, -0.4, 1.3, 4.0, 250.0, 1500.0, 80.0, 0.1),
    "hip_yaw": (Z, -0.7, 0.7, 6.0, 250.0, 1500.0, 60.0, 0.1),
    "hip_roll": (X, -0.5, 0.8, 6.0, 250.0, 1500.0, 60.0, 0.1),
    "hip_pitch": (Y, -2.1, 0.5, 6.0, 250.0, 1500.0, 60.0, 0.1),
    "knee": (Y, -0.05, 2.4, 6.0, 250.0, 1500.0, 60.0, 0.1),
    "ankle_pitch": (Y, -0.35, 0.87, 6.0, 150.0, 800.0, 40.0, 0.1),
    "ankle_roll": (X, -0.35, 0.35, 6.0, 80.0, 800.0, 40.0, 0.1),
    "shoulder_pitch": (Y, -3.1, 1.0, 6.0, 100.0, 1200.0, 60.0, 0.05),
    "shoulder_roll": (X, -1.59, 3.1, 6.0, 100.0, 1200.0, 60.0, 0.05),
    "shoulder_yaw": (Z, -2.618, 2.618, 6.0, 100.0, 1200.0, 60.0, 0.05),
    "elbow": (Y, -2.6, 0.0, 8.0, 80.0, 900.0, 40.0, 0.05),
    "wrist_yaw": (Z, -1.97, 1.97, 8.0, 25.0, 200.0, 5.0, 0.02),
    "wrist_pitch": (Y, -1.61, 1.61, 8.0, 25.0, 200.0, 5.0, 0.02),
    "wrist_roll": (X, -1.61, 1.61, 8.0, 25.0, 200.0, 5.0, 0.02),
}
ACCEL = 30.0  #: joint acceleration limit [rad/s^2] (our choice)
LEG_JOINTS = ("hip_yaw", "hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")
ARM_JOINTS = (
    "shoulder_pitch",
    "shoulder_roll",
    "shoulder_yaw",
    "elbow",
    "wrist_yaw",
    "wrist_pitch",
    "wrist_roll",
)
#: Home (left side; right mirrors rolls/yaws): slightly bent knees, arms hanging, elbows a little bent.
_HOME = {"hip_pitch": -0.1, "knee": 0.2, "ankle_pitch": -0.1, "shoulder_roll": 0.12, "elbow": -0.3}


#: The wrist frame turned 90 deg about the forearm: at wrist_yaw = 0 the forearm is neutral (a hanging hand's
#: palm faces the thigh, the fingers close along y like a human pinch across the palm), so wrist_yaw's
#: +-1.4 rad is pronation/supination about neutral, wrist_pitch flexion and wrist_roll deviation.
_NEUTRAL_FOREARM = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _joint(base: str, side: str) -> Joint:
    axis, lo, hi, vel, effort, kp, kv, armature = _JOINTS[base]
    if side == "right" and axis != Y:  # mirror about the sagittal plane: roll and yaw change sign
        lo, hi = -hi, -lo
    name = f"{side}_{base}" if side else base
    return Joint(name, "revolute", axis, lo, hi, vel, ACCEL, effort, kp, kv, armature=armature, damping=0.5)


def _segment(mass: float, length: float, radius: float, com_frac: float) -> Inertial:
    """A limb segment hanging along -z from its proximal joint: cylinder inertia [kg m^2]."""
    return Inertial.solid(
        mass, np.array([0.0, 0.0, -com_frac * length]), cylinder_inertia(mass, radius, length)
    )


def _limb(name: str, a: float, b: float, r: float, color: tuple[float, float, float, float]) -> tuple[Geom]:
    return (Geom.capsule_between(f"{name}:limb", (0.0, 0.0, -a), (0.0, 0.0, -b), r, color),)


def _leg(side: str) -> list[Link]:
    s = 1.0 if side == "left" else -1.0
    p = f"{side}_"
    foot_c = np.array([0.045, 0.0, -ANKLE_H + 0.025])
    return [
        Link(
            p + "thigh",
            "pelvis",
            transform((0.0, s * HIP_HALF_WIDTH, -HIP_DROP)),
            tuple(_joint(j, side) for j in LEG_JOINTS[:3]),
            _segment(0.1 * MASS, THIGH, 0.07, 0.433),
            _limb(p + "thigh", 0.03, THIGH - 0.03, 0.07, _CLOTH),
        ),
        Link(
            p + "shank",
            p + "thigh",
            transform((0.0, 0.0, -THIGH)),
            (_joint("knee", side),),
            _segment(0.0465 * MASS, SHANK, 0.05, 0.433),
            _limb(p + "shank", 0.03, SHANK - 0.03, 0.05, _CLOTH),
        ),
        Link(
            p + "foot",
            p + "shank",
            transform((0.0, 0.0, -SHANK)),
            tuple(_joint(j, side) for j in LEG_JOINTS[4:]),
            Inertial.solid(0.0145 * MASS, foot_c, box_inertia(0.0145 * MASS, (0.26, 0.1, 0.05))),
            (Geom(p + "foot:sole", "box", (0.13, 0.05, 0.025), transform(foot_c), (0.2, 0.2, 0.22, 1.0)),),
        ),
    ]


def _arm(side: str) -> tuple[list[Link], list[Frame]]:
    s = 1.0 if side == "left" else -1.0
    p = f"{side}_"
    group: CollisionGroup = "left" if side == "left" else "right"
    shoulder = transform((0.0, s * SHOULDER_HALF_WIDTH, SHOULDER_Z - _pelvis_height() - WAIST_Z))
    links = [
        Link(
            p + "upper_arm",
            "torso",
            shoulder,
            tuple(_joint(j, side) for j in ARM_JOINTS[:3]),
            _segment(0.028 * MASS, UPPER_ARM, 0.045, 0.436),
            _limb(p + "upper_arm", 0.0, UPPER_ARM - 0.03, 0.045, _SKIN),
            group,
        ),
        Link(
            p + "forearm",
            p + "upper_arm",
            transform((0.0, 0.0, -UPPER_ARM)),
            (_joint("elbow", side),),
            _segment(0.016 * MASS, FOREARM, 0.038, 0.43),
            _limb(p + "forearm", 0.0, FOREARM - 0.02, 0.038, _SKIN),
            group,
        ),
        Link(
            p + "wrist",
            p + "forearm",
            transform((0.0, 0.0, -FOREARM), _NEUTRAL_FOREARM),
            tuple(_joint(j, side) for j in ARM_JOINTS[4:]),
            Inertial.solid(0.02, np.zeros(3), np.eye(3) * 1e-5),
            (),
            group,
        ),
    ]
    # gripper frame in the (turned) wrist frame: z down the hand, y = the wrist's x (left at home),
    # x = y cross z
    mount = transform((0.0, 0.0, 0.0), np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]))
    hand_links, hand_frames = parallel_gripper(side, p + "wrist", mount, HAND, group)
    frames = [Frame(p + "shoulder", "torso", shoulder), *hand_frames]
    return links + hand_links, frames


def _pelvis_height() -> float:
    """Pelvis frame height at home with flat feet on the floor [m]."""
    hip, knee = _HOME["hip_pitch"], _HOME["knee"]
    return HIP_DROP + THIGH * math.cos(hip) + SHANK * math.cos(hip + knee) + ANKLE_H


def humanoid_description() -> RobotDescription:
    """The ``humanoid`` robot."""
    torso_c = np.array([0.0, 0.0, 0.2])
    chest_z = SHOULDER_Z - _pelvis_height() - WAIST_Z
    links = [
        Link(
            "pelvis",
            None,
            inertial=Inertial.solid(
                0.142 * MASS, np.array([0.0, 0.0, 0.02]), box_inertia(0.142 * MASS, (0.2, 0.32, 0.2))
            ),
            geoms=(Geom.capsule_between("pelvis:hips", (0.0, -0.07, 0.02), (0.0, 0.07, 0.02), 0.1, _CLOTH),),
        ),
        Link(
            "torso",
            "pelvis",
            transform((0.0, 0.0, WAIST_Z)),
            tuple(_joint(j, "") for j in ("waist_yaw", "waist_roll", "waist_pitch")),
            Inertial.solid(0.355 * MASS, torso_c, box_inertia(0.355 * MASS, (0.22, 0.34, 0.45))),
            (
                Geom.capsule_between(
                    "torso:trunk", (0.0, 0.0, 0.08), (0.0, 0.0, chest_z - 0.1), 0.13, _CLOTH
                ),
                Geom.capsule_between(
                    "torso:shoulders", (0.0, -0.15, chest_z - 0.02), (0.0, 0.15, chest_z - 0.02), 0.06, _CLOTH
                ),
            ),
        ),
        Link(
            "head",
            "torso",
            transform((0.0, 0.0, chest_z + 0.09)),
            (),
            Inertial.solid(
                0.081 * MASS, np.array([0.0, 0.0, 0.12]), box_inertia(0.081 * MASS, (0.2, 0.16, 0.25))
            ),
            (
                Geom.capsule_between("head:neck", (0.0, 0.0, -0.03), (0.0, 0.0, 0.04), 0.05, _SKIN),
                Geom("head:skull", "sphere", (0.1,), transform((0.01, 0.0, 0.14)), _SKIN),
            ),
        ),
    ]
    frames: list[Frame] = []
    home: dict[str, float] = {}
    for side in ("left", "right"):
        links += _leg(side)
        arm_links, arm_frames = _arm(side)
        links += arm_links
        frames += arm_frames
        frames.append(Frame(f"{side}_sole", f"{side}_foot", transform((0.045, 0.0, -ANKLE_H))))
        for base, value in _HOME.items():
            mirrored = base.endswith(("roll", "yaw")) and side == "right"
            home[f"{side}_{base}"] = -value if mirrored else value
        home.update({f"{side}_finger_a_joint": HAND.stroke, f"{side}_finger_b_joint": HAND.stroke})
    return RobotDescription(
        name=NAME,
        links=tuple(links),
        frames=tuple(frames),
        home=home,
        arm_joints={s: tuple(f"{s}_{j}" for j in ARM_JOINTS) for s in ("left", "right")},
        gripper_joints={s: (f"{s}_finger_a_joint", f"{s}_finger_b_joint") for s in ("left", "right")},
        tcp_frames={"left": "left_tcp", "right": "right_tcp"},
        shoulder_frames={"left": "left_shoulder", "right": "right_shoulder"},
        floating=True,
        root_home=transform((0.0, 0.0, _pelvis_height())),
        anchor="pelvis_anchor",
    )
