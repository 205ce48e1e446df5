"""Auxiliary objects of a pick: the closed door or drawer enclosing the target, the objects blocking its
way out, and a free spot to put a blocker aside.

**Enclosing part.** A target on a cabinet support is behind the cabinet's door (of a two-door cabinet,
the leaf in front of it); a target in a drawer is behind that drawer. It matters while closed.

**Blockers** (CHOICE: the planned take-out decides). The take-out is planned with the scene's objects as
obstacles; if that fails or the carried target still touches another object, it is planned again with the
target's neighbours on the same support left out of the obstacles, and every neighbour that the carried
target (its points moved along the leave segment) or the hand sphere comes within ``clearance`` of, while
still inside the container, is a blocker. Blockers are ordered by when the take-out would hit them.
A planned path may wind past a neighbour with a hand sphere's room to spare where a robot's gripper and
wrist, which follow the straight approach through the opening, do not fit: with ``corridor_radius`` > 0,
every neighbour with points inside the container within that radius of the straight line from the target
out of a front opening (cabinets, shelves) blocks as well, nearest to the opening first.

**Free spot.** Candidate spots on the open support surfaces (counters, tables, shelf boards; cabinet and
drawer floors only when open) where the object's footprint holds no points, outside the target's take-out
corridor, nearest first (at least ``spot_spread`` apart). The scheduler starts that corridor at the
target's centre (the fingers close around it) and makes it at least ``corridor_radius`` wide.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.perception.cloud import LabelledCloud
from hsi_planning.planning import Planner, PlanRequest
from hsi_planning.scene.furniture import SupportSurface, opening_direction
from hsi_planning.scene.geometry import support_of
from hsi_planning.scene.model import support_surfaces
from hsi_planning.scheduler.reach_planner import contact_from_points
from hsi_planning.scheduler.world import SceneWorld, WorldState, label_points
from hsi_planning.trajectory import Hand, WristTrajectory

_LOG = logging.getLogger(__name__)
F64 = NDArray[np.float64]
_UP = np.array([0.0, 0.0, 1.0])
_FRONT_ACCESS = ("cabinet", "shelf")
FRONT_RISE = 0.05  #: [m] how much higher than the contact a free wrist pose out of a front opening lies


@dataclass(frozen=True)
class AuxiliaryConfig:
    """Blocker detection and free-spot search."""

    clearance: float = 0.01  #: [m] a neighbour closer than this to the carried target blocks it
    hand_radius: float = 0.035  #: [m] hand sphere checked along the take-out
    palm_offset: float = 0.06  #: [m] wrist distance beyond the target's box along the approach axis
    spot_step: float = 0.02  #: [m] spacing of candidate free spots
    spot_margin: float = 0.02  #: [m] free margin around a spot's footprint
    spot_spread: float = 0.08  #: [m] least distance between the spots offered (nearest first); 0 = any
    corridor_margin: float = 0.03  #: [m] extra width of the target's take-out corridor kept free
    #: [m] free height above the object on a spot reached from above (counters, tables, drawers): the
    #: gripper's length; a pulled-out drawer's floor still under the counter top has none
    spot_headroom: float = 0.2
    free_distance: float = 0.35  #: [m] free wrist pose distance from the contact (take-out end)
    #: [m] radius of the straight approach corridor out of a front opening that must be free of
    #: neighbours (a gripper's half width plus room); 0 = only the planned take-out decides
    corridor_radius: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "clearance",
            "hand_radius",
            "palm_offset",
            "spot_margin",
            "spot_spread",
            "corridor_margin",
            "corridor_radius",
            "spot_headroom",
        ):
            if getattr(self, name) < 0.0:
                raise ConfigError(f"AuxiliaryConfig.{name} must be >= 0 m, got {getattr(self, name)}")
        if not (self.spot_step > 0.0 and self.free_distance > 0.0):
            raise ConfigError("AuxiliaryConfig: spot_step and free_distance must be > 0 m")


def enclosing_part(world: SceneWorld, target: str, state: WorldState) -> str | None:
    """The closed door or drawer in front of ``target``, or None when it is reachable as is."""
    support = support_of(world.spec, target)
    parts = world.parts
    if support.body in parts:  # a drawer
        return None if support.body in state.opened else support.body
    doors = [p for p in parts.values() if p.furniture == support.furniture and p.kind == "hinge"]
    if not doors:
        return None
    pos = world.object_position(target, state)
    door = min(doors, key=lambda d: float(np.linalg.norm(_leaf_centre(world, d.name) - pos[:2])))
    return None if door.name in state.opened else door.name


def _leaf_centre(world: SceneWorld, door: str) -> F64:
    seg = world.door_panel(door, 0.0)
    return np.asarray(seg.mean(axis=0), dtype=np.float64)


def approach_axis(world: SceneWorld, support: SupportSurface) -> F64:
    """(3,) unit direction out of the opening a hand uses for objects on ``support``: the front normal of
    cabinets and shelves, +z for counters, tables and (pulled-out) drawers."""
    furniture = world.spec.furniture_by_name(support.furniture)
    if furniture.kind in _FRONT_ACCESS:
        return np.asarray(opening_direction(furniture), dtype=np.float64)
    return _UP.copy()


def free_pose(contact: ArrayLike, axis: ArrayLike, distance: float) -> F64:
    """(3,) [m] a free wrist pose ``distance`` out of the opening from ``contact`` (front: along the axis,
    slightly raised; top access: straight up)."""
    c, a = np.asarray(contact, dtype=np.float64), np.asarray(axis, dtype=np.float64)
    if abs(a[2]) > 0.9:
        return np.asarray(c + distance * _UP)
    return np.asarray(c + distance * a + FRONT_RISE * _UP)


def _inside(points: F64, support: SupportSurface, axis: F64) -> NDArray[np.bool_]:
    """Which points lie inside the support's container (before its opening plane / under its ceiling)."""
    hx, _ = support.half_extents
    front = support.frame[:3, 3] + hx * support.opening * (1.0 if abs(axis[2]) < 0.9 else 0.0)
    if abs(axis[2]) > 0.9:
        top = support.top_z + (support.ceiling if np.isfinite(support.ceiling) else 0.3)
        return np.asarray(points[:, 2] < top)
    return np.asarray((points - front) @ axis < 0.0)


