"""Grasping in the execution check: a weld activated on contact.

Mechanism: the world declares one inactive ``equality weld`` per hand x graspable body (free objects,
doors, drawers). A ``grasp`` event closes the hand's fingers (position targets ramp to the closed stop at the
gripper's speed limit) and makes the grasp *pending*; while pending, the weld is activated as soon as

- both fingers touch the target (a contact between a pad of finger ``a`` and the target and one between a pad
  of finger ``b`` and the target), or
- the TCP is within ``tcp_distance_m`` of the target's surface (inside counts) while the fingers close and
  one finger already touches it, or the fingers have reached the closed stop (a thin or small target).

A hand may touch its target without that counting as a collision (:meth:`GraspController.allowed`; as
MoveIt allows gripper-object contacts on a pick's approach and retreat): from ``approach_s`` before the
grasp event, while it closes and holds, and after the release until it has let go of it (at least
``release_grace_s``).

On activation the weld's relative pose is set to the current gripper-to-target pose, so the target keeps
where it is in the hand (no jump); a door's or drawer's weld point is the TCP (a free object's is its
origin), so the part follows the point the trajectory moves along its arc. With ``stop_fingers`` the
finger targets stop where the fingers are (a force-limited gripper does not squeeze on against the weld).
A ``release`` event deactivates the weld and opens the fingers to the trajectory's opening
(:mod:`hsi_retarget.finger_room`), which they follow from then on. A grasp still pending after ``timeout_s``
is recorded as failed (the fingers stay closed, nothing is held).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from hsi_planning.errors import ConfigError, RetargetError
from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.sim_check.handle_grip import pivot
from hsi_retarget.sim_check.mjcf import HANDS
from hsi_retarget.sim_check.world import SimWorld


@dataclass(frozen=True)
class GraspConfig:
    """When a pending grasp becomes a weld."""

    tcp_distance_m: float = 0.004  #: TCP-to-target surface distance that counts as touching [m]
    timeout_s: float = 1.5  #: a pending grasp fails after this time without contact [s]
    #: hand-target contacts are allowed this long before the hand's grasp event (its approach) [s]
    approach_s: float = 1.0
    #: hand-target contacts stay allowed this long after a release, and on while the hand stays in touch
    #: (its retreat) [s]
    release_grace_s: float = 0.5
    #: the fingers stop where they are when the weld is made (a force-limited gripper), instead of
    #: squeezing on to the closed stop against the weld [-]
    stop_fingers: bool = True

    def __post_init__(self) -> None:
        for name in ("tcp_distance_m", "timeout_s", "approach_s", "release_grace_s"):
            value = getattr(self, name)
            if not (value >= 0.0 and math.isfinite(value)):
                raise ConfigError(f"GraspConfig.{name} must be finite and >= 0, got {value}")


@dataclass(frozen=True)
class GraspRecord:
    """One grasp-state change: ``kind`` is ``grasp`` (weld on), ``release`` (weld off) or ``failed``."""

    time_s: float  #: simulated time since the start of the execution [s]
    hand: str  #: ``left`` or ``right``
    target: str  #: object or door/drawer body name
    kind: str  #: ``grasp`` | ``release`` | ``failed``
    how: str = ""  #: ``contact`` (both fingers) or ``proximity`` (TCP close) for ``grasp``
    #: how a ``grasp`` holds: ``weld`` (rigidly) or ``pivot`` (a handle bar free to turn about its axis,
    #: :mod:`hsi_retarget.sim_check.handle_grip`)
    hold: str = ""


class GraspController:
    """Finger commands and grasp welds of both hands of a :class:`SimWorld`."""

    def __init__(self, world: SimWorld, config: GraspConfig | None = None) -> None:
        self.world = world
        self.config = config if config is not None else GraspConfig()
        robot = world.robot
        self.open_value = {h: float(robot.q_upper[world.finger_q[h][0]]) for h in HANDS}  #: [m]
        self.closed_value = {h: float(robot.q_lower[world.finger_q[h][0]]) for h in HANDS}  #: [m]
        self.finger_command: dict[str, float | None] = dict.fromkeys(HANDS)  #: None = follow the trajectory
        self.finger_speed = {h: float(robot.v_max[robot.v_index(robot.gripper_joints[h][0])]) for h in HANDS}
        self._finger_now: dict[str, float] = {}
        self.held: dict[str, str] = {}  #: hand -> welded body
        self.pending: dict[str, tuple[str, float]] = {}  #: hand -> (target, event time [s])
        self.released: dict[str, tuple[str, float]] = {}  #: hand -> (target, release time [s])
        self.expected: list[tuple[float, str, str]] = []  #: upcoming grasps: (time [s], hand, target)
        self.records: list[GraspRecord] = []
        self._target_geoms: dict[str, np.ndarray] = {}
        for (hand, target), eq in world.welds.items():  # welds left on by a previous execution: still held
            if (
                world.data.eq_active[eq]
                or world.data.eq_active[list(world.pivots.get((hand, target), ()))].any()
            ):
                self.held[hand] = target
                self.finger_command[hand] = self.closed_value[hand]

    def finger_targets(self, dt: float, reference: dict[str, float] | None = None) -> dict[str, float | None]:
        """Finger position targets [m] for the next ``dt`` [s]: moving towards the commanded opening at the
        gripper's speed limit; None where the trajectory's finger values apply. After a release the fingers
        open towards the trajectory's value ``reference[hand]`` [m] (default: fully open) at that speed,
        and follow the trajectory once they are there."""
        out: dict[str, float | None] = {}
        for hand, command in self.finger_command.items():
            goal = command
            if goal is None:
                if hand not in self._finger_now:  # following the trajectory
                    out[hand] = None
                    continue
                goal = (reference or {}).get(hand, self.open_value[hand])
            now = self._finger_now.get(hand)
            if now is None:
                now = float(np.mean(self.world.robot_q()[self.world.finger_q[hand]]))
            step = self.finger_speed[hand] * dt
            now = float(np.clip(goal, now - step, now + step))
            self._finger_now[hand] = now
            out[hand] = now
            if command is None and now == goal:  # opened to the trajectory's value: follow it again
                del self._finger_now[hand]
        return out

    def command(self, event: ContactEvent, time: float) -> None:
        """Apply a trajectory event at simulated ``time`` [s]; the fingers start moving from where they are.

        Raises:
            SceneError: the event names no free object, door or drawer of the world.
            RetargetError: a grasp by a hand that holds another body.
        """
        hand = event.hand
        self._finger_now.pop(hand, None)
        if event.kind == "grasp":
            self.world.target_kind(event.object_name)
            held = self.held.get(hand)
            if held == event.object_name:
                return
            if held:
                raise RetargetError(f"grasp of {event.object_name} by the {hand} hand, which holds {held}")
            self.pending[hand] = (event.object_name, time)
            self.finger_command[hand] = self.closed_value[hand]
            return
        self.pending.pop(hand, None)
        self.finger_command[hand] = None  # open towards the trajectory's fingers (finger_targets)
        self._finger_now[hand] = float(np.mean(self.world.robot_q()[self.world.finger_q[hand]]))
        target = self.held.pop(hand, "")
        if target:
            self.world.data.eq_active[self.world.welds[(hand, target)]] = 0
            for eq in self.world.pivots.get((hand, target), ()):
                self.world.data.eq_active[eq] = 0
            self.released[hand] = (target, time)
            self.records.append(GraspRecord(time, hand, target, "release"))

    def expect(self, events: Sequence[ContactEvent], start: float) -> None:
        """The grasps of a trajectory starting at simulated time ``start`` [s] (event times relative to it):
        each hand may touch its next target during its approach (:attr:`GraspConfig.approach_s`)."""
        self.expected = [(start + e.time, e.hand, e.object_name) for e in events if e.kind == "grasp"]

    def allowed(self, hand: int, time: float) -> set[str]:
        """Bodies hand ``hand`` (0 left, 1 right) may touch: its held or pending target, the target it is
        approaching (:attr:`GraspConfig.approach_s` before its grasp event) and the one it has just
        released (:attr:`GraspConfig.release_grace_s`, or on while it stays in touch: :meth:`update`)."""
        name = HANDS[hand]
        out = set()
        if name in self.held:
            out.add(self.held[name])
        if name in self.pending:
            out.add(self.pending[name][0])
        if name in self.released:
            out.add(self.released[name][0])
        soon = time + self.config.approach_s
        out.update(target for at, h, target in self.expected if h == name and time - 1e-9 <= at <= soon)
        return out

    def update(self, time: float) -> None:
        """Weld pending grasps whose target is touched; fail those past the timeout; end a release's
        allowance once past its grace the hand no longer touches what it let go of. Needs fresh contacts."""
        for hand, (target, since) in list(self.released.items()):
            if time - since > self.config.release_grace_s and not self._hand_touches(hand, target):
                del self.released[hand]
        for hand, (target, since) in list(self.pending.items()):
            how = self._touch(hand, target)
            if how:
                hold = self._weld(hand, target)
                if self.config.stop_fingers:  # a force-limited gripper stops on the object
                    stop = self._finger_now.get(hand)
                    if stop is not None:
                        self.finger_command[hand] = stop
                del self.pending[hand]
                self.records.append(GraspRecord(time, hand, target, "grasp", how, hold))
            elif time - since > self.config.timeout_s:
                del self.pending[hand]
                self.records.append(GraspRecord(time, hand, target, "failed"))

    def _geoms(self, target: str) -> np.ndarray:
        if target not in self._target_geoms:
            w = self.world
            self._target_geoms[target] = np.flatnonzero(
                (w.geom_owner == target) & ((w.model.geom_contype | w.model.geom_conaffinity) > 0)
            )
        return self._target_geoms[target]

    def _touch(self, hand: str, target: str) -> str:
        w, d = self.world, self.world.data
        targets = self._geoms(target)
        touching = [False, False]
        if d.ncon:
            pairs = np.asarray(d.contact.geom[: d.ncon])
            for k, pads in enumerate(w.finger_geoms[hand]):
                hit = (np.isin(pairs[:, 0], pads) & np.isin(pairs[:, 1], targets)) | (
                    np.isin(pairs[:, 1], pads) & np.isin(pairs[:, 0], targets)
                )
                touching[k] = bool(hit.any())
        if all(touching):
            return "contact"
        closed = self._finger_now.get(hand) == self.finger_command[hand]
        if not (any(touching) or closed):
            return ""
        probe, limit = w.tcp_probe[hand], self.config.tcp_distance_m
        for g in targets:
            if mujoco.mj_geomDistance(w.model, d, probe, int(g), limit + 0.01, None) <= limit:
                return "proximity"
        return ""

    def _hand_touches(self, hand: str, target: str) -> bool:
        """Any geom of ``hand`` in contact with ``target``."""
        w, d = self.world, self.world.data
        if not d.ncon:
            return False
        pairs = np.asarray(d.contact.geom[: d.ncon])
        own = w.geom_hand[pairs] == HANDS.index(hand)
        theirs = np.isin(pairs, self._geoms(target))
        return bool(((own[:, 0] & theirs[:, 1]) | (own[:, 1] & theirs[:, 0])).any())

    def _weld(self, hand: str, target: str) -> str:
        """Weld ``target`` to ``hand``'s gripper at their current relative pose. A free object's weld point
        is its origin; a door's or drawer's is the TCP, where the hand pulls its handle: the joint then
        follows the point the trajectory moves along its arc, not a point off the gripper. A handle with a
        pivot pair (:attr:`SimWorld.pivots`) is held by it instead. Returns ``weld`` or ``pivot``."""
        w = self.world
        m, d = w.model, w.data
        mujoco.mj_kinematics(m, d)
        b1, b2 = w.gripper_body[hand], w.body_ids[target]
        pins = w.pivots.get((hand, target))
        if pins is not None and target in w.bar_axes:  # a handle bar: held, free to turn about its axis
            pivot(
                m, d, pins=pins, bodies=(b1, b2), tcp=d.geom_xpos[w.tcp_probe[hand]], axis=w.bar_axes[target]
            )
            self.held[hand] = target
            return "pivot"
        rot1, rot2 = d.xmat[b1].reshape(3, 3), d.xmat[b2].reshape(3, 3)
        anchor = d.geom_xpos[w.tcp_probe[hand]] if w.target_kind(target) == "part" else d.xpos[b2]
        inv = np.zeros(4)
        rel = np.zeros(4)
        mujoco.mju_negQuat(inv, d.xquat[b1])
        mujoco.mju_mulQuat(rel, inv, d.xquat[b2])
        eq = w.welds[(hand, target)]
        m.eq_data[eq, 0:3] = rot2.T @ (anchor - d.xpos[b2])  # the weld point in body2's frame
        m.eq_data[eq, 3:6] = rot1.T @ (anchor - d.xpos[b1])  # the same point in body1's frame
        m.eq_data[eq, 6:10] = rel  # body2 orientation relative to body1
        d.eq_active[eq] = 1
        self.held[hand] = target
        return "weld"
