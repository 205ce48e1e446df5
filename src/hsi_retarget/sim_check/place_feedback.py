"""Closed-loop placement: the carry of the task's object corrected from where the object is in the hand.

A plan puts the object down where it planned to grasp it. In MuJoCo the object can sit elsewhere in the
hand: a drawer opened a centimetre less than the IK had it moves the mug in it, a target moved after
planning, the humanoid's pelvis leaning under its reaching arm (its anchor weld is soft) closes the hand
off its commanded pose. A robot that sees the object in its hand corrects the carry; this controller does
so from the simulated object pose (a stand-in for tracking the held object with the cameras).

While the task's object is welded to a hand, every control step measures where it sits in the hand,
``H = T_m^-1 p_object`` (``T_m``: the measured TCP pose (4, 4) in the world; in the hand frame, so the
hand may turn during the carry; relative to the measured TCP, not the commanded one, so that an arm
lagging its command while it moves fast is not read as a grasp offset), predicts where the object lands,
``T(tau_r) H`` (``T``: the trajectory's TCP pose in the world, ``tau_r``: that hand's release of the
object), and aims the world translation ``shift`` (3,) [m] of the TCP at the placement minus that landing,
low-passed over ``filter_s`` (the first estimate, at the grasp, is taken at once). The estimate stands
still while the object touches anything but the robot (set down early, pushed against the scene: its pose
in the hand then says nothing about the grasp) and from ``lead_s`` before the release. The shift eases in
from the grasp to ``lead_s`` before the release (a long carry is not bent far from its plan while it
passes the scene). It never pushes the object down (it may lift it) and is bounded by ``max_shift_m`` (the
report records the largest shift). The arm joints take it through the damped inverse of the TCP Jacobian
with the orientation kept (``dq = J^T (J J^T + damping^2 I)^-1 [shift; 0]``; both hands of a two-handed
carry), clipped to the joint limits. After the release the shift is held for ``hold_s`` (the fingers open
around the object) and eased out over ``ease_s``. The shifted hand keeps ``clearance_m`` to the furniture
(:mod:`hsi_retarget.sim_check.shift_guard`: the shift loses its part towards a nearby wall), and the
shifted arm keeps that clearance to the rest of the robot (the shift is scaled down until it does). What
the TCP lags its command at the release (the humanoid's pelvis leaning) is not corrected.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError
from hsi_retarget.easing import ease
from hsi_retarget.joint_trajectory import JointTrajectory
from hsi_retarget.sim_check.mjcf import HANDS
from hsi_retarget.sim_check.shift_guard import ShiftGuard
from hsi_retarget.sim_check.world import KIND_ROBOT, SimWorld

F64 = NDArray[np.float64]
_LOG = logging.getLogger(__name__)
_ROOM_STEPS = 6  #: [-] bisection steps of the shift scale that keeps the arms' room (1/64 of it)


@dataclass(frozen=True)
class PlaceFeedbackConfig:
    """Gains and bounds of :class:`PlaceFeedback`."""

    enabled: bool = True  #: correct the carry of the task's object from its simulated pose [-]
    filter_s: float = 0.3  #: time constant of the low-pass on the shift estimate [s]
    lead_s: float = 0.5  #: the shift is fully in this long before the release [s]
    max_shift_m: float = 0.05  #: largest TCP shift [m]
    damping: float = 0.02  #: damping of the Jacobian inverse [m]
    hold_s: float = 0.8  #: the shift is held this long after the release [s]
    ease_s: float = 0.8  #: then eased out over this time [s]
    #: clearance to the furniture that the shifted hand keeps (:mod:`hsi_retarget.sim_check.shift_guard`) [m]
    clearance_m: float = 0.003

    def __post_init__(self) -> None:
        for name in ("filter_s", "lead_s", "max_shift_m", "damping", "hold_s", "ease_s", "clearance_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"PlaceFeedbackConfig.{name} must be finite and >= 0, got {value}")


@dataclass
class _Carry:
    """The task object's release in the trajectory in force, per hand."""

    release: dict[str, float] = field(default_factory=dict)  #: hand -> release time [s] (trajectory time)
    at_release: dict[str, F64] = field(default_factory=dict)  #: hand -> (4, 4) world TCP pose there