def _hits(
    leave: WristTrajectory,
    target_pts: F64,
    others: dict[str, F64],
    inside: NDArray[np.bool_],
    config: AuxiliaryConfig,
) -> list[str]:
    contact = leave.position[leave.contact_index]
    order: dict[str, int] = {}
    names = list(others)
    if not names:
        return []
    pts = np.vstack([others[n] for n in names])
    owner = np.concatenate([np.full(len(others[n]), i) for i, n in enumerate(names)])
    tree = cKDTree(pts)
    for i in np.flatnonzero(inside):
        moved = target_pts + (leave.position[i] - contact)
        d, j = tree.query(moved, k=1)
        dh, jh = tree.query(leave.position[i], k=1)
        for dist, idx, limit in (
            (np.min(d), j[int(np.argmin(d))], config.clearance),
            (dh, jh, config.hand_radius),
        ):
            name = names[int(owner[int(idx)])]
            if float(dist) < limit and name not in order:
                order[name] = int(i)
    return sorted(order, key=order.__getitem__)


def find_blockers(
    world: SceneWorld,
    planner: Planner,
    target: str,
    state: WorldState,
    *,
    hand: Hand = "right",
    config: AuxiliaryConfig | None = None,
) -> list[str]:
    """Objects to move before ``target`` can be taken out (see the module docstring); ``state`` must have
    the target's container open.

    Raises:
        PlanningError: the target is not visible, or cannot be taken out even with its neighbours moved.
    """
    config = config or AuxiliaryConfig()
    support = support_of(world.spec, target)
    cloud = world.state_cloud(state, complete=world.neighbours(target))
    target_pts = label_points(cloud, [target])
    if len(target_pts) == 0:
        raise PlanningError(
            f"{target!r} is not visible in the cloud (hidden or out of view); it cannot be picked"
        )
    axis = approach_axis(world, support)
    contact, _ = contact_from_points(target_pts, axis, config.palm_offset)
    free = free_pose(contact, axis, config.free_distance)
    neighbours = [o.name for o in world.spec.objects if o.on == support.name and o.name != target]
    neighbours = [n for n in neighbours if n not in state.held]
    others = {n: label_points(cloud, [n]) for n in neighbours}
    others = {n: p for n, p in others.items() if len(p)}
    in_way = _corridor_blockers(target_pts, others, support, axis, config.corridor_radius)
    for attempt, plan_cloud in enumerate((cloud, _without(cloud, list(others)))):
        request = PlanRequest(
            cloud=plan_cloud,
            target=target,
            hand=hand,
            action="grasp",
            start_position=free,
            approach_axis=axis,
            retreat_position=free,
        )
        try:
            leave = planner.plan(request).leave
        except PlanningError as exc:
            if attempt == 1:
                raise PlanningError(
                    f"{target!r} cannot be taken out of {support.name!r} even with {sorted(others)} "
                    f"moved: {exc}"
                ) from exc
            _LOG.debug(
                "take-out of %s with every obstacle failed (%s); trying without neighbours", target, exc
            )
            continue
        hits = _hits(leave, target_pts, others, _inside(leave.position, support, axis), config)
        hits += [n for n in in_way if n not in hits]
        if attempt == 0 and not hits:
            return []
        if attempt == 1:
            return hits
    return []


def _corridor_blockers(
    target_pts: F64, others: dict[str, F64], support: SupportSurface, axis: F64, radius: float
) -> list[str]:
    """Neighbours with points inside the container within ``radius`` [m] of the straight line from the
    target's centre out along a front opening's ``axis``, nearest to the opening first (none for top
    access or ``radius`` 0)."""
    if radius <= 0.0 or abs(float(axis[2])) > 0.9:
        return []
    centre = 0.5 * (target_pts.min(axis=0) + target_pts.max(axis=0))
    found: dict[str, float] = {}
    for name, pts in others.items():
        rel = pts - centre
        along = rel @ axis
        lateral = np.linalg.norm(rel - np.outer(along, axis), axis=1)
        near = (along > 0.0) & (lateral < radius) & _inside(pts, support, axis)
        if near.any():
            found[name] = float(along[near].min())
    return sorted(found, key=lambda n: -found[n])


