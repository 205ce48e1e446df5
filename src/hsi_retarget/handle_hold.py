"""The holder's TCP goals while it has hold of a door's or drawer's handle, made to move as the part does.

A hand that holds a handle and the part form a closed chain: the handle can only go along the part's arc
(a door's circle about its hinge, a drawer's line), and it turns as the part does. The planned wrist
follows the human's hand, which keeps near that arc but turns its own way: in humanoid
``cabinet_bottle/reshape/1`` the commanded TCP turned 11-18 deg and moved 3-5 cm against the door for
10 s while the other hand grasped a bottle, the grasp weld in MuJoCo fought the arm, and the strained body
shook the grasping hand 3 cm off its bottle (its grasp failed).

:func:`hold_handle` replaces the holder's TCP goal, from its grasp of the handle to its release, by the
pose the part would give it: the goal at the grasp (the part closed) carried by the part's motion to the
opening whose arc point is nearest to the planned position,
``T(t) = M(f(t)) T(t_grasp)`` with ``f(t) = argmin_f |M(f) p(t_grasp) - p(t)|``, and eases back to the
planned goal over ``ease_s`` after the release. Only a hold that opens the part is reshaped (its grasp
comes before the opening arc ends, with the part closed); a hand that takes the handle of a part another
hand opened is left as planned.

While the part stands open (between its opening and closing arcs, eased in and out), the goal may also
slide up to ``slack`` of the opening *further open*, towards the opening nearest to where the holder's
tracked TCP is (:meth:`HandleHold.target`, applied frame by frame in :func:`~hsi_retarget.tracking.track`):
the door or drawer gives way to a holder stretched by the other hand's reach instead of the holder's pose
giving way. Never less open: a door closed a little put its panel in the way of the arm reaching past it
(humanoid cabinet_bottle/reshape/1: the bottle grasp then missed by 8.6 cm).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from hsi_planning.errors import ConfigError
from hsi_retarget.easing import ease
from hsi_retarget.mapping import RobotGoals
from hsi_retarget.part_scene import HandleArc, PartPhase

__all__ = ["HandleHold", "hold_handle"]

F64 = NDArray[np.float64]


def _holds(events: Sequence[Any], part: PartPhase) -> list[tuple[str, float, float]]:
    """(hand, grasp time, release time [s]; inf: never released) of each hold of ``part``'s handle that
    starts before its opening arc ends."""
    out = []
    for i, e in enumerate(events):
        if e.kind != "grasp" or e.object_name != part.part or e.time > part.t_open:
            continue
        later = [r.time for r in events[i + 1 :] if r.kind == "release" and r.hand == e.hand]
        out.append((str(e.hand), float(e.time), float(min(later)) if later else math.inf))
    return out


@dataclass(frozen=True, eq=False)
class HandleHold:
    """One hold of a handle that opens the part: the holder's goals at frames ``grasp`` .. ``release - 1``
    are the part's motion at an opening applied to its TCP goal ``start`` (4, 4) at the grasp."""

    hand: str  #: ``left`` / ``right``
    grasp: int  #: frame of the grasp
    release: int  #: frame of the release (the frame count: never released)
    start: F64  #: (4, 4) TCP goal at the grasp, the part closed [m]
    planned: F64  #: (T,) [-] opening of the planned goal at each frame (NaN outside the hold)
    #: (T,) [-] opening the goal may slide further open by, towards the reached TCP (0 on the opening and
    #: closing arcs; never less open: the other hand reaches past the part)
    slack: F64
    arc: HandleArc  #: the TCP's path as the part opens
    motion: Callable[[float], F64]  #: opening [-] -> (4, 4) world motion of the part

    def pose(self, fraction: float) -> F64:
        """(4, 4) [m] the holder's TCP with the part opened to ``fraction`` [-]."""
        return np.asarray(self.motion(float(np.clip(fraction, 0.0, 1.0))) @ self.start)

    def target(self, i: int, tcp: F64) -> F64 | None:
        """(4, 4) [m] the holder's goal at frame ``i`` with its TCP at ``tcp`` (3,) [m] now: the planned
        opening, slid further open towards the one nearest to the TCP by up to :attr:`slack` (``None``
        outside the hold)."""
        if not self.grasp < i < self.release:
            return None
        f, slack = float(self.planned[i]), float(self.slack[i])
        if slack > 0.0 and np.isfinite(tcp).all():
            f = float(np.clip(self.arc.nearest(tcp), f, f + slack))
        return self.pose(f)


