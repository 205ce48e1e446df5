"""Judge an execution: success, placement error, opening, collisions, tracking, perturbation recovery.

Success = the object within ``placement_tolerance_m`` of its placement and no longer held, the door opened
>= ``door_open_rad`` / the drawer >= ``drawer_open_m`` when required, no collisions
(:mod:`hsi_retarget.sim_check.monitor`), and a floating robot still standing. Limit violations and tracking
errors are reported but do not decide success.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from hsi_retarget.sim_check.config import ExecutionConfig, TaskGoal
from hsi_retarget.sim_check.grasp import GraspController
from hsi_retarget.sim_check.monitor import ContactMonitor, LimitMonitor
from hsi_retarget.sim_check.perturb import PerturbationEvent, Push, event_dict
from hsi_retarget.sim_check.report import ExecutionReport, ExecutionTrace, PerturbationRecord
from hsi_retarget.sim_check.world import SimWorld

_LOG = logging.getLogger(__name__)
_BASELINE_S = 0.2  #: window before a perturbation for the baseline tracking error [s]


@dataclass(frozen=True)
class RunLog:
    """Everything an execution leaves behind for judging."""

    world: SimWorld
    goal: TaskGoal
    config: ExecutionConfig
    trace: ExecutionTrace
    grasp: GraspController
    contacts: ContactMonitor
    limits: LimitMonitor
    events: tuple[PerturbationEvent, ...]  #: perturbations, by time
    replanned: tuple[bool, ...]  #: per handled event: the hook returned a trajectory
    fell: bool
    place_shift_m: float  #: largest carry correction of the task object [m]
    duration_s: float  #: simulated [s]
    wall_s: float  #: wall-clock [s]


def perturbation_records(log: RunLog) -> list[PerturbationRecord]:
    """Peak error and recovery of every perturbation from the tracking trace."""
    trace, cfg = log.trace, log.config
    err = trace.tcp_error.max(axis=1) if trace.t.size else np.zeros(0)
    out = []
    for i, event in enumerate(log.events):
        end = event.time_s + (event.duration_s if isinstance(event, Push) else 0.0)
        before = err[(trace.t >= event.time_s - _BASELINE_S) & (trace.t < event.time_s)]
        window = (trace.t >= event.time_s) & (trace.t <= end + cfg.recovery_window_s)
        baseline = float(before.max()) if before.size else 0.0
        peak = float(err[window].max()) if window.any() else 0.0
        ok = (trace.t >= end) & window & (err <= max(cfg.recovery_error_m, 1.5 * baseline))
        after = np.flatnonzero(ok)
        rec_time = float(trace.t[after[0]] - end) if after.size else None
        replanned = i < len(log.replanned) and log.replanned[i]
        out.append(
            PerturbationRecord(event_dict(event), peak, baseline, bool(after.size), rec_time, replanned)
        )
    return out


def _goal_failures(log: RunLog) -> tuple[list[str], float | None, float | None, float | None]:
    world, goal, cfg = log.world, log.goal, log.config
    failures: list[str] = []
    placement_error = opening = required = None
    if goal.object_name and goal.placement is not None:
        pos = world.object_pose(goal.object_name)[:3]
        placement_error = float(np.linalg.norm(pos - np.asarray(goal.placement, dtype=float)))
        if placement_error > cfg.placement_tolerance_m:
            failures.append(
                f"{goal.object_name} ends {placement_error:.3f} m from its placement "
                f"(> {cfg.placement_tolerance_m} m)"
            )
        if goal.object_name in log.grasp.held.values():
            failures.append(f"{goal.object_name} is still held at the end")
    if goal.open_part:
        opening = world.opening(goal.open_part)
        required = cfg.door_open_rad if world.is_door(goal.open_part) else cfg.drawer_open_m
        if opening < required:
            failures.append(f"{goal.open_part} opened {opening:.3f} < {required:.3f}")
    return failures, placement_error, opening, required


def judge(log: RunLog) -> ExecutionReport:
    """The :class:`ExecutionReport` of a finished run."""
    world, goal, trace = log.world, log.goal, log.trace
    failures, placement_error, opening, required = _goal_failures(log)
    collisions = log.contacts.records()
    if collisions:
        first = collisions[0]
        failures.append(f"{len(collisions)} colliding pairs, first {first.robot_geom} ↔ {first.other_geom}")
    if log.fell:
        failures.append("the robot fell")
    tcp = trace.tcp_error
    report = ExecutionReport(
        object=goal.object_name or goal.open_part,
        robot=world.robot.name,
        planner=goal.planner,
        success=not failures,
        placement_error_m=placement_error,
        duration_s=log.duration_s,
        collisions=len(collisions),
        max_tracking_error_m=float(tcp.max()) if tcp.size else 0.0,
        rms_tracking_error_m=float(np.sqrt(np.mean(tcp**2))) if tcp.size else 0.0,
        max_joint_error=float(trace.joint_error.max()) if trace.joint_error.size else 0.0,
        opening_part=goal.open_part,
        opening=opening,
        opening_required=required,
        collision_details=tuple(collisions),
        limit_violations=tuple(log.limits.records()),
        perturbations=tuple(perturbation_records(log)),
        grasps=tuple(log.grasp.records),
        object_final_poses={n: world.object_pose(n).tolist() for n in world.objects},
        failures=tuple(failures),
        replans=sum(log.replanned),
        place_shift_m=log.place_shift_m,
        wall_time_s=log.wall_s,
        realtime_factor=log.duration_s / log.wall_s if log.wall_s > 0 else 0.0,
        trace=trace,
    )
    _LOG.info("execution of %s on %s: success=%s %s", report.object, report.robot, report.success, failures)
    return report
