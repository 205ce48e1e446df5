"""Frame-by-frame IK of robot goals (:func:`track`); a second pass pulled towards arm configurations that
reach the grasps and releases the first one missed is :func:`hsi_retarget.retrack.retrack_missed`.

The first frame is solved to convergence from the nominal pose; every later frame takes up to
``iterations_per_frame`` steps from the previous solution, within ``velocity_factor`` times the joint
velocity limits over the frame period (:class:`~hsi_retarget.retarget.RetargetConfig`), and stops early
once its TCP errors sit at the weighted tasks' residual (``settle_position``/``settle_orientation``). The
second pass starts where its arm tasks first weigh in, from the first pass's :class:`Trace`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin
import trimesh
from numpy.typing import NDArray

from hsi_retarget.arm_branch import ArmBranch
from hsi_retarget.carry_correction import carry_frames, correct_carry
from hsi_retarget.foot_clearance import part_sweep
from hsi_retarget.handle_hold import HandleHold
from hsi_retarget.held_object import attach
from hsi_retarget.human_motion import SIDES
from hsi_retarget.humanoid_ik import Footsteps, plan_footsteps
from hsi_retarget.ik import IKSolver, IKTargets
from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.mapping import RobotGoals, nominal_configuration
from hsi_retarget.part_arcs import PartArcs
from hsi_retarget.part_scene import PartPhase, follow_part
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance

if TYPE_CHECKING:  # retarget imports this module
    from hsi_retarget.retarget import RetargetConfig

__all__ = ["Trace", "footstep_plan", "frame_targets", "tcp_errors", "track"]

_LOG = logging.getLogger(__name__)
F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Trace:
    """Per-frame state of a :func:`track` pass, for a second pass that differs only from some frame on."""

    qs: F64  #: (T, nq) configurations
    pos_err: dict[str, F64]  #: side -> (T,) [m] TCP position errors (NaN where inactive)
    ori_err: dict[str, F64]  #: side -> (T,) [rad] TCP orientation errors (NaN where inactive)
    fallbacks: NDArray[np.int64]  #: (T,) [-] QP fallbacks through each frame
    clearance: F64  #: (T,) [m] least collision slack through each frame
    #: (frame, goals after it, corrections so far) for each change of the goals at that frame (a carry
    #: re-aimed, the goals following the posed part's contents)
    versions: list[tuple[int, RobotGoals, list[dict[str, Any]]]]
    #: (frame, part) where the opened part was posed as the holder reached it (None: not posed)
    posed: tuple[int, PartPhase] | None = None
    feet: Footsteps | None = None  #: the floating base's footstep plan (the same for a second pass)
    #: (T,) the opened part's scene and exempt hand each frame heeded (``diag["layers"]`` of :func:`track`)
    layers: list[tuple[SceneDistance | None, str]] | None = None


def frame_targets(
    goals: RobotGoals,
    i: int,
    feet: Footsteps | None = None,
    holder: str = "",
    arm: Sequence[ArmBranch] = (),
) -> IKTargets:
    """The IK goals of frame ``i`` of ``goals``: with the humanoid's ``feet``, the hand ``holder``
    ('' none) holding an opened part, and the ``arm`` configuration tasks weighted at that frame."""
    lift = float(goals.lift[i])
    root = goals.root[i]
    if feet is not None and np.isfinite(feet.com[i]).all():  # stepping: pelvis over the stance foot
        root = np.array(root)
        root[:2, 3] = feet.com[i]
        root[2, 3] -= feet.crouch[i]
    pulls: dict[str, tuple[F64, float]] = {}
    for b in arm:
        if b.weight[i] > pulls.get(b.side, (b.q, 0.0))[1]:
            pulls[b.side] = (b.q, float(b.weight[i]))
    return IKTargets(
        tcp={s: goals.tcp[s][i] for s in goals.tcp if goals.active[s][i]},
        root=root,
        lift=lift if np.isfinite(lift) else None,
        feet={s: feet.feet[s][i] for s in SIDES} if feet is not None else {},
        support=feet.support[i] if feet is not None else SIDES,
        com=feet.com[i] if feet is not None and np.isfinite(feet.com[i]).all() else None,
        contact={s: float(c[i]) for s, c in goals.contact.items() if goals.active[s][i] and c[i] > 0.0},
        holding=(holder,) if holder else (),
        arm=pulls,
    )


def _slid(targets: IKTargets, handles: Sequence[HandleHold], i: int, q: F64, robot: RobotModel) -> IKTargets:
    """``targets`` with the goals of the hands holding a handle at frame ``i`` slid along the part's arc
    towards where their TCP is at ``q`` (:meth:`~hsi_retarget.handle_hold.HandleHold.target`)."""
    tcp = dict(targets.tcp)
    for h in handles:
        if h.hand in tcp and h.slack[i] > 0.0:
            frame = robot.tcp_frames[h.hand]
            goal = h.target(i, robot.fk(q, (frame,))[frame][:3, 3])
            if goal is not None:
                tcp[h.hand] = goal
    return replace(targets, tcp=tcp)


def track(
    goals: RobotGoals,
    robot: RobotModel,
    solver: IKSolver,
    cfg: RetargetConfig,
    *,
    part: PartPhase | None = None,
    events: Sequence[ContactEvent] = (),
    arm: Sequence[ArmBranch] = (),
    trace: bool = False,
    resume: tuple[int, Trace] | None = None,
    objects: Mapping[str, trimesh.Trimesh] | None = None,
    stop: int | None = None,
    handles: Sequence[HandleHold] = (),
) -> tuple[F64, dict[str, F64], dict[str, F64], dict[str, Any]]:
    """Frame-by-frame IK of ``goals``: configurations (T, nq), TCP position [m] and orientation [rad] errors
    per side (T,) (NaN where inactive) and diagnostics (fallbacks, clearance, footsteps; with ``events``
    the re-aimed ``goals`` and their ``carry_corrections``). ``part``: an opened door or drawer kept clear
    of while it stands open (:mod:`hsi_retarget.part_scene`) and, with ``cfg.moving_part`` (default: on a
    floating base), wherever the holder's tracked hand has taken it while holding its handle
    (:mod:`hsi_retarget.part_arcs`). ``events``: contact events in the goals' time [s] whose carries are
    re-aimed from the TCP pose reached at their grasp as the IK gets there
    (:func:`~hsi_retarget.carry_correction.correct_carry`). ``arm``: arm configuration tasks
    (:mod:`hsi_retarget.arm_branch`). With ``cfg.reached_part`` the part is posed, at the first frame of
    its open interval, as far open as the holder took it (:meth:`~hsi_retarget.part_scene.PartPhase.reached`;
    ``diag["part"]``, ``diag["part_fraction"]``), and with ``events`` the grasps of its contents follow it
    (:func:`~hsi_retarget.part_scene.follow_part`). With ``trace`` ``diag["trace"]`` keeps the per-frame state
    (:class:`Trace`); ``resume`` = (frame k, a trace of these goals without ``arm``) takes frames before k
    from it (the targets there are the same) and tracks on from k. ``objects``: name -> world mesh at rest
    of the free objects; with ``events``, each one grasped is collision geometry of its hand from the
    frame its grasp was reached (within ``cfg.held_reach``) until its release
    (:mod:`hsi_retarget.held_object`; ``diag["held"]`` lists them). ``stop``: track only the frames before
    it (the later rows stay zero, their errors NaN; with ``trace`` a later call can ``resume`` from it).
    ``handles``: holds of a handle whose goal slides along the part's arc towards the holder's TCP while
    the part stands open (:mod:`hsi_retarget.handle_hold`). ``diag["layers"]`` (T,): the part scene and
    its exempt hand each frame heeded (``(None, '')``: none), for the checks after the tracking."""
    n = goals.t.shape[0]
    planned = resume[1].feet if resume is not None else None
    feet = planned if planned is not None else footstep_plan(robot, goals, cfg, part)
    q = nominal_configuration(robot, goals.root[0], float(goals.lift[0]))
    qs = np.zeros((n, robot.nq))
    carries, corrections = carry_frames(goals.t, events), []
    pos_err = {s: np.full(n, np.nan) for s in goals.tcp}
    ori_err = {s: np.full(n, np.nan) for s in goals.tcp}
    fallbacks, min_clear = 0, np.inf
    fallbacks_to, clear_to = np.zeros(n, dtype=np.int64), np.full(n, np.inf)  # through each frame
    versions: list[tuple[int, RobotGoals, list[dict[str, Any]]]] = []  # goals after each carry correction
    tol_p, tol_o = solver.config.position_tolerance, solver.config.orientation_tolerance
    layer: tuple[SceneDistance | None, str] = (None, "")
    grippers = robot.gripper_joints
    fingers = {s: [robot.q_index(j) for j in grippers[s]] for s in goals.finger if s in grippers}
    settle = (cfg.settle_position, cfg.settle_orientation)
    before: tuple[dict[str, float], dict[str, float]] | None = None  # the last errors measured
    start = 0
    posed: tuple[int, PartPhase] | None = None
    holds = _holds(goals.t, carries) if objects else []
    moving = cfg.moving_part if cfg.moving_part is not None else robot.floating
    arcs = PartArcs(part, goals.t, robot) if part is not None and moving else None
    held_log: list[dict[str, Any]] = []
    layers: list[tuple[SceneDistance | None, str]] = [(None, "")] * n  # the part layer of each frame
    if resume is not None and resume[0] > 0:
        start, old = resume
        if old.layers is not None:
            layers[:start] = old.layers[:start]
        if old.posed is not None and old.posed[0] < start:
            posed = old.posed
            part = posed[1]
        q, qs[:start] = old.qs[start - 1].copy(), old.qs[:start]
        for s in goals.tcp:
            pos_err[s][:start], ori_err[s][:start] = old.pos_err[s][:start], old.ori_err[s][:start]
        fallbacks, min_clear = int(old.fallbacks[start - 1]), float(old.clearance[start - 1])
        fallbacks_to[:start], clear_to[:start] = old.fallbacks[:start], old.clearance[:start]
        versions = [v for v in old.versions if v[0] < start]
        if versions:
            goals, corrections = versions[-1][1], list(versions[-1][2])
        for g, r, hand, name in holds:  # objects held across the resumed frame
            miss = float(old.pos_err[hand][g]) if g < start <= r else math.inf
            if _hold(solver, robot, objects, (name, hand), qs[g], part=part, miss=miss, cfg=cfg):
                held_log.append({"hand": hand, "object": name, "time_s": float(goals.t[g])})
        was = {s for s in goals.tcp if np.isfinite(old.pos_err[s][start - 1])}
        before = (
            {s: float(old.pos_err[s][start - 1]) for s in was},
            {s: float(old.ori_err[s][start - 1]) for s in was},
        )
    for i in range(start, n if stop is None else min(max(stop, start), n)):
        if cfg.reached_part and part is not None and posed is None and i > 0 and goals.t[i] >= part.t_open:
            part = _reached(part, goals.t, qs, i, robot)
            posed = (i, part)
            if events:  # a hand that grasps what the part holds goes where that now is
                goals = follow_part(goals, part, events)
                versions.append((i, goals, list(corrections)))
        now = (None, "") if part is None else part.at(float(goals.t[i]))
        if arcs is not None and arcs.holding(float(goals.t[i])):  # where the holder has taken it
            now = arcs.at(i, qs)
        if now[0] is not layer[0] or now[1] != layer[1]:
            layer = now
            solver.set_part_scene(*layer)
        layers[i] = layer
        for _, r, hand, _ in holds:
            if r == i:  # the hand opens: what it held stays behind
                solver.release(hand)
        for s, idx in fingers.items():  # the fingers are no IK variables: set to their opening
            if np.isfinite(goals.finger[s][i]):
                q[idx] = goals.finger[s][i]
        targets = frame_targets(goals, i, feet, layer[1], arm)
        if handles:
            targets = _slid(targets, handles, i, q, robot)
        errors: tuple[dict[str, float], dict[str, float]] | None = None  # those of q, once measured
        if i == 0:
            result = solver.solve(q, targets, cfg.initial_iterations)
            q, fallbacks = result.q, result.fallbacks
        else:
            dt = float(goals.t[i] - goals.t[i - 1]) * cfg.velocity_factor
            q_start = q
            for step in range(cfg.iterations_per_frame):
                q_prev = q
                q, info = solver.step(q, targets, dt, q_start)
                errors = None
                fallbacks += int(info.fallback > 0)
                min_clear = min(min_clear, info.min_clearance)
                if float(np.max(np.abs(q - q_prev))) < cfg.settle_step:  # settled: more steps change ~nothing
                    break
                errors = solver.errors(q, targets)
                if all(errors[0][s] <= tol_p and errors[1][s] <= tol_o for s in errors[0]):
                    break
                if _residual(errors, before, first=step == 0, settle=settle, contact=targets.contact):
                    break
                before = errors
            # a large step can cut into a margin beyond its linearization: push back out on this frame
            extra = cfg.repair_iterations if info.min_clearance < 0.01 else 0
            if extra and solver.clearance_bound(q_prev, q, info.min_clearance) > -cfg.repair_depth:
                extra = 0  # the last step cannot have cut that deep: skip the full clearance query
            while extra > 0 and solver.clearance(q, within=0.0) < -cfg.repair_depth:
                q, info = solver.step(q, targets, dt, q_start)
                errors = None
                extra -= 1
        qs[i] = q
        if i in carries:  # the hand closes here: carry from the pose it reached
            goals, found, _ = correct_carry(goals, qs, robot, carries[i])
            corrections += found
            versions.append((i, goals, list(corrections)))
        pe, oe = errors if errors is not None else solver.errors(q, targets)
        before = (pe, oe)
        for s in pe:
            pos_err[s][i], ori_err[s][i] = pe[s], oe[s]
        for g, r, hand, name in holds:
            if g == i and r > i:  # the grasp reached: the object moves with the hand
                miss = pe.get(hand, math.inf)
                if _hold(solver, robot, objects, (name, hand), q, part=part, miss=miss, cfg=cfg):
                    held_log.append({"hand": hand, "object": name, "time_s": float(goals.t[i])})
        fallbacks_to[i], clear_to[i] = fallbacks, min_clear
    solver.set_part_scene(None)
    solver.release()
    diag: dict[str, Any] = {
        "qp_fallbacks": fallbacks,
        "min_collision_slack_m": float(min_clear),
        "layers": layers,
    }
    if objects:
        diag["held"] = held_log
    if feet is not None:
        diag["footsteps"] = feet.steps
    if part is not None:
        diag["part"], diag["part_fraction"] = part, part.fraction
    if events:
        diag["goals"], diag["carry_corrections"] = goals, corrections
    if trace:
        diag["trace"] = Trace(qs, pos_err, ori_err, fallbacks_to, clear_to, versions, posed, feet, layers)
    return qs, pos_err, ori_err, diag


def footstep_plan(
    robot: RobotModel, goals: RobotGoals, cfg: RetargetConfig, part: PartPhase | None
) -> Footsteps | None:
    """A floating base's footstep plan under the pelvis goals, clear of ``part``'s sweep (``None`` for a
    fixed base)."""
    if not robot.floating:
        return None
    return plan_footsteps(robot, goals.t, goals.root, cfg.support, keep_out=part_sweep(part))


def _holds(t: F64, carries: Mapping[int, Sequence[ContactEvent]]) -> list[tuple[int, int, str, str]]:
    """(grasp frame, release frame (T: none), hand, object) of every carry of ``carries``
    (:func:`~hsi_retarget.carry_correction.carry_frames`) in frames of ``t`` (T,) [s]."""
    out = []
    for g, events in sorted(carries.items()):
        for e in events:
            if e.kind != "grasp":
                continue
            release = next((v for v in events if v.kind == "release" and v.hand == e.hand), None)
            r = t.shape[0] if release is None else int(np.searchsorted(t, release.time - 1e-9))
            out.append((g, r, e.hand, e.object_name))
    return out


def _hold(
    solver: IKSolver,
    robot: RobotModel,
    objects: Mapping[str, trimesh.Trimesh] | None,
    what: tuple[str, str],
    q: F64,
    *,
    part: PartPhase | None,
    miss: float,
    cfg: RetargetConfig,
) -> bool:
    """Attach the object ``what`` = (name, hand) to that hand at ``q`` (nq,) when its grasp was reached
    within ``cfg.held_reach`` [m] (``miss``): moved with ``part`` when it stands in it. Whether it was."""
    name, hand = what
    if objects is None or name not in objects or not miss <= cfg.held_reach or hand not in robot.tcp_frames:
        return False
    frame = robot.tcp_frames[hand]
    shift = part.shift() if part is not None and name in part.contents else None
    solver.hold(attach(name, hand, objects[name], robot.fk(q, (frame,))[frame], shift))
    return True


def _reached(part: PartPhase, t: F64, qs: F64, i: int, robot: RobotModel) -> PartPhase:
    """``part`` posed as far open as its holder's TCP took it between the grasp (the frame at
    ``part.t_grasp``) and frame ``i - 1`` of configurations ``qs`` (T, nq) at times ``t`` (T,) [s];
    unchanged without a holder TCP or a grasp before frame ``i``."""
    frame = robot.tcp_frames.get(part.holder)
    grasp = int(np.searchsorted(t, part.t_grasp, side="right")) - 1
    if frame is None or not 0 <= grasp < i:
        return part
    at_grasp = robot.fk(qs[grasp], (frame,))[frame][:3, 3]
    at_open = robot.fk(qs[i - 1], (frame,))[frame][:3, 3]
    fraction = part.reached(at_grasp, at_open)
    _LOG.debug("%s opened to %.0f%% by the %s hand", part.part, 100.0 * fraction, part.holder)
    return part.posed(fraction)


def _residual(
    errors: tuple[dict[str, float], dict[str, float]],
    before: tuple[dict[str, float], dict[str, float]] | None,
    *,
    first: bool,
    settle: tuple[float, float],
    contact: dict[str, float],
) -> bool:
    """Whether the TCP position [m] and orientation [rad] ``errors`` per side are the tasks' residual: after
    a frame's ``first`` step, within ``settle`` (position [m], orientation [rad]) of the previous frame's
    (``before``), else improved by less than that over the last step (``before``). A side's ``settle``
    shrinks with its ``contact`` closeness [0..1]: at a contact its errors may not grow from frame to frame
    at all. Never with ``settle`` zero, without ``before`` or when the sides differ."""
    if before is None or not (settle[0] > 0.0 or settle[1] > 0.0) or errors[0].keys() != before[0].keys():
        return False
    pairs = [
        (now[k], was[k], s * (1.0 - contact.get(k, 0.0)))
        for now, was, s in zip(errors, before, settle, strict=True)
        for k in now
    ]
    if first:  # no worse than the last frame's residual
        return all(e <= b + s for e, b, s in pairs)
    return all(e >= b - s for e, b, s in pairs)  # a step that barely helped


def tcp_errors(robot: RobotModel, goals: RobotGoals, qs: F64) -> tuple[dict[str, F64], dict[str, F64]]:
    """TCP position [m] and orientation [rad] errors (T,) per side of ``qs`` against ``goals`` (NaN where
    the side's goal is inactive)."""
    n = goals.t.shape[0]
    pos = {s: np.full(n, np.nan) for s in goals.tcp}
    ori = {s: np.full(n, np.nan) for s in goals.tcp}
    frames = tuple(robot.tcp_frames[s] for s in goals.tcp)
    for i in range(n):
        fk = robot.fk(qs[i], frames)
        for s in goals.tcp:
            if goals.active[s][i]:
                pose, goal = fk[robot.tcp_frames[s]], goals.tcp[s][i]
                pos[s][i] = float(np.linalg.norm(goal[:3, 3] - pose[:3, 3]))
                ori[s][i] = float(np.linalg.norm(pin.log3(goal[:3, :3] @ pose[:3, :3].T)))
    return pos, ori
