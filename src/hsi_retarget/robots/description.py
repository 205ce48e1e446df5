"""Kinematic/dynamic robot description: the one source of truth for the URDF and the MJCF of a robot.

A robot is a tree of :class:`Link` s. Each link's frame is placed in its parent's frame by ``origin`` and
then moved by its ``joints`` (applied in order, all at the link origin; several joints on one link become a
chain of massless links in URDF and several joints in one body in MJCF). Named :class:`Frame` s (TCPs,
shoulders, soles) are URDF links on fixed joints and MJCF sites. Conventions: [m], [rad], [kg]; inertia
tensors about the centre of mass with the link frame's axes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError

JointKind = Literal["revolute", "prismatic"]
GeomKind = Literal["box", "cylinder", "capsule", "sphere"]
#: Collision groups: ``body`` (base, torso, legs, head), ``left``/``right`` (arm + gripper of a side).
CollisionGroup = Literal["body", "left", "right"]

Mat4 = NDArray[np.float64]


def rot_x(angle: float) -> NDArray[np.float64]:
    """Rotation matrix (3, 3) about x by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> NDArray[np.float64]:
    """Rotation matrix (3, 3) about y by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> NDArray[np.float64]:
    """Rotation matrix (3, 3) about z by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def transform(
    pos: tuple[float, float, float] | NDArray[np.float64] = (0.0, 0.0, 0.0),
    rot: NDArray[np.float64] | None = None,
) -> Mat4:
    """Homogeneous transform (4, 4) from a position (3,) [m] and a rotation (3, 3)."""
    out = np.eye(4)
    if rot is not None:
        out[:3, :3] = rot
    out[:3, 3] = pos
    return out


def cylinder_inertia(mass: float, radius: float, length: float) -> NDArray[np.float64]:
    """Inertia tensor (3, 3) [kg m^2] of a solid cylinder about its centre, axis along z."""
    side = mass * (3.0 * radius**2 + length**2) / 12.0
    return np.diag([side, side, 0.5 * mass * radius**2])


def box_inertia(mass: float, size: tuple[float, float, float]) -> NDArray[np.float64]:
    """Inertia tensor (3, 3) [kg m^2] of a solid box of full extents ``size`` [m] about its centre."""
    x, y, z = size
    return np.diag([y * y + z * z, x * x + z * z, x * x + y * y]) * mass / 12.0


def axis_to_z(direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """A rotation (3, 3) whose z axis is the unit vector of ``direction`` (3,)."""
    z = np.asarray(direction, dtype=float)
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = helper - z * float(helper @ z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


@dataclass(frozen=True)
class Inertial:
    """Mass properties of a link."""

    mass: float  #: [kg]
    com: tuple[float, float, float]  #: centre of mass in the link frame [m]
    inertia: tuple[float, float, float, float, float, float]  #: (ixx, iyy, izz, ixy, ixz, iyz) [kg m^2]

    def __post_init__(self) -> None:
        tensor = self.tensor
        eig = np.linalg.eigvalsh(tensor)
        if self.mass <= 0.0 or eig[0] <= 0.0 or eig[0] + eig[1] < eig[2] * (1.0 - 1e-9):
            raise ConfigError(
                f"inertial mass {self.mass} kg, principal moments {eig} kg m^2: mass and moments must be "
                "positive and satisfy the triangle inequality"
            )

    @property
    def tensor(self) -> NDArray[np.float64]:
        """The inertia tensor (3, 3) [kg m^2] about the centre of mass, link-frame axes."""
        ixx, iyy, izz, ixy, ixz, iyz = self.inertia
        return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])

    @staticmethod
    def solid(mass: float, com: NDArray[np.float64], tensor: NDArray[np.float64]) -> Inertial:
        """An :class:`Inertial` from a centre of mass (3,) [m] and a (3, 3) tensor [kg m^2]."""
        t = 0.5 * (tensor + tensor.T)
        c = np.asarray(com, dtype=float)
        return Inertial(
            float(mass),
            (float(c[0]), float(c[1]), float(c[2])),
            (float(t[0, 0]), float(t[1, 1]), float(t[2, 2]), float(t[0, 1]), float(t[0, 2]), float(t[1, 2])),
        )


@dataclass(frozen=True)
class Geom:
    """A collision (and visual) primitive, posed in the link frame.

    ``size`` follows MJCF: box half extents (3,) [m]; cylinder/capsule (radius, half length) [m] with the
    axis along the primitive's z; sphere (radius,) [m].
    """

    name: str
    kind: GeomKind
    size: tuple[float, ...]
    pose: Mat4 = field(default_factory=lambda: np.eye(4))  #: (4, 4) pose in the link frame [m]
    rgba: tuple[float, float, float, float] = (0.6, 0.6, 0.65, 1.0)  #: colour [0..1]

    @staticmethod
    def capsule_between(
        name: str,
        p0: NDArray[np.float64] | tuple[float, ...],
        p1: NDArray[np.float64] | tuple[float, ...],
        radius: float,
        rgba: tuple[float, float, float, float] = (0.6, 0.6, 0.65, 1.0),
    ) -> Geom:
        """A capsule of ``radius`` [m] whose segment runs from ``p0`` to ``p1`` (3,) [m] (link frame)."""
        a, b = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
        half = 0.5 * float(np.linalg.norm(b - a))
        if half < 1e-6:
            return Geom(name, "sphere", (radius,), transform(0.5 * (a + b)), rgba)
        return Geom(name, "capsule", (radius, half), transform(0.5 * (a + b), axis_to_z(b - a)), rgba)


