"""The planner-agnostic front: one request type, one result type, one ``plan(request)`` interface.

Every wrist planner (the implicit neural planner, later the minimum-jerk baseline) takes a
:class:`PlanRequest` — a labelled world-frame cloud, the target's label name, the hand, the action and
the wrist's current pose — and returns a :class:`PlanResult`: the ``approach`` segment (ends at the
contact pose), the ``leave`` segment (starts there and ends at a retreat pose outside the container)
and per-stage timings. :func:`make_planner` builds a planner by name (``"implicit"``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import CloudError, ConfigError, PlanningError
from hsi_planning.perception.cloud import LabelledCloud
from hsi_planning.trajectory import ACTIONS, HANDS, Action, Hand, WristTrajectory

#: Names accepted by :func:`make_planner`.
PLANNER_NAMES: tuple[str, ...] = ("implicit", "minjerk")
#: Wrist orientation used when a request gives no start orientation: x forward, z up (identity).
DEFAULT_START_QUATERNION: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
#: [m] labels this far around the target, start and retreat are completed (the planning grid's reach).
COMPLETION_REACH = 0.7


def _vec(value: ArrayLike | None, n: int, name: str) -> NDArray[np.float64] | None:
    if value is None:
        return None
    arr = np.array(value, dtype=np.float64, copy=True).reshape(-1)
    if arr.shape != (n,) or not np.isfinite(arr).all():
        raise PlanningError(f"{name} must be {n} finite numbers, got {np.asarray(value).tolist()!r}")
    return arr


@dataclass(frozen=True, eq=False)
class PlanRequest:
    """What to plan: reach ``target`` in ``cloud`` with ``hand`` from the wrist pose ``start_position``.

    Attributes:
        cloud: world-frame labelled cloud with label names (the target is named by label name).
        target: label name of the object to grasp (or, for ``place``, the held object at its placement).
        hand: moving hand.
        action: ``grasp`` (approach empty, leave carrying) or ``place`` (approach carrying, leave empty).
        start_position: (3,) [m] current wrist position (world).
        start_quaternion: (4,) [x y z w] current wrist orientation (default: identity).
        approach_axis: (3,) direction out of the container opening, if known (e.g. from the scene spec);
            None = estimated from the cloud.
        retreat_position: (3,) [m] where the leave segment ends (joined by a straight segment); None =
            it ends at rest where the learned field leaves the container towards the start position.
        place_position: (3,) [m] for ``place``: bottom centre of the held object at its placement; None =
            the object's points in ``cloud`` already show it at its placement.
        object_labels: extra label names that belong to the target (e.g. parts of one object).
        complete: fill in the hidden parts of shelf boards and other objects from the labels' classes
            (:mod:`~hsi_planning.implicit.scene_completion`) before planning.
    """

    cloud: LabelledCloud
    target: str
    hand: Hand = "right"
    action: Action = "grasp"
    start_position: NDArray[np.float64] = field(default_factory=lambda: np.array([0.2, -0.25, 1.0]))
    start_quaternion: NDArray[np.float64] | None = None
    approach_axis: NDArray[np.float64] | None = None
    retreat_position: NDArray[np.float64] | None = None
    place_position: NDArray[np.float64] | None = None
    object_labels: tuple[str, ...] = ()
    complete: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.cloud, LabelledCloud):
            raise PlanningError(f"cloud must be a LabelledCloud, got {type(self.cloud).__name__}")
        if len(self.cloud) == 0:
            raise PlanningError("the point cloud is empty; the planner needs the target and obstacle points")
        if not isinstance(self.target, str) or not self.target:
            raise PlanningError(f"target must be a non-empty label name, got {self.target!r}")
        if self.hand not in HANDS:
            raise PlanningError(f"hand={self.hand!r} is not valid; choose one of {list(HANDS)}")
        if self.action not in ACTIONS:
            raise PlanningError(f"action={self.action!r} is not valid; choose one of {list(ACTIONS)}")
        start = _vec(self.start_position, 3, "start_position")
        object.__setattr__(self, "start_position", start)
        quat = _vec(self.start_quaternion, 4, "start_quaternion")
        if quat is not None:
            norm = float(np.linalg.norm(quat))
            if norm < 1e-9:
                raise PlanningError("start_quaternion must be a non-zero [x y z w] quaternion")
            quat = quat / norm
        object.__setattr__(self, "start_quaternion", quat)
        axis = _vec(self.approach_axis, 3, "approach_axis")
        if axis is not None:
            norm = float(np.linalg.norm(axis))
            if norm < 1e-9:
                raise PlanningError("approach_axis must be a non-zero direction (or None to estimate it)")
            axis = axis / norm
        object.__setattr__(self, "approach_axis", axis)
        object.__setattr__(self, "retreat_position", _vec(self.retreat_position, 3, "retreat_position"))
        object.__setattr__(self, "place_position", _vec(self.place_position, 3, "place_position"))
        object.__setattr__(self, "object_labels", tuple(str(s) for s in self.object_labels))

    @classmethod
    def from_arrays(
        cls,
        points: ArrayLike,
        labels: ArrayLike,
        label_names: dict[int, str],
        target: str,
        **kwargs: Any,
    ) -> PlanRequest:
        """A request from raw arrays: points (N, 3) [m], labels (N,) ints, id → name table.

        Raises:
            PlanningError: empty, NaN or malformed cloud (the :class:`CloudError` is chained).
        """
        try:
            cloud = LabelledCloud(np.asarray(points), np.asarray(labels), label_names=label_names)
        except CloudError as exc:
            raise PlanningError(f"invalid point cloud: {exc}") from exc
        return cls(cloud=cloud, target=target, **kwargs)

    def target_points(
        self, clip: tuple[ArrayLike, ArrayLike] | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], list[int]]:
        """The cloud as the planners see it: points (N, 3) [m], labels (N,) and the target's label ids.

        With ``complete`` the hidden parts of shelf boards and of the other objects are filled in
        (:func:`~hsi_planning.implicit.scene_completion.complete_cloud`); with ``clip`` (lo (3,), hi (3,))
        [m] only those inside that box (for a planner that crops the cloud to it anyway). For ``place``
        with a ``place_position``, the held object's points are moved to the placement.

        Raises:
            PlanningError: the target (or an ``object_labels`` name) is not a label of the cloud, or it
                has no point in it (hidden or out of view).
        """
        ids = []
        for name in (self.target, *self.object_labels):
            try:
                ids.append(self.cloud.label_id(name))
            except CloudError as exc:
                raise PlanningError(f"target {name!r} is not a label of the cloud: {exc}") from exc
        points = np.asarray(self.cloud.points, dtype=np.float64)
        labels = np.asarray(self.cloud.labels, dtype=np.int64)
        if not np.isin(labels, ids).any():
            raise PlanningError(f"target {self.target!r} has no point in the cloud (hidden or out of view)")
        if self.complete:
            from hsi_planning.implicit.scene_completion import complete_cloud

            held = points[np.isin(labels, ids)]
            reach = np.vstack([held, self.start_position[None]])
            if self.retreat_position is not None:
                reach = np.vstack([reach, self.retreat_position[None]])
            points, labels = complete_cloud(
                points,
                labels,
                self.cloud.label_classes,
                ids,
                label_names=self.cloud.label_names,
                region=(reach.min(axis=0) - COMPLETION_REACH, reach.max(axis=0) + COMPLETION_REACH),
                clip=clip,
            )
        if self.action == "place" and self.place_position is not None:
            from hsi_planning.implicit.problem import move_label_to

            for i in ids:
                if (labels == i).any():
                    points = move_label_to(points, labels, i, self.place_position)
        return points, labels, ids

    @property
    def quaternion(self) -> NDArray[np.float64]:
        """(4,) [x y z w] start orientation (identity when none was given)."""
        q = self.start_quaternion
        return np.array(DEFAULT_START_QUATERNION if q is None else q, dtype=np.float64)


@dataclass(frozen=True)
class PlanResult:
    """A planned reach: ``approach`` ends at the contact pose, ``leave`` starts there.

    Attributes:
        approach: timed 6D wrist trajectory to the contact (``contact_index`` = last sample).
        leave: timed 6D wrist trajectory from the contact to the retreat pose (``contact_index`` = 0).
        timings: [s] wall time per planning stage (and ``total``).
        info: plain diagnostics (matched prior, fit loss, fallbacks used, clearances [m]).
    """

    approach: WristTrajectory
    leave: WristTrajectory
    timings: dict[str, float] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.approach.segment != "approach" or self.leave.segment != "leave":
            raise PlanningError(
                f"PlanResult needs an approach and a leave segment, got {self.approach.segment!r} and "
                f"{self.leave.segment!r}"
            )
        object.__setattr__(self, "timings", {str(k): float(v) for k, v in self.timings.items()})
        object.__setattr__(self, "info", dict(self.info))

    @property
    def contact_position(self) -> NDArray[np.float64]:
        """(3,) [m] wrist position at the contact."""
        return np.array(self.approach.position[self.approach.contact_index], copy=True)

    @property
    def total_seconds(self) -> float:
        """[s] total planning time (``timings["total"]``, NaN if it was not recorded)."""
        return float(self.timings.get("total", math.nan))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: both segments (:meth:`WristTrajectory.to_dict`), timings and info."""
        return {
            "approach": self.approach.to_dict(),
            "leave": self.leave.to_dict(),
            "timings": dict(self.timings),
            "info": dict(self.info),
        }