class PlaceFeedback:
    """The in-hand placement correction of one execution (see the module docstring)."""

    def __init__(
        self,
        world: SimWorld,
        object_name: str,
        placement: tuple[float, float, float] | None,
        config: PlaceFeedbackConfig | None = None,
    ) -> None:
        """``object_name``: the task's free object ('' none); ``placement``: its goal position (3,) [m]
        (None: no correction)."""
        self.world, self.object_name = world, object_name
        self.placement = None if placement is None else np.append(np.asarray(placement, dtype=float), 1.0)
        self.config = config if config is not None else PlaceFeedbackConfig()
        self.shift = np.zeros(3)  #: current TCP shift (3,) [m], world frame
        self.largest = 0.0  #: largest shift aimed at so far [m]
        self._carry = _Carry()
        self._hands: tuple[str, ...] = ()  #: the hands the shift moves
        self._released_at: float | None = None  #: execution time of the release [s]
        self._grasped_at = 0.0  #: trajectory time of the grasp [s]
        robot = world.robot
        self._own = np.flatnonzero(world.geom_owner == object_name) if object_name else np.zeros(0, int)
        self._arm_v = {h: robot.arm_v_indices(h) for h in HANDS}
        self._arm_q = {h: robot.arm_q_indices(h) for h in HANDS}
        self._active = (
            self.config.enabled and bool(object_name) and self.placement is not None and robot.nq > 0
        )
        self._guard = ShiftGuard(world, self.config.clearance_m) if self._active else None

    def switch(self, trajectory: JointTrajectory) -> None:
        """Take the releases of the task object from ``trajectory`` (now in force)."""
        self._carry = _Carry()
        if not self._active:
            return
        name, robot = self.object_name, self.world.robot
        for e in trajectory.events:
            if e.kind == "release" and e.object_name == name and e.hand not in self._carry.release:
                pose = robot.frame_pose(trajectory.sample(e.time), robot.tcp_frames[e.hand])
                self._carry.release[e.hand] = float(e.time)
                self._carry.at_release[e.hand] = self.world.base @ pose

    def command(self, q_ref: F64, tau: float, t: float, held: dict[str, str], dt: float) -> F64:
        """``q_ref`` (nq,) at trajectory time ``tau`` [s] (execution time ``t`` [s]) with the shift applied
        to the carrying arm(s); ``held``: hand -> welded body now; ``dt``: control period [s]."""
        if not self._active:
            return q_ref
        cfg, name = self.config, self.object_name
        carrying = tuple(h for h in HANDS if held.get(h) == name and h in self._carry.release)
        weight = 1.0
        if carrying:
            if not self._hands:  # the grasp: the shift eases in from here to the release
                self._grasped_at = tau
            self._hands, self._released_at = carrying, None
            hand = carrying[0]
            if tau < self._carry.release[hand] - cfg.lead_s and not self._touching():
                self._estimate(tau, hand, dt)
            span = self._carry.release[hand] - cfg.lead_s - self._grasped_at
            weight = float(ease(np.array([(tau - self._grasped_at) / max(span, 1e-9)]))[0])
        elif self._hands and self._released_at is None:
            self._released_at = t
        if self._released_at is not None:
            late = (t - self._released_at - cfg.hold_s) / max(cfg.ease_s, 1e-9)
            weight = 1.0 - float(ease(np.array([late]))[0])
            if weight <= 0.0:
                self.shift[:] = 0.0
                self._hands, self._released_at = (), None
        if not self._hands or not np.any(self.shift) or self._guard is None:
            return q_ref
        shift = self._guard.limit(q_ref, self._hands, weight * self.shift)
        q = self._apply(q_ref, shift)
        if self._guard.arm_room(q_ref, q, self._hands):
            return q
        lo, hi = 0.0, 1.0  # the largest part of the shift that keeps the arms' room (bisection)
        for _ in range(_ROOM_STEPS):
            mid = 0.5 * (lo + hi)
            lo, hi = (
                (mid, hi)
                if self._guard.arm_room(q_ref, self._apply(q_ref, mid * shift), self._hands)
                else (lo, mid)
            )
        return self._apply(q_ref, lo * shift) if lo > 0.0 else q_ref

    def _touching(self) -> bool:
        """Whether the object touches anything but the robot (it is set down, or pressed against the
        scene: where it sits relative to the hand then says nothing about the grasp)."""
        d, kind = self.world.data, self.world.geom_kind
        if d.ncon == 0 or self._own.size == 0:
            return False
        pairs = np.asarray(d.contact.geom[: d.ncon])
        mine = np.isin(pairs, self._own)
        other = np.where(mine[:, 0], pairs[:, 1], pairs[:, 0])
        return bool(np.any(mine.any(axis=1) & ~mine.all(axis=1) & (kind[other] != KIND_ROBOT)))

    def _estimate(self, tau: float, hand: str, dt: float) -> None:
        """Update the shift that puts the object on its placement at the release, from where it sits in the
        hand now (relative to the measured TCP)."""
        w, cfg = self.world, self.config
        if self.placement is None:  # not active
            return
        site = w.tcp_site[hand]
        now = np.eye(4)
        now[:3, :3] = np.asarray(w.data.site_xmat[site]).reshape(3, 3)
        now[:3, 3] = w.data.site_xpos[site]
        in_hand = np.linalg.solve(now, np.append(w.object_pose(self.object_name)[:3], 1.0))
        landing = (self._carry.at_release[hand] @ in_hand)[:3]
        wanted = self.placement[:3] - landing
        wanted[2] = max(wanted[2], 0.0)  # lift an object that sits low; never press one down
        norm = float(np.linalg.norm(wanted))
        if norm > cfg.max_shift_m:
            wanted *= cfg.max_shift_m / norm
        gain = 1.0 if not np.any(self.shift) else min(1.0, dt / max(cfg.filter_s, 1e-9))  # first: at once
        self.shift = self.shift + gain * (wanted - self.shift)
        self.largest = max(self.largest, float(np.linalg.norm(self.shift)))
        if _LOG.isEnabledFor(logging.DEBUG):  # every control step of a carry: no formatting otherwise
            _LOG.debug("tau %.2f landing error %s shift %s", tau, -wanted.round(4), self.shift.round(4))

    def _apply(self, q_ref: F64, shift: F64) -> F64:
        robot, cfg = self.world.robot, self.config
        twist = np.concatenate([self.world.base[:3, :3].T @ shift, np.zeros(3)])  # robot frame
        q = q_ref.copy()
        for hand in self._hands:
            jac = robot.jacobian(q_ref, robot.tcp_frames[hand])[:, self._arm_v[hand]]
            dq = jac.T @ np.linalg.solve(jac @ jac.T + cfg.damping**2 * np.eye(6), twist)
            iq = self._arm_q[hand]
            q[iq] = np.clip(q[iq] + dq, robot.q_lower[iq], robot.q_upper[iq])
        return q
