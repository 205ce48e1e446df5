"""The one definition of a planning problem, shared by training (data build) and the runtime planner.

Everything that must be computed **identically** at training and at planning time lives here:

- the condition vector c (4,) = (goal object height [m], hand left −1 / right +1, action grasp 0 /
  place 1, segment approach 0 / leave 1) — :func:`condition_vector`;
- which labels are the target and which are obstacles (every label present in the cloud except the
  target and the hand's held object; the floor and unlabelled points count as obstacles) —
  :func:`make_problem`;
- the object-centric grid: centred on the target's bounding-box centre and shifted by
  ``field_config.approach_shift`` along the approach axis (out of the container opening) — the grid
  never depends on the demonstration, so training and runtime grids agree — :func:`problem_grid`;
- the fields (:func:`problem_fields`), the network's grid-local coordinates (:func:`unit_points`,
  :func:`to_grid_local`: x − grid centre [m]; the network sees that divided by half the grid edge, see
  :func:`hsi_planning.implicit.model.to_unit_cube`) and the motion-prior matching feature
  (:func:`local_feature`).

For a **place**, the target is the held object itself at its placement (its points moved there, see
:func:`move_label_to`), so ``held_labels`` is empty for a place problem whose target is the held object.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import PlanningError
from hsi_planning.fields.config import FieldConfig
from hsi_planning.fields.field_set import FieldSet, compute_fields
from hsi_planning.fields.grid import GridSpec
from hsi_planning.implicit.model import COND_DIM, to_unit_cube
from hsi_planning.scene.geometry import opening_axis, support_of
from hsi_planning.scene.spec import SceneSpec
from hsi_planning.trajectory import ACTIONS, HANDS, SEGMENTS, Action, Hand, Segment, WristTrajectory

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

#: Layout seeds (``generate_layouts(spec, count, seed)``) used for training data: 0..9999.
TRAIN_SEEDS = range(0, 10_000)
#: Benchmarks and tests use layout seeds from here on (never overlapping :data:`TRAIN_SEEDS`).
TEST_SEED_START = 100_000
#: Field parameters of the planner: the default 0.80 m / 0.025 m grid, shifted 0.15 m out of the opening.
PLANNER_FIELD_CONFIG = FieldConfig(approach_shift=0.15)
#: Blocks per axis of the local-feature downsampling (6³ blocks per field).
FEATURE_BLOCKS = 6
#: Multipliers of (height [1/m], hand, action, segment) in the feature: a different hand, action or
#: segment (distance ≥ 20) always outweighs the field part (432 values in [0, 1], typical distances 1–5).
CONDITION_FEATURE_SCALE: tuple[float, float, float, float] = (2.0, 10.0, 10.0, 10.0)


def condition_vector(goal_height: float, hand: Hand, action: Action, segment: Segment) -> F32:
    """The network's condition c: (4,) float32 = (goal_height [m], hand ∓1, action 0/1, segment 0/1).

    Raises:
        PlanningError: non-finite height, or a hand/action/segment name that is not valid.
    """
    if not np.isfinite(goal_height):
        raise PlanningError(f"goal_height must be finite [m], got {goal_height}")
    for name, value, valid in (
        ("hand", hand, HANDS),
        ("action", action, ACTIONS),
        ("segment", segment, SEGMENTS),
    ):
        if value not in valid:
            raise PlanningError(f"{name}={value!r} is not valid; choose one of {list(valid)}")
    return np.array(
        [
            float(goal_height),
            -1.0 if hand == "left" else 1.0,
            0.0 if action == "grasp" else 1.0,
            0.0 if segment == "approach" else 1.0,
        ],
        dtype=np.float32,
    )


@dataclass(frozen=True)
class Condition:
    """A planning condition (see :func:`condition_vector`); ``goal_height`` [m] is the target's height."""

    goal_height: float  #: [m] height (z) of the target's bounding-box centre
    hand: Hand = "right"  #: [-] the moving hand
    action: Action = "grasp"  #: [-] the contact's action
    segment: Segment = "approach"  #: [-] approach (ends at the contact) or leave (starts there)

    def __post_init__(self) -> None:
        condition_vector(self.goal_height, self.hand, self.action, self.segment)  # validates
        object.__setattr__(self, "goal_height", float(self.goal_height))

    def vector(self) -> F32:
        """(4,) float32 condition c."""
        return condition_vector(self.goal_height, self.hand, self.action, self.segment)


