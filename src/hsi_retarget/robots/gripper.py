"""Parallel-jaw gripper: a palm and two slide fingers, with a ``tcp`` frame between the fingertips.

Finger ``a`` slides along +y of the gripper frame, finger ``b`` along -y; each joint is the gap between
its pad and the mid-plane [m] (0 = closed, ``stroke`` = open). The TCP frame has z along the approach
direction (out of the palm) and y along the finger axis (finger ``a`` opens towards +y).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hsi_retarget.robots.description import (
    CollisionGroup,
    Frame,
    Geom,
    Inertial,
    Joint,
    Link,
    Mat4,
    box_inertia,
    transform,
)

_DARK = (0.15, 0.15, 0.17, 1.0)
_PAD = (0.35, 0.35, 0.38, 1.0)


@dataclass(frozen=True)
class GripperSpec:
    """Dimensions and drive of a parallel-jaw gripper."""

    stroke: float  #: travel per finger [m] (total opening = 2 * stroke)
    palm_size: tuple[float, float, float]  #: palm box full extents (x, y, z) [m], z from the mount
    palm_mass: float  #: [kg]
    finger_size: tuple[float, float, float]  #: finger box full extents (x, y, z) [m]
    finger_mass: float  #: per finger [kg]
    tcp_depth: float  #: TCP distance below the fingertips, along -z [m]
    speed: float  #: finger speed limit [m/s]
    force: float  #: finger force limit [N]
    kp: float  #: finger position gain [N/m]
    kv: float  #: finger damping [N s/m]
    coupling: float = 0.0  #: length of a cylindrical coupling (radius 0.038 m) before the palm [m]


#: Robotiq 2F-85-like: 85 mm opening, 0.92 kg.
ROBOTIQ_2F85 = GripperSpec(
    stroke=0.0425,
    palm_size=(0.07, 0.125, 0.08),
    palm_mass=0.8,
    finger_size=(0.022, 0.014, 0.055),
    finger_mass=0.06,
    tcp_depth=0.015,
    speed=0.075,
    force=100.0,
    kp=2000.0,
    kv=30.0,
    coupling=0.01,
)


#: Robotiq 2F-140-like: 140 mm opening (mugs, bottles and boxes up to ~13 cm fit with room to spare),
#: the 2F-85's finger and palm depth so the TCP stays where it was, a wider palm for the longer stroke.
ROBOTIQ_2F140 = replace(
    ROBOTIQ_2F85,
    stroke=0.07,
    palm_size=(0.07, 0.15, 0.08),
    palm_mass=0.95,
    finger_mass=0.07,
    speed=0.1,
    force=125.0,
)


def parallel_gripper(
    side: str, parent: str, mount: Mat4, spec: GripperSpec, group: CollisionGroup
) -> tuple[list[Link], list[Frame]]:
    """Links ``{side}_gripper_link``, ``{side}_finger_a``, ``{side}_finger_b`` and the ``{side}_tcp`` frame.

    ``mount`` (4, 4): the gripper frame (z out of the palm) in the ``parent`` link frame.
    """
    base = f"{side}_gripper_link"
    px, py, pz = spec.palm_size
    z0 = spec.coupling
    geoms = [Geom(f"{base}:palm", "box", (px / 2, py / 2, pz / 2), transform((0.0, 0.0, z0 + pz / 2)), _DARK)]
    if spec.coupling > 0.0:
        geoms.append(
            Geom(f"{base}:coupling", "cylinder", (0.038, z0 / 2), transform((0.0, 0.0, z0 / 2)), _DARK)
        )
    palm_inertia = Inertial.solid(
        spec.palm_mass,
        np.array([0.0, 0.0, z0 + pz / 2]),
        box_inertia(spec.palm_mass, (px, max(py, 1e-3), pz + z0)),
    )
    links = [
        Link(
            base, parent, np.array(mount, dtype=float), inertial=palm_inertia, geoms=tuple(geoms), group=group
        )
    ]
    fx, fy, fz = spec.finger_size
    finger_top = z0 + pz
    for tag, sign in (("a", 1.0), ("b", -1.0)):
        name = f"{side}_finger_{tag}"
        joint = Joint(
            f"{name}_joint",
            "prismatic",
            (0.0, sign, 0.0),
            0.0,
            spec.stroke,
            spec.speed,
            1.0,
            spec.force,
            spec.kp,
            spec.kv,
            armature=0.05,
            damping=1.0,
        )
        centre = np.array([0.0, sign * fy / 2, fz / 2])
        links.append(
            Link(
                name,
                base,
                transform((0.0, 0.0, finger_top)),
                (joint,),
                Inertial.solid(spec.finger_mass, centre, box_inertia(spec.finger_mass, (fx, fy, fz))),
                (Geom(f"{name}:pad", "box", (fx / 2, fy / 2, fz / 2), transform(centre), _PAD),),
                group,
            )
        )
    tcp = transform((0.0, 0.0, finger_top + fz - spec.tcp_depth))
    return links, [Frame(f"{side}_tcp", base, tcp)]
