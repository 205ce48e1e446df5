"""Scene specs: the YAML description of furniture, objects and cameras, as frozen dataclasses.

Frames: the world has z up; a robot/person stands near the origin facing +x. A piece of furniture has
its own frame at the centre of its footprint on the floor, rotated by ``yaw`` about z: local x points
from its front (the opening, facing the person when ``yaw`` = 0) to its back, local y along its width.
An object rests on a *support* (a furniture part's top surface) at an ``xy`` offset in that support's
frame (same axes as the furniture, origin at the centre of the usable surface); its height is derived.

A :class:`SceneSpec` is valid by construction: building one checks names, supports, bounds and
overlaps and raises :class:`~hsi_planning.errors.SceneError` naming the item and what is valid.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

from hsi_planning.config import from_mapping, load_yaml
from hsi_planning.errors import ConfigError, SceneError

FurnitureKind = Literal["cabinet", "drawer_unit", "shelf", "table", "counter"]
ObjectKind = Literal["bottle", "mug", "bowl", "can", "box", "teapot"]
FURNITURE_KINDS: tuple[str, ...] = get_args(FurnitureKind)
OBJECT_KINDS: tuple[str, ...] = get_args(ObjectKind)
#: Furniture kinds that enclose their contents on the sides (they have an opening direction).
CONTAINER_KINDS: tuple[str, ...] = ("cabinet", "drawer_unit", "shelf")


def _check_name(name: str, what: str) -> None:
    if not name or "/" in name or not name.replace("_", "").replace("-", "").isalnum():
        raise SceneError(f"{what} name {name!r}: use letters, digits, '_' or '-' (no '/', not empty)")


def _normalize(item: Any, floats: tuple[str, ...], float_tuples: tuple[str, ...]) -> None:
    """Store plain Python floats (numpy scalars and lists from callers become floats/tuples)."""
    for name in floats:
        value = getattr(item, name)
        if value is not None:
            object.__setattr__(item, name, float(value))
    for name in float_tuples:
        value = getattr(item, name)
        if value is not None:
            object.__setattr__(item, name, tuple(float(v) for v in value))


def _check_len(values: tuple[float, ...], n: int, what: str) -> None:
    # Fixed-length fields are declared ``tuple[float, ...]`` and checked here.
    if len(values) != n:
        raise SceneError(f"{what}: expected {n} values, got {len(values)}: {list(values)}")


@dataclass(frozen=True)
class CameraSpec:
    """A fixed camera looking from ``pos`` at ``target``."""

    name: str
    pos: tuple[float, ...]  #: camera position (3,) in the world [m]
    target: tuple[float, ...]  #: (3,) point the optical axis goes through [m]
    fovy: float = 45.0  #: vertical field of view [deg]
    resolution: tuple[int, ...] = (320, 240)  #: image width, height [px]

    def __post_init__(self) -> None:
        _normalize(self, ("fovy",), ("pos", "target"))
        object.__setattr__(self, "resolution", tuple(int(v) for v in self.resolution))
        _check_name(self.name, "camera")
        _check_len(self.pos, 3, f"camera '{self.name}' pos")
        _check_len(self.target, 3, f"camera '{self.name}' target")
        _check_len(self.resolution, 2, f"camera '{self.name}' resolution")
        if not 1.0 <= self.fovy <= 170.0:
            raise SceneError(f"camera '{self.name}': fovy {self.fovy} must be in [1, 170] degrees")
        if min(self.resolution) < 8:
            raise SceneError(f"camera '{self.name}': resolution {self.resolution} must be >= 8 px each")
        if sum((a - b) ** 2 for a, b in zip(self.pos, self.target, strict=True)) < 1e-6:
            raise SceneError(f"camera '{self.name}': target must differ from pos")


@dataclass(frozen=True)
class FurnitureSpec:
    """A piece of furniture. ``size`` is (width, depth, height) of the carcass [m]."""

    name: str
    kind: FurnitureKind
    pos: tuple[float, ...]  #: (2,) footprint centre in the world [m]
    size: tuple[float, ...]  #: (3,) width (local y), depth (local x), height (z) [m]
    yaw: float = 0.0  #: rotation about z [deg]; 0 = front faces -x (towards the origin)
    boards: tuple[float, ...] = ()  #: cabinet/shelf: board top-surface heights above the floor [m]
    doors: int = 1  #: cabinet: number of hinged doors (1 or 2) [-]
    hinge: Literal["left", "right"] = "left"  #: single door: hinge side seen from the front [-]
    drawers: int = 1  #: drawer_unit: number of drawers, stacked, drawer1 on top [-]
    thickness: float = 0.018  #: panel thickness [m]

    def __post_init__(self) -> None:
        _normalize(self, ("yaw", "thickness"), ("pos", "size", "boards"))
        _check_name(self.name, "furniture")
        _check_len(self.pos, 2, f"furniture '{self.name}' pos")
        _check_len(self.size, 3, f"furniture '{self.name}' size (width, depth, height)")
        where = f"furniture '{self.name}' ({self.kind})"
        w, d, h = self.size
        if min(self.size) <= 0.0:
            raise SceneError(f"{where}: size {self.size} must be positive (width, depth, height) [m]")
        if not 0.0 < self.thickness <= min(w, d, h) / 6.0:
            raise SceneError(f"{where}: thickness {self.thickness} must be in (0, min(size)/6] [m]")
        if self.boards and self.kind not in ("cabinet", "shelf"):
            raise SceneError(f"{where}: only cabinet and shelf have boards")
        lo, hi = 3.0 * self.thickness, h - 2.0 * self.thickness
        if any(not lo < b < hi for b in self.boards):
            raise SceneError(f"{where}: boards {self.boards} must lie in ({lo:.3f}, {hi:.3f}) [m]")
        heights = sorted((self.thickness, *self.boards, h - self.thickness))
        if min(b - a for a, b in itertools.pairwise(heights)) < 2.0 * self.thickness:
            raise SceneError(
                f"{where}: boards {self.boards} are closer than 2 thicknesses to each other/carcass"
            )
        if self.kind == "cabinet" and self.doors not in (1, 2):
            raise SceneError(f"{where}: doors must be 1 or 2, got {self.doors}")
        if self.kind == "drawer_unit" and not 1 <= self.drawers <= int((h - self.thickness) / 0.08):
            raise SceneError(f"{where}: drawers {self.drawers} must be in [1, (height - thickness)/0.08]")

    @property
    def board_names(self) -> tuple[str, ...]:
        """Names of the board bodies, ``<name>/board1`` lowest."""
        return tuple(f"{self.name}/board{i + 1}" for i in range(len(self.boards)))

    @property
    def support_names(self) -> tuple[str, ...]:
        """Names an object may rest ``on``."""
        if self.kind == "drawer_unit":
            return tuple(f"{self.name}/drawer{i + 1}" for i in range(self.drawers))
        if self.kind in ("cabinet", "shelf"):
            return (self.name, *self.board_names)
        return (self.name,)


@dataclass(frozen=True)
class ObjectSpec:
    """A free object resting on a support.

    ``size`` (optional, before ``scale``): box ``(lx, ly, lz)``; round kinds ``(diameter, height)`` of
    the main body [m]. ``mass`` and ``friction`` default per kind (see :mod:`.objects`).
    """

    name: str
    kind: ObjectKind
    on: str  #: support name, e.g. "shelf1/board2", "counter1", "drawer_unit1/drawer1"
    xy: tuple[float, ...] = (0.0, 0.0)  #: (2,) offset on the support, support frame (x: inwards) [m]
    yaw: float = 0.0  #: rotation about z relative to the support frame [deg]
    scale: float = 1.0  #: uniform scale of the shape [-]
    size: tuple[float, ...] | None = None  #: kind-dependent dimensions [m]
    mass: float | None = None  #: [kg]
    friction: float | None = None  #: sliding friction coefficient [-]

    def __post_init__(self) -> None:
        _normalize(self, ("yaw", "scale", "mass", "friction"), ("xy", "size"))
        _check_name(self.name, "object")
        _check_len(self.xy, 2, f"object '{self.name}' xy")
        where = f"object '{self.name}' ({self.kind})"
        if not 0.1 <= self.scale <= 10.0:
            raise SceneError(f"{where}: scale {self.scale} must be in [0.1, 10]")
        if self.size is not None:
            n = 3 if self.kind == "box" else 2
            if len(self.size) != n or min(self.size) <= 0.0:
                what = "(lx, ly, lz)" if n == 3 else "(diameter, height)"
                raise SceneError(f"{where}: size {self.size} must be {n} positive values {what} [m]")
        if self.mass is not None and not 0.0 < self.mass <= 50.0:
            raise SceneError(f"{where}: mass {self.mass} must be in (0, 50] kg")
        if self.friction is not None and not 0.0 < self.friction <= 3.0:
            raise SceneError(f"{where}: friction {self.friction} must be in (0, 3]")


@dataclass(frozen=True)
class SceneSpec:
    """A whole scene. Constructing one validates it (see the module docstring)."""

    name: str
    furniture: tuple[FurnitureSpec, ...]
    objects: tuple[ObjectSpec, ...] = ()
    cameras: tuple[CameraSpec, ...] = ()
    meta: dict[str, Any] = field(default_factory=dict, hash=False)  #: free-form provenance (layout variation)

    def __post_init__(self) -> None:
        object.__setattr__(self, "furniture", tuple(self.furniture))
        object.__setattr__(self, "objects", tuple(self.objects))
        object.__setattr__(self, "cameras", tuple(self.cameras))
        object.__setattr__(self, "meta", copy.deepcopy(dict(self.meta)))
        from hsi_planning.scene.validate import validate_scene

        validate_scene(self)

    def furniture_by_name(self, name: str) -> FurnitureSpec:
        """The furniture called ``name``; :class:`SceneError` lists the valid names otherwise."""
        for f in self.furniture:
            if f.name == name:
                return f
        raise SceneError(
            f"scene '{self.name}': no furniture {name!r}; valid: {[f.name for f in self.furniture]}"
        )

    def object_by_name(self, name: str) -> ObjectSpec:
        """The object called ``name``; :class:`SceneError` lists the valid names otherwise."""
        for o in self.objects:
            if o.name == name:
                return o
        raise SceneError(f"scene '{self.name}': no object {name!r}; valid: {[o.name for o in self.objects]}")

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any], source: str = "<scene>") -> SceneSpec:
        """Build and validate a spec from a parsed YAML mapping; errors start with ``source``."""
        if not isinstance(doc, Mapping):
            raise SceneError(f"{source}: a scene spec must be a mapping with keys {_TOP_KEYS}")
        unknown = sorted(set(doc) - set(_TOP_KEYS))
        if unknown:
            raise SceneError(f"{source}: unknown key(s) {unknown}; valid: {list(_TOP_KEYS)}")
        if "name" not in doc or "furniture" not in doc:
            raise SceneError(f"{source}: 'name' and 'furniture' are required; valid keys: {list(_TOP_KEYS)}")
        meta = doc.get("meta") or {}
        if not isinstance(meta, Mapping):
            raise SceneError(f"{source}: 'meta' must be a mapping")
        try:
            return cls(
                name=str(doc["name"]),
                furniture=_items(FurnitureSpec, doc.get("furniture"), "furniture", source),
                objects=_items(ObjectSpec, doc.get("objects"), "objects", source),
                cameras=_items(CameraSpec, doc.get("cameras"), "cameras", source),
                meta=dict(meta),
            )
        except SceneError as exc:
            msg = str(exc)
            raise SceneError(msg if msg.startswith(source) else f"{source}: {msg}") from exc

    def to_dict(self) -> dict[str, Any]:
        """A plain (YAML-safe) mapping; ``SceneSpec.from_dict(s.to_dict()) == s``."""
        out: dict[str, Any] = {"name": self.name}
        out["furniture"] = [_item_dict(f) for f in self.furniture]
        out["objects"] = [_item_dict(o) for o in self.objects]
        out["cameras"] = [_item_dict(c) for c in self.cameras]
        if self.meta:
            out["meta"] = copy.deepcopy(self.meta)
        return out


_TOP_KEYS = ("name", "furniture", "objects", "cameras", "meta")


def _items(cls: type[Any], raw: Any, key: str, source: str) -> tuple[Any, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise SceneError(f"{source}: '{key}' must be a list of mappings")
    out = []
    for i, item in enumerate(raw):
        label = item.get("name", "?") if isinstance(item, Mapping) else "?"
        where = f"{source}: {key}[{i}] '{label}'"
        if not isinstance(item, Mapping):
            raise SceneError(
                f"{where}: must be a mapping with keys {[f.name for f in dataclasses.fields(cls)]}"
            )
        # YAML 1.1 (PyYAML) reads an unquoted ``on:`` key as the boolean True.
        fixed = {("on" if k is True else k): v for k, v in item.items()}
        try:
            out.append(from_mapping(cls, fixed, where=where))
        except ConfigError as exc:
            raise SceneError(str(exc)) from exc
    return tuple(out)


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def _item_dict(item: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in dataclasses.fields(item):
        value = getattr(item, f.name)
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        if required or value != f.default:
            out[f.name] = _plain(value)
    return out


def load_scene_spec(path: str | Path) -> SceneSpec:
    """Read and validate a scene spec YAML file; errors name the file (and line for syntax errors)."""
    try:
        doc = load_yaml(path)
    except ConfigError as exc:
        raise SceneError(str(exc)) from exc
    return SceneSpec.from_dict(doc, source=str(path))