def _unit(v: ArrayLike, name: str) -> F64:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise PlanningError(f"{name} must be 3 finite numbers, got {a.tolist()}")
    n = float(np.linalg.norm(a))
    if n < 1e-9:
        raise PlanningError(f"{name} must be a non-zero vector")
    return a / n


@dataclass(frozen=True, eq=False)
class PlanningProblem:
    """One planning problem: a labelled world-frame cloud, what to reach and how (arrays are copied).

    Attributes:
        points: (N, 3) [m] world-frame cloud.
        labels: (N,) int64 label per point (−1 = unlabelled).
        target_labels: label ids of the target (the object to grasp, or the held object at its placement).
        obstacle_labels: label ids treated as obstacles (disjoint from the target labels).
        hand: moving hand; action: grasp or place; segment: approach or leave.
        approach_axis: (3,) unit vector out of the container opening (+z for open tables/counters).
        contact_position: (3,) [m] wrist position at the contact, if known.
        contact_quaternion: (4,) [x y z w] wrist orientation at the contact, if known.
        target_name: free text (label name of the target).
    """

    points: F64
    labels: NDArray[np.int64]
    target_labels: tuple[int, ...]
    obstacle_labels: tuple[int, ...]
    hand: Hand
    action: Action
    segment: Segment
    approach_axis: F64
    contact_position: F64 | None = None
    contact_quaternion: F64 | None = None
    target_name: str = ""

    def __post_init__(self) -> None:
        pts = np.array(self.points, dtype=np.float64, copy=True)
        lab = np.array(self.labels, copy=True).reshape(-1)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
            raise PlanningError(f"points must be (N, 3) with N ≥ 1 [m], got {pts.shape}")
        if not np.isfinite(pts).all():
            raise PlanningError("points contain NaN or infinite values")
        if lab.shape != (pts.shape[0],) or not np.issubdtype(lab.dtype, np.integer):
            raise PlanningError(f"labels must be ({pts.shape[0]},) integers, got {lab.shape} {lab.dtype}")
        tgt = tuple(sorted({int(v) for v in self.target_labels}))
        obs = tuple(sorted({int(v) for v in self.obstacle_labels}))
        if not tgt:
            raise PlanningError("target_labels is empty; name the target's label id(s)")
        if set(tgt) & set(obs):
            raise PlanningError(f"labels {sorted(set(tgt) & set(obs))} are both target and obstacle")
        if not np.isin(lab, tgt).any():
            raise PlanningError(
                f"no point carries a target label {list(tgt)}; present: {np.unique(lab).tolist()}"
            )
        condition_vector(0.0, self.hand, self.action, self.segment)  # validates the names
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "labels", lab.astype(np.int64))
        object.__setattr__(self, "target_labels", tgt)
        object.__setattr__(self, "obstacle_labels", obs)
        object.__setattr__(self, "approach_axis", _unit(self.approach_axis, "approach_axis"))
        if self.contact_position is not None:
            cp = np.array(self.contact_position, dtype=np.float64, copy=True).reshape(-1)
            if cp.shape != (3,) or not np.isfinite(cp).all():
                raise PlanningError(f"contact_position must be 3 finite numbers [m], got {cp.tolist()}")
            object.__setattr__(self, "contact_position", cp)
        if self.contact_quaternion is not None:
            q = np.array(self.contact_quaternion, dtype=np.float64, copy=True).reshape(-1)
            if q.shape != (4,) or not np.isfinite(q).all() or abs(float(np.linalg.norm(q)) - 1.0) > 1e-3:
                raise PlanningError(
                    f"contact_quaternion must be a unit [x y z w] quaternion, got {q.tolist()}"
                )
            object.__setattr__(self, "contact_quaternion", q / np.linalg.norm(q))

    @property
    def target_points(self) -> F64:
        """(Nt, 3) [m] points of the target (a copy)."""
        return np.array(self.points[np.isin(self.labels, self.target_labels)], copy=True)

    @property
    def target_centre(self) -> F64:
        """(3,) [m] centre of the target points' axis-aligned bounding box."""
        p = self.points[np.isin(self.labels, self.target_labels)]
        return np.asarray(0.5 * (p.min(axis=0) + p.max(axis=0)), dtype=np.float64)

    @property
    def goal_height(self) -> float:
        """[m] the condition's goal object height: z of :attr:`target_centre`."""
        return float(self.target_centre[2])

    @property
    def condition(self) -> Condition:
        """The problem's :class:`Condition`."""
        return Condition(self.goal_height, self.hand, self.action, self.segment)

    def condition_vector(self) -> F32:
        """(4,) float32 condition c of this problem."""
        return self.condition.vector()


