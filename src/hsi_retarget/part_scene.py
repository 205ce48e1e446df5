"""The door or drawer a schedule opens, as an obstacle while it stands open.

The retargeting's scene leaves out every part a schedule touches (it moves). Between the end of its
opening arc and the start of its closing arc, the part stands still at its opened pose: there it is put
back, opened, as an extra collision scene (:meth:`~hsi_retarget.ik.IKSolver.set_part_scene`), with the
objects that ride in it (a drawer's contents) moved along. The hand that opened it is exempt while it
still holds the handle; every other sphere (the reaching hand, the arm over a drawer's front) keeps its
margin to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hsi_retarget.scene_distance import SceneDistance

if TYPE_CHECKING:
    from hsi_planning.scheduler.schedule import Schedule


@dataclass(frozen=True, eq=False)
class PartPhase:
    """An opened part standing still: its scene and when it applies (schedule time [s])."""

    part: str  #: door or drawer name, e.g. ``drawer_unit1/drawer1``
    holder: str  #: the hand holding its handle meanwhile ('' none)
    t_open: float  #: [s] the opening arc ends
    t_free: float  #: [s] the holder has let go and left the handle (inf: holds it until closing)
    t_close: float  #: [s] the closing arc starts (inf: stays open)
    scene: SceneDistance  #: the part (and what rides in it) at its opened pose

    def at(self, t: float) -> tuple[SceneDistance | None, str]:
        """The extra scene and its exempt hand at time ``t`` [s] (``None`` outside the open interval)."""
        if not self.t_open <= t < self.t_close:
            return None, ""
        return self.scene, self.holder if t < self.t_free else ""


def opened_part(schedule: Schedule, spec: Any, exclude: tuple[str, ...] = ()) -> PartPhase | None:
    """The :class:`PartPhase` of the part ``schedule`` opens in scene ``spec`` (``None``: no part, or no
    opening arc); objects named in ``exclude`` (the task's targets) are not added."""
    from hsi_planning.scene import scene_meshes
    from hsi_planning.scene.geometry import support_of
    from hsi_planning.scheduler.world import SceneWorld

    part = str(schedule.info.get("part", ""))
    keys = [k for k in schedule.keyframes if k.object_name == part and k.hand]
    opens = [k.time for k in keys if k.action == "open"]
    if not part or not opens:
        return None
    t_open = max(opens)
    closes = [k.time for k in keys if k.action == "close" and k.time > t_open]
    t_close = min(closes) if closes else math.inf
    holder = str(schedule.info.get("door_hand", keys[0].hand))
    later = [
        k.time for k in schedule.keyframes if k.hand == holder and k.time > t_open and k.object_name != part
    ]
    t_free = min(later) if later else math.inf
    world = SceneWorld(spec)
    motion = world.part_transform(part, 1.0)
    meshes = scene_meshes(spec)
    riding = [o.name for o in spec.objects if o.name not in exclude and support_of(spec, o.name).body == part]
    moved = {}
    for name in (part, *riding):
        mesh = meshes[name].copy()
        mesh.apply_transform(motion)
        moved[name] = mesh
    return PartPhase(
        part, holder, float(t_open), float(t_free), float(t_close), SceneDistance(moved, ground=())
    )
