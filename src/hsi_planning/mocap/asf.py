"""Acclaim Skeleton File (ASF) parser.

Sections used: ``:units`` (``length`` factor, ``angle deg|rad``), ``:root`` (``order``, ``axis``,
``position``, ``orientation``), ``:bonedata`` (``begin … end`` blocks with ``name``, ``direction``,
``length``, ``axis a b c ORDER``, ``dof``, ``limits``) and ``:hierarchy``.

Units: a length in the file times ``0.0254 / length`` is metres (the Acclaim ``length`` factor scales
inches; HDM05 and CMU use ``length 0.45``). Reference: the Acclaim ASF/AMC specification as documented
by the CMU Graphics Lab motion-capture database and M. Müller et al., *Documentation Mocap Database
HDM05*, Tech. Rep. CG-2007-2, Universität Bonn, 2007.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hsi_planning.errors import MotionDataError
from hsi_planning.mocap.skeleton import Z_UP_FROM_Y_UP, Joint, Skeleton, euler_matrix

INCH_M = 0.0254


@dataclass
class _Bone:
    name: str
    line: int
    direction: list[float] = field(default_factory=list)
    length: float | None = None
    axis: list[float] = field(default_factory=list)
    axis_order: str = "xyz"
    dofs: tuple[str, ...] = ()


def _floats(tokens: list[str], n: int, where: str) -> list[float]:
    if len(tokens) != n:
        raise MotionDataError(f"{where}: expected {n} numbers, got {len(tokens)}: {' '.join(tokens)!r}")
    try:
        return [float(t) for t in tokens]
    except ValueError as exc:
        raise MotionDataError(f"{where}: not a number in {' '.join(tokens)!r}") from exc


def _order(token: str, where: str) -> str:
    order = token.lower()
    if sorted(order) != ["x", "y", "z"]:
        raise MotionDataError(f"{where}: rotation order {token!r} is not a permutation of XYZ")
    return order


def _dofs(tokens: list[str], where: str) -> tuple[str, ...]:
    dofs = tuple(t.lower() for t in tokens)
    bad = [d for d in dofs if d not in ("rx", "ry", "rz", "tx", "ty", "tz")]
    if bad:
        raise MotionDataError(f"{where}: unsupported dof(s) {bad}; valid: rx ry rz tx ty tz")
    return dofs


def load_asf(path: str | Path, world_from_source: np.ndarray | None = None) -> Skeleton:
    """Parse an ASF file into a :class:`Skeleton` (``convention="acclaim"``, offsets in [m]).

    Args:
        path: the ``.asf`` file.
        world_from_source: (3, 3) rotation from the file frame to the world; default y-up → z-up.

    Raises:
        MotionDataError: missing file or section, malformed line, unknown bone (message names file:line).
    """
    path = Path(path)
    if not path.is_file():
        raise MotionDataError(f"{path}: no such ASF file")
    lines = path.read_text(encoding="latin-1").splitlines()
    section = ""
    length_factor = 1.0
    deg = True
    root: dict[str, list[str]] = {}
    root_line = 0
    bones: dict[str, _Bone] = {}
    current: _Bone | None = None
    children: dict[str, list[str]] = {}
    seen_sections: set[str] = set()
    in_limits = False
    for lineno, raw in enumerate(lines, start=1):
        where = f"{path}:{lineno}"
        text = raw.split("#", 1)[0].strip()
        if not text:
            continue
        tokens = text.split()
        if tokens[0].startswith(":"):
            section = tokens[0][1:].lower()
            seen_sections.add(section)
            in_limits = False
            if section == "root":
                root_line = lineno
            continue
        key = tokens[0].lower()
        if section == "units":
            if key == "length":
                length_factor = _floats(tokens[1:], 1, where)[0]
                if length_factor <= 0:
                    raise MotionDataError(f"{where}: units length must be > 0, got {length_factor}")
            elif key == "angle":
                if len(tokens) != 2 or tokens[1].lower() not in ("deg", "rad"):
                    raise MotionDataError(f"{where}: units angle must be 'deg' or 'rad'")
                deg = tokens[1].lower() == "deg"
        elif section == "root":
            root[key] = tokens[1:]
        elif section == "bonedata":
            if key == "begin":
                current = _Bone(name="", line=lineno)
                in_limits = False
            elif current is None:
                raise MotionDataError(f"{where}: {tokens[0]!r} outside a begin … end bone block")
            elif key == "end":
                if not current.name or current.length is None or not current.direction:
                    raise MotionDataError(
                        f"{path}:{current.line}: bone block needs name, direction and length"
                    )
                if current.name in bones:
                    raise MotionDataError(f"{path}:{current.line}: duplicate bone {current.name!r}")
                bones[current.name] = current
                current = None
            elif key == "name":
                current.name = tokens[1] if len(tokens) == 2 else ""
                in_limits = False
            elif key == "direction":
                current.direction = _floats(tokens[1:], 3, where)
            elif key == "length":
                current.length = _floats(tokens[1:], 1, where)[0]
            elif key == "axis":
                current.axis = _floats(tokens[1:4], 3, where)
                current.axis_order = _order(tokens[4], where) if len(tokens) > 4 else "xyz"
            elif key == "dof":
                current.dofs = _dofs(tokens[1:], where)
            elif key == "limits" or (in_limits and tokens[0].startswith("(")):
                in_limits = True
            elif key in ("id", "bodymass", "cofmass"):
                pass
            else:
                raise MotionDataError(f"{where}: unknown bone keyword {tokens[0]!r}")
        elif section == "hierarchy":
            if key in ("begin", "end"):
                continue
            children.setdefault(tokens[0], []).extend(tokens[1:])
    for required in ("root", "bonedata", "hierarchy"):
        if required not in seen_sections:
            raise MotionDataError(f"{path}: missing :{required} section")
    if current is not None:
        raise MotionDataError(f"{path}:{current.line}: bone block without 'end'")
    unit_m = INCH_M / length_factor
    angle = np.pi / 180.0 if deg else 1.0
    joints = [_root_joint(path, root_line, root, unit_m, angle)]
    order = ["root"]
    queue = ["root"]
    while queue:
        parent = queue.pop(0)
        for child in children.get(parent, []):
            if child not in bones:
                raise MotionDataError(
                    f"{path}: :hierarchy names unknown bone {child!r}; bones: {sorted(bones)}"
                )
            if child in order:
                raise MotionDataError(f"{path}: bone {child!r} appears twice in :hierarchy")
            bone = bones[child]
            direction = np.asarray(bone.direction)
            norm = float(np.linalg.norm(direction))
            if norm < 1e-9:
                raise MotionDataError(f"{path}:{bone.line}: bone {child!r} has a zero direction")
            axis = euler_matrix(np.asarray(bone.axis or [0.0, 0.0, 0.0]) * angle, bone.axis_order)
            assert bone.length is not None
            offset = direction / norm * bone.length * unit_m
            joints.append(Joint(child, parent, offset, axis, bone.dofs, "applied"))
            order.append(child)
            queue.append(child)
    orphans = sorted(set(bones) - set(order))
    if orphans:
        raise MotionDataError(f"{path}: bone(s) {orphans} are not reachable from root in :hierarchy")
    world = Z_UP_FROM_Y_UP if world_from_source is None else world_from_source
    return Skeleton(path.stem, tuple(joints), "acclaim", world, unit_m)


def _root_joint(path: Path, line: int, root: dict[str, list[str]], unit_m: float, angle: float) -> Joint:
    where = f"{path}:{line}"
    order_tokens = root.get("order")
    if not order_tokens:
        raise MotionDataError(f"{where}: :root needs 'order' (e.g. TX TY TZ RX RY RZ)")
    dofs = _dofs(order_tokens, where)
    position = np.asarray(_floats(root.get("position", ["0", "0", "0"]), 3, where)) * unit_m
    orientation = np.asarray(_floats(root.get("orientation", ["0", "0", "0"]), 3, where)) * angle
    axis_tokens = root.get("axis", ["XYZ"])
    axis = euler_matrix(orientation, _order(axis_tokens[0], where))
    return Joint("root", None, position, axis, dofs, "applied")
