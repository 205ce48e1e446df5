"""The UI's minimum-jerk comparison: the real baseline planned on the learned segments' own requests.

The task's planner is wrapped in a :class:`RecordingPlanner`, which keeps every
(:class:`~hsi_planning.planning.PlanRequest`, :class:`~hsi_planning.planning.PlanResult`) the scheduler
asked for. Once the schedule exists, :func:`minjerk_comparison` finds the recorded plan behind each of
its planned segments (same hand, segment kind and end points: the scheduler also plans probes and
rejected assignments) and runs :class:`~hsi_planning.minjerk.MinJerkPlanner` on the same request with
the learned plan as ``reference`` (its contact pose, retreat and durations). Each failure is returned as
a message, never raised, so the UI can show it.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import HsiError
from hsi_planning.planning import Planner, PlanRequest, PlanResult
from hsi_planning.scheduler import Schedule
from hsi_planning.trajectory import WristTrajectory

OVERLAY_WALL_TIME = 10.0  #: [s] IPOPT wall-time limit per attempt of the comparison's min-jerk plans

__all__ = ["MinJerkPath", "RecordingPlanner", "learned_requests", "minjerk_comparison"]

_log = logging.getLogger(__name__)

F64 = NDArray[np.float64]
#: Tolerance on end points when matching a schedule segment to a recorded plan [m].
_MATCH_TOL = 1e-6


class RecordingPlanner:
    """A :class:`~hsi_planning.planning.Planner` that forwards to ``inner`` and records each call."""

    def __init__(self, inner: Planner) -> None:
        self.inner = inner
        self.name = inner.name
        self._lock = threading.Lock()
        self._calls: list[tuple[PlanRequest, PlanResult]] = []

    def plan(self, request: PlanRequest) -> PlanResult:
        """``inner.plan(request)``, recorded when it succeeds."""
        result = self.inner.plan(request)
        with self._lock:
            self._calls.append((request, result))
        return result

    @property
    def calls(self) -> list[tuple[PlanRequest, PlanResult]]:
        """The successful calls so far, oldest first (a copy of the list)."""
        with self._lock:
            return list(self._calls)


@dataclass(frozen=True)
class MinJerkPath:
    """The minimum-jerk counterpart of one planned segment of a schedule."""

    index: int  #: index of the segment in ``schedule.segments`` [-]
    hand: str  #: ``left`` or ``right`` [-]
    learned: F64  #: (T, 3) [m] the learned segment's wrist path
    position: F64  #: (K, 3) [m] the minimum-jerk wrist path between the same end poses


def _matches(seg: WristTrajectory, planned: WristTrajectory) -> bool:
    if seg.hand != planned.hand or seg.segment != planned.segment:
        return False
    pairs = ((seg.position[0], planned.position[0]), (seg.position[-1], planned.position[-1]))
    return all(np.allclose(a, b, atol=_MATCH_TOL) for a, b in pairs)


def learned_requests(
    schedule: Schedule, calls: list[tuple[PlanRequest, PlanResult]]
) -> dict[int, tuple[PlanRequest, PlanResult]]:
    """Segment index -> the recorded call whose approach or leave is that segment of ``schedule``
    (the latest matching call; segments without one, e.g. a second hand following rigidly, are left out)."""
    out: dict[int, tuple[PlanRequest, PlanResult]] = {}
    for i, seg in enumerate(schedule.segments):
        traj = seg.trajectory
        for request, result in reversed(calls):
            if _matches(traj, result.approach if traj.segment == "approach" else result.leave):
                out[i] = (request, result)
                break
    return out


def minjerk_comparison(
    schedule: Schedule, calls: list[tuple[PlanRequest, PlanResult]]
) -> tuple[list[MinJerkPath], list[str]]:
    """Plan the minimum-jerk baseline for every learned segment of ``schedule`` (see the module doc).

    Args:
        schedule: the task's schedule.
        calls: the (request, learned result) pairs the scheduler planned (:attr:`RecordingPlanner.calls`).

    Returns:
        The minimum-jerk paths, one per matched segment, and one message per failure (a segment without
        a recorded request, or the baseline failing on it).
    """
    from hsi_planning.minjerk import MinJerkPlanner, MinJerkPlannerConfig
    from hsi_planning.minjerk.optimizer import MinJerkConfig

    # The comparison is drawn after the task, so IPOPT gets more time than a planning call: on a slow or
    # busy machine 3 s per attempt was not enough for a carrying leave.
    planner = MinJerkPlanner(MinJerkPlannerConfig(optimizer=MinJerkConfig(max_wall_time=OVERLAY_WALL_TIME)))
    matched = learned_requests(schedule, calls)
    errors = [
        f"segment {i} ({s.trajectory.hand} {s.trajectory.segment}): no recorded learned plan"
        for i, s in enumerate(schedule.segments)
        if i not in matched and s.trajectory.position.shape[0] >= 2
    ]
    solved: dict[int, PlanResult | str] = {}  # id(result) -> min-jerk plan or failure message
    paths: list[MinJerkPath] = []
    for i, (request, result) in matched.items():
        key = id(result)
        if key not in solved:
            try:
                solved[key] = planner.plan(request, reference=result)
            except HsiError as exc:
                solved[key] = f"{type(exc).__name__}: {exc}"
        traj = schedule.segments[i].trajectory
        plan = solved[key]
        if isinstance(plan, str):
            errors.append(f"segment {i} ({traj.hand} {traj.segment}): {plan}")
            continue
        jerk = plan.approach if traj.segment == "approach" else plan.leave
        paths.append(
            MinJerkPath(i, traj.hand, np.array(traj.position, copy=True), np.array(jerk.position, copy=True))
        )
    for msg in errors:
        _log.warning("min-jerk comparison: %s", msg)
    return paths, errors
