"""Biovision Hierarchy (BVH) reader and writer.

A BVH file has a ``HIERARCHY`` (``ROOT``/``JOINT`` blocks with ``OFFSET`` and ``CHANNELS``, leaves
ending in ``End Site``) and a ``MOTION`` section (``Frames:``, ``Frame Time:``, one line of channel
values per frame, angles in degrees). Rotation channels are read left to right as intrinsic rotations:
``Zrotation Xrotation Yrotation`` means ``R = Rz · Rx · Ry``. BVH has no length unit; the loader takes
one (``unit_m``, centimetres by default) and End Sites become joints ``<parent>_end``.

:func:`save_bvh` writes any :class:`~hsi_planning.mocap.skeleton.Skeleton` (including an Acclaim one:
each bone becomes a BVH joint at the bone's start, leaf bones get an End Site at their tip) so an AMC
clip can be round-tripped; the joint points then agree with the Acclaim bone ends.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hsi_planning.errors import MotionDataError
from hsi_planning.mocap.skeleton import (
    ROTATION_DOFS,
    TRANSLATION_DOFS,
    Z_UP_FROM_Y_UP,
    FloatArray,
    Joint,
    Motion,
    Skeleton,
    rotation_from_channels,
)

_CHANNEL_TO_DOF = {
    "xposition": "tx",
    "yposition": "ty",
    "zposition": "tz",
    "xrotation": "rx",
    "yrotation": "ry",
    "zrotation": "rz",
}
_DOF_TO_CHANNEL = {v: k.capitalize() for k, v in _CHANNEL_TO_DOF.items()}


def _number(token: str, where: str) -> float:
    try:
        return float(token)
    except ValueError as exc:
        raise MotionDataError(f"{where}: not a number: {token!r}") from exc


def load_bvh(
    path: str | Path, unit_m: float = 0.01, world_from_source: FloatArray | None = None
) -> tuple[Skeleton, Motion]:
    """Parse a BVH file.

    Args:
        path: the ``.bvh`` file.
        unit_m: [m] length of one file unit (0.01: centimetres).
        world_from_source: (3, 3) rotation file frame → world; default y-up → z-up.

    Returns:
        (skeleton with ``convention="bvh"``, motion with angles [rad], translations [m], fps from
        ``Frame Time``).

    Raises:
        MotionDataError: missing section, unbalanced braces, unknown channel, wrong number of values on a
            frame line, frame count mismatch (message names file:line).
    """
    path = Path(path)
    if not path.is_file():
        raise MotionDataError(f"{path}: no such BVH file")
    if not unit_m > 0:
        raise MotionDataError(f"unit_m must be > 0 [m], got {unit_m}")
    lines = path.read_text(encoding="latin-1").splitlines()
    tokens = [(i + 1, line.split()) for i, line in enumerate(lines) if line.strip()]
    if not tokens or tokens[0][1][0].upper() != "HIERARCHY":
        raise MotionDataError(f"{path}:1: expected 'HIERARCHY' as the first keyword")
    joints: list[Joint] = []
    channels: list[tuple[str, str]] = []
    stack: list[str] = []
    pending: tuple[str, str | None] | None = None
    offset: list[float] | None = None
    dofs: tuple[str, ...] = ()
    names: set[str] = set()
    k = 1
    motion_at = -1

    def flush(where: str) -> None:
        nonlocal pending, offset, dofs
        if pending is None:
            return
        if offset is None:
            raise MotionDataError(f"{where}: joint {pending[0]!r} has no OFFSET")
        joints.append(
            Joint(pending[0], pending[1], np.asarray(offset) * unit_m, np.eye(3), dofs, "intrinsic")
        )
        channels.extend((pending[0], d) for d in dofs)
        pending, offset, dofs = None, None, ()

    while k < len(tokens):
        lineno, tok = tokens[k]
        where = f"{path}:{lineno}"
        key = tok[0].upper()
        if key in ("ROOT", "JOINT"):
            flush(where)
            if (key == "ROOT") != (not stack) or len(tok) != 2:
                raise MotionDataError(
                    f"{where}: {tok[0]} must be 'ROOT name' at top level or 'JOINT name' inside"
                )
            name = tok[1]
            if name in names:
                raise MotionDataError(f"{where}: duplicate joint name {name!r}")
            names.add(name)
            pending = (name, stack[-1] if stack else None)
            stack.append(name)
        elif key == "END":
            flush(where)
            if not stack:
                raise MotionDataError(f"{where}: End Site outside a joint")
            name = f"{stack[-1]}_end"
            while name in names:
                name += "_"
            names.add(name)
            pending = (name, stack[-1])
            stack.append(name)
        elif key == "OFFSET":
            if pending is None:
                raise MotionDataError(f"{where}: OFFSET outside a joint header")
            if len(tok) != 4:
                raise MotionDataError(f"{where}: OFFSET needs 3 numbers, got {len(tok) - 1}")
            offset = [_number(t, where) for t in tok[1:]]
        elif key == "CHANNELS":
            if pending is None:
                raise MotionDataError(f"{where}: CHANNELS outside a joint header")
            count = int(_number(tok[1], where)) if len(tok) > 1 else -1
            if count != len(tok) - 2:
                raise MotionDataError(
                    f"{where}: CHANNELS announces {tok[1:2]} but lists {len(tok) - 2} names"
                )
            unknown = [c for c in tok[2:] if c.lower() not in _CHANNEL_TO_DOF]
            if unknown:
                raise MotionDataError(
                    f"{where}: unknown channel(s) {unknown}; valid: {sorted(_DOF_TO_CHANNEL.values())}"
                )
            dofs = tuple(_CHANNEL_TO_DOF[c.lower()] for c in tok[2:])
        elif key == "{":
            pass
        elif key == "}":
            flush(where)
            if not stack:
                raise MotionDataError(f"{where}: unbalanced '}}'")
            stack.pop()
        elif key == "MOTION":
            flush(where)
            motion_at = k
            break
        else:
            raise MotionDataError(f"{where}: unexpected keyword {tok[0]!r} in HIERARCHY")
        k += 1
    if stack:
        raise MotionDataError(f"{path}: unbalanced braces: joint {stack[-1]!r} is never closed")
    if motion_at < 0:
        raise MotionDataError(f"{path}: missing MOTION section")
    if not joints:
        raise MotionDataError(f"{path}: HIERARCHY has no ROOT joint")
    fps, values = _motion(path, tokens[motion_at + 1 :], len(channels))
    scale = np.array([np.pi / 180.0 if d in ROTATION_DOFS else unit_m for _, d in channels])
    world = Z_UP_FROM_Y_UP if world_from_source is None else world_from_source
    skeleton = Skeleton(path.stem, tuple(joints), "bvh", world, unit_m)
    return skeleton, Motion(tuple(channels), values * scale[None, :], fps)


def _motion(path: Path, tokens: list[tuple[int, list[str]]], n_channels: int) -> tuple[float, FloatArray]:
    if len(tokens) < 2:
        raise MotionDataError(f"{path}: MOTION needs 'Frames:' and 'Frame Time:' lines")
    (l1, t1), (l2, t2) = tokens[0], tokens[1]
    if len(t1) != 2 or t1[0].lower() != "frames:":
        raise MotionDataError(f"{path}:{l1}: expected 'Frames: <count>'")
    if len(t2) != 3 or [t.lower() for t in t2[:2]] != ["frame", "time:"]:
        raise MotionDataError(f"{path}:{l2}: expected 'Frame Time: <seconds>'")
    n_frames = int(_number(t1[1], f"{path}:{l1}"))
    frame_time = _number(t2[2], f"{path}:{l2}")
    if frame_time <= 0:
        raise MotionDataError(f"{path}:{l2}: Frame Time must be > 0 [s], got {frame_time}")
    rows = tokens[2:]
    if len(rows) != n_frames:
        raise MotionDataError(f"{path}: 'Frames: {n_frames}' but {len(rows)} frame lines follow")
    values = np.empty((n_frames, n_channels))
    for i, (lineno, tok) in enumerate(rows):
        if len(tok) != n_channels:
            raise MotionDataError(
                f"{path}:{lineno}: frame has {len(tok)} values, the hierarchy has {n_channels} channels"
            )
        values[i] = [_number(t, f"{path}:{lineno}") for t in tok]
    return 1.0 / frame_time, values


def save_bvh(path: str | Path, skeleton: Skeleton, motion: Motion, unit_m: float = 0.01) -> None:
    """Write ``skeleton`` + ``motion`` as BVH (lengths in units of ``unit_m`` [m], angles [deg]).

    Every joint gets channels ``Zrotation Yrotation Xrotation`` (the root also
    ``Xposition Yposition Zposition``) holding its rest-relative local rotation C·M·C⁻¹.
    """
    path = Path(path)
    n = motion.n_frames
    per_joint: dict[str, dict[str, FloatArray]] = {}
    for i, (jname, dof) in enumerate(motion.channels):
        per_joint.setdefault(jname, {})[dof] = motion.values[:, i]
    children: dict[str, list[Joint]] = {}
    for joint in skeleton.joints:
        if joint.parent is not None:
            children.setdefault(joint.parent, []).append(joint)
    by_name = {j.name: j for j in skeleton.joints}
    acclaim = skeleton.convention == "acclaim"

    def bvh_offset(joint: Joint) -> FloatArray:
        if not acclaim or joint.parent is None:
            return joint.offset
        parent = by_name[joint.parent]
        return np.zeros(3) if parent.parent is None else parent.offset

    out: list[str] = ["HIERARCHY"]
    columns: list[FloatArray] = []

    def emit(joint: Joint, depth: int) -> None:
        pad = "  " * depth
        kids = children.get(joint.name, [])
        if not acclaim and not kids and not joint.dofs and joint.parent is not None:
            out.extend(
                [f"{pad}End Site", f"{pad}{{", f"{pad}  OFFSET {_fmt(joint.offset / unit_m)}", f"{pad}}}"]
            )
            return
        out.append(f"{pad}{'ROOT' if joint.parent is None else 'JOINT'} {joint.name}")
        out.append(f"{pad}{{")
        out.append(f"{pad}  OFFSET {_fmt(bvh_offset(joint) / unit_m)}")
        vals = per_joint.get(joint.name, {})
        names = ["Zrotation", "Yrotation", "Xrotation"]
        if joint.parent is None:
            names = ["Xposition", "Yposition", "Zposition", *names]
            for dof in TRANSLATION_DOFS:
                columns.append(vals.get(dof, np.zeros(n)) / unit_m)
        local = joint.axis @ rotation_from_channels(joint, vals, n) @ joint.axis.T
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # gimbal lock: still an exact decomposition
            zyx = Rotation.from_matrix(local).as_euler("ZYX", degrees=True)
        columns.extend([zyx[:, 0], zyx[:, 1], zyx[:, 2]])
        out.append(f"{pad}  CHANNELS {len(names)} {' '.join(names)}")
        for kid in kids:
            emit(kid, depth + 1)
        if acclaim and not kids:
            out.extend(
                [
                    f"{pad}  End Site",
                    f"{pad}  {{",
                    f"{pad}    OFFSET {_fmt(joint.offset / unit_m)}",
                    f"{pad}  }}",
                ]
            )
        out.append(f"{pad}}}")

    emit(skeleton.joints[0], 0)
    table = np.stack(columns, axis=1)
    out.extend(["MOTION", f"Frames: {n}", f"Frame Time: {1.0 / motion.fps:.15g}"])
    out.extend(" ".join(f"{v:.6f}" for v in row) for row in table)
    path.write_text("\n".join(out) + "\n", encoding="utf-8")


def _fmt(values: FloatArray) -> str:
    return " ".join(f"{v:.6f}" for v in values)