@dataclass(frozen=True)
class Joint:
    """A one-DoF joint with its limits and its position actuator."""

    name: str
    kind: JointKind
    axis: tuple[float, float, float]  #: unit axis in the link frame [-]
    lower: float  #: position limit [rad] or [m]
    upper: float  #: position limit [rad] or [m]
    velocity: float  #: speed limit [rad/s] or [m/s]
    acceleration: float  #: acceleration limit [rad/s^2] or [m/s^2] (not in URDF; model metadata)
    effort: float  #: actuator torque/force limit [N m] or [N]
    kp: float  #: position actuator stiffness [N m/rad] or [N/m]
    kv: float  #: position actuator damping [N m s/rad] or [N s/m]
    armature: float = 0.0  #: reflected rotor inertia [kg m^2] or [kg]
    damping: float = 0.0  #: passive viscous damping [N m s/rad] or [N s/m]

    def __post_init__(self) -> None:
        if not self.lower < self.upper:
            raise ConfigError(f"joint {self.name}: lower limit {self.lower} must be below {self.upper}")
        if min(self.velocity, self.acceleration, self.effort, self.kp) <= 0.0 or self.kv < 0.0:
            raise ConfigError(f"joint {self.name}: velocity, acceleration, effort and kp must be > 0")
        if abs(float(np.linalg.norm(self.axis)) - 1.0) > 1e-9:
            raise ConfigError(f"joint {self.name}: axis {self.axis} must be a unit vector")


@dataclass(frozen=True)
class Link:
    """A rigid link: placement in the parent link, joints, mass properties and collision geometry."""

    name: str
    parent: str | None  #: parent link name; None for the root
    origin: Mat4 = field(default_factory=lambda: np.eye(4))  #: (4, 4) pose in the parent link frame [m]
    joints: tuple[Joint, ...] = ()  #: joints applied in order at the link origin (empty: fixed)
    inertial: Inertial | None = None
    geoms: tuple[Geom, ...] = ()
    group: CollisionGroup = "body"


@dataclass(frozen=True)
class Frame:
    """A named frame rigidly attached to a link (URDF: link on a fixed joint; MJCF: site)."""

    name: str
    link: str
    pose: Mat4 = field(default_factory=lambda: np.eye(4))  #: (4, 4) pose in the link frame [m]


@dataclass(frozen=True)
class RobotDescription:
    """A whole robot: links in parent-before-child order, named frames, semantics and the home pose."""

    name: str
    links: tuple[Link, ...]
    frames: tuple[Frame, ...]
    home: dict[str, float]  #: joint name -> home position [rad] or [m] (missing: 0)
    arm_joints: dict[str, tuple[str, ...]]  #: side -> arm joint names, proximal first
    gripper_joints: dict[str, tuple[str, ...]]  #: side -> finger joint names
    tcp_frames: dict[str, str]  #: side -> TCP frame name (z: approach, y: finger closing direction)
    shoulder_frames: dict[str, str]  #: side -> shoulder frame name
    floating: bool = False  #: root link on a free joint (``root_joint``)
    root_home: Mat4 = field(default_factory=lambda: np.eye(4))  #: (4, 4) home pose of a floating root [m]
    anchor: str | None = None  #: mocap body welded to the root in MJCF (weld inactive by default)

    def __post_init__(self) -> None:
        seen: set[str] = set()
        names: set[str] = set()
        for link in self.links:
            if link.parent is not None and link.parent not in seen:
                raise ConfigError(f"link {link.name}: parent {link.parent} must come earlier in the list")
            if link.name in names:
                raise ConfigError(f"duplicate link name {link.name}")
            seen.add(link.name)
            names.add(link.name)
        for j in self.joints:
            if j.name in names:
                raise ConfigError(f"joint name {j.name} clashes with a link or joint name")
            names.add(j.name)
            home = self.home.get(j.name, 0.0)
            if not j.lower <= home <= j.upper:
                raise ConfigError(f"home {home} of joint {j.name} is outside [{j.lower}, {j.upper}]")
        for f in self.frames:
            if f.link not in seen or f.name in names:
                raise ConfigError(f"frame {f.name}: unknown link {f.link} or duplicate name")
            names.add(f.name)
        if sum(1 for link in self.links if link.parent is None) != 1:
            raise ConfigError(f"robot {self.name} must have exactly one root link")

    @property
    def joints(self) -> tuple[Joint, ...]:
        """All joints in tree order."""
        return tuple(j for link in self.links for j in link.joints)

    def joint(self, name: str) -> Joint:
        """The joint called ``name``."""
        for j in self.joints:
            if j.name == name:
                return j
        raise ConfigError(f"robot {self.name} has no joint {name!r}; joints: {[j.name for j in self.joints]}")

    def children(self, name: str) -> tuple[Link, ...]:
        """Links whose parent is ``name``."""
        return tuple(link for link in self.links if link.parent == name)

    @property
    def total_mass(self) -> float:
        """Sum of the link masses [kg]."""
        return float(sum(link.inertial.mass for link in self.links if link.inertial is not None))
