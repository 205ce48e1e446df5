"""A cheap stand-in planner for costing hand assignments: straight minimum-jerk segments.

The scheduler schedules every candidate hand assignment once with :class:`LinearPlanner` to compare
their total deviation costs (Eq. 24) without calling the real planner for each; only the chosen one is
then scheduled with the real planner. Contacts are placed exactly as :class:`ReachModelPlanner` places
them; durations follow the reach model's Fitts law (intercept 0.45 s, slope 0.15 s/bit, width 0.05 m).
Obstacles are ignored.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import PlanningError
from hsi_planning.planning import PlanRequest, PlanResult
from hsi_planning.scheduler.reach_planner import contact_from_points
from hsi_planning.trajectory import WristTrajectory

F64 = NDArray[np.float64]
_SAMPLES = 16


def fitts_duration(distance: float) -> float:
    """[s] movement time of a reach over ``distance`` [m] (Fitts law with the reach model's constants)."""
    return 0.45 + 0.15 * math.log2(max(2.0 * distance / 0.05, 1.0))


def _segment(
    start: F64, end: F64, q0: F64, q1: F64, *, request: PlanRequest, segment: str
) -> WristTrajectory:
    duration = fitts_duration(float(np.linalg.norm(end - start)))
    tau = np.linspace(0.0, 1.0, _SAMPLES)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    pos = start + s[:, None] * (end - start)
    quat = np.where(s[:, None] < 0.5, q0, q1)
    return WristTrajectory(
        t=tau * duration,
        position=pos,
        quaternion=quat,
        hand=request.hand,
        action=request.action,
        segment=segment,  # type: ignore[arg-type]
        contact_index=-1 if segment == "approach" else 0,
        planner=LinearPlanner.name,
        object_name=request.target,
    )


class LinearPlanner:
    """Straight minimum-jerk approach and leave (see the module docstring)."""

    name = "linear"

    def __init__(self, palm_offset: float = 0.06) -> None:
        self.palm_offset = palm_offset

    def plan(self, request: PlanRequest) -> PlanResult:
        cloud = request.cloud
        names = cloud.label_names or {}
        own = {request.target, *request.object_labels}
        ids = [k for k, v in names.items() if v in own]
        target = np.asarray(cloud.points[np.isin(cloud.labels, ids)], dtype=np.float64)
        if len(target) == 0:
            raise PlanningError(f"target {request.target!r} has no points in the cloud")
        if request.place_position is not None:
            bottom = np.array([*(0.5 * (target.min(0) + target.max(0)))[:2], target[:, 2].min()])
            target = target + (request.place_position - bottom)
        axis = request.approach_axis if request.approach_axis is not None else np.array([0.0, 0.0, 1.0])
        contact, contact_q = contact_from_points(target, axis, self.palm_offset)
        retreat = request.retreat_position if request.retreat_position is not None else request.start_position
        approach = _segment(
            request.start_position,
            contact,
            request.quaternion,
            contact_q,
            request=request,
            segment="approach",
        )
        leave = _segment(contact, retreat, contact_q, contact_q, request=request, segment="leave")
        return PlanResult(approach, leave, {"total": 0.0}, {"contact": contact.tolist()})
