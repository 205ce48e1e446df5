"""A fast geometric test of whether a target object can be reached (used to keep pickable layouts).

Works in the frame of the target's support with the axis-aligned boxes of the objects' exact shapes:

- the target must fit: its top plus ``headroom`` stays under the support's ceiling;
- front access (cabinet, shelf): the corridor from the opening to the target (target width plus
  ``hand_margin`` per side) is free, or every object in it has a free corridor itself (the scheduler
  can move it aside first), i.e. the target is not fully enclosed from the opening; with ``direct``
  the corridor itself must be free (one reach, no blocker to move first);
- top access (drawer, counter, table): on two opposite sides (±x or ±y) the gap to the next object or
  wall is at least ``finger_clearance``.

:func:`exposing_fraction` says how far a drawer must be pulled for an object in it to come out from under
the carcass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError
from hsi_planning.scene.furniture import furniture_bodies, furniture_frame
from hsi_planning.scene.model import object_pose_on, support_surface
from hsi_planning.scene.spec import SceneSpec
from hsi_planning.scene.validate import object_points


@dataclass(frozen=True)
class ReachConfig:
    """Clearances of the reachability test."""

    hand_margin: float = 0.02  #: free lateral margin each side of the approach corridor [m]
    headroom: float = 0.02  #: free height above the target under the ceiling [m]
    finger_clearance: float = 0.015  #: free gap on two opposite sides for a grasp from above [m]

    def __post_init__(self) -> None:
        if min(self.hand_margin, self.headroom, self.finger_clearance) < 0.0:
            raise ConfigError("ReachConfig: hand_margin, headroom and finger_clearance must be >= 0 m")


def _boxes(spec: SceneSpec, support_name: str) -> dict[str, NDArray[np.float64]]:
    """Axis-aligned (2, 3) [min; max] boxes [m] of the objects on one support, in its frame."""
    support = support_surface(spec, support_name)
    out = {}
    for o in spec.objects:
        if o.on == support_name:
            pts = object_points(o, object_pose_on(o, support))
            local = (pts - support.frame[:3, 3]) @ support.frame[:3, :3]
            out[o.name] = np.stack([local.min(axis=0), local.max(axis=0)])
    return out


def _corridor_blockers(
    name: str, boxes: dict[str, NDArray[np.float64]], hx: float, margin: float
) -> list[str]:
    box = boxes[name]
    y0, y1 = box[0, 1] - margin, box[1, 1] + margin
    return [
        other
        for other, ob in boxes.items()
        if other != name and ob[0, 0] < box[0, 0] and ob[1, 1] > y0 and ob[0, 1] < y1 and ob[1, 0] > -hx
    ]


def _side_gaps(
    name: str, boxes: dict[str, NDArray[np.float64]], walls: tuple[float, float]
) -> NDArray[np.float64]:
    """Free gaps [m] of the target in directions (+x, -x, +y, -y)."""
    box = boxes[name]
    gaps = np.array([walls[0] - box[1, 0], box[0, 0] + walls[0], walls[1] - box[1, 1], box[0, 1] + walls[1]])
    for other, ob in boxes.items():
        if other == name:
            continue
        if ob[1, 1] > box[0, 1] and ob[0, 1] < box[1, 1]:  # overlaps in y: limits ±x
            if ob[0, 0] >= box[1, 0]:
                gaps[0] = min(gaps[0], ob[0, 0] - box[1, 0])
            elif ob[1, 0] <= box[0, 0]:
                gaps[1] = min(gaps[1], box[0, 0] - ob[1, 0])
        if ob[1, 0] > box[0, 0] and ob[0, 0] < box[1, 0]:  # overlaps in x: limits ±y
            if ob[0, 1] >= box[1, 1]:
                gaps[2] = min(gaps[2], ob[0, 1] - box[1, 1])
            elif ob[1, 1] <= box[0, 1]:
                gaps[3] = min(gaps[3], box[0, 1] - ob[1, 1])
    return gaps


def target_reachable(
    spec: SceneSpec, target: str, config: ReachConfig | None = None, *, direct: bool = False
) -> bool:
    """Whether ``target`` can be reached (see the module docstring); ``direct``: without moving another
    object out of the way first."""
    config = config or ReachConfig()
    o = spec.object_by_name(target)
    support = support_surface(spec, o.on)
    boxes = _boxes(spec, o.on)
    if boxes[target][1, 2] + config.headroom > support.ceiling:
        return False
    kind = spec.furniture_by_name(support.furniture).kind
    hx, hy = support.half_extents
    if kind in ("cabinet", "shelf"):
        blockers = _corridor_blockers(target, boxes, hx, config.hand_margin)
        if direct:
            return not blockers
        return all(not _corridor_blockers(b, boxes, hx, config.hand_margin) for b in blockers)
    walls = (hx, hy) if kind == "drawer_unit" else (math.inf, math.inf)
    gaps = _side_gaps(target, boxes, walls)
    c = config.finger_clearance
    return bool((gaps[0] >= c and gaps[1] >= c) or (gaps[2] >= c and gaps[3] >= c))


def exposing_fraction(spec: SceneSpec, target: str, least: float, most: float, margin: float = 0.05) -> float:
    """[-] how far (fraction of the travel) the drawer holding ``target`` must be pulled for the whole
    object to come out from under the carcass with ``margin`` [m] to spare (room for the fingers and the
    hand behind it), clipped to [``least``, ``most``]; ``least`` for a target not in a drawer. A person
    pulls a drawer as far as the object needs: an object at the back of a deep drawer needs more.

    Raises:
        ConfigError: ``least``/``most`` outside (0, 1] or ``least > most``, or a negative ``margin``.
    """
    if not (0.0 < least <= most <= 1.0) or margin < 0.0:
        raise ConfigError(
            f"exposing_fraction: need 0 < least <= most <= 1 and margin >= 0 m, got {least}, {most}, {margin}"
        )
    o = spec.object_by_name(target)
    support = support_surface(spec, o.on)
    f = spec.furniture_by_name(support.furniture)
    if f.kind != "drawer_unit":
        return least
    plan = next((b for b in furniture_bodies(f) if b.name == support.body and b.joint is not None), None)
    if plan is None or plan.joint is None or plan.joint.range[1] <= 0.0:
        return least
    pts = object_points(o, object_pose_on(o, support))
    frame = furniture_frame(f)
    local = (pts - frame[:3, 3]) @ frame[:3, :3]  # the drawer slides along the furniture frame's -x
    front = -0.5 * f.size[1]
    need = (float(local[:, 0].max()) + margin - front) / plan.joint.range[1]
    return float(np.clip(need, least, most))
