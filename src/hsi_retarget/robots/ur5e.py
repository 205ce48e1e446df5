"""UR5e arm from Universal Robots' published Denavit–Hartenberg parameters and link masses.

Source: UR's "Parameters for calculations of kinematics and dynamics" (e-Series): DH ``d``, ``a``, ``alpha``
and the link masses/centres of mass below. URDF link ``i`` has the frame of joint ``i`` (DH frame ``i-1``
rotated by ``q_i``), so the next joint sits at ``Tz(d_i) Tx(a_i) Rx(alpha_i)`` in it and the arm chain
reproduces the DH product exactly. Inertias are solid cylinders (the published table gives none).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError
from hsi_retarget.robots.description import (
    CollisionGroup,
    Frame,
    Geom,
    Inertial,
    Joint,
    Link,
    Mat4,
    cylinder_inertia,
    rot_x,
    rot_y,
    transform,
)

UR5E_D = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)  #: DH d [m]
UR5E_A = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)  #: DH a [m]
UR5E_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)  #: DH alpha [rad]
UR5E_MASS = (3.761, 8.058, 2.846, 1.37, 1.3, 0.365)  #: link masses [kg]
#: Centres of mass in DH frame i [m] (published).
UR5E_COM = (
    (0.0, -0.02561, 0.00193),
    (0.2125, 0.0, 0.11336),
    (0.15, 0.0, 0.0265),
    (0.0, -0.0018, 0.01634),
    (0.0, 0.0018, 0.01634),
    (0.0, 0.0, -0.001159),
)
UR5E_BASE_MASS = 4.0  #: mounting base [kg] (not in the DH table; ur_description's value)
#: Inertia cylinders in DH frame i: (radius [m], length [m], axis).
_CYLINDERS = (
    (0.06, 0.15, "y"),
    (0.054, 0.425, "x"),
    (0.045, 0.392, "x"),
    (0.045, 0.12, "y"),
    (0.045, 0.12, "y"),
    (0.0375, 0.0345, "z"),
)
JOINTS = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
LINKS = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link")
EFFORT = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)  #: joint torque limits [N m] (size 3/3/3/1/1/1 joints)
SPEED = math.pi  #: joint speed limit, every joint [rad/s] (180 deg/s)
ACCEL = 10.0  #: joint acceleration limit used by the planners [rad/s^2] (our choice; not published)
_KP = (1.0e4, 1.0e4, 1.0e4, 2.0e3, 2.0e3, 2.0e3)  #: position gains [N m/rad]
_KV = (400.0, 400.0, 400.0, 40.0, 40.0, 40.0)  #: actuator damping [N m s/rad]
_ARMATURE = (0.2, 0.2, 0.2, 0.05, 0.05, 0.05)  #: reflected rotor inertia [kg m^2] (approximate)
_GREY = (0.7, 0.72, 0.75, 1.0)
_BLUE = (0.25, 0.45, 0.7, 1.0)


def dh_transform(theta: float, d: float, a: float, alpha: float) -> Mat4:
    """Standard DH link transform ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``: (4, 4) [m]."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def ur5e_fk(q: NDArray[np.float64]) -> Mat4:
    """Flange (tool0 = DH frame 6) pose in the arm base (DH frame 0) for joint angles ``q`` (6,) [rad]."""
    q = np.asarray(q, dtype=float)
    if q.shape != (6,):
        raise ConfigError(f"ur5e_fk needs 6 joint angles, got shape {q.shape}")
    out = np.eye(4)
    for i in range(6):
        out = out @ dh_transform(float(q[i]), UR5E_D[i], UR5E_A[i], UR5E_ALPHA[i])
    return out


def _link_const(i: int) -> Mat4:
    """Constant part of DH link ``i`` (0-based): DH frame i+1 in the frame of joint i+1."""
    return dh_transform(0.0, UR5E_D[i], UR5E_A[i], UR5E_ALPHA[i])


