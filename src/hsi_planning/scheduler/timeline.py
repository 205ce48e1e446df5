"""The schedule under construction: a clock, the hip pose, each wrist's state, and snapshot keyframes.

Each wrist is either attached to the body (``ready``: free, ``carry``: holding an object; its position is a
hip-frame offset, so it follows the hip) or fixed in the world (at a handle, at a contact, after a planned
segment). Every change of time ends with a *snapshot*: one keyframe per key joint at the new time. A
snapshot checks that both wrists are within ``arm_reach`` of their shoulders for the hip pose of that
instant and raises :class:`~hsi_planning.errors.PlanningError` otherwise, so a finished schedule is
reachable by construction.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import PlanningError
from hsi_planning.scheduler.body import BodyConfig, HipPose, wrist_quaternion
from hsi_planning.scheduler.schedule import ContactEvent, Keyframe, PlannedSegment, Schedule
from hsi_planning.trajectory import HANDS, Hand, WristTrajectory

F64 = NDArray[np.float64]


@dataclass
class WristState:
    """One wrist: ``mode`` ready / carry (hip-relative) or world (``position``, ``quaternion`` fixed)."""

    mode: str = "ready"
    position: F64 = field(default_factory=lambda: np.zeros(3))
    quaternion: F64 = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    holding: str = ""  #: object in the hand ('' = none)
    contact: str = ""  #: furniture part the hand holds ('' = none)
    carry_local: F64 | None = None  #: (3,) [m] hip heading-frame carry position (two-handed carry)


class Timeline:
    """Builds a :class:`Schedule` (see the module docstring)."""

    def __init__(self, body: BodyConfig, hip: HipPose, holding: dict[Hand, str]) -> None:
        self.body = body
        self.t = 0.0
        self.hip = hip
        self.wrists = {
            h: WristState(mode="carry" if holding.get(h) else "ready", holding=holding.get(h, ""))
            for h in HANDS
        }
        self.keyframes: list[Keyframe] = []
        self.segments: list[PlannedSegment] = []
        self.steps: list[str] = []
        self.root_path: list[F64] = [hip.xy]
        #: every free object carried, in grasp order: ``object``, ``hands``, its bottom centre at the
        #: ``grasp`` and its ``place`` target [m] (world; lists; the schedule's ``info["carries"]``)
        self.carries: list[dict[str, Any]] = []
        self.snapshot("start")

    # --------------------------------------------------------------------------------- queries

    def position(self, hand: Hand) -> F64:
        """(3,) [m] current world position of ``hand``'s wrist."""
        w = self.wrists[hand]
        if w.mode == "world":
            return w.position.copy()
        if w.mode == "carry" and w.carry_local is not None:
            c, s = math.cos(self.hip.yaw), math.sin(self.hip.yaw)
            x, y, z = (float(v) for v in w.carry_local)
            turned = np.array([c * x - s * y, s * x + c * y, z])
            return np.asarray(self.hip.position + turned, dtype=np.float64)
        offset = self.body.carry_offset if w.mode == "carry" else self.body.ready_offset
        return self.hip.wrist_offset(hand, offset)

    def quaternion(self, hand: Hand) -> F64:
        """(4,) [x y z w] current wrist orientation (forward along the heading when attached to the body)."""
        w = self.wrists[hand]
        if w.mode == "world":
            return w.quaternion.copy()
        h = self.hip.heading
        return wrist_quaternion([h[0], h[1], 0.0])

    def activity(self, hand: Hand) -> str:
        w = self.wrists[hand]
        if w.contact:
            return "hold"
        return "carry" if w.holding else "idle"

    # --------------------------------------------------------------------------------- output

    def snapshot(
        self,
        action: str,
        *,
        acting: dict[Hand, tuple[str, ContactEvent, str]] | None = None,
        hip_action: str | None = None,
    ) -> None:
        """Keyframes of every key joint at the current time; ``acting`` maps a hand to its (action,
        contact event, object). Raises :class:`PlanningError` if a wrist is out of reach."""
        acting = acting or {}
        for hand in HANDS:
            pos = self.position(hand)
            d = self.hip.reach_distance(hand, pos, self.body)
            if d > self.body.arm_reach + 1e-6:
                raise PlanningError(
                    f"t = {self.t:.2f} s ({action}): the {hand} wrist at {np.round(pos, 3).tolist()} is "
                    f"{d:.3f} m from its shoulder, beyond the arm reach of {self.body.arm_reach} m from the "
                    f"hip pose {self.hip.to_dict()}"
                )
            act, event, obj = acting.get(
                hand, (self.activity(hand), "", self.wrists[hand].holding or self.wrists[hand].contact)
            )
            self.keyframes.append(
                Keyframe(self.t, f"{hand}_wrist", pos, self.quaternion(hand), act, event, hand, obj)  # type: ignore[arg-type]
            )
        body_action = hip_action or action
        self.keyframes.append(Keyframe(self.t, "hip", self.hip.position, self.hip.quaternion(), body_action))
        self.keyframes.append(
            Keyframe(self.t, "root", self.hip.root_position(), self.hip.root_quaternion(), body_action)
        )

    def advance(self, duration: float) -> None:
        if not duration > 0.0:
            raise PlanningError(f"a step must take time, got {duration} s")
        self.t += float(duration)

    def step(self, line: str) -> None:
        """Add one line to the step summary (prefixed with the current time)."""
        self.steps.append(f"{self.t:6.2f} s  {line}")

    # ------------------------------------------------------------------------------ motions

    def move(
        self,
        duration: float,
        action: str,
        *,
        hip: HipPose | None = None,
        wrists: dict[Hand, tuple[F64, F64]] | None = None,
        acting: dict[Hand, tuple[str, ContactEvent, str]] | None = None,
    ) -> None:
        """An unplanned move over ``duration`` [s]: the hip to ``hip`` and/or wrists to world poses
        (position (3,), quaternion (4,)) — a handle grasp, a door arc step, a step of the body."""
        self.advance(duration)
        if hip is not None:
            self.hip = hip
            if np.linalg.norm(hip.xy - self.root_path[-1]) > 1e-9:
                self.root_path.append(hip.xy)
        for hand, (position, quaternion) in (wrists or {}).items():
            w = self.wrists[hand]
            w.mode = "world"
            w.position = np.array(position, dtype=np.float64)
            w.quaternion = np.array(quaternion, dtype=np.float64)
        self.snapshot(action, acting=acting)

    def hold(self, duration: float, action: str, acting: dict[Hand, tuple[str, ContactEvent, str]]) -> None:
        """Nothing moves for ``duration`` [s] (closing or opening the fingers)."""
        self.move(duration, action, acting=acting)

    def attach(self, hands: Sequence[Hand], duration: float, action: str) -> None:
        """Bring world-fixed wrists back to the body (ready or carry pose) together."""
        for hand in hands:
            w = self.wrists[hand]
            w.mode = "carry" if w.holding else "ready"
        self.advance(duration)
        self.snapshot(action, acting={h: (action, "", self.wrists[h].holding) for h in hands})

    def attach_time(self, hands: Sequence[Hand], speed: float, minimum: float) -> float:
        """[s] time to bring ``hands`` back to the body at ``speed`` [m/s] (at least ``minimum``)."""
        gaps = [float(np.linalg.norm(self.attached(h) - self.position(h))) for h in hands]
        return max(minimum, max(gaps, default=0.0) / speed)

    def attached(self, hand: Hand) -> F64:
        """(3,) [m] where ``hand``'s wrist goes when brought back to the body: the carry pose while it
        holds an object, else the ready pose."""
        w = self.wrists[hand]
        mode, w.mode = w.mode, "carry" if w.holding else "ready"
        try:
            return self.position(hand)
        finally:
            w.mode = mode

    def planned(
        self,
        trajectories: dict[Hand, WristTrajectory],
        step: str,
        action: str,
        event: ContactEvent = "",
        obj: str = "",
    ) -> None:
        """Planned segments of one or both hands starting now (equal durations); each wrist ends fixed
        at its trajectory's last pose; ``event`` happens at the end."""
        durations = {round(tr.duration, 9) for tr in trajectories.values()}
        if len(durations) != 1:
            raise PlanningError(f"simultaneous segments must last equally long, got {sorted(durations)} s")
        for tr in trajectories.values():
            self.segments.append(PlannedSegment(self.t, tr, step))
        self.advance(next(iter(trajectories.values())).duration)
        acting: dict[Hand, tuple[str, ContactEvent, str]] = {}
        for hand, tr in trajectories.items():
            w = self.wrists[hand]
            w.mode, w.position, w.quaternion = "world", tr.position[-1].copy(), tr.quaternion[-1].copy()
            acting[hand] = (action, event, obj)
        self.snapshot(action, acting=acting)

    def move_hip(self, hip: HipPose, duration: float, action: str) -> None:
        """Move the hip (a walking step, a turn, a posture change) in one keyframe interval."""
        self.move(duration, action, hip=hip)

    def build(self, task_id: str, info: dict[str, object]) -> Schedule:
        return Schedule(
            task_id=task_id,
            keyframes=tuple(self.keyframes),
            segments=tuple(self.segments),
            steps=tuple(self.steps),
            root_path=np.array(self.root_path),
            info={**info, "carries": [dict(c) for c in self.carries]} if self.carries else dict(info),
        )
