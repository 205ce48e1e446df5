"""Geometric primitives shared by the MuJoCo model and the trimesh meshes of a scene.

Every body of a scene is described once as a list of :class:`Prim` (box, cylinder, capsule) in the
body frame; :mod:`hsi_planning.scene.mjcf` writes them as MJCF geoms and
:mod:`hsi_planning.scene.geometry` turns the very same list into triangle meshes, so both agree.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, cast

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import SceneError

PrimKind = Literal["box", "cylinder", "capsule"]

#: Polygon sections used to mesh round primitives (max chord error 0.2 % of the radius).
_SECTIONS = 48


@dataclass(frozen=True)
class Prim:
    """One collision/visual primitive of a body, posed in the body frame.

    ``size`` follows MJCF: box ``(hx, hy, hz)`` half extents [m]; cylinder ``(radius, half_height)`` [m];
    capsule ``(radius, half_length)`` [m] of the cylindrical part. The axis of cylinders and capsules is
    the primitive's local z.
    """

    kind: PrimKind
    size: tuple[float, ...]
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: centre in the body frame [m]
    rot: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)  #: row-major 3x3 rotation [-]
    rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0)  #: colour [0..1]
    part: str = "geom"  #: short part name, used in the geom name

    def __post_init__(self) -> None:
        expected = 3 if self.kind == "box" else 2
        if len(self.size) != expected or min(self.size) <= 0.0:
            raise SceneError(
                f"{self.kind} prim '{self.part}': size {self.size} must be {expected} positive values"
            )

    @property
    def matrix(self) -> NDArray[np.float64]:
        """Pose of the primitive in the body frame: (4, 4) homogeneous transform [m]."""
        out = np.eye(4)
        out[:3, :3] = np.asarray(self.rot, dtype=float).reshape(3, 3)
        out[:3, 3] = self.pos
        return out

    @property
    def volume(self) -> float:
        """Volume as MuJoCo computes it [m^3]."""
        if self.kind == "box":
            return float(8.0 * self.size[0] * self.size[1] * self.size[2])
        r, h = self.size
        cyl = float(np.pi * r * r * 2.0 * h)
        return cyl if self.kind == "cylinder" else cyl + float(4.0 / 3.0 * np.pi * r**3)

    def transformed(self, transform: NDArray[np.float64]) -> Prim:
        """The same primitive with its pose pre-multiplied by ``transform`` (4, 4)."""
        m = transform @ self.matrix
        return Prim(
            kind=self.kind,
            size=self.size,
            pos=(float(m[0, 3]), float(m[1, 3]), float(m[2, 3])),
            rot=tuple(float(v) for v in m[:3, :3].reshape(-1)),
            rgba=self.rgba,
            part=self.part,
        )

    def mesh(self) -> trimesh.Trimesh:
        """Triangle mesh of the primitive in the body frame."""
        if self.kind == "box":
            mesh = trimesh.creation.box(extents=[2.0 * s for s in self.size])
        elif self.kind == "cylinder":
            mesh = trimesh.creation.cylinder(
                radius=self.size[0], height=2.0 * self.size[1], sections=_SECTIONS
            )
        else:
            mesh = trimesh.creation.capsule(
                height=2.0 * self.size[1], radius=self.size[0], count=[_SECTIONS, _SECTIONS]
            )
        mesh.apply_transform(self.matrix)
        return cast(trimesh.Trimesh, mesh)


def box_from_bounds(
    lo: tuple[float, float, float],
    hi: tuple[float, float, float],
    part: str,
    rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0),
) -> Prim:
    """An axis-aligned box spanning ``lo``..``hi`` (3,) [m] in the body frame."""
    if any(h <= lo_ for lo_, h in zip(lo, hi, strict=True)):
        raise SceneError(f"box '{part}': bounds {lo}..{hi} are empty (a size is too small)")
    size = tuple(0.5 * (h - lo_) for lo_, h in zip(lo, hi, strict=True))
    pos = tuple(0.5 * (h + lo_) for lo_, h in zip(lo, hi, strict=True))
    return Prim("box", size, pos=(pos[0], pos[1], pos[2]), rgba=rgba, part=part)


def rot_z(angle: float) -> NDArray[np.float64]:
    """Rotation about +z by ``angle`` [rad] as a (3, 3) matrix."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def pose_matrix(
    pos: NDArray[np.float64] | tuple[float, ...], rot: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """A (4, 4) homogeneous transform from a position (3,) [m] and an optional (3, 3) rotation."""
    out = np.eye(4)
    out[:3, 3] = np.asarray(pos, dtype=float)
    if rot is not None:
        out[:3, :3] = rot
    return out


def rot_tuple(rot: NDArray[np.float64]) -> tuple[float, ...]:
    """A (3, 3) rotation as the row-major 9-tuple stored in :class:`Prim`."""
    return tuple(float(v) for v in np.asarray(rot, dtype=float).reshape(-1))


def matrix_to_quat(rot: NDArray[np.float64]) -> NDArray[np.float64]:
    """A (3, 3) rotation as a unit quaternion (4,) in MuJoCo's (w, x, y, z) order."""
    quat: NDArray[np.float64] = Rotation.from_matrix(rot).as_quat(scalar_first=True)
    if quat[0] < 0.0:
        quat = -quat
    return quat


@dataclass(frozen=True)
class JointPlan:
    """A one-DoF articulation of a furniture part (door hinge or drawer slide)."""

    kind: Literal["hinge", "slide"]
    axis: tuple[float, float, float]  #: joint axis in the body frame [-]
    pos: tuple[float, float, float]  #: a point on the axis in the body frame [m]
    range: tuple[float, float]  #: joint limits [rad] (hinge) or [m] (slide)
    damping: float  #: viscous damping [N·m·s/rad] or [N·s/m]


@dataclass(frozen=True)
class BodyPlan:
    """One labelled body of the scene: its world pose at rest, primitives and articulation."""

    name: str  #: body (= label) name
    semantic_class: str  #: e.g. "mug", "cabinet_door"
    kind: Literal["object", "furniture", "floor"]
    pose: NDArray[np.float64]  #: (4, 4) body frame in the world at rest [m]
    prims: tuple[Prim, ...]
    parent: str | None = None  #: label parent (furniture name for furniture parts)
    joint: JointPlan | None = None  #: hinge/slide joint; objects get a free joint instead
    mass: float = 0.0  #: object mass [kg]; 0 for static bodies
    friction: float = 1.0  #: sliding friction coefficient [-]
    density: float = 600.0  #: density of articulated furniture parts [kg/m^3]
    extras: dict[str, float] = field(default_factory=dict)  #: free-form numbers (e.g. handle height) [m]

    def world_prims(self) -> list[Prim]:
        """The primitives posed in the world frame at rest."""
        return [p.transformed(self.pose) for p in self.prims]

    def mesh(self) -> trimesh.Trimesh:
        """All primitives concatenated into one world-frame mesh at rest."""
        return cast(trimesh.Trimesh, trimesh.util.concatenate([p.mesh() for p in self.world_prims()]))