def _inertial(i: int) -> Inertial:
    radius, length, axis = _CYLINDERS[i]
    rot = {"x": rot_y(math.pi / 2), "y": rot_x(math.pi / 2), "z": np.eye(3)}[axis]
    tensor_dh = rot @ cylinder_inertia(UR5E_MASS[i], radius, length) @ rot.T
    c = _link_const(i)
    com = c[:3, :3] @ np.asarray(UR5E_COM[i]) + c[:3, 3]
    return Inertial.solid(UR5E_MASS[i], com, c[:3, :3] @ tensor_dh @ c[:3, :3].T)


#: Collision capsules per link in DH frame i: (part, p0, p1, radius [m]).
_CAPSULES: tuple[
    tuple[tuple[str, tuple[float, float, float], tuple[float, float, float], float], ...], ...
] = (
    (("pan", (0.0, -0.07, 0.0), (0.0, 0.0, 0.0), 0.06), ("lift", (0.0, 0.0, 0.0), (0.0, 0.0, 0.135), 0.06)),
    (
        ("tube", (0.425, 0.0, 0.135), (0.0, 0.0, 0.135), 0.055),
        ("elbow", (0.0, 0.0, 0.135), (0.0, 0.0, 0.03), 0.05),
    ),
    (
        ("tube", (0.3922, 0.0, 0.02), (0.0, 0.0, 0.02), 0.042),
        ("wrist", (0.0, 0.0, 0.02), (0.0, 0.0, 0.07), 0.04),
    ),
    (("housing", (0.0, -0.065, 0.0), (0.0, 0.02, 0.0), 0.045),),
    (("housing", (0.0, 0.06, 0.0), (0.0, 0.0, -0.02), 0.045),),
    (("flange", (0.0, 0.0, -0.06), (0.0, 0.0, -0.015), 0.04),),
)


def ur5e_arm(side: str, parent: str, mount: Mat4, group: CollisionGroup) -> tuple[list[Link], list[Frame]]:
    """The links of one UR5e mounted at ``mount`` (4, 4) (DH base frame in ``parent``), names ``{side}_*``.

    Frames: ``{side}_shoulder`` (on the shoulder-lift axis, above the base; fixed in the parent),
    ``{side}_tool0`` (DH frame 6, the flange, z out of the flange).
    """
    base = f"{side}_ur_base_link"
    base_inertia = cylinder_inertia(UR5E_BASE_MASS, 0.075, 0.09)
    links = [
        Link(
            base,
            parent,
            np.array(mount, dtype=float),
            inertial=Inertial.solid(UR5E_BASE_MASS, np.array([0.0, 0.0, 0.045]), base_inertia),
            geoms=(Geom(f"{base}:mount", "cylinder", (0.075, 0.045), transform((0.0, 0.0, 0.045)), _BLUE),),
            group=group,
        ),
    ]
    prev, origin = base, np.eye(4)
    for i in range(6):
        name = f"{side}_{LINKS[i]}"
        joint = Joint(
            f"{side}_{JOINTS[i]}_joint",
            "revolute",
            (0.0, 0.0, 1.0),
            -math.pi if i == 2 else -2.0 * math.pi,
            math.pi if i == 2 else 2.0 * math.pi,
            SPEED,
            ACCEL,
            EFFORT[i],
            _KP[i],
            _KV[i],
            armature=_ARMATURE[i],
            damping=0.5,
        )
        c = _link_const(i)
        geoms = tuple(
            Geom.capsule_between(
                f"{name}:{part}",
                c[:3, :3] @ np.asarray(p0) + c[:3, 3],
                c[:3, :3] @ np.asarray(p1) + c[:3, 3],
                r,
                _BLUE if i in (0, 3, 5) else _GREY,
            )
            for part, p0, p1, r in _CAPSULES[i]
        )
        links.append(Link(name, prev, origin, (joint,), _inertial(i), geoms, group))
        prev, origin = name, c
    frames = [
        Frame(f"{side}_shoulder", base, transform((0.0, 0.0, UR5E_D[0]))),
        Frame(f"{side}_tool0", prev, origin),
    ]
    return links, frames
