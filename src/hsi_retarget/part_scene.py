"""The door or drawer a schedule opens, as an obstacle while it stands open.

The retargeting's scene leaves out every part a schedule touches (it moves). Between the end of its
opening arc and the start of its closing arc, the part stands still at its opened pose: there it is put
back, opened, as an extra collision scene (:meth:`~hsi_retarget.ik.IKSolver.set_part_scene`), with the
objects that ride in it (a drawer's contents) moved along. The gripper and fingers of the hand that
opened it are exempt while it still holds the handle; every other sphere (the reaching hand, the arm
over a drawer's front, the holder's own forearm and upper arm) keeps its margin to it.

The part stands where the robot's hand actually took it, not where the schedule meant it to: a hand that
pulled a drawer short leaves it short. :meth:`PartPhase.reached` finds the opening [0..1] that carries
the holder's TCP at the grasp nearest to where it is at the end of the arc, and :meth:`PartPhase.posed`
puts the part (and what rides in it) there (:func:`~hsi_retarget.tracking.track` does both once per pass,
with :attr:`~hsi_retarget.retarget.RetargetConfig.reached_part`). What the part holds moves with it:
:func:`follow_part` moves the goals of a hand that grasps one of its :attr:`PartPhase.contents` by the
difference between the reached and the scheduled opening (a drawer pulled 2 cm short: its mug is 2 cm
further in), eased in from the end of the opening arc to the grasp and out after it, so that the hand
closes where the object is and the carry re-aimed from there (:mod:`hsi_retarget.carry_correction`)
still puts it down on its placement.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_retarget.easing import ease
from hsi_retarget.scene_distance import SceneDistance

if TYPE_CHECKING:
    from hsi_planning.scheduler.schedule import Schedule
    from hsi_retarget.joint_trajectory import ContactEvent
    from hsi_retarget.mapping import RobotGoals

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PartPhase:
    """An opened part standing still: its scene and when it applies (schedule time [s])."""

    part: str  #: door or drawer name, e.g. ``drawer_unit1/drawer1``
    holder: str  #: the hand holding its handle meanwhile ('' none)
    t_open: float  #: [s] the opening arc ends
    t_free: float  #: [s] the holder has let go and left the handle (inf: holds it until closing)
    t_close: float  #: [s] the closing arc starts (inf: stays open)
    scene: SceneDistance  #: the part (and what rides in it) at its opened pose
    t_grasp: float = -math.inf  #: [s] the holder has taken the handle (the end of its reach)
    fraction: float = 1.0  #: [-] opening of :attr:`scene` (1: as scheduled)
    meshes: Mapping[str, Any] | None = None  #: name -> closed-pose trimesh of the part and its riders
    motion: Callable[[float], NDArray[np.float64]] | None = None  #: opening [-] -> (4, 4) world motion
    contents: tuple[str, ...] = ()  #: the objects standing on the part (a drawer's), the task's included
    #: [s] the holder lets go of the handle after opening it (its release keyframe; inf: unknown)
    t_release: float = math.inf

    def shift(self) -> F64:
        """(4, 4) world motion from the part as scheduled (opening 1) to it at :attr:`fraction`: where
        its contents are, relative to where the schedule put them (identity without a motion)."""
        if self.motion is None or self.fraction == 1.0:
            return np.eye(4)
        return np.asarray(self.motion(self.fraction) @ np.linalg.inv(self.motion(1.0)))

    def posed(self, fraction: float) -> PartPhase:
        """This phase with the part opened to ``fraction`` [-] (clipped to [0, 1]); itself when it has no
        meshes and motion, or is already there."""
        f = float(np.clip(fraction, 0.0, 1.0))
        if self.meshes is None or self.motion is None or f == self.fraction:
            return self
        motion = self.motion(f)
        moved = {}
        for name, mesh in self.meshes.items():
            copy = mesh.copy()
            copy.apply_transform(motion)
            moved[name] = copy
        return replace(self, fraction=f, scene=SceneDistance(moved, ground=(), padding=self.scene.padding))

    def reached(self, tcp_at_grasp: NDArray[np.float64], tcp_at_open: NDArray[np.float64]) -> float:
        """The opening [0..1] that moves the holder's TCP from ``tcp_at_grasp`` (3,) [m] nearest to
        ``tcp_at_open`` (3,) [m]: how far the hand took the part (1 without a motion)."""
        if self.motion is None:
            return 1.0
        grasp, target = np.asarray(tcp_at_grasp, dtype=float), np.asarray(tcp_at_open, dtype=float)
        if not (np.isfinite(grasp).all() and np.isfinite(target).all()):
            return self.fraction
        return HandleArc(self.motion, grasp).nearest(target)

    def at(self, t: float) -> tuple[SceneDistance | None, str]:
        """The extra scene and its exempt hand at time ``t`` [s] (``None`` outside the open interval)."""
        if not self.t_open <= t < self.t_close:
            return None, ""
        return self.scene, self.holder if t < self.t_free else ""


class HandleArc:
    """The path of a TCP that holds the part at ``grasp`` (3,) [m] (its pose with the part closed) as
    ``motion`` (opening [0..1] -> (4, 4) world motion) opens it; its points are computed once, for many
    :meth:`nearest` calls (a part posed on every frame, :mod:`hsi_retarget.part_arcs`)."""

    def __init__(self, motion: Callable[[float], F64], grasp: F64) -> None:
        self._motion = motion
        self._grasp = np.array(grasp, dtype=np.float64)
        self._points: dict[float, F64] = {}

    def _at(self, fraction: float) -> F64:
        point = self._points.get(fraction)
        if point is None:
            m = self._motion(fraction)
            point = self._points[fraction] = m[:3, :3] @ self._grasp + m[:3, 3]
        return point

    def nearest(self, target: F64) -> float:
        """The opening [0..1] whose TCP is nearest to ``target`` (3,) [m]: the best of 51 evenly spaced,
        refined within a grid step."""

        def miss(f: float) -> float:
            return float(np.linalg.norm(self._at(f) - target))

        best = min(np.linspace(0.0, 1.0, 51), key=miss)
        return float(min(np.clip(best + np.linspace(-0.02, 0.02, 21), 0.0, 1.0), key=miss))


def opened_part(
    schedule: Schedule, spec: Any, exclude: tuple[str, ...] = (), padding: float = 0.0
) -> PartPhase | None:
    """The :class:`PartPhase` of the part ``schedule`` opens in scene ``spec`` (``None``: no part, or no
    opening arc); objects named in ``exclude`` (the task's targets) are not added. ``padding`` [m]: the
    part's scene is grown by it (:class:`~hsi_retarget.scene_distance.SceneDistance`)."""
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
    reaches = [k.time for k in keys if k.hand == holder and k.action == "reach" and k.time <= min(opens)]
    releases = [k.time for k in keys if k.hand == holder and k.contact_event == "release" and k.time > t_open]
    world = SceneWorld(spec)
    motion = world.part_transform(part, 1.0)
    meshes = scene_meshes(spec)
    riding = [o.name for o in spec.objects if o.name not in exclude and support_of(spec, o.name).body == part]
    closed = {name: meshes[name].copy() for name in (part, *riding)}
    moved = {}
    for name, mesh in closed.items():
        copy = mesh.copy()
        copy.apply_transform(motion)
        moved[name] = copy
    return PartPhase(
        part,
        holder,
        float(t_open),
        float(t_free),
        float(t_close),
        SceneDistance(moved, ground=(), padding=padding),
        t_grasp=float(max(reaches)) if reaches else -math.inf,
        meshes=closed,
        motion=lambda f: world.part_transform(part, f),
        contents=tuple(o.name for o in spec.objects if support_of(spec, o.name).body == part),
        t_release=float(min(releases)) if releases else math.inf,
    )


def follow_part(
    goals: RobotGoals, part: PartPhase, events: Sequence[ContactEvent], ease_s: float = 0.5
) -> RobotGoals:
    """``goals`` whose hands grasping one of ``part``'s contents (``events`` in the goals' time [s]) after
    it opened are moved by :meth:`PartPhase.shift` (a drawer's: a translation), eased in from the end of
    the opening arc to the grasp and out over ``ease_s`` [s] after it; ``goals`` itself when nothing moves."""
    move = part.shift()
    if np.allclose(move, np.eye(4)) or not part.contents:
        return goals
    rotvec = Rotation.from_matrix(move[:3, :3]).as_rotvec()
    t, tcp = goals.t, {s: np.array(p) for s, p in goals.tcp.items()}
    for e in events:
        if e.kind != "grasp" or e.object_name not in part.contents or e.hand not in tcp:
            continue
        if not part.t_open <= e.time < part.t_close:
            continue
        rise = ease((t - part.t_open) / max(e.time - part.t_open, 1e-9))
        weight = np.where(t <= e.time, rise, 1.0 - ease((t - e.time) / max(ease_s, 1e-9)))
        sel = np.flatnonzero(weight > 0.0)
        step = np.tile(np.eye(4), (sel.shape[0], 1, 1))
        step[:, :3, :3] = Rotation.from_rotvec(weight[sel, None] * rotvec[None, :]).as_matrix()
        step[:, :3, 3] = weight[sel, None] * move[None, :3, 3]
        tcp[e.hand][sel] = step @ tcp[e.hand][sel]
    return replace(goals, tcp=tcp)
