"""Arm configurations that reach the grasps and placements the frame-by-frame IK missed.

The per-frame IK follows the goals from wherever the arm is. In a tight space (a shelf compartment, a
cabinet) it can get stuck in a configuration that cannot reach the goal (the elbow up against the board
above) while another configuration can. :func:`missed_contacts` lists the grasps and releases of free
objects whose tracked TCP ended more than ``trigger`` from its goal; :func:`find_branches` solves each
statically, from the nominal arm pose and from ``seeds`` random configurations of that arm (seeded). The
solution nearest to the nominal arm pose (its joints shifted by whole turns towards it) that reaches the
goal within ``tolerance`` without cutting into the collision margins becomes an :class:`ArmBranch`: a
joint-space task on that arm (:attr:`~hsi_retarget.ik.IKTargets.arm`) at full weight from ``settle_s``
before the contact to ``hold_s`` after it, eased in over ``lead_s`` before and out over ``release_s``
after. :func:`~hsi_retarget.retarget.retarget` then tracks the goals again with these tasks, and again
with the weights scaled by each ``escalation`` factor while a contact still misses (:func:`scaled`).
On a floating base (the humanoid) the solves start from the first tracking's configuration at the contact
(its pelvis, waist and legs on that frame's footholds, ``start_at``) and keep the feet where the footstep
plan has them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.mapping import RobotGoals, nominal_configuration
from hsi_retarget.robots import RobotModel

if TYPE_CHECKING:  # ik imports nothing from here; the types only
    from hsi_retarget.ik import IKSolver, IKTargets

__all__ = ["ArmBranch", "ArmBranchConfig", "Missed", "find_branches", "missed_contacts", "scaled"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ArmBranchConfig:
    """How missed contacts are searched and how strongly the found configuration pulls."""

    seeds: int = 12  #: [-] random arm configurations tried per missed contact (besides the nominal pose)
    weight: float = 0.05  #: [1/rad^2] weight of the arm configuration task at full strength
    lead_s: float = 1.5  #: [s] the weight eases in over this long before full strength
    settle_s: float = 0.5  #: [s] full strength from this long before the contact
    hold_s: float = 0.3  #: [s] full strength until this long after the contact
    release_s: float = 0.5  #: [s] the weight eases out over this long after that
    #: [m] TCP miss at a contact that starts a search: one the grasp cannot survive (a re-tracked approach
    #: also changes; at 1 cm, 2 cm misses that still grasped were traded for new collisions)
    trigger: float = 0.03
    tolerance: float = 0.01  #: [m] a solution reaches the contact within this
    orientation_tolerance: float = 0.1  #: [rad] a solution's largest TCP orientation error
    clearance: float = -0.002  #: [m] a solution's least sphere clearance minus its margin
    iterations: int = 200  #: [-] IK steps of one static solve
    #: [-] a static solve also stops once its TCP position error fell less than ``stall_progress`` over
    #: this many steps (stuck short of the goal against a board, or creeping in well within ``tolerance``)
    stall_steps: int = 20
    stall_progress: float = 0.001  #: [m] see ``stall_steps``
    seed: int = 0  #: [-] random generator seed
    #: [-] factors on ``weight`` of further re-trackings while a re-tracked contact still misses by more
    #: than ``trigger`` (the arm pulled harder towards the found configuration before it enters a tight
    #: space); the re-tracking that misses least in total is kept
    escalation: tuple[float, ...] = (4.0,)

    def __post_init__(self) -> None:
        if not all(math.isfinite(f) and f > 0.0 for f in self.escalation):
            raise ConfigError(
                f"ArmBranchConfig.escalation factors must be finite and > 0, got {self.escalation}"
            )
        if self.seeds < 0 or self.iterations < 1 or self.stall_steps < 1 or not self.stall_progress >= 0.0:
            raise ConfigError(
                "ArmBranchConfig.seeds must be >= 0, iterations and stall_steps >= 1, stall_progress >= 0 m, "
                f"got {self.seeds}, {self.iterations}, {self.stall_steps}, {self.stall_progress}"
            )
        spans = (self.weight, self.lead_s, self.settle_s, self.hold_s, self.release_s)
        if not all(math.isfinite(v) and v >= 0.0 for v in spans):
            raise ConfigError(
                f"ArmBranchConfig.weight and the *_s spans [s] must be finite and >= 0, got {spans}"
            )
        if not self.tolerance > 0.0 or not self.orientation_tolerance > 0.0 or not self.trigger > 0.0:
            raise ConfigError(
                "ArmBranchConfig.trigger, tolerance [m] and orientation_tolerance [rad] must be > 0, got "
                f"{self.trigger}, {self.tolerance}, {self.orientation_tolerance}"
            )


@dataclass(frozen=True)
class Missed:
    """A contact whose tracked TCP ended off its goal."""

    side: str  #: ``left`` or ``right``
    index: int  #: [-] frame of the contact
    time: float  #: [s]
    error: float  #: [m] tracked TCP position error there
    target: str  #: the object grasped or released


@dataclass(frozen=True, eq=False)
class ArmBranch:
    """A configuration of one arm that reaches a missed contact, and its task weight over time."""

    side: str  #: ``left`` or ``right``
    time: float  #: [s] the contact
    q: F64  #: (nq,) the configuration (the other joints as solved with it)
    weight: F64  #: (T,) [1/rad^2] its task weight per frame
    error: float  #: [m] TCP position residual of the static solve


def missed_contacts(
    t: F64, windows: Sequence[GraspWindow], pos_err: dict[str, F64], tolerance: float
) -> list[Missed]:
    """The grasps and releases of free objects among ``windows`` whose TCP position error ``pos_err``
    (side -> (T,) [m], NaN where inactive) at the frame nearest the event (frame times ``t`` (T,) [s])
    exceeds ``tolerance`` [m]."""
    out = []
    for w in windows:
        if not w.free or w.hand not in pos_err:
            continue
        i = int(np.argmin(np.abs(t - w.time)))
        err = float(pos_err[w.hand][i])
        if np.isfinite(err) and err > tolerance:
            out.append(Missed(w.hand, i, float(t[i]), err, w.target))
    return out


def find_branches(
    goals: RobotGoals,
    robot: RobotModel,
    solver: IKSolver,
    missed: Sequence[Missed],
    targets_at: Callable[[int], IKTargets],
    *,
    config: ArmBranchConfig | None = None,
    start_at: Callable[[int], F64] | None = None,
) -> list[ArmBranch]:
    """An :class:`ArmBranch` for each of ``missed`` that some static solve reaches (see the module
    docstring). ``targets_at(i)``: the IK goals of frame ``i``, called before its solves (it may also set
    the solver's scene of that frame, e.g. an opened part). ``start_at(i)``: the (nq,) configuration the
    solves of frame ``i`` start from, their arm joints set to the nominal pose's or drawn (default: the
    nominal configuration at the root and lift goals)."""
    cfg = config or ArmBranchConfig()
    rng = np.random.default_rng(cfg.seed)
    out = []
    for m in missed:
        targets = targets_at(m.index)
        iq = robot.arm_q_indices(m.side)
        lo, hi = np.maximum(robot.q_lower[iq], -math.pi), np.minimum(robot.q_upper[iq], math.pi)
        nominal = nominal_configuration(robot, goals.root[m.index], float(goals.lift[m.index]))
        start = nominal if start_at is None else np.array(start_at(m.index), dtype=np.float64)
        start[iq] = nominal[iq]  # the arm from its nominal pose
        best: tuple[float, F64, float] | None = None
        for k in range(cfg.seeds + 1):
            q0 = start.copy()
            if k > 0:
                q0[iq] = rng.uniform(lo, hi)
            stall = (cfg.stall_steps, cfg.stall_progress)
            res = solver.solve(q0, targets, cfg.iterations, stall=stall, give_up=cfg.tolerance)
            if (
                res.position_error.get(m.side, math.inf) > cfg.tolerance
                or res.orientation_error.get(m.side, math.inf) > cfg.orientation_tolerance
                or solver.clearance(res.q) < cfg.clearance
            ):
                continue
            q = _turned_towards(robot, res.q, start, iq)
            distance = float(np.linalg.norm(q[iq] - start[iq]))
            if best is None or distance < best[0]:
                best = (distance, q, res.position_error[m.side])
        if best is not None:
            weight = cfg.weight * _profile(goals.t, m.time, cfg)
            out.append(ArmBranch(m.side, m.time, best[1], weight, best[2]))
    return out


def scaled(branches: Sequence[ArmBranch], factor: float) -> list[ArmBranch]:
    """``branches`` with their task weights (T,) [1/rad^2] multiplied by ``factor`` [-] (copies)."""
    return [ArmBranch(b.side, b.time, b.q.copy(), b.weight * factor, b.error) for b in branches]


def _turned_towards(robot: RobotModel, q: F64, ref: F64, iq: NDArray[np.int64]) -> F64:
    """``q`` (nq,) with its arm joints ``iq`` shifted by whole turns towards ``ref`` where the limits
    allow (the same pose)."""
    out = np.array(q)
    turns = np.round((ref[iq] - q[iq]) / (2.0 * math.pi)) * 2.0 * math.pi
    shifted = q[iq] + turns
    ok = (shifted >= robot.q_lower[iq]) & (shifted <= robot.q_upper[iq])
    out[iq] = np.where(ok, shifted, q[iq])
    return out


def _profile(t: F64, time: float, cfg: ArmBranchConfig) -> F64:
    """(T,) [0..1]: 1 from ``settle_s`` before ``time`` [s] to ``hold_s`` after it, eased in and out."""
    full_from, full_to = time - cfg.settle_s, time + cfg.hold_s
    rise = np.clip((t - (full_from - cfg.lead_s)) / max(cfg.lead_s, 1e-9), 0.0, 1.0)
    fall = np.clip(((full_to + cfg.release_s) - t) / max(cfg.release_s, 1e-9), 0.0, 1.0)
    u = np.minimum(rise, fall)
    return np.asarray(u * u * (3.0 - 2.0 * u))