def _without(cloud: LabelledCloud, names: list[str]) -> LabelledCloud:
    table = cloud.label_names or {}
    ids = [k for k, v in table.items() if v in set(names)]
    return cloud.select(~np.isin(cloud.labels, ids))


def free_spots(
    world: SceneWorld,
    state: WorldState,
    obj: str,
    cloud: LabelledCloud,
    *,
    avoid: tuple[F64, F64, float] | None = None,
    config: AuxiliaryConfig | None = None,
    limit: int = 8,
) -> list[tuple[str, F64]]:
    """Up to ``limit`` (support name, bottom-centre position (3,) [m]) spots where ``obj`` fits, nearest to
    its current position first. ``avoid`` = (point (3,), direction (3,), half width [m]): a take-out
    corridor (from the point along the horizontal direction) to keep free."""
    config = config or AuxiliaryConfig()
    size = world.object_size(obj)
    radius = 0.5 * float(np.hypot(size[0], size[1])) if len(size) == 3 else 0.5 * float(size[0])
    height = float(size[-1])
    here = world.object_position(obj, state)
    pts = np.asarray(cloud.points, dtype=np.float64)
    own = label_points(cloud, [obj])
    if len(own):
        keep = cKDTree(own).query(pts, k=1)[0] > 1e-9
        pts = pts[keep]
    found: list[tuple[float, str, F64]] = []
    for support in support_surfaces(world.spec).values():
        kind = world.spec.furniture_by_name(support.furniture).kind
        if support.ceiling < height + 0.02 or not support_open(world, support, kind, state):
            continue
        hx, hy = support.half_extents
        if hx < radius or hy < radius:
            continue
        xs = np.arange(-hx + radius, hx - radius + 1e-9, config.spot_step)
        ys = np.arange(-hy + radius, hy - radius + 1e-9, config.spot_step)
        local = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
        frame = support.frame
        if support.body in world.parts:  # a drawer's floor: where the opened drawer has it
            frame = world.part_transform(support.body, 1.0) @ frame
        world_xy = (frame[:3, :3] @ np.column_stack([local, np.zeros(len(local))]).T).T + frame[:3, 3]
        # a hand that puts the object down from above needs room above it as well
        above = height + (config.spot_headroom if approach_axis(world, support)[2] > 0.5 else 0.0)
        slab = pts[(pts[:, 2] > support.top_z + 0.01) & (pts[:, 2] < support.top_z + above)]
        ok = np.ones(len(world_xy), dtype=bool)
        if len(slab):
            d, _ = cKDTree(slab[:, :2]).query(world_xy[:, :2], k=1)
            ok &= d > radius + config.spot_margin
        if avoid is not None:
            ok &= ~_in_corridor(world_xy[:, :2], avoid, radius + config.corridor_margin)
        for p in world_xy[ok]:
            pos = np.array([p[0], p[1], support.top_z])
            found.append((float(np.linalg.norm(pos - here)), support.name, pos))
    found.sort(key=lambda f: f[0])
    out: list[tuple[str, F64]] = []
    for _, name, pos in found:  # nearest first, spread out: a spot next to a failed one fails alike
        if all(np.linalg.norm(pos - q) >= config.spot_spread for _, q in out):
            out.append((name, pos))
            if len(out) == limit:
                break
    return out


def _in_corridor(xy: F64, avoid: tuple[F64, F64, float], clearance: float) -> NDArray[np.bool_]:
    """(N,) spots ``xy`` (N, 2) [m] whose footprint (``clearance`` [m] beyond the centre) reaches into the
    take-out corridor ``avoid`` = (start (3,), direction (3,), half width [m]): the strip from the start along
    the horizontal direction, or for a vertical take-out (from above) the disc around the start."""
    start, direction, half = avoid
    rel = xy - np.asarray(start)[:2]
    horizontal = float(np.hypot(direction[0], direction[1]))
    if horizontal < 0.2:  # lifted out upwards: keep the column above the start free
        return np.asarray(np.linalg.norm(rel, axis=1) < half + clearance)
    dh = np.array([direction[0], direction[1]]) / horizontal
    along = rel @ dh
    across = np.abs(rel @ np.array([-dh[1], dh[0]]))
    return np.asarray((along > -half) & (across < half + clearance))


def support_open(world: SceneWorld, support: SupportSurface, kind: str, state: WorldState) -> bool:
    """Whether ``support`` (of furniture ``kind``) can be reached in ``state``: drawers and cabinet
    shelves only with their drawer / every door of the cabinet open."""
    if support.body in world.parts:
        return support.body in state.opened
    if kind == "cabinet":
        doors = [p for p in world.parts.values() if p.furniture == support.furniture]
        return all(d.name in state.opened for d in doors)
    return True
