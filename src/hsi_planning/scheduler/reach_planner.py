"""The human-reach model as a :class:`~hsi_planning.planning.Planner` (the "teacher" planner).

:class:`ReachModelPlanner` answers a :class:`~hsi_planning.planning.PlanRequest` from the labelled cloud
alone: the contact is ``palm_offset`` beyond the target points' box along the approach axis (as the
implicit planner's training contacts), the wrist there points into the target, and both segments come
from :func:`~hsi_planning.demos.generate_reach` with the cloud's other points as obstacles
(:class:`CloudObstacles`: distance to the nearest point, less half a voxel). The scheduler's tests use
it while the learned planner is not available; any other planner can be injected instead.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from hsi_planning.demos import ObstacleField, ReachModelConfig, ReachRequest, generate_reach
from hsi_planning.demos.reach_model import PLANNER_NAME
from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.planning import PlanRequest, PlanResult
from hsi_planning.scheduler.body import wrist_quaternion

F64 = NDArray[np.float64]
_FLOOR_NAMES = ("floor",)


class CloudObstacles(ObstacleField):
    """Obstacle distances from labelled points: |x - nearest point| - ``surface_offset`` [m].

    Args:
        points: (N, 3) [m] obstacle points.
        labels: (N,) label ids of the points.
        names: label id -> name (names the geometry in messages; :meth:`without` drops by name).
        surface_offset: [m] thickness given to each point (about half the cloud's voxel size).
    """

    def __init__(
        self, points: ArrayLike, labels: ArrayLike, names: dict[int, str], surface_offset: float = 0.005
    ) -> None:
        self._pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self._lab = np.asarray(labels, dtype=np.int64).reshape(-1)
        self._label_names = dict(names)
        self._offset = float(surface_offset)
        self._tree = cKDTree(self._pts) if len(self._pts) else None
        present = sorted({int(v) for v in np.unique(self._lab)})
        self._names = tuple(self._label_names.get(i, str(i)) for i in present)

    @property
    def names(self) -> tuple[str, ...]:
        return self._names

    def without(self, names: Iterable[str]) -> ObstacleField:
        drop = {k for k, v in self._label_names.items() if v in set(names)}
        if not drop:
            return self
        keep = ~np.isin(self._lab, list(drop))
        return CloudObstacles(self._pts[keep], self._lab[keep], self._label_names, self._offset)

    def _query(self, points: ArrayLike) -> tuple[F64, NDArray[np.int64]]:
        pts = self._check(points)
        if self._tree is None:
            return np.full(len(pts), np.inf), np.full(len(pts), -1, dtype=np.int64)
        dist, idx = self._tree.query(pts, k=1)
        return np.asarray(dist, dtype=np.float64), np.asarray(idx, dtype=np.int64)

    def inside(self, points: ArrayLike) -> NDArray[np.bool_]:
        return np.asarray(self.distance(points) < 0.0)

    def distance(self, points: ArrayLike) -> F64:
        dist, _ = self._query(points)
        return np.asarray(dist - self._offset, dtype=np.float64)

    def push_direction(self, points: ArrayLike) -> F64:
        pts = self._check(points)
        dist, idx = self._query(pts)
        if self._tree is None:
            return np.zeros_like(pts)
        diff = pts - self._pts[idx]
        return np.asarray(diff / np.maximum(dist, 1e-12)[:, None], dtype=np.float64)

    def nearest_name(self, points: ArrayLike) -> list[str]:
        _, idx = self._query(points)
        if self._tree is None:
            return ["" for _ in idx]
        return [self._label_names.get(int(self._lab[i]), "") for i in idx]


def contact_from_points(points: ArrayLike, axis: ArrayLike, palm_offset: float) -> tuple[F64, F64]:
    """Wrist contact for a target seen as ``points`` (M, 3) [m], reached against ``axis`` (3,) (the
    direction out of the opening, pointing at the hand).

    Returns:
        (position (3,) [m]: ``palm_offset`` beyond the points' box along ``axis``, on the line through
        the box centre; quaternion (4,) [x y z w] with the wrist x axis along ``-axis``).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        raise PlanningError("the target has no points in the cloud; the contact cannot be placed")
    a = np.asarray(axis, dtype=np.float64).reshape(3)
    a = a / np.linalg.norm(a)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    s_max = float((pts @ a).max())
    position = centre - float(centre @ a) * a + (s_max + palm_offset) * a
    return np.asarray(position, dtype=np.float64), wrist_quaternion(-a)


@dataclass(frozen=True)
class ReachPlannerConfig:
    """Settings of :class:`ReachModelPlanner`."""

    palm_offset: float = 0.06  #: [m] wrist distance beyond the target's box along the approach axis
    surface_offset: float = 0.005  #: [m] thickness given to each obstacle point
    seed: int = 0  #: [-] seed of the reach model's random generator (per request: seed + a counter)

    def __post_init__(self) -> None:
        if not 0.0 <= self.palm_offset < 0.3:
            raise ConfigError(f"ReachPlannerConfig.palm_offset must be in [0, 0.3) m, got {self.palm_offset}")
        if not 0.0 <= self.surface_offset < 0.05:
            raise ConfigError("ReachPlannerConfig.surface_offset must be in [0, 0.05) m")


class ReachModelPlanner:
    """The calibrated human-reach model behind the :class:`~hsi_planning.planning.Planner` interface."""

    name = PLANNER_NAME

    def __init__(
        self, config: ReachPlannerConfig | None = None, model: ReachModelConfig | None = None
    ) -> None:
        self.config = config or ReachPlannerConfig()
        self.model = model or ReachModelConfig()
        self._calls = 0

    def plan(self, request: PlanRequest) -> PlanResult:
        """Approach to and leave from ``request.target`` (see the module docstring).

        Raises:
            PlanningError: the target has no points, or the reach model finds no collision-free path.
        """
        t0 = time.perf_counter()
        cloud = request.cloud
        names = cloud.label_names or {}
        own = {request.target, *request.object_labels}
        ids = [k for k, v in names.items() if v in own]
        mask = np.isin(cloud.labels, ids)
        target = np.asarray(cloud.points[mask], dtype=np.float64)
        if len(target) == 0:
            raise PlanningError(
                f"target {request.target!r} has no points in the cloud; labels present: "
                f"{sorted({names.get(int(i), str(i)) for i in np.unique(cloud.labels)})}"
            )
        if request.place_position is not None:
            bottom = np.array([*(0.5 * (target.min(0) + target.max(0)))[:2], target[:, 2].min()])
            target = target + (request.place_position - bottom)
        axis = request.approach_axis
        if axis is None:
            away = request.start_position - target.mean(axis=0)
            away[2] = 0.0
            axis = away / max(float(np.linalg.norm(away)), 1e-9)
        contact, contact_q = contact_from_points(target, axis, self.config.palm_offset)
        obstacles = CloudObstacles(
            cloud.points[~mask], cloud.labels[~mask], names, self.config.surface_offset
        )
        lo, hi = target.min(axis=0), target.max(axis=0)
        radius = float(0.5 * np.hypot(hi[0] - lo[0], hi[1] - lo[1]))
        retreat = request.retreat_position if request.retreat_position is not None else request.start_position
        segments = []
        for segment, free in (("approach", request.start_position), ("leave", retreat)):
            self._calls += 1
            rng = np.random.default_rng([self.config.seed, self._calls])
            reach = ReachRequest(
                start_position=free,
                start_quaternion=request.quaternion,
                contact_position=contact,
                contact_quaternion=contact_q,
                approach_axis=-np.asarray(axis),
                hand=request.hand,
                action=request.action,
                segment=segment,  # type: ignore[arg-type]
                object_name=request.target,
                carried_radius=radius,
            )
            segments.append(generate_reach(reach, obstacles, self.model, rng))
        total = time.perf_counter() - t0
        info = {"contact": contact.tolist(), "approach_axis": np.asarray(axis).tolist(), "planner": self.name}
        return PlanResult(segments[0], segments[1], {"total": total}, info)
