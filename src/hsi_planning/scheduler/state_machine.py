"""The bimanual scheduler (CHOICE §6): a pick (and place) goal → a :class:`Schedule` of keyframes.

State machine per candidate hand assignment::

    navigate → open (door/drawer, if closed)
    → [per blocker: reach → grasp → take out → navigate → place (a free spot) → release]
    → navigate → reach → grasp → take out → close
    → [put the blockers back] → navigate → place → release

1. The **enclosing part** (closed door or drawer) and the **blockers** (the planned take-out collides
   with them, :func:`~.auxiliary.find_blockers`) are found first; each blocker gets free spots.
2. The **hand assignments** (:func:`~.hands.candidate_assignments`) are each scheduled with the cheap
   :class:`~.linear_planner.LinearPlanner` and costed by the total deviation cost (Eq. 24); the cheapest
   feasible one is scheduled again with the real planner (the next one if that fails).
3. Every wrist keyframe is checked against the hip pose of the same instant while the schedule is built
   (:class:`~.timeline.Timeline`), so a returned schedule is reachable throughout.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import PlanningError, SceneError
from hsi_planning.planning import Planner
from hsi_planning.scene.geometry import support_of
from hsi_planning.scene.model import support_surface, support_surfaces
from hsi_planning.scene.objects import object_mass
from hsi_planning.scheduler import articulation, handling
from hsi_planning.scheduler.actions import TaskRun
from hsi_planning.scheduler.auxiliary import (
    approach_axis,
    enclosing_part,
    find_blockers,
    free_spots,
    support_open,
)
from hsi_planning.scheduler.body import HipPose
from hsi_planning.scheduler.config import SchedulerConfig
from hsi_planning.scheduler.goals import check_place_free
from hsi_planning.scheduler.hands import (
    Assignment,
    HandState,
    candidate_assignments,
    deviation_cost,
    hand_crossing,
    needs_both_hands,
)
from hsi_planning.scheduler.linear_planner import LinearPlanner
from hsi_planning.scheduler.schedule import Schedule
from hsi_planning.scheduler.timeline import Timeline
from hsi_planning.scheduler.world import SceneWorld, WorldState, label_points
from hsi_planning.trajectory import HANDS, Hand

_LOG = logging.getLogger(__name__)
F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Task:
    """A pick (and place) request.

    Attributes:
        target: object to pick.
        place: (3,) [m] bottom centre of the object after placing, or None (pick and hold).
        place_support: support name of the placement ('' = found from ``place``).
        hands: what the hands hold at the start.
        hand: '' (the scheduler decides), ``left``, ``right`` or ``both``.
        door_hand: '' (the scheduler decides), ``left`` or ``right``: the hand that opens the target's
            door or drawer (ignored when there is none).
        task_id: echoed in the schedule.
    """

    target: str
    place: F64 | None = None
    place_support: str = ""
    hands: HandState = field(default_factory=HandState)
    hand: str = ""
    door_hand: str = ""
    task_id: str = ""

    def __post_init__(self) -> None:
        if self.place is not None:
            place = np.array(self.place, dtype=np.float64, copy=True).reshape(-1)
            if place.shape != (3,) or not np.isfinite(place).all():
                raise PlanningError(f"place must be 3 finite numbers x, y, z [m], got {place.tolist()!r}")
            object.__setattr__(self, "place", place)


class Scheduler:
    """Schedules tasks in one world with one planner (see the module docstring)."""

    def __init__(self, world: SceneWorld, planner: Planner, config: SchedulerConfig | None = None) -> None:
        self.world = world
        self.planner = planner
        self.config = config or SchedulerConfig()

    def schedule(self, task: Task) -> Schedule:
        """The keyframe schedule of ``task``.

        Raises:
            PlanningError: unknown target, no free hand, unreachable target or placement, no assignment
                that can be scheduled (the message lists each one's reason).
            SceneError: the scene cannot be rendered or queried.
        """
        t0 = time.perf_counter()
        world, cfg = self.world, self.config
        if not world.is_object(task.target):
            valid = [o.name for o in world.spec.objects]
            raise PlanningError(
                f"{task.target!r} is not an object of scene {world.spec.name!r}; valid: {valid}"
            )
        for obj in task.hands.held():
            if not world.is_object(obj):
                raise PlanningError(f"held object {obj!r} is not an object of scene {world.spec.name!r}")
        if task.target in task.hands.held():
            if task.place is None:
                raise PlanningError(f"{task.target!r} is already in a hand; give a place to put it down")
            self._check_place(task)
            return self._place_only(task, t0)
        state = WorldState(held=frozenset(task.hands.held()))
        if task.place is not None:
            self._check_place(task)
        part = enclosing_part(world, task.target, state)
        spec_obj = world.spec.object_by_name(task.target)
        both = needs_both_hands(
            spec_obj.kind, world.object_size(task.target), object_mass(spec_obj), cfg.hands
        )
        options = candidate_assignments(task.hands, both, part is not None, task.hand, task.door_hand)
        opened = state.with_opened(part, True) if part else state
        probe: Hand = "right" if options[0].grasp == "both" else options[0].grasp  # type: ignore[assignment]
        blockers = find_blockers(world, self.planner, task.target, opened, hand=probe, config=cfg.auxiliary)
        spots = {b: self._spots(b, task.target, opened) for b in blockers}
        costs: dict[str, float] = {}
        crossed: dict[str, float] = {}
        reasons: dict[str, str] = {}
        for option in options:
            try:
                dry = self._run(task, option, blockers, spots, LinearPlanner(cfg.auxiliary.palm_offset))
                costs[option.describe()] = deviation_cost(dry, cfg.hands.deviation_weight)
                if (crossing := hand_crossing(dry)) > cfg.hands.max_crossing:
                    crossed[option.describe()] = crossing
            except PlanningError as exc:
                reasons[option.describe()] = str(exc)
                _LOG.debug("assignment %r is infeasible: %s", option.describe(), exc)
        ranked = sorted(
            (o for o in options if o.describe() in costs),
            key=lambda o: (o.describe() in crossed, costs[o.describe()]),
        )
        for option in ranked:
            try:
                schedule = self._run(task, option, blockers, spots, self.planner)
            except PlanningError as exc:
                reasons[option.describe()] = f"with {self.planner.name}: {exc}"
                continue
            info = {
                "assignment": option.describe(),
                "strategy": option.strategy,
                "grasp_hand": option.grasp,
                "door_hand": option.door or "",
                "part": part or "",
                "blockers": blockers,
                "costs": costs,
                "crossed": crossed,
                "rejected": reasons,
                "deviation_cost": deviation_cost(schedule, cfg.hands.deviation_weight),
                "planner": self.planner.name,
                "compute_s": time.perf_counter() - t0,
            }
            return Schedule(
                schedule.task_id,
                schedule.keyframes,
                schedule.segments,
                schedule.steps,
                schedule.root_path,
                {**schedule.info, **info},
            )
        detail = "; ".join(f"[{k}] {v}" for k, v in reasons.items()) or "no assignment"
        raise PlanningError(f"cannot schedule picking {task.target!r}: {detail}")

    def _check_place(self, task: Task) -> None:
        """Raise :class:`PlanningError` unless ``task.place`` is a free, open spot for the target."""
        assert task.place is not None
        world = self.world
        place = np.asarray(task.place, dtype=np.float64)
        name = task.place_support or _support_at(world, place)
        support = support_surface(world.spec, name)
        kind = world.spec.furniture_by_name(support.furniture).kind
        if not support_open(world, support, kind, WorldState()):
            raise PlanningError(f"place on {name!r}: it is inside closed furniture; choose an open surface")
        size = world.object_size(task.target)
        radius = 0.5 * (float(np.hypot(size[0], size[1])) if len(size) == 3 else float(size[0]))
        cloud = world.state_cloud(WorldState(held=frozenset({task.target, *task.hands.held()})))
        check_place_free(
            place,
            support,
            cloud,
            radius=radius,
            height=float(size[-1]),
            margin=self.config.goals.place_clearance,
        )

    def _place_only(self, task: Task, t0: float) -> Schedule:
        """Put down an object that is already held (by one hand or both)."""
        cfg = self.config
        hands = tuple(h for h in HANDS if task.hands.holding(h) == task.target)
        start = HipPose.standing(np.asarray(cfg.start_xy), math.radians(cfg.start_yaw), cfg.body)
        holding: dict[Hand, str] = {h: task.hands.holding(h) for h in HANDS if task.hands.holding(h)}
        tl = Timeline(cfg.body, start, holding)
        run = TaskRun(self.world, self.planner, cfg, tl, WorldState(held=frozenset(task.hands.held())))
        run.shapes[task.target] = _shape(self.world, task.target)
        assert task.place is not None
        place = np.asarray(task.place, dtype=np.float64)
        handling.place(run, task.target, hands, place, task.place_support or _support_at(self.world, place))
        info = {
            "assignment": f"place with {' and '.join(hands)}",
            "strategy": "place",
            "grasp_hand": "both" if len(hands) == 2 else hands[0],
            "planner": self.planner.name,
            "deviation_cost": 0.0,
            "compute_s": time.perf_counter() - t0,
        }
        schedule = tl.build(task.task_id, info)
        return Schedule(
            schedule.task_id,
            schedule.keyframes,
            schedule.segments,
            schedule.steps,
            schedule.root_path,
            {**schedule.info, "deviation_cost": deviation_cost(schedule, cfg.hands.deviation_weight)},
        )

    def _spots(self, blocker: str, target: str, state: WorldState) -> list[tuple[str, F64]]:
        cloud = self.world.state_cloud(state, complete=self.world.neighbours(target))
        axis = approach_axis(self.world, support_of(self.world.spec, target))
        pts = label_points(cloud, [target])
        if len(pts) == 0:
            raise PlanningError(f"the target {target!r} has no points in the cloud; no spot can be chosen")
        # the corridor starts at the target's centre: the fingers close around it and the palm and wrist
        # follow, so a blocker set down beside the target is as much in the way as one in front of it; it is
        # as wide as the target, or the robot's approach corridor where that is wider
        aux = self.config.auxiliary
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        half = max(0.5 * float(np.ptp(pts[:, :2], axis=0).max()), aux.corridor_radius)
        spots = free_spots(self.world, state, blocker, cloud, avoid=(centre, axis, half), config=aux)
        if not spots:
            raise PlanningError(f"no free spot to put the blocking {blocker!r} aside")
        return spots

    def _run(
        self,
        task: Task,
        option: Assignment,
        blockers: list[str],
        spots: dict[str, list[tuple[str, F64]]],
        planner: Planner,
    ) -> Schedule:
        cfg, world = self.config, self.world
        start = HipPose.standing(np.asarray(cfg.start_xy), math.radians(cfg.start_yaw), cfg.body)
        holding: dict[Hand, str] = {h: task.hands.holding(h) for h in HANDS if task.hands.holding(h)}
        tl = Timeline(cfg.body, start, holding)
        run = TaskRun(world, planner, cfg, tl, WorldState(held=frozenset(task.hands.held())))
        for obj in task.hands.held():
            run.shapes[obj] = _shape(world, obj)
        grasp: tuple[Hand, ...] = HANDS if option.grasp == "both" else (option.grasp,)  # type: ignore[assignment]
        mover: tuple[Hand, ...] = (grasp[-1],)
        part = enclosing_part(world, task.target, run.state)
        if part and option.door:
            articulation.open_part(run, part, option.door, hold=option.strategy == "cotemporal")
        moved: list[tuple[str, F64, str]] = []
        for b in blockers:
            home = world.object_position(b, run.state)
            handling.grasp(run, b, mover)
            self._put_aside(run, b, mover, spots[b])
            moved.append((b, home, support_of(world.spec, b).name))
        handling.grasp(run, task.target, grasp)
        if part and option.close:
            articulation.close_part(run, part, option.close)
        elif part:
            tl.step(f"leave {part} open: no free hand to close it")
        if cfg.restore_blockers:
            free = [h for h in HANDS if not tl.wrists[h].holding and not tl.wrists[h].contact]
            for b, home, support in reversed(moved):
                if not free:
                    tl.step(f"leave {b} aside: no free hand to put it back")
                    continue
                handling.grasp(run, b, (free[0],))
                handling.place(run, b, (free[0],), home, support)
        if task.place is not None:
            place_support = task.place_support or _support_at(world, task.place)
            handling.place(run, task.target, grasp, np.asarray(task.place, dtype=np.float64), place_support)
        elif tl.t > 0.0:
            tl.step(f"hold {task.target}")
        return tl.build(task.task_id, {"opened": sorted(run.state.opened)})

    def _put_aside(
        self, run: TaskRun, blocker: str, hands: tuple[Hand, ...], spots: list[tuple[str, F64]]
    ) -> None:
        errors = []
        for support, pos in spots:
            snapshot = (len(run.timeline.keyframes), len(run.timeline.segments), len(run.timeline.steps))
            saved = (
                run.timeline.t,
                run.timeline.hip,
                {h: _copy(w) for h, w in run.timeline.wrists.items()},
                list(run.timeline.root_path),
                run.state,
                dict(run.shapes),
            )
            try:
                handling.place(run, blocker, hands, pos, support)
                return
            except PlanningError as exc:
                errors.append(f"{support} {np.round(pos, 2).tolist()}: {exc}")
                tl = run.timeline
                del tl.keyframes[snapshot[0] :], tl.segments[snapshot[1] :], tl.steps[snapshot[2] :]
                tl.t, tl.hip, tl.wrists, tl.root_path, run.state, run.shapes = saved
        raise PlanningError(f"no reachable free spot for the blocking {blocker!r}: {'; '.join(errors[:3])}")


def _copy(w: Any) -> Any:
    from dataclasses import replace

    return replace(w, position=w.position.copy(), quaternion=w.quaternion.copy())


def _shape(world: SceneWorld, obj: str) -> F64:
    """Points (M, 3) [m] of a held object relative to its bottom centre (from the rest cloud, or a box)."""
    pts = label_points(world.cloud(), [obj])
    if len(pts):
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        return np.asarray(
            pts - np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]]), dtype=np.float64
        )
    size = world.object_size(obj)
    half = np.array([size[0], size[1] if len(size) == 3 else size[0], 0.0]) / 2.0
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (0, 1)], dtype=np.float64)
    return np.asarray(corners * np.array([half[0], half[1], size[-1]]), dtype=np.float64)


def _support_at(world: SceneWorld, position: ArrayLike) -> str:
    """Name of the support surface whose top holds ``position`` (3,) [m]."""
    p = np.asarray(position, dtype=np.float64)
    for s in support_surfaces(world.spec).values():
        local = s.frame[:3, :3].T @ (p - s.frame[:3, 3])
        if abs(local[2]) < 0.03 and abs(local[0]) <= s.half_extents[0] and abs(local[1]) <= s.half_extents[1]:
            return s.name
    raise SceneError(
        f"place position {np.round(p, 3).tolist()} is on no support surface of {world.spec.name!r}"
    )