def make_problem(
    points: ArrayLike,
    labels: ArrayLike,
    target_labels: Sequence[int],
    *,
    hand: Hand,
    action: Action,
    segment: Segment,
    approach_axis: ArrayLike,
    held_labels: Sequence[int] = (),
    contact_position: ArrayLike | None = None,
    contact_quaternion: ArrayLike | None = None,
    target_name: str = "",
) -> PlanningProblem:
    """Build a :class:`PlanningProblem`; obstacles = every label in the cloud except target and held.

    Args:
        points: (N, 3) [m]; labels: (N,) ints (the floor's label and −1 = unlabelled are obstacles).
        target_labels: the target's label id(s).
        held_labels: label id(s) of the object in the moving hand (not an obstacle to itself).
        approach_axis: (3,) direction out of the opening (:func:`hsi_planning.scene.opening_axis`).
    """
    lab = np.asarray(labels).reshape(-1)
    excluded = {int(v) for v in target_labels} | {int(v) for v in held_labels}
    obstacles = tuple(int(v) for v in np.unique(lab) if int(v) not in excluded)
    return PlanningProblem(
        points=np.asarray(points, dtype=np.float64),
        labels=np.asarray(lab),
        target_labels=tuple(int(v) for v in target_labels),
        obstacle_labels=obstacles,
        hand=hand,
        action=action,
        segment=segment,
        approach_axis=np.asarray(approach_axis, dtype=np.float64),
        contact_position=None if contact_position is None else np.asarray(contact_position, dtype=np.float64),
        contact_quaternion=None
        if contact_quaternion is None
        else np.asarray(contact_quaternion, dtype=np.float64),
        target_name=target_name,
    )


def move_label_to(points: ArrayLike, labels: ArrayLike, label: int, bottom_centre: ArrayLike) -> F64:
    """(N, 3) [m] copy of ``points`` with the points of ``label`` translated so that the bottom centre
    of their bounding box lies at ``bottom_centre`` (3,) [m] (e.g. a held object at its placement)."""
    pts = np.array(points, dtype=np.float64, copy=True)
    sel = np.asarray(labels).reshape(-1) == int(label)
    if not sel.any():
        raise PlanningError(f"no point carries label {label}")
    p = pts[sel]
    bottom = np.array([*(0.5 * (p.min(axis=0) + p.max(axis=0)))[:2], p[:, 2].min()])
    pts[sel] = p + (np.asarray(bottom_centre, dtype=np.float64).reshape(3) - bottom)
    return pts