@runtime_checkable
class Planner(Protocol):
    """Anything that plans a :class:`PlanResult` for a :class:`PlanRequest`."""

    name: str

    def plan(self, request: PlanRequest) -> PlanResult:
        """Plan approach and leave for ``request``; raises :class:`PlanningError` when it cannot."""
        ...


def default_checkpoint() -> Path:
    """[path] the shipped implicit-planner checkpoint: ``models/planner.pt`` of the source checkout, else
    the installed ``share/hsi/models/planner.pt``."""
    import sys

    candidates = [
        Path(__file__).resolve().parents[2] / "models" / "planner.pt",
        Path(sys.prefix) / "share" / "hsi" / "models" / "planner.pt",
    ]
    for path in candidates:
        if path.is_file():
            return path
    return candidates[0]


def make_planner(name: str, checkpoint: str | Path | None = None, **options: Any) -> Planner:
    """A planner by name.

    Args:
        name: ``"implicit"`` (the neural implicit planner) or ``"minjerk"`` (the CasADi/IPOPT
            minimum-jerk baseline).
        checkpoint: [path] the implicit planner's checkpoint (default: :func:`default_checkpoint`).
        options: overrides of the planner's config fields (e.g. ``fit_steps=20``).

    Raises:
        ConfigError: unknown planner name or option.
        PlanningError: the checkpoint cannot be read.
    """
    if name == "implicit":
        from hsi_planning.config import from_mapping
        from hsi_planning.implicit.planner import ImplicitPlanner, ImplicitPlannerConfig

        config = from_mapping(ImplicitPlannerConfig, options, where="implicit planner options")
        return ImplicitPlanner(Path(checkpoint) if checkpoint is not None else default_checkpoint(), config)
    if name == "minjerk":
        from hsi_planning.config import from_mapping
        from hsi_planning.minjerk import MinJerkPlanner, MinJerkPlannerConfig

        return MinJerkPlanner(from_mapping(MinJerkPlannerConfig, options, where="minjerk planner options"))
    raise ConfigError(f"unknown planner {name!r}; available: {list(PLANNER_NAMES)}")
