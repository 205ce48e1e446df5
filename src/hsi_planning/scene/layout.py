"""Randomized layout variants of a scene (CHOICE §8.2.2), seeded and reproducible.

Per variant: obstacles (every object but ``target``) are shifted within ±``shift`` on their support,
rotated within ±``rotate`` about z and scaled by ``scale_min``..``scale_max``; with ``reshape`` the
containers (cabinet, shelf, drawer unit) get independent width/depth/height factors in
``reshape_min``..``reshape_max`` (front face kept in place; object offsets and board heights scale
with them; neighbours are pushed sideways if the container grew into them). Candidates in which an
object leaves its support, does not fit under its ceiling or comes closer than ``clearance`` to
another object are resampled; only variants where the target is reachable
(:func:`~hsi_planning.scene.reach.target_reachable`) are kept. The applied variation is recorded in
``spec.meta["layout"]``. Variant ``i`` depends only on ``(seed, i)``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hsi_planning.errors import ConfigError, SceneError
from hsi_planning.scene.furniture import SupportSurface, furniture_supports
from hsi_planning.scene.model import object_pose_on
from hsi_planning.scene.reach import ReachConfig, target_reachable
from hsi_planning.scene.spec import CONTAINER_KINDS, FurnitureSpec, ObjectSpec, SceneSpec
from hsi_planning.scene.validate import TOLERANCE, footprint, furniture_footprint, object_points, polygon_gap

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LayoutConfig:
    """Ranges of the randomization."""

    shift: float = 0.05  #: max obstacle shift along each support axis [m]
    rotate: float = 90.0  #: max obstacle rotation about z [deg]
    scale_min: float = 0.8  #: min obstacle scale [-]
    scale_max: float = 1.25  #: max obstacle scale [-]
    reshape: bool = False  #: also reshape containers [-]
    reshape_min: float = 0.7  #: min container width/depth/height factor [-]
    reshape_max: float = 1.5  #: max container width/depth/height factor [-]
    target: str | None = None  #: object kept as is and required reachable; None: all objects vary [-]
    clearance: float = 0.005  #: min horizontal gap between objects on the same level [m]
    furniture_gap: float = 0.02  #: gap kept between furniture pushed apart [m]
    object_tries: int = 40  #: samples per object before the whole variant is resampled [-]
    layout_tries: int = 200  #: variant samples before giving up [-]
    reach: ReachConfig = field(default_factory=ReachConfig)  #: reachability test parameters

    def __post_init__(self) -> None:
        if self.shift < 0.0 or not 0.0 <= self.rotate <= 180.0:
            raise ConfigError(
                f"LayoutConfig: shift {self.shift} must be >= 0 m, rotate {self.rotate} in [0, 180] deg"
            )
        if not 0.0 < self.scale_min <= self.scale_max:
            raise ConfigError(
                f"LayoutConfig: need 0 < scale_min <= scale_max, got {self.scale_min}, {self.scale_max}"
            )
        if not 0.0 < self.reshape_min <= self.reshape_max:
            raise ConfigError(
                "LayoutConfig: need 0 < reshape_min <= reshape_max,"
                f" got {self.reshape_min}, {self.reshape_max}"
            )
        if self.clearance < 0.0 or self.furniture_gap < 0.0:
            raise ConfigError("LayoutConfig: clearance and furniture_gap must be >= 0 m")
        if self.object_tries < 1 or self.layout_tries < 1:
            raise ConfigError("LayoutConfig: object_tries and layout_tries must be >= 1")


def _reshape(f: FurnitureSpec, fw: float, fd: float, fh: float) -> FurnitureSpec:
    """Scale a container about its front face (the front stays where it was)."""
    w, d, h = f.size
    yaw = math.radians(f.yaw)
    back = (d * fd - d) / 2.0
    pos = (f.pos[0] + back * math.cos(yaw), f.pos[1] + back * math.sin(yaw))
    boards = tuple(b * fh for b in f.boards)
    return dataclasses.replace(f, pos=pos, size=(w * fw, d * fd, h * fh), boards=boards)


def _separate(furniture: list[FurnitureSpec], gap: float) -> list[FurnitureSpec] | None:
    """Push overlapping furniture apart sideways (later items move); None if that does not converge."""
    out = list(furniture)
    for _ in range(4 * len(out) + 4):
        moved = False
        for j in range(len(out)):
            for i in range(j):
                overlap = gap - polygon_gap(furniture_footprint(out[i]), furniture_footprint(out[j]))
                if overlap <= 0.0:
                    continue
                yaw = math.radians(out[j].yaw)
                lateral = np.array([-math.sin(yaw), math.cos(yaw)])
                side = 1.0 if float(np.dot(np.subtract(out[j].pos, out[i].pos), lateral)) >= 0.0 else -1.0
                step = side * (overlap + 1e-4) * lateral
                out[j] = dataclasses.replace(out[j], pos=(out[j].pos[0] + step[0], out[j].pos[1] + step[1]))
                moved = True
        if not moved:
            return out
    return None


def _place(
    o: ObjectSpec, support: SupportSurface, placed: list[tuple[np.ndarray, float, float]], clearance: float
) -> tuple[np.ndarray, float, float] | None:
    """Footprint and z-range of ``o`` if it fits on its support without touching ``placed``; else None."""
    pts = object_points(o, object_pose_on(o, support))
    local = (pts - support.frame[:3, 3]) @ support.frame[:3, :3]
    hx, hy = support.half_extents
    if np.abs(local[:, 0]).max() > hx - TOLERANCE or np.abs(local[:, 1]).max() > hy - TOLERANCE:
        return None
    if local[:, 2].max() > support.ceiling - TOLERANCE:
        return None
    item = (footprint(pts), float(pts[:, 2].min()), float(pts[:, 2].max()))
    for poly, z0, z1 in placed:
        if min(item[2], z1) - max(item[1], z0) > 0.0 and polygon_gap(item[0], poly) < clearance:
            return None
    return item


def _sample(
    spec: SceneSpec, config: LayoutConfig, rng: np.random.Generator, name: str, layout: dict[str, Any]
) -> SceneSpec | None:
    furniture, fmeta = list(spec.furniture), {}
    factors: dict[str, tuple[float, float]] = {}
    if config.reshape:
        for k, f in enumerate(furniture):
            if f.kind in CONTAINER_KINDS:
                fw, fd, fh = (float(v) for v in rng.uniform(config.reshape_min, config.reshape_max, 3))
                furniture[k] = _reshape(f, fw, fd, fh)
                fmeta[f.name] = {"width": fw, "depth": fd, "height": fh}
                factors[f.name] = (fd, fw)
        separated = _separate(furniture, config.furniture_gap)
        if separated is None:
            return None
        furniture = separated
    try:
        supports = {s.name: s for f in furniture for s in furniture_supports(f)}
    except SceneError:
        return None
    order = sorted(spec.objects, key=lambda o: o.name != config.target)  # the target first
    placed: list[tuple[np.ndarray, float, float]] = []
    new_objects: dict[str, ObjectSpec] = {}
    ometa: dict[str, Any] = {}
    for o in order:
        fd, fw = factors.get(o.on.split("/", 1)[0], (1.0, 1.0))
        base = dataclasses.replace(o, xy=(o.xy[0] * fd, o.xy[1] * fw))
        vary = o.name != config.target
        for _ in range(config.object_tries if vary else 1):
            if vary:
                dx, dy = (float(v) for v in rng.uniform(-config.shift, config.shift, 2))
                dyaw = float(rng.uniform(-config.rotate, config.rotate))
                s = float(rng.uniform(config.scale_min, config.scale_max))
                cand = dataclasses.replace(
                    base,
                    xy=(base.xy[0] + dx, base.xy[1] + dy),
                    yaw=o.yaw + dyaw,
                    scale=o.scale * s,
                    mass=None if o.mass is None else o.mass * s**3,
                )
            else:
                dx = dy = dyaw = 0.0
                s, cand = 1.0, base
            item = _place(cand, supports[o.on], placed, config.clearance)
            if item is not None:
                placed.append(item)
                new_objects[o.name] = cand
                ometa[o.name] = {"shift": [dx, dy], "yaw": dyaw, "scale": s}
                break
        else:
            return None
    objects = tuple(new_objects[o.name] for o in spec.objects)
    meta = {**spec.meta, "layout": {**layout, "furniture": fmeta, "objects": ometa}}
    try:
        return SceneSpec(name, tuple(furniture), objects, spec.cameras, meta)
    except SceneError:
        return None


def generate_layouts(
    spec: SceneSpec, count: int, seed: int, config: LayoutConfig | None = None
) -> list[SceneSpec]:
    """``count`` randomized, valid variants of ``spec`` (see the module docstring).

    Raises:
        SceneError: unknown target, target unreachable in the source scene, or a variant could not be
            sampled within ``config.layout_tries`` attempts.
    """
    config = config or LayoutConfig()
    if count < 0:
        raise SceneError(f"generate_layouts: count {count} must be >= 0")
    if config.target is not None:
        spec.object_by_name(config.target)
        if not target_reachable(spec, config.target, config.reach):
            raise SceneError(
                f"generate_layouts: target {config.target!r} is not reachable in '{spec.name}' itself"
            )
    out: list[SceneSpec] = []
    for i in range(count):
        rng = np.random.default_rng([seed, i])
        layout = {
            "source": spec.name,
            "seed": seed,
            "index": i,
            "reshape": config.reshape,
            "target": config.target,
        }
        for attempt in range(config.layout_tries):
            variant = _sample(spec, config, rng, f"{spec.name}_v{i:03d}", layout)
            if variant is None:
                continue
            if config.target is not None and not target_reachable(variant, config.target, config.reach):
                continue
            _log.debug("variant %d of %s after %d attempts", i, spec.name, attempt + 1)
            out.append(variant)
            break
        else:
            raise SceneError(
                f"generate_layouts: no valid variant {i} of '{spec.name}' in {config.layout_tries} tries;"
                " widen the containers, remove objects or relax LayoutConfig"
            )
    return out