def hold_handle(
    goals: RobotGoals,
    events: Sequence[Any],
    part: PartPhase | None,
    slack: float = 0.1,
    ease_s: float = 0.3,
) -> tuple[RobotGoals, list[HandleHold], list[dict[str, Any]]]:
    """``goals`` with the TCP goals of the hands holding ``part``'s handle moved as the part moves (see the
    module docstring); ``events``: contact events in the goals' time [s]; ``slack`` [-]: opening the goal
    may slide by while the part stands open (eased in and out over ``ease_s``); ``ease_s`` [s]: back to
    the plan after the release. Returns the goals (``goals`` itself when nothing changes), the holds (for
    :func:`~hsi_retarget.tracking.track`) and one record per hold (hand, times, the largest position [m]
    and angle [deg] change of its goals)."""
    if not (ease_s >= 0.0 and 0.0 <= slack <= 1.0):
        raise ConfigError(f"hold_handle: ease_s must be >= 0 [s] and slack in [0, 1], got {ease_s}, {slack}")
    if part is None or part.motion is None:
        return goals, [], []
    found = [h for h in _holds(events, part) if h[0] in goals.tcp]
    if not found:
        return goals, [], []
    t, tcp = goals.t, {s: np.array(p) for s, p in goals.tcp.items()}
    holds, records = [], []
    for hand, t_grasp, t_release in found:
        g = int(np.searchsorted(t, t_grasp, side="left"))
        if g >= t.shape[0]:
            continue
        r = int(np.searchsorted(t, t_release, side="left")) if math.isfinite(t_release) else t.shape[0]
        start = tcp[hand][g].copy()
        arc = HandleArc(part.motion, start[:3, 3])
        span = max(ease_s, 1e-9)
        weight = 1.0 - ease((t - t_release) / span)  # 1 up to the release, then eased out (inf: never)
        frames = np.flatnonzero((t > t[g]) & (weight > 0.0))
        planned = np.full(t.shape, np.nan)
        planned[frames] = [arc.nearest(tcp[hand][i, :3, 3]) for i in frames]
        rise = ease((t - part.t_open) / span) * (1.0 - ease((t - part.t_close + span) / span))
        hold = HandleHold(hand, g, r, start, planned, slack * rise, arc, part.motion)
        moved_p, moved_deg = 0.0, 0.0
        for i in frames:
            plan = tcp[hand][i]
            held, w = hold.pose(planned[i]), float(weight[i])
            pose = held.copy()
            if w < 1.0:  # easing back to the plan after the release
                rots = Rotation.from_matrix(np.stack([held[:3, :3], plan[:3, :3]]))
                pose[:3, :3] = Slerp([0.0, 1.0], rots)([1.0 - w]).as_matrix()[0]
                pose[:3, 3] = w * held[:3, 3] + (1.0 - w) * plan[:3, 3]
            moved_p = max(moved_p, float(np.linalg.norm(pose[:3, 3] - plan[:3, 3])))
            turn = Rotation.from_matrix(pose[:3, :3] @ plan[:3, :3].T).magnitude()
            moved_deg = max(moved_deg, math.degrees(float(turn)))
            tcp[hand][i] = pose
        holds.append(hold)
        records.append(
            {
                "hand": hand,
                "part": part.part,
                "t_grasp": t_grasp,
                "t_release": t_release,
                "max_shift_m": moved_p,
                "max_turn_deg": moved_deg,
            }
        )
    return replace(goals, tcp=tcp), holds, records
