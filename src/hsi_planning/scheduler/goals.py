"""Goals from clicks: a clicked point (RViz "Publish Point") or a camera ray → an object to pick or a place.

A click resolves to the nearest labelled point of the cloud within ``click_radius``; a camera ray to the
first cloud point within ``ray_radius`` of the ray (then as a click there). The label decides:

- an **object** → :class:`PickGoal`;
- the top of a **support surface** (counter, table, shelf board, cabinet floor, open drawer) →
  :class:`PlaceGoal` at the clicked spot, after checking that the spot is free for the object to place
  (no points above the surface within its footprint plus ``place_clearance``, enough headroom);
- anything else (floor, furniture sides, doors, nothing near, or farther than ``max_distance`` from the
  person) → :class:`~hsi_planning.errors.PlanningError` saying what was clicked and what is valid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.perception.cloud import UNLABELLED, LabelledCloud
from hsi_planning.scene.furniture import SupportSurface
from hsi_planning.scene.model import support_surfaces
from hsi_planning.scene.spec import CameraSpec, SceneSpec

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class GoalConfig:
    """How clicks and rays resolve to goals."""

    click_radius: float = 0.05  #: [m] largest distance from a click to the nearest labelled point
    ray_radius: float = 0.015  #: [m] largest distance of a cloud point from a camera ray
    max_distance: float = 3.0  #: [m] largest floor distance of a goal from the person
    surface_tolerance: float = 0.03  #: [m] a click within this of a support's top counts as on it
    place_clearance: float = 0.02  #: [m] free margin around a placed object's footprint
    default_radius: float = 0.05  #: [m] footprint radius assumed when the object to place is unknown
    default_height: float = 0.15  #: [m] height assumed when the object to place is unknown

    def __post_init__(self) -> None:
        for name in ("click_radius", "ray_radius", "max_distance", "surface_tolerance", "default_radius"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"GoalConfig.{name} must be > 0 m, got {getattr(self, name)}")
        if self.place_clearance < 0.0 or self.default_height <= 0.0:
            raise ConfigError("GoalConfig: place_clearance >= 0 m and default_height > 0 m")


@dataclass(frozen=True)
class PickGoal:
    """Pick ``object_name`` (resolved from ``point`` (3,) [m], or named)."""

    object_name: str
    point: F64


@dataclass(frozen=True)
class PlaceGoal:
    """Put the held object down with its bottom centre at ``position`` (3,) [m] on ``support``."""

    support: str
    position: F64


Goal = PickGoal | PlaceGoal


def _p3(value: ArrayLike, what: str) -> F64:
    arr = np.array(value, dtype=np.float64, copy=True).reshape(-1)
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise PlanningError(
            f"{what} must be 3 finite numbers x, y, z [m], got {np.asarray(value).tolist()!r}"
        )
    return arr


def resolve_click(
    point: ArrayLike,
    cloud: LabelledCloud,
    spec: SceneSpec,
    config: GoalConfig | None = None,
    *,
    person_xy: ArrayLike = (0.0, 0.0),
    footprint: tuple[float, float] | None = None,
) -> Goal:
    """The goal a click at ``point`` (3,) [m] designates (see the module docstring).

    Args:
        footprint: (radius, height) [m] of the object that would be placed (None: the config defaults).

    Raises:
        PlanningError: the click designates nothing valid; the message says what was hit.
    """
    config = config or GoalConfig()
    p = _p3(point, "clicked point")
    where = f"the click at {np.round(p, 3).tolist()}"
    far = float(np.linalg.norm(p[:2] - np.asarray(person_xy, dtype=np.float64).reshape(2)))
    if far > config.max_distance:
        raise PlanningError(
            f"{where} is {far:.2f} m from the person, beyond max_distance {config.max_distance} m; "
            "click an object or a surface nearby"
        )
    labelled = cloud.labels != UNLABELLED
    if not labelled.any():
        raise PlanningError("the cloud has no labelled points; a click cannot be resolved")
    pts, labs = cloud.points[labelled], cloud.labels[labelled]
    dist, idx = cKDTree(pts).query(p, k=1)
    names = cloud.label_names or {}
    name = names.get(int(labs[idx]), str(int(labs[idx])))
    if dist > config.click_radius:
        raise PlanningError(
            f"{where} hits nothing: the nearest point of the cloud ({name}) is {float(dist):.3f} m away "
            f"(limit {config.click_radius} m); click on an object or on the top of a counter or shelf board"
        )
    if name in {o.name for o in spec.objects}:
        return PickGoal(name, p)
    if name == "floor":
        raise PlanningError(
            f"{where} is on the floor, {far:.2f} m from the person; the floor is not a pick or place "
            "target: click an object, or the top of a counter, table or shelf board"
        )
    for support in support_surfaces(spec).values():
        if support.body == name and _on_top(p, support, config.surface_tolerance):
            radius, height = footprint or (config.default_radius, config.default_height)
            position = np.array([p[0], p[1], support.top_z])
            check_place_free(
                position, support, cloud, radius=radius, height=height, margin=config.place_clearance
            )
            return PlaceGoal(support.name, position)
    raise PlanningError(
        f"{where} is on {name!r}, fixed furniture that cannot be picked; click an object to pick, or the "
        "top of a counter, table, shelf board or open drawer to place"
    )


def _on_top(p: F64, support: SupportSurface, tolerance: float) -> bool:
    local = support.frame[:3, :3].T @ (p - support.frame[:3, 3])
    hx, hy = support.half_extents
    return bool(abs(local[2]) <= tolerance and abs(local[0]) <= hx and abs(local[1]) <= hy)


def check_place_free(
    position: ArrayLike,
    support: SupportSurface,
    cloud: LabelledCloud,
    *,
    radius: float,
    height: float,
    margin: float,
) -> None:
    """Raise :class:`PlanningError` unless a ``radius`` × ``height`` [m] object fits at ``position`` (3,).

    The footprint (plus ``margin``) must lie on the support and hold no cloud points between 1 cm above the
    surface and the object's height; the object must fit under the support's ceiling.
    """
    p = _p3(position, "place position")
    local = support.frame[:3, :3].T @ (p - support.frame[:3, 3])
    hx, hy = support.half_extents
    if abs(local[0]) + radius > hx + 1e-9 or abs(local[1]) + radius > hy + 1e-9:
        raise PlanningError(
            f"place at {np.round(p, 3).tolist()}: a {2 * radius:.2f} m wide object does not fit on "
            f"{support.name!r} there (usable half size {hx:.2f} x {hy:.2f} m)"
        )
    if height > support.ceiling:
        raise PlanningError(
            f"place on {support.name!r}: the object is {height:.2f} m tall, the free height is "
            f"{support.ceiling:.2f} m"
        )
    rel = cloud.points - p
    above = (rel[:, 2] > 0.01) & (rel[:, 2] < height)
    near = np.hypot(rel[:, 0], rel[:, 1]) < radius + margin
    hit = above & near
    if hit.any():
        names = cloud.label_names or {}
        occupants = sorted({names.get(int(v), str(int(v))) for v in cloud.labels[hit]})
        raise PlanningError(
            f"place at {np.round(p, 3).tolist()} on {support.name!r} is not free: {occupants} within "
            f"{radius + margin:.2f} m; click a free spot"
        )


def camera_ray(camera: CameraSpec, pixel: ArrayLike) -> tuple[F64, F64]:
    """(origin (3,) [m], unit direction (3,)) of the ray through ``pixel`` (u, v) [px] of ``camera``.

    Pixel (0, 0) is the top-left corner of the image of size ``camera.resolution``; the camera looks from
    ``pos`` at ``target`` with world z up (the same frame as the scene's MuJoCo camera).
    """
    u, v = (float(x) for x in np.asarray(pixel, dtype=np.float64).reshape(2))
    width, height = camera.resolution
    if not (0.0 <= u <= width and 0.0 <= v <= height):
        raise PlanningError(
            f"pixel ({u}, {v}) lies outside the {width}x{height} image of camera {camera.name!r}"
        )
    pos, target = np.asarray(camera.pos, dtype=np.float64), np.asarray(camera.target, dtype=np.float64)
    fwd = (target - pos) / np.linalg.norm(target - pos)
    up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, fwd)
    half_h = math.tan(math.radians(camera.fovy) / 2.0)
    half_w = half_h * width / height
    x = (2.0 * u / width - 1.0) * half_w
    y = (1.0 - 2.0 * v / height) * half_h
    d = fwd + x * right + y * cam_up
    return pos, np.asarray(d / np.linalg.norm(d), dtype=np.float64)


def ray_hit(
    origin: ArrayLike, direction: ArrayLike, cloud: LabelledCloud, config: GoalConfig | None = None
) -> F64:
    """(3,) [m] the first cloud point within ``ray_radius`` of the ray (nearest along it).

    Raises:
        PlanningError: the ray passes no cloud point.
    """
    config = config or GoalConfig()
    o = _p3(origin, "ray origin")
    d = _p3(direction, "ray direction")
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    rel = np.asarray(cloud.points, dtype=np.float64) - o
    along = rel @ d
    perp = np.linalg.norm(rel - along[:, None] * d, axis=1)
    hit = (along > 0.0) & (perp <= config.ray_radius)
    if not hit.any():
        raise PlanningError(
            f"the ray from {np.round(o, 3).tolist()} along {np.round(d, 3).tolist()} hits nothing "
            "in the cloud"
        )
    idx = np.flatnonzero(hit)
    return np.asarray(cloud.points[idx[int(np.argmin(along[idx]))]], dtype=np.float64)
