"""Hand state and hand assignment: who holds what, which ways the task can be split between the hands, and
the total deviation cost that picks one (CHOICE Eq. 24).

**Strategies.**

- ``single``: one hand grasps (no door or drawer to open);
- ``both``: a two-handed grasp and carry (objects a hand cannot hold: ``two_hand_kinds``, wider than
  ``max_one_hand_width`` or heavier than ``max_one_hand_mass``);
- ``sequential``: one hand opens the door/drawer and lets go, then grasps; the other hand (if free) closes;
- ``cotemporal``: one hand opens and holds the door/drawer while the other grasps and takes out, then the
  first closes.

One hand free → the sequential (or single) plan with that hand. Both free → every strategy with either
hand is scheduled and the least total deviation cost wins::

    J = Σ_{h ∈ {left, right}} Σ_k |q_{h,k} − q_{h,k−1}| + w · T                  (Eq. 24, as implemented)

with q_{h,k} the wrist of hand h at keyframe k in the hip's heading frame (arm motion relative to the
body, so walking itself costs nothing here), T [s] the task duration and w = 2 m/s. The paper's exact
Eq. 24 was not available to us; this is our reading of "total deviation cost with w = 2": the hands'
total deviation plus the time the task takes.

**Crossed hands** (CHOICE). An assignment whose wrists cross, the left one further right than the right one
in the hip's heading frame by more than ``max_crossing`` at some keyframe (:func:`hand_crossing`), ranks
after every assignment that does not, whatever its cost: e.g. the left hand holding a drawer open on the
right of the body while the right hand reaches past it into the drawer. A person can still do it,
awkwardly; robot arms reaching across each other collide or leave their reach (the IK then misses the
inner hand's goals by 20-35 cm).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.scheduler.schedule import Schedule
from hsi_planning.trajectory import HANDS, Hand

Strategy = Literal["single", "both", "sequential", "cotemporal"]


@dataclass(frozen=True)
class HandState:
    """What each hand holds ('' = free)."""

    left: str = ""
    right: str = ""

    def holding(self, hand: Hand) -> str:
        return self.left if hand == "left" else self.right

    def free_hands(self) -> tuple[Hand, ...]:
        return tuple(h for h in HANDS if not self.holding(h))

    def with_object(self, hand: Hand, obj: str) -> HandState:
        return HandState(obj, self.right) if hand == "left" else HandState(self.left, obj)

    def held(self) -> tuple[str, ...]:
        return tuple(o for o in (self.left, self.right) if o)

    @classmethod
    def parse(cls, items: Iterable[str]) -> HandState:
        """From ``['left:mug1', ...]`` (CLI ``--holding``); raises :class:`ConfigError` for bad items."""
        state = cls()
        for item in items:
            hand, sep, obj = item.partition(":")
            if not sep or hand not in HANDS or not obj:
                raise ConfigError(f"holding {item!r}: use left:<object> or right:<object>")
            if state.holding(hand):  # type: ignore[arg-type]
                raise ConfigError(f"holding {item!r}: the {hand} hand already holds {state.holding(hand)!r}")  # type: ignore[arg-type]
            state = state.with_object(hand, obj)  # type: ignore[arg-type]
        return state


@dataclass(frozen=True)
class HandConfig:
    """What one hand can hold, and the weight of Eq. 24."""

    deviation_weight: float = 2.0  #: [m/s] w of Eq. 24: the cost of one second of task time
    two_hand_kinds: tuple[str, ...] = ("box",)  #: [-] object kinds without a handle or rim: both hands
    max_one_hand_width: float = 0.2  #: [m] wider objects (largest horizontal extent) take both hands
    max_one_hand_mass: float = 2.0  #: [kg] heavier objects take both hands
    #: [m] wrists crossed by more than this (see the module docstring) rank the assignment last; inf = never
    max_crossing: float = 0.1

    def __post_init__(self) -> None:
        if self.deviation_weight < 0.0:
            raise ConfigError(f"HandConfig.deviation_weight must be >= 0 m/s, got {self.deviation_weight}")
        if not self.max_crossing >= 0.0:
            raise ConfigError(f"HandConfig.max_crossing must be >= 0 m (inf: never), got {self.max_crossing}")
        if not (self.max_one_hand_width > 0.0 and self.max_one_hand_mass > 0.0):
            raise ConfigError("HandConfig: max_one_hand_width [m] and max_one_hand_mass [kg] must be > 0")


@dataclass(frozen=True)
class Assignment:
    """One way to split the task between the hands."""

    strategy: Strategy
    grasp: Hand | Literal["both"]  #: the hand(s) that grasp the target
    door: Hand | None = None  #: the hand that opens the door/drawer (None: nothing to open)
    close: Hand | None = None  #: the hand that closes it again (None: left open)

    def describe(self) -> str:
        """One line, e.g. ``cotemporal: left opens and holds, right grasps, left closes``."""
        grasp = "both hands grasp" if self.grasp == "both" else f"{self.grasp} grasps"
        if self.door is None:
            return f"{self.strategy}: {grasp}"
        verb = "opens and holds" if self.strategy == "cotemporal" else "opens"
        close = f", {self.close} closes" if self.close else ", left open: no free hand to close"
        return f"{self.strategy}: {self.door} {verb}, {grasp}{close}"


def needs_both_hands(kind: str, size: tuple[float, ...], mass: float, config: HandConfig) -> bool:
    """Whether an object of ``kind``, ``size`` (box (lx, ly, lz) or (diameter, height)) [m] and ``mass``
    [kg] needs both hands."""
    width = math.hypot(size[0], size[1]) if len(size) == 3 else size[0]
    return (
        kind in config.two_hand_kinds or width > config.max_one_hand_width or mass > config.max_one_hand_mass
    )


def candidate_assignments(
    hands: HandState, both: bool, has_part: bool, preferred: str = "", door: str = ""
) -> list[Assignment]:
    """Feasible assignments for a target (``both``: needs two hands; ``has_part``: a door/drawer to open).

    ``preferred``: '' (scheduler decides), ``left``, ``right`` or ``both`` restricts the grasping hand;
    ``door``: '' (scheduler decides), ``left`` or ``right`` restricts the hand that opens the door/drawer
    (ignored without one), e.g. to re-plan the way an executed plan already opened it.

    Raises:
        PlanningError: not enough free hands (the message says which hand holds what).
    """
    free = hands.free_hands()
    held = ", ".join(f"{h} holds {hands.holding(h)!r}" for h in HANDS if hands.holding(h))
    if not free:
        raise PlanningError(f"no free hand: {held}; place something first")
    out: list[Assignment] = []
    if both:
        if len(free) < 2:
            raise PlanningError(f"the target needs both hands but {held}")
        doors: list[Hand | None] = list(free) if has_part else [None]
        out = [Assignment("both", "both", d, None) for d in doors]
    elif not has_part:
        out = [Assignment("single", h) for h in free]
    else:
        for h in free:
            other = next((o for o in free if o != h), None)
            out.append(Assignment("sequential", h, h, other))
            if other is not None:
                out.append(Assignment("cotemporal", other, h, h))
    if preferred:
        if preferred not in ("left", "right", "both"):
            raise ConfigError(f"hand={preferred!r} is not valid; choose left, right, both or ''")
        out = [a for a in out if a.grasp == preferred]
        if not out:
            raise PlanningError(
                f"the {preferred} hand cannot grasp this target ({held or 'both hands free'})"
            )
    if door not in ("", "left", "right"):
        raise ConfigError(f"door_hand={door!r} is not valid; choose left, right or ''")
    if door and has_part:
        out = [a for a in out if a.door == door]
        if not out:
            grasp = f"the {preferred} hand grasping" if preferred else "any grasping hand"
            raise PlanningError(
                f"the {door} hand cannot open the door/drawer with {grasp} ({held or 'both hands free'})"
            )
    return out


def deviation_cost(schedule: Schedule, weight: float) -> float:
    """Eq. 24 (see the module docstring): wrist motion in the hip heading frame [m] + ``weight`` [m/s] · T."""
    total = 0.0
    for joint in ("left_wrist", "right_wrist"):
        local = np.array([p for _, p in _local_wrists(schedule, joint)]).reshape(-1, 3)
        total += float(np.linalg.norm(np.diff(local, axis=0), axis=1).sum())
    return total + weight * schedule.duration


def hand_crossing(schedule: Schedule) -> float:
    """[m] The most the left wrist lies right of the right wrist (hip heading frame) at a keyframe both have;
    negative while the hands stay apart, -inf without common keyframes."""
    left, right = (dict(_local_wrists(schedule, j)) for j in ("left_wrist", "right_wrist"))
    return max((float(right[t][1] - left[t][1]) for t in left if t in right), default=-math.inf)


def _local_wrists(schedule: Schedule, joint: str) -> list[tuple[float, np.ndarray]]:
    """(keyframe time [s] (rounded), the ``joint`` wrist (3,) [m] in the hip's heading frame) per keyframe."""
    hips = {round(k.time, 9): k for k in schedule.of("hip")}
    out: list[tuple[float, np.ndarray]] = []
    for k in schedule.of(joint):
        hip = hips.get(round(k.time, 9))
        if hip is None:
            raise PlanningError(f"no hip keyframe at t = {k.time:.3f} s for the {joint} keyframe")
        yaw = _yaw(hip.quaternion)
        c, s = math.cos(yaw), math.sin(yaw)
        rel = k.position - hip.position
        out.append((round(k.time, 9), np.array([c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1], rel[2]])))
    return out


def _yaw(quat: np.ndarray) -> float:
    x, y, z, w = (float(v) for v in quat)
    # heading of the rotated x axis projected on the floor
    fx, fy = 1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z)
    return math.atan2(fy, fx)
