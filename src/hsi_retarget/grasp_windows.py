"""The grasps and releases of a schedule as windows around their events (:class:`GraspWindow`), which
:mod:`hsi_retarget.grasp_depth` turns into gripper goals, and the rims of the drawers objects are grasped
from (:func:`container_rims`)."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # the scheduler package is heavy; only its types are needed here
    from hsi_planning.scheduler.schedule import Schedule
    from hsi_retarget.grasp_depth import GraspDepthConfig

__all__ = ["GraspWindow", "container_rims", "grasp_windows"]

_EPS = 1e-3  #: [s] tolerance matching event and segment times


@dataclass(frozen=True)
class GraspWindow:
    """One grasp or release of a hand, with the planned approach before it and the withdrawal after it."""

    hand: str  #: ``left`` or ``right``
    kind: str  #: ``grasp`` or ``release``
    target: str  #: object or door/drawer name
    free: bool  #: a free object (held rigidly, carried) rather than a door or drawer handle
    time: float  #: [s] the event
    before: tuple[float, float]  #: [s] the approach into the contact (start, end)
    after: tuple[float, float]  #: [s] the withdrawal after it (start, end)
    #: [m] world height of the rim of the open container a top-down grasp reaches into (-inf: none)
    rim: float = -np.inf


def container_rims(scene: Any) -> dict[str, float]:
    """Object -> world height [m] of the walls' top of the drawer it stands in (:attr:`GraspWindow.rim`),
    for the objects of a scene spec; objects on open surfaces or boards have none (``{}`` for anything
    but a spec)."""
    if not (hasattr(scene, "furniture") and hasattr(scene, "objects")):
        return {}
    from hsi_planning.scene.model import support_surfaces

    supports = support_surfaces(scene)
    kinds = {f.name: f.kind for f in scene.furniture}
    out = {}
    for obj in scene.objects:
        s = supports.get(obj.on)
        if s is not None and kinds.get(s.furniture) == "drawer_unit" and s.body != s.furniture:  # a drawer
            out[obj.name] = float(s.top_z + s.ceiling)
    return out


def _hands(hand: str) -> tuple[str, ...]:
    return ("left", "right") if hand == "both" else (hand,)


def grasp_windows(
    schedule: Schedule,
    objects: Collection[str],
    config: GraspDepthConfig,
    rims: Mapping[str, float] | None = None,
) -> list[GraspWindow]:
    """The grasp and release windows of ``schedule`` (time order); ``objects`` are the free objects (other
    targets are doors and drawers). The approach is the hand's last planned segment ending at the event, the
    withdrawal its first one starting after it (``ramp_s`` windows where there is none). ``rims``: object ->
    world height [m] of the rim of the open container it is grasped from (:attr:`GraspWindow.rim`)."""
    names = set(objects)
    rims = rims or {}
    out: list[GraspWindow] = []
    for k in schedule.events():
        if k.contact_event not in ("grasp", "release"):
            continue
        for hand in _hands(k.hand):
            own = sorted(
                (s for s in schedule.segments if s.trajectory.hand == hand), key=lambda s: s.start_time
            )
            before = [s for s in own if abs(s.end_time - k.time) <= _EPS]
            after = [s for s in own if s.start_time >= k.time - _EPS and s.end_time > k.time + _EPS]
            b = (before[-1].start_time, k.time) if before else (k.time - config.ramp_s, k.time)
            a = (after[0].start_time, after[0].end_time) if after else (k.time, k.time + config.ramp_s)
            if after and after[0].start_time - k.time > config.ramp_s + 1.0:  # a later, unrelated segment
                a = (k.time, k.time + config.ramp_s)
            free = k.object_name in names
            rim = rims.get(k.object_name, -np.inf) if k.contact_event == "grasp" else -np.inf
            out.append(GraspWindow(hand, str(k.contact_event), k.object_name, free, k.time, b, a, rim))
    return out