def approach_axis_for(spec: SceneSpec, target: str) -> F64:
    """(3,) unit approach axis of object ``target``: out of the opening (the hand moves in along −axis).

    Objects on counters/tables and in drawers (pulled out first) are reached from above (+z); objects in
    cabinets and on shelves along the container's front normal (:func:`hsi_planning.scene.opening_axis`).
    """
    support = support_of(spec, target)
    kind = spec.furniture_by_name(support.furniture).kind
    if kind in ("counter", "table", "drawer_unit"):
        return np.array([0.0, 0.0, 1.0])
    return np.asarray(opening_axis(spec, target), dtype=np.float64)


def problem_grid(problem: PlanningProblem, field_config: FieldConfig = PLANNER_FIELD_CONFIG) -> GridSpec:
    """The object-centric grid: target box centre + ``approach_shift`` [m] along ``approach_axis``."""
    return GridSpec.around(
        problem.target_points,
        field_config.size,
        field_config.resolution,
        field_config.approach_shift,
        problem.approach_axis,
    )


def problem_fields(
    problem: PlanningProblem,
    demo: WristTrajectory | None = None,
    field_config: FieldConfig = PLANNER_FIELD_CONFIG,
) -> FieldSet:
    """D_t, D_o (and D_toa with ``demo``) of ``problem`` on :func:`problem_grid` (the demo never moves it).

    Raises:
        CloudError / PlanningError: see :func:`hsi_planning.fields.compute_fields`.
    """
    return compute_fields(
        problem.points,
        problem.labels,
        problem.target_labels,
        problem.obstacle_labels,
        demo,
        config=field_config,
        grid=problem_grid(problem, field_config),
    )


def unit_points(grid: GridSpec) -> F32:
    """(n³, 3) [-] the grid nodes as network inputs ([-1, 1], C order matching ``field.reshape(-1)``)."""
    return to_unit_cube(grid.points(), grid.centre, 0.5 * grid.size)


def to_grid_local(positions: ArrayLike, grid: GridSpec) -> F64:
    """(T, 3) [m] positions relative to the grid centre (the frame of the prior bank's trajectories)."""
    p = np.asarray(positions, dtype=np.float64)
    return np.asarray(p - np.asarray(grid.centre), dtype=np.float64)


def from_grid_local(local: ArrayLike, grid: GridSpec) -> F64:
    """(T, 3) [m] world positions from grid-local ones (inverse of :func:`to_grid_local`)."""
    p = np.asarray(local, dtype=np.float64)
    return np.asarray(p + np.asarray(grid.centre), dtype=np.float64)


def _block_mean(field: NDArray[np.floating], blocks: int) -> F64:
    arr = np.asarray(field, dtype=np.float64)
    for axis in range(3):
        parts = np.array_split(arr, blocks, axis=axis)
        arr = np.concatenate([p.mean(axis=axis, keepdims=True) for p in parts], axis=axis)
    return arr


def local_feature(field_set: FieldSet, cond: ArrayLike, blocks: int = FEATURE_BLOCKS) -> F32:
    """Motion-prior matching feature: (2·blocks³ + 4,) float32.

    D_o and D_t, each multiplied by ε (so in [0, 1]) and averaged over ``blocks``³ blocks of the grid
    (C order), then the condition (4,) multiplied by :data:`CONDITION_FEATURE_SCALE`.
    """
    c = np.asarray(cond, dtype=np.float64).reshape(-1)
    if c.shape != (COND_DIM,) or not np.isfinite(c).all():
        raise PlanningError(f"cond must be ({COND_DIM},) finite, got {c.shape}")
    if not 1 <= blocks <= field_set.grid.n:
        raise PlanningError(f"blocks={blocks} must be in 1..{field_set.grid.n}")
    eps = field_set.config.epsilon
    parts = [
        _block_mean(field_set.d_o * eps, blocks).reshape(-1),
        _block_mean(field_set.d_t * eps, blocks).reshape(-1),
        c * np.asarray(CONDITION_FEATURE_SCALE),
    ]
    return np.concatenate(parts).astype(np.float32)


def feature_dim(blocks: int = FEATURE_BLOCKS) -> int:
    """Length of :func:`local_feature`'s vector."""
    return 2 * blocks**3 + COND_DIM
