"""Grasps and releases the frame-by-frame IK missed, tracked again towards arm configurations that reach
them (:mod:`hsi_retarget.arm_branch`).

:func:`retrack_missed` lists the free objects' contacts whose tracked TCP ended more than the trigger
distance off, solves each statically (:func:`~hsi_retarget.arm_branch.find_branches`) and tracks the goals
again with the found arm configurations as joint tasks, resumed from the first pass's trace where the first
task weighs in. The tries (the task weights scaled by 1, then each escalation factor while a contact still
misses) are tracked only up to the last missed contact; only the one missing least there is tracked on to
the end, and kept when it misses less than the first pass over all contacts.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from hsi_retarget.arm_branch import (
    ArmBranch,
    ArmBranchConfig,
    Missed,
    find_branches,
    missed_contacts,
    scaled,
)
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.handle_hold import HandleHold
from hsi_retarget.ik import IKSolver, IKTargets
from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.mapping import RobotGoals
from hsi_retarget.part_scene import PartPhase
from hsi_retarget.robots import RobotModel
from hsi_retarget.tracking import Trace, footstep_plan, frame_targets, track

if TYPE_CHECKING:
    from hsi_retarget.retarget import RetargetConfig

__all__ = ["retrack_missed", "tracked_goals"]

F64 = NDArray[np.float64]
_LOG = logging.getLogger(__name__)


def retrack_missed(
    goals: RobotGoals,
    robot: RobotModel,
    solver: IKSolver,
    cfg: RetargetConfig,
    first: tuple[F64, dict[str, F64], dict[str, Any]],
    *,
    part: PartPhase | None,
    events: Sequence[ContactEvent],
    windows: Sequence[GraspWindow],
    objects: Mapping[str, trimesh.Trimesh] | None = None,
    handles: Sequence[HandleHold] = (),
) -> tuple[F64, dict[str, Any]]:
    """Configurations (T, nq) and diagnostics of ``goals`` tracked again with arm configuration tasks at the
    grasps and releases of free objects that the ``first`` tracking (configurations, TCP position errors,
    diagnostics) missed by more than the trigger distance (:mod:`hsi_retarget.arm_branch`), when that
    misses less in total at all those contacts (``windows``); else the first tracking's. ``objects``: the
    held objects' meshes, ``handles``: the handle holds, as for :func:`track`.
    ``diag["arm_branches"]`` reports the search when there was one."""
    qs, pos_err, diag = first
    trace = diag.pop("trace", None)
    posed = diag.get("part", part)
    branch_cfg = cfg.arm_branch
    missed = [] if branch_cfg is None else missed_contacts(goals.t, windows, pos_err, branch_cfg.trigger)
    if branch_cfg is None or not missed:
        return qs, diag
    started = time.perf_counter()

    # a floating base stands where the first pass had it, on the same footholds
    feet = trace.feet if isinstance(trace, Trace) else footstep_plan(robot, goals, cfg, part)

    def targets_at(i: int) -> IKTargets:  # the goals and the opened part as the first pass had them at i
        scene, holder = (None, "") if posed is None else posed.at(float(goals.t[i]))
        solver.set_part_scene(scene, holder)
        return frame_targets(tracked_goals(goals, trace, i), i, feet, holder=holder)

    branches = find_branches(
        goals,
        robot,
        solver,
        missed,
        targets_at,
        config=branch_cfg,
        start_at=(lambda i: qs[i]) if robot.floating else None,
    )
    solver.set_part_scene(None)
    contacts = missed_contacts(goals.t, windows, pos_err, 0.0)  # every free contact, with its error
    report: dict[str, Any] = {
        "missed": [
            {"side": m.side, "time_s": m.time, "error_m": m.error, "target": m.target} for m in missed
        ],
        "found": [{"side": b.side, "time_s": b.time, "static_error_m": b.error} for b in branches],
        "tried_per_contact": branch_cfg.seeds + 1,
        "kept": False,
        "contact_error_before_m": sum(m.error for m in contacts),
    }
    if branches:
        qs, diag = _retrack(
            goals,
            robot,
            solver,
            cfg,
            (qs, diag, trace),
            branches=branches,
            branch_cfg=branch_cfg,
            missed=missed,
            contacts=contacts,
            report=report,
            part=part,
            events=events,
            objects=objects,
            handles=handles,
        )
    report["time_s"] = time.perf_counter() - started
    _LOG.info(
        "arm branches: %d of %d missed contacts reached by a static solve; tracked again: %s",
        len(branches),
        len(missed),
        "kept" if report["kept"] else "not kept",
    )
    diag["arm_branches"] = report
    return qs, diag


def tracked_goals(goals: RobotGoals, trace: Trace | None, i: int) -> RobotGoals:
    """The goals as the pass of ``trace`` tracked frame ``i``: ``goals`` as re-aimed before that frame. A
    carry re-aimed at its grasp applies from the next frame on (the grasp frame was tracked towards the
    grasp itself, the pose a missed grasp is searched for), the goals following the posed part from the
    frame it was posed on (its version comes first among that frame's). Without a trace: ``goals``."""
    if not isinstance(trace, Trace):
        return goals
    posed_at = trace.posed[0] if trace.posed is not None else -1
    out, last = goals, -1
    for frame, version, _ in trace.versions:
        if frame < i or (frame == i == posed_at and last != i):
            out = version
        last = frame
    return out


def _retrack(
    goals: RobotGoals,
    robot: RobotModel,
    solver: IKSolver,
    cfg: RetargetConfig,
    first: tuple[F64, dict[str, Any], Trace | None],
    *,
    branches: Sequence[ArmBranch],
    branch_cfg: ArmBranchConfig,
    missed: Sequence[Missed],
    contacts: Sequence[Missed],
    report: dict[str, Any],
    **kwargs: Any,
) -> tuple[F64, dict[str, Any]]:
    """The ``first`` tracking (configurations, diagnostics, trace) or ``goals`` tracked again with the
    ``branches``' arm tasks, scaled by 1 and then each escalation factor of ``branch_cfg`` while a ``missed``
    contact still misses by more than its trigger: each try up to the last missed contact only, the one
    missing least there tracked on to the end and kept when it misses less than the first over all
    ``contacts`` (``report`` filled in). ``kwargs``: ``part``, ``events``, ``objects``, ``handles`` of
    :func:`track`."""
    qs, diag, trace = first
    n = goals.t.shape[0]
    # the targets differ from the first frame that an arm task weighs on: track on from there
    start = min(int(np.argmax(b.weight > 0.0)) if (b.weight > 0.0).any() else n for b in branches)
    resume = (start, trace) if isinstance(trace, Trace) and start < n else None
    stop = max(m.index for m in missed) + 1  # the tries are compared up to here
    early = [m for m in contacts if m.index < stop]

    def miss(errors: dict[str, F64], among: Sequence[Missed]) -> float:
        return sum(float(np.nan_to_num(errors[m.side][m.index], nan=m.error)) for m in among)

    best: tuple[float, float, list[ArmBranch], dict[str, Any]] = (math.inf, 1.0, [], {})
    report["factors_tried"] = []
    for factor in (1.0, *branch_cfg.escalation):  # harder pulls only while a contact still misses
        arm = scaled(branches, factor)
        _, pos2, _, diag2 = track(
            goals, robot, solver, cfg, arm=arm, resume=resume, trace=True, stop=stop, **kwargs
        )
        report["factors_tried"].append(factor)
        there = miss(pos2, early)
        if there < best[0]:
            best = (there, factor, arm, diag2)
        if all(pos2[m.side][m.index] <= branch_cfg.trigger for m in missed):
            break
    report["factor"] = best[1]
    if best[0] >= sum(m.error for m in early):  # no try gets nearer there: the rest is not tracked
        report["contact_error_after_m"] = None  # not tracked to the end
        return qs, diag
    qs2, pos2, _, diag2 = track(
        goals, robot, solver, cfg, arm=best[2], resume=(stop, best[3]["trace"]), **kwargs
    )
    report["contact_error_after_m"] = after = miss(pos2, contacts)
    report["kept"] = after < report["contact_error_before_m"]
    return (qs2, diag2) if report["kept"] else (qs, diag)
