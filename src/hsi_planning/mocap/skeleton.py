"""Common skeleton and motion dataclasses for ASF/AMC and BVH, and forward kinematics.

One kinematic model covers both formats. Every joint ``j`` has a rest offset ``o_j``, a rest axis frame
``C_j`` (Acclaim ``axis``; identity for BVH) and an ordered list of degrees of freedom. With ``M_j`` the
rotation built from the joint's rotation channels, the rest-relative world rotation is

    Q_j = Q_parent · C_j · M_j · C_j⁻¹        (the standard Acclaim formula L = C·M·C⁻¹)

and the world orientation of the joint's own frame is ``Q_j · C_j``. Positions follow the source
convention (:attr:`Skeleton.convention`):

- ``"acclaim"`` (ASF): a joint is a *bone*; its point is the bone's distal end,
  ``p_j = p_parent + Q_j · o_j`` with ``o_j = length · direction`` — what Acclaim viewers draw.
- ``"bvh"``: a joint is a rotation centre, ``p_j = p_parent + Q_parent · o_j``; End Sites become extra
  joints named ``<parent>_end`` without channels.

Rotation channel order: Acclaim ``dof rx ry rz`` applies x first (``M = Rz·Ry·Rx``); a BVH channel list
``Zrotation Yrotation Xrotation`` is read left to right as intrinsic rotations (``M = Rz·Ry·Rx``). Each
format's loader stores the order so that :func:`rotation_from_channels` composes ``M`` correctly.

World frame: the stack is z-up (x forward, y left, z up). Acclaim and BVH files are y-up; the loaders'
default ``world_from_source`` is the proper rotation ``x_w = z_s, y_w = x_s, z_w = y_s``
(:data:`Z_UP_FROM_Y_UP`), which maps the Acclaim rest pose (facing +z, left +x) to facing +x, left +y.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import MotionDataError

FloatArray = NDArray[np.float64]
Convention = Literal["acclaim", "bvh"]

#: (3, 3) rotation taking y-up source coordinates (Acclaim/BVH) to the stack's z-up world.
Z_UP_FROM_Y_UP: FloatArray = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

ROTATION_DOFS = ("rx", "ry", "rz")
TRANSLATION_DOFS = ("tx", "ty", "tz")
VALID_DOFS = ROTATION_DOFS + TRANSLATION_DOFS


def axis_rotations(axis: str, angles: FloatArray) -> FloatArray:
    """Rotation matrices about one coordinate axis.

    Args:
        axis: ``"x"``, ``"y"`` or ``"z"``.
        angles: (T,) [rad].

    Returns:
        (T, 3, 3) rotation matrices (column-vector convention).
    """
    a = np.asarray(angles, dtype=np.float64).reshape(-1)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros((a.shape[0], 3, 3))
    i = "xyz".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    out[:, i, i] = 1.0
    out[:, j, j] = c
    out[:, k, k] = c
    out[:, k, j] = s
    out[:, j, k] = -s
    return out


def euler_matrix(angles_rad: FloatArray, order: str) -> FloatArray:
    """Single rotation ``R = R_{order[-1]} · … · R_{order[0]}`` (first letter applied first).

    Args:
        angles_rad: (3,) [rad], in the order of ``order`` (e.g. ``"xyz"``).
        order: permutation of ``"xyz"`` (case-insensitive).

    Returns:
        (3, 3) rotation matrix.
    """
    rot = np.eye(3)
    for axis, angle in zip(order.lower(), np.asarray(angles_rad, dtype=np.float64), strict=True):
        rot = axis_rotations(axis, np.array([angle]))[0] @ rot
    return rot


@dataclass(frozen=True)
class Joint:
    """One joint (Acclaim bone or BVH joint).

    Attributes:
        name: unique joint name.
        parent: parent joint name; ``None`` for the root.
        offset: (3,) [m] rest offset in the source frame (see the module docstring for its meaning).
        axis: (3, 3) rest orientation C of the joint's local frame in the source frame.
        dofs: channel names in file order, each of ``rx ry rz tx ty tz``.
        rotation_order: ``"applied"`` (first rotation channel is applied first: Acclaim) or
            ``"intrinsic"`` (first channel is the outermost matrix: BVH).
    """

    name: str
    parent: str | None
    offset: FloatArray
    axis: FloatArray = field(default_factory=lambda: np.eye(3))
    dofs: tuple[str, ...] = ()
    rotation_order: Literal["applied", "intrinsic"] = "applied"

    def __post_init__(self) -> None:
        offset = np.array(self.offset, dtype=np.float64, copy=True).reshape(-1)
        axis = np.array(self.axis, dtype=np.float64, copy=True)
        if offset.shape != (3,) or not np.all(np.isfinite(offset)):
            raise MotionDataError(
                f"joint {self.name!r}: offset must be 3 finite numbers, got {self.offset!r}"
            )
        if axis.shape != (3, 3) or not np.allclose(axis @ axis.T, np.eye(3), atol=1e-6):
            raise MotionDataError(f"joint {self.name!r}: axis must be a (3, 3) rotation matrix")
        bad = [d for d in self.dofs if d not in VALID_DOFS]
        if bad:
            raise MotionDataError(f"joint {self.name!r}: unknown dof(s) {bad}; valid: {list(VALID_DOFS)}")
        if len(set(self.dofs)) != len(self.dofs):
            raise MotionDataError(f"joint {self.name!r}: repeated dof in {self.dofs}")
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "axis", axis)


@dataclass(frozen=True)
class Skeleton:
    """A kinematic tree in topological order (parents before children, root first).

    Attributes:
        name: skeleton name (e.g. the ASF ``:name`` or the file stem).
        joints: the joints, root first.
        convention: ``"acclaim"`` (joint points are bone ends) or ``"bvh"`` (rotation centres).
        world_from_source: (3, 3) rotation from the file's frame to the stack's z-up world.
        length_unit_m: [m] length of one file length unit (translation channels in motion files).
    """

    name: str
    joints: tuple[Joint, ...]
    convention: Convention = "acclaim"
    world_from_source: FloatArray = field(default_factory=Z_UP_FROM_Y_UP.copy)
    length_unit_m: float = 1.0

    def __post_init__(self) -> None:
        if not self.joints:
            raise MotionDataError(f"skeleton {self.name!r} has no joints")
        seen: set[str] = set()
        for i, joint in enumerate(self.joints):
            if joint.name in seen:
                raise MotionDataError(f"skeleton {self.name!r}: duplicate joint {joint.name!r}")
            if (i == 0) != (joint.parent is None):
                raise MotionDataError(f"skeleton {self.name!r}: exactly the first joint must be the root")
            if joint.parent is not None and joint.parent not in seen:
                raise MotionDataError(
                    f"skeleton {self.name!r}: joint {joint.name!r} comes before its parent {joint.parent!r}"
                )
            seen.add(joint.name)
        rot = np.array(self.world_from_source, dtype=np.float64, copy=True)
        if rot.shape != (3, 3) or not np.isclose(np.linalg.det(rot), 1.0, atol=1e-6):
            raise MotionDataError("world_from_source must be a (3, 3) proper rotation")
        object.__setattr__(self, "world_from_source", rot)
        if not self.length_unit_m > 0:
            raise MotionDataError(f"length_unit_m must be > 0 [m], got {self.length_unit_m}")

    @property
    def names(self) -> tuple[str, ...]:
        """Joint names in topological order."""
        return tuple(j.name for j in self.joints)

    def joint(self, name: str) -> Joint:
        """The joint called ``name``; :class:`MotionDataError` listing valid names otherwise."""
        for j in self.joints:
            if j.name == name:
                return j
        raise MotionDataError(f"skeleton {self.name!r} has no joint {name!r}; joints: {list(self.names)}")

    def channels(self) -> tuple[tuple[str, str], ...]:
        """All (joint, dof) channels in skeleton order."""
        return tuple((j.name, d) for j in self.joints for d in j.dofs)


@dataclass(frozen=True)
class Motion:
    """Joint-channel samples of one clip.

    Attributes:
        channels: (joint, dof) per column; dofs ``rx ry rz`` in [rad], ``tx ty tz`` in [m] (source frame).
        values: (T, D) channel values.
        fps: [Hz] frame rate.
    """

    channels: tuple[tuple[str, str], ...]
    values: FloatArray
    fps: float = 120.0

    def __post_init__(self) -> None:
        values = np.array(self.values, dtype=np.float64, copy=True)
        if values.ndim != 2 or values.shape[1] != len(self.channels):
            raise MotionDataError(
                f"motion values must be (T, {len(self.channels)}) for its channels, got {values.shape}"
            )
        if not np.all(np.isfinite(values)):
            raise MotionDataError("motion values contain NaN or infinity")
        if not self.fps > 0:
            raise MotionDataError(f"fps must be > 0 [Hz], got {self.fps}")
        object.__setattr__(self, "values", values)

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.values.shape[0])

    def column(self, joint: str, dof: str) -> FloatArray | None:
        """(T,) values of one channel, or ``None`` when the motion does not have it."""
        for i, ch in enumerate(self.channels):
            if ch == (joint, dof):
                return np.array(self.values[:, i])
        return None


@dataclass(frozen=True)
class JointTrajectories:
    """Forward-kinematics result in the stack's z-up world.

    Attributes:
        positions: joint name → (T, 3) [m] joint point (bone end for Acclaim, centre for BVH).
        rotations: joint name → (T, 3, 3) world orientation of the joint's local frame.
        fps: [Hz] frame rate.
        convention: the skeleton's convention (what a joint point means).
    """

    positions: dict[str, FloatArray]
    rotations: dict[str, FloatArray]
    fps: float
    convention: Convention = "acclaim"

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(next(iter(self.positions.values())).shape[0])

    @property
    def t(self) -> FloatArray:
        """(T,) [s] sample times from 0."""
        return np.arange(self.n_frames) / self.fps


def rotation_from_channels(joint: Joint, values: dict[str, FloatArray], n: int) -> FloatArray:
    """(T, 3, 3) rotation M of ``joint`` from its rotation channels (missing channels are 0 [rad])."""
    rot = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    rot_dofs = [d for d in joint.dofs if d in ROTATION_DOFS]
    for dof in rot_dofs:
        step = axis_rotations(dof[1], values.get(dof, np.zeros(n)))
        rot = step @ rot if joint.rotation_order == "applied" else rot @ step
    return rot


def forward_kinematics(skeleton: Skeleton, motion: Motion) -> JointTrajectories:
    """World joint positions and orientations of every frame.

    Args:
        skeleton: the kinematic tree.
        motion: channel values; channels of joints absent from the skeleton raise an error.

    Returns:
        :class:`JointTrajectories` in the z-up world: positions (T, 3) [m], rotations (T, 3, 3).
    """
    names = set(skeleton.names)
    unknown = sorted({j for j, _ in motion.channels if j not in names})
    if unknown:
        raise MotionDataError(f"motion has channels for unknown joint(s) {unknown}")
    n = motion.n_frames
    per_joint: dict[str, dict[str, FloatArray]] = {}
    for i, (jname, dof) in enumerate(motion.channels):
        per_joint.setdefault(jname, {})[dof] = motion.values[:, i]
    world = skeleton.world_from_source
    q_world: dict[str, FloatArray] = {}
    p_src: dict[str, FloatArray] = {}
    positions: dict[str, FloatArray] = {}
    rotations: dict[str, FloatArray] = {}
    for joint in skeleton.joints:
        vals = per_joint.get(joint.name, {})
        local = joint.axis @ rotation_from_channels(joint, vals, n) @ joint.axis.T
        trans = np.stack([vals.get(d, np.zeros(n)) for d in TRANSLATION_DOFS], axis=1)
        if joint.parent is None:
            q = local
            p = joint.offset[None, :] + trans
        else:
            q = q_world[joint.parent] @ local
            carrier = q if skeleton.convention == "acclaim" else q_world[joint.parent]
            p = p_src[joint.parent] + carrier @ joint.offset + trans
        q_world[joint.name] = q
        p_src[joint.name] = p
        positions[joint.name] = p @ world.T
        rotations[joint.name] = world @ q @ joint.axis
    return JointTrajectories(positions, rotations, motion.fps, skeleton.convention)
