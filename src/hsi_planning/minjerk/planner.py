"""The collision-free minimum-jerk baseline planner: same requests and results as the implicit planner.

:meth:`MinJerkPlanner.plan` takes a :class:`~hsi_planning.planning.PlanRequest` (or the implicit
planner's positional form ``plan(cloud, target, hand, action, start_pose)``) and returns a
:class:`~hsi_planning.planning.PlanResult` with an ``approach`` (start → contact) and a ``leave``
(contact → retreat) :class:`~hsi_planning.trajectory.WristTrajectory`, ``planner="minjerk"``, 120 Hz.

The problem is set up exactly as the implicit planner does, with its own functions: the target is the
label ``request.target`` (+ ``object_labels``; moved to ``place_position`` for a place), the approach axis
is ``request.approach_axis`` or :func:`~hsi_planning.implicit.path.estimate_approach_axis`, the contact
is :func:`~hsi_planning.implicit.prior.contact_point` (``palm_offset`` beyond the target along the axis)
and the retreat is ``request.retreat_position`` or the start. The contact **orientation** (a robot
planner's choice, the implicit planner takes it from its prior): wrist x along −axis (into the target),
z up — or, for a top grasp (axis ≈ +z), z horizontal towards the start; the leave returns to the start
orientation. Obstacles are every other point of the **same cloud**; the target's own points count too
on empty segments (near the contact the clearance is relaxed, see :mod:`.clearance`), while on carrying
segments (grasp → leave, place → approach) they move with the hand as its bounding sphere.

Compare like with like via ``reference=``: the contact pose, retreat and durations of another plan (e.g.
the learned one), which also warm-starts the optimizer.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.minjerk.optimizer import MinJerkConfig
from hsi_planning.minjerk.segment import SegmentSettings, SegmentSpec, build_fields, plan_segment
from hsi_planning.perception.cloud import LabelledCloud
from hsi_planning.planning import PlanRequest, PlanResult
from hsi_planning.trajectory import SEGMENTS, Action, Hand, WristTrajectory

_LOG = logging.getLogger(__name__)

F64 = NDArray[np.float64]
PLANNER_NAME = "minjerk"


@dataclass(frozen=True)
class MinJerkPlannerConfig:
    """Settings of the minimum-jerk baseline (the optimizer's and the segments' are nested)."""

    optimizer: MinJerkConfig = field(default_factory=MinJerkConfig)  #: [-] IPOPT problem (bounds, knots, ...)
    segment: SegmentSettings = field(
        default_factory=SegmentSettings
    )  #: [-] grids, spheres, warm start, timing
    palm_offset: float = 0.06  #: [m] wrist distance beyond the target along the axis (the implicit planner's)
    start_clearance: float = 0.01  #: [m] a start or contact this close to an obstacle point is inside it

    def __post_init__(self) -> None:
        for name in ("palm_offset", "start_clearance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"{name} must be a finite number >= 0 [m], got {value}")


def contact_orientation(axis: ArrayLike, toward: ArrayLike) -> F64:
    """(4,) [x y z w] wrist orientation at the contact: x = −``axis`` (into the target), z up; for a top
    grasp (|axis_z| > 0.9) z is the horizontal direction from the contact ``toward`` (3,) [m] (the start)."""
    a = np.asarray(axis, dtype=np.float64).reshape(3)
    x = -a / np.linalg.norm(a)
    if abs(x[2]) > 0.9:
        z = np.asarray(toward, dtype=np.float64).reshape(3).copy()
        z[2] = 0.0
        z = z if np.linalg.norm(z) > 1e-6 else np.array([-1.0, 0.0, 0.0])
    else:
        z = np.array([0.0, 0.0, 1.0])
    z = z - (z @ x) * x
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.asarray(Rotation.from_matrix(np.stack([x, y, z], axis=1)).as_quat(), dtype=np.float64)


def _pose(value: ArrayLike, name: str) -> tuple[F64, F64 | None]:
    pose = np.asarray(value, dtype=np.float64).reshape(-1)
    if pose.shape not in ((3,), (7,)) or not np.isfinite(pose).all():
        raise PlanningError(
            f"{name} must be 3 (position [m]) or 7 (+ [x y z w]) finite numbers, got {pose.shape}"
        )
    if pose.shape == (3,):
        return pose.copy(), None
    q = pose[3:] / max(float(np.linalg.norm(pose[3:])), 1e-12)
    return pose[:3].copy(), q


def _request(
    cloud: LabelledCloud, target: str | None, hand: Hand, action: Action, start_pose: ArrayLike | None
) -> PlanRequest:
    if target is None:
        raise PlanningError("plan(cloud, ...) needs a target label name")
    if start_pose is None:
        return PlanRequest(cloud=cloud, target=target, hand=hand, action=action)
    pos, quat = _pose(start_pose, "start_pose")
    return PlanRequest(
        cloud=cloud, target=target, hand=hand, action=action, start_position=pos, start_quaternion=quat
    )


class MinJerkPlanner:
    """The minimum-jerk baseline (see the module doc); implements :class:`~hsi_planning.planning.Planner`."""

    name = PLANNER_NAME

    def __init__(self, config: MinJerkPlannerConfig | None = None) -> None:
        self.config = config or MinJerkPlannerConfig()

    def plan(
        self,
        request: PlanRequest | LabelledCloud,
        target: str | None = None,
        hand: Hand = "right",
        action: Action = "grasp",
        start_pose: ArrayLike | None = None,
        *,
        duration: float | None = None,
        leave_duration: float | None = None,
        contact_pose: ArrayLike | None = None,
        reference: PlanResult | None = None,
    ) -> PlanResult:
        """Plan approach and leave: ``plan(request)`` or ``plan(cloud, target, hand, action, start_pose)``.

        Args:
            request: a :class:`PlanRequest`, or the labelled world-frame cloud.
            target, hand, action, start_pose: with a cloud (``start_pose``: (3,) or (7,) [m, x y z w]).
            duration: [s] of the approach; None = the reference's, else a human-like default.
            leave_duration: [s] of the leave; None = the reference's, else a human-like default.
            contact_pose: (3,) [m] or (7,) [m, x y z w] wrist contact pose; None = the reference's contact,
                else computed as the implicit planner does.
            reference: another plan of the same problem (e.g. the learned planner's): its contact pose,
                retreat, durations and paths (as warm starts) are used unless given explicitly.

        Raises:
            PlanningError: unknown or invisible target, start or contact inside an obstacle, an
                impossible duration, IPOPT failing (its return status is named).
        """
        if not isinstance(request, PlanRequest):
            request = _request(request, target, hand, action, start_pose)
        t_start = time.perf_counter()
        points, is_target, ids = self._points(request)
        timings: dict[str, float] = {"prepare": time.perf_counter() - t_start}
        start = np.asarray(request.start_position, dtype=np.float64)
        q_start = request.quaternion
        contact, q_contact, axis = self._contact(request, points, is_target, contact_pose, reference)
        retreat = self._retreat(request, reference)
        self._check_free(points[~is_target], {"start position": start, "contact position": contact})
        target_pts = points[is_target]
        centre = 0.5 * (target_pts.min(axis=0) + target_pts.max(axis=0))
        radius = float(np.linalg.norm(target_pts - centre, axis=1).max())
        durations = {"approach": duration, "leave": leave_duration}
        initial = {
            seg: None if reference is None else self._initial(getattr(reference, seg), a, b)
            for seg, (a, b) in (("approach", (start, contact)), ("leave", (contact, retreat)))
        }
        t0 = time.perf_counter()
        cover = np.vstack([start, contact, retreat, *(p for p in initial.values() if p is not None)])
        without_target, with_target = build_fields(
            points[~is_target],
            target_pts,
            cover,
            self.config.segment,
            reach=float(np.linalg.norm(centre - contact)),
            held_radius=radius,
        )
        timings["fields"] = time.perf_counter() - t0
        segments: dict[str, WristTrajectory] = {}
        info: dict[str, Any] = {
            "approach_axis": axis.tolist(),
            "contact": contact.tolist(),
            "target_labels": ids,
        }
        ends = {
            "approach": (start, contact, q_start, q_contact),
            "leave": (contact, retreat, q_contact, q_start),
        }
        for seg in SEGMENTS:
            a, b, qa, qb = ends[seg]
            carrying = (request.action, seg) in (("grasp", "leave"), ("place", "approach"))
            ref = None if reference is None else getattr(reference, seg)
            spec = SegmentSpec(
                start=a,
                goal=b,
                q_start=qa,
                q_goal=qb,
                duration=durations[seg] if durations[seg] is not None else (ref.duration if ref else None),
                grid=without_target if carrying else with_target,
                contact=contact,
                q_contact=q_contact,
                hand=request.hand,
                action=request.action,
                segment=seg,
                object_name=request.target,
                held_centre=centre if carrying else None,
                held_radius=radius if carrying else 0.0,
                initial=initial[seg],
            )
            traj, _, seg_times = plan_segment(spec, self.config.optimizer, self.config.segment, self.name)
            segments[seg] = traj
            timings.update({f"{k}_{seg}": v for k, v in seg_times.items()})
            info[seg] = {
                k: traj.meta[k]
                for k in ("status", "iterations", "warm_start", "jerk_cost", "min_margin", "duration")
            }
        timings["total"] = time.perf_counter() - t_start
        _LOG.info(
            "minjerk plan %s/%s %s: %.0f ms",
            request.hand,
            request.action,
            request.target,
            1e3 * timings["total"],
        )
        return PlanResult(approach=segments["approach"], leave=segments["leave"], timings=timings, info=info)

    @staticmethod
    def _points(request: PlanRequest) -> tuple[F64, NDArray[np.bool_], list[int]]:
        """World points (N, 3) [m], the target mask (N,) and the target label ids."""
        points, labels, ids = request.target_points()
        is_target = np.isin(labels, ids)
        return points, is_target, ids

    def _contact(
        self,
        request: PlanRequest,
        points: F64,
        is_target: NDArray[np.bool_],
        contact_pose: ArrayLike | None,
        reference: PlanResult | None,
    ) -> tuple[F64, F64, F64]:
        """(contact position (3,) [m], contact quaternion (4,), approach axis (3,))."""
        from hsi_planning.implicit.path import Clearance, estimate_approach_axis
        from hsi_planning.implicit.prior import contact_point

        start = np.asarray(request.start_position, dtype=np.float64)
        axis = request.approach_axis
        if axis is None:
            axis = estimate_approach_axis(points[is_target], Clearance(points[~is_target]), start)
        axis = np.asarray(axis, dtype=np.float64)
        quat: F64 | None = None
        if contact_pose is not None:
            pos, quat = _pose(contact_pose, "contact_pose")
        elif reference is not None:
            ci = reference.approach.contact_index
            pos, quat = reference.approach.position[ci].copy(), reference.approach.quaternion[ci].copy()
        else:
            pos = contact_point(points[is_target], axis, self.config.palm_offset)
        if quat is None:
            quat = contact_orientation(axis, start - pos)
        return pos, quat, axis

    @staticmethod
    def _retreat(request: PlanRequest, reference: PlanResult | None) -> F64:
        if request.retreat_position is not None:
            return np.asarray(request.retreat_position, dtype=np.float64).copy()
        if reference is not None:
            return np.asarray(reference.leave.position[-1], dtype=np.float64).copy()
        return np.asarray(request.start_position, dtype=np.float64).copy()

    def _check_free(self, obstacles: F64, poses: dict[str, F64]) -> None:
        from hsi_planning.minjerk.sdf import nearest_distance

        for what, p in poses.items():
            d = float(nearest_distance(obstacles, p)[0])
            if d < self.config.start_clearance:
                raise PlanningError(
                    f"the {what} {p.round(3).tolist()} [m] lies inside an obstacle: {d:.3f} m from the "
                    f"nearest obstacle point (needs >= {self.config.start_clearance} m); "
                    "move it to free space"
                )

    @staticmethod
    def _initial(ref: WristTrajectory, a: F64, b: F64) -> F64:
        """(200, 3) [m] the reference path resampled uniformly in time, ends moved onto a and b."""
        t = np.linspace(ref.t[0], ref.t[-1], 200)
        path = np.stack([np.interp(t, ref.t, ref.position[:, k]) for k in range(3)], axis=1)
        u = np.linspace(0.0, 1.0, 200)[:, None]
        return np.asarray(path + (1.0 - u) * (a - path[0]) + u * (b - path[-1]), dtype=np.float64)
