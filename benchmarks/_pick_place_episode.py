"""One episode of ``benchmarks/pick_place.py``: a case run through the demo's pipeline
(:func:`hsi_nodes.demo.pipeline.run_task`) for one robot, planner and perturbation setting, as a JSON row.

Perturbations. ``run_task`` has no perturbation argument yet, so a perturbed episode runs it with the
package-level :func:`hsi_retarget.sim_check.execute` (which ``run_task`` imports at call time) temporarily
replaced by a wrapper that adds seeded events (:func:`hsi_retarget.sim_check.random_perturbations`: pushes
on arm links, the target moved up to 5 cm before its grasp) and a re-plan hook. On a target move the hook
re-plans like the pipeline does (the layout with the object at its new place is re-observed, the task
re-resolved and re-scheduled, then turned into a robot trajectory by the pipeline's ``robot_trajectory``),
finds the moment of the new trajectory closest to the robot's current configuration and continues from
there after a short joint-space blend. The re-plan keeps the executed plan's grasping hand and the hand
that opened the door or drawer (``DemoTask.door_hand``), is joined only at a moment where its hands hold
what the robot's hold now, and one whose gripper events contradict what the hands hold (a hand holding the
door told to grasp the object) is not taken: the executed plan goes on. When the re-plan itself fails
(the scheduler or an optimizer on the new layout), the executed schedule is retargeted again with the
target's grasp re-aimed at its new place (``robot_trajectory(..., moved=...)``,
:mod:`hsi_retarget.moved_target`) and joined the same way. So is it when the re-plan's IK misses a grasp
or release of a free object by more than the arm-branch trigger (:func:`contact_miss`) and the re-aimed
executed schedule misses less there (``perturbation.reaim_compared`` counts the comparisons,
``perturbation.reaimed`` the re-aimed trajectories taken, ``perturbation.replans_full`` the full re-plans
taken). That order is the humanoid's; the dual arm (:data:`REAIM_FIRST`) takes the re-aimed executed
schedule first and the full re-plan only where the re-aimed one misses a contact and the re-plan misses
less (:func:`_reaimed_or_replanned`): its executed door or drawer and stance stay as they are.
Pushes are not re-planned (the controller recovers). The wrapper goes away when ``run_task`` takes a
perturbation config.

IK time: ``trajectory.meta`` of the retargeting (``ik_time_s`` over ``frames``: per-frame differential IK,
the arm-branch search and second tracking pass where a grasp was missed, joint smoothing and residuals of
the initial plan; re-plans are reported separately). ``ik_search_s``: the arm-branch part of it (static
solves from seeded arm configurations and the second tracking pass).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
from _pick_place_cases import Case

from hsi_nodes.demo.pipeline import (
    PipelineConfig,
    TaskOutcome,
    make_demo_planner,
    resolve_task,
    robot_trajectory,
    run_task,
)
from hsi_nodes.demo.tasks import DemoTask
from hsi_planning.errors import HsiError, PlanningError, RetargetError
from hsi_planning.perception import CloudConfig, LabelledCloud
from hsi_planning.planning import Planner
from hsi_planning.scene import SceneSpec, moved_object
from hsi_planning.scheduler import Schedule

_LOG = logging.getLogger("pick_place")
BLEND_MIN_S = 0.3  #: [s] shortest joint-space blend from the current configuration into a re-plan
BLEND_SPEED = 0.5  #: [-] fraction of the joint velocity limits used by that blend
MATCH_WINDOW_S = 3.0  #: [s] a re-plan is joined within this time of the current trajectory time
CLOUD_VOXEL = 0.01  #: [m] voxel of the rendered clouds (as the demo's runner)
#: robot -> whether a target move is answered by the executed schedule re-aimed at the moved target first
#: (the full re-plan only where that misses a grasp or release), instead of the full re-plan first
#: (measured per robot; see the README)
REAIM_FIRST: dict[str, bool] = {"dual_ur5e": True, "humanoid": False}

_planners: dict[tuple[str, str], Planner] = {}
_clouds: dict[str, LabelledCloud] = {}


def planner_for(name: str, checkpoint: str) -> Planner:
    """The planner ``name`` (built once per process)."""
    key = (name, checkpoint)
    if key not in _planners:
        _planners[key] = make_demo_planner(name, checkpoint)
    return _planners[key]


def observe(spec: SceneSpec) -> LabelledCloud:
    """The labelled cloud of ``spec`` rendered from its cameras (the last few cached per process)."""
    from hsi_planning.scheduler import SceneWorld

    key = f"{spec.name}:{spec.meta.get('layout')}:{[(o.name, o.xy) for o in spec.objects]}"
    if key not in _clouds:
        if len(_clouds) >= 4:
            _clouds.pop(next(iter(_clouds)))
        _clouds[key] = SceneWorld(spec, cloud_config=CloudConfig(voxel_size=CLOUD_VOXEL)).cloud()
    return _clouds[key]


def demo_task(case: Case) -> DemoTask:
    """The case as a demo task (object by name, place click on the drawn spot)."""
    t = case.template
    return DemoTask(
        t.name, case.spec.name, place_click=case.place_click, object_name=t.obj, description=t.description
    )


def _plan_trajectory(task: DemoTask, spec: SceneSpec, planner: Planner, cfg: PipelineConfig) -> Any:
    """The pipeline's stages up to the joint trajectory: resolve, schedule, then
    :func:`~hsi_nodes.demo.pipeline.robot_trajectory` (retarget with grasp depth, gripper dwell)."""
    from hsi_planning.scheduler import SceneWorld, Scheduler

    sched_cfg = cfg.scheduler_config()
    world = SceneWorld(spec, observe(spec), CloudConfig(voxel_size=cfg.voxel_size))
    request = resolve_task(task, world, sched_cfg)
    schedule: Schedule = Scheduler(world, planner, sched_cfg).schedule(request)
    return robot_trajectory(schedule, spec, cfg)


def join(new: Any, q_now: np.ndarray, t_now: float, world: Any, held: dict[str, str] | None = None) -> Any:
    """The part of trajectory ``new`` from its configuration closest to ``q_now`` (searched within
    :data:`MATCH_WINDOW_S` of ``t_now`` [s]; with ``held`` (hand -> body held now) only among the moments
    where the re-plan's hands hold the same), preceded by a blend from ``q_now``; time 0 = now.

    Raises:
        RetargetError: no such moment (the re-plan opens the door with the other hand, say)."""
    from hsi_retarget.joint_trajectory import JointTrajectory

    near = np.flatnonzero(np.abs(new.t - t_now) <= MATCH_WINDOW_S)
    near = near if near.size else np.arange(len(new.t))
    if held is not None:  # only where the re-plan's hands hold what the robot's hold now
        near = near[[holds_at(new.events, float(new.t[k])) == held for k in near]]
        if not near.size:
            raise RetargetError(
                f"re-plan not taken: within {MATCH_WINDOW_S} s of {t_now:.1f} s its hands never hold "
                f"what they hold now ({held or 'nothing'})"
            )
    k = int(near[np.argmin(np.abs(new.q[near] - q_now[None, :]).max(axis=1))])
    robot = world.robot
    blend = BLEND_MIN_S
    for name in robot.joint_names:
        iq, iv = robot.q_index(name), robot.v_index(name)
        if math.isfinite(robot.v_max[iv]) and robot.v_max[iv] > 0:
            blend = max(blend, abs(new.q[k, iq] - q_now[iq]) / (BLEND_SPEED * robot.v_max[iv]))
    t0 = float(new.t[k])
    times = np.concatenate([[0.0], new.t[k:] - t0 + blend])
    qs = np.vstack([q_now[None, :], new.q[k:]])
    events = tuple(
        dataclasses.replace(e, time=e.time - t0 + blend) for e in new.events if e.time >= t0 - 1e-9
    )
    meta = {**new.meta, "replan_join_time_s": t0, "replan_blend_s": blend}
    return JointTrajectory(new.robot, times, qs, new.joint_names, events, meta, new.floating_index)


def holds_at(events: Sequence[Any], t: float) -> dict[str, str]:
    """Hand -> object held at time ``t`` [s] after the gripper ``events`` before it."""
    held: dict[str, str] = {}
    for e in sorted((e for e in events if e.time < t), key=lambda e: e.time):
        if e.kind == "grasp":
            held[e.hand] = e.object_name
        else:
            held.pop(e.hand, None)
    return held


def opening_hand(trajectory: Any, spec: SceneSpec, target: str) -> str:
    """The hand a trajectory first grasps a door or drawer (not a free object) with before it grasps
    ``target``: ``left``, ``right`` or '' (none)."""
    free = {o.name for o in spec.objects}
    for e in sorted(trajectory.events, key=lambda e: e.time):
        if e.kind == "grasp" and e.object_name == target:
            return ""
        if e.kind == "grasp" and e.object_name not in free:
            return str(e.hand)
    return ""


def contact_miss(trajectory: Any) -> float:
    """[m] the TCP errors summed over the free objects' grasps and releases of ``trajectory``'s retargeting
    when its IK missed one by more than the arm-branch search's trigger (what is left after the search,
    ``meta["arm_branches"]``), else 0: the grasps and releases are within reach of the gripper."""
    report = trajectory.meta.get("arm_branches") or {}
    if not report:
        return 0.0
    after = report.get("contact_error_after_m")
    kept = bool(report.get("kept")) and after is not None
    return float(after if kept else report.get("contact_error_before_m", math.inf))


def grasping_hand(trajectory: Any, target: str) -> str:
    """The hand a trajectory grasps ``target`` with: ``left``, ``right``, ``both``, or '' (none)."""
    hands = sorted({e.hand for e in trajectory.events if e.kind == "grasp" and e.object_name == target})
    return "both" if len(hands) == 2 else (hands[0] if hands else "")


def grasp_conflict(events: Sequence[Any], held: dict[str, str]) -> str:
    """Why a re-plan's gripper ``events`` (from now on) cannot follow the grasps the hands hold now
    (``held``: hand -> body), or '' when they can: a hand holding a body releases it before it grasps
    another, and a hand holding nothing has nothing to release."""
    for hand in ("left", "right"):
        mine = sorted((e for e in events if e.hand == hand), key=lambda e: e.time)
        if not mine:
            continue
        first = mine[0]
        if hand in held and first.kind == "grasp" and first.object_name != held[hand]:
            return f"the re-plan's {hand} hand grasps {first.object_name} while it holds {held[hand]}"
        if hand not in held and first.kind == "release":
            return f"the re-plan's {hand} hand releases {first.object_name or 'a grasp'} but holds nothing"
    return ""


def _reaimed_or_replanned(
    reaimed: Callable[[], Any], replanned: Callable[[], Any], record: dict[str, Any]
) -> Any:
    """The executed schedule re-aimed at the moved target (``reaimed()``), or the full re-plan
    (``replanned()``) where the re-aimed one misses a grasp or release (:func:`contact_miss`) and the re-plan
    misses less (or the re-aiming fails); counted in ``record``.

    Raises:
        HsiError: neither gives a trajectory."""
    aimed, miss = None, math.inf
    try:
        aimed = reaimed()
        miss = contact_miss(aimed)
    except HsiError as exc:
        record["replan_errors"].append(f"re-aim: {type(exc).__name__}: {exc}")
    if miss > 0.0:
        record["reaim_compared"] += 1
        try:
            full = replanned()
        except HsiError as exc:
            if aimed is None:
                raise
            record["replan_errors"].append(f"{type(exc).__name__}: {exc}")
        else:
            if aimed is None or contact_miss(full) < miss:
                record["replans_full"] += 1
                return full
    record["reaimed"] += 1
    return aimed


@contextlib.contextmanager
def perturbed_execution(
    case: Case,
    planner: Planner,
    cfg: PipelineConfig,
    seed: int,
    record: dict[str, Any],
    *,
    reaim_first: bool = False,
) -> Iterator[None]:
    """Within the block, ``run_task``'s execution gets seeded perturbations and the re-plan hook (module
    docstring; ``reaim_first``: the executed schedule re-aimed at the moved target comes first, the full
    re-plan only where its IK misses a contact); ``record`` receives the events, the re-plan count and their
    wall time [s]."""
    from hsi_retarget import sim_check
    from hsi_retarget.sim_check import PerturbationConfig, TargetMove, random_perturbations
    from hsi_retarget.sim_check.perturb import event_dict

    original = sim_check.execute
    task = demo_task(case)
    record.update(events=[], replans=0, replan_wall_s=0.0, replan_errors=[], replan_ik_fps=[])
    record.update(reaimed=0, reaim_compared=0, replans_full=0)
    roles = {"hand": "", "door": ""}  #: the executed plan's grasping and opening hands, kept by a re-plan

    def hook(world: Any, event: Any, start: float) -> Any:
        if not isinstance(event, TargetMove):
            return None
        t0 = time.perf_counter()
        try:
            spec = moved_object(case.spec, event.object_name, event.offset)
            replan = dataclasses.replace(task, hand=roles["hand"], door_hand=roles["door"])
            moved = {event.object_name: np.asarray(event.offset, dtype=np.float64)}

            def reaimed() -> Any:  # the executed schedule, its grasp re-aimed at the moved target
                return robot_trajectory(record["schedule"], spec, cfg, moved=moved)

            if reaim_first and record.get("schedule") is not None:
                new = _reaimed_or_replanned(
                    reaimed, lambda: _plan_trajectory(replan, spec, planner, cfg), record
                )
            else:
                try:
                    new = _plan_trajectory(replan, spec, planner, cfg)
                except PlanningError as exc:
                    if record.get("schedule") is None:
                        raise
                    record["replan_errors"].append(f"{type(exc).__name__}: {exc}")
                    new = reaimed()
                    record["reaimed"] += 1
                else:
                    full, miss = new, contact_miss(new)
                    if miss > 0.0 and record.get("schedule") is not None:  # the re-plan's IK misses a contact
                        aimed = reaimed()
                        record["reaim_compared"] += 1
                        if contact_miss(aimed) < miss:
                            new = aimed
                    record["replans_full" if new is full else "reaimed"] += 1
            t_now = world.time - start
            held = {h: body for (h, body), eq in world.welds.items() if world.data.eq_active[eq]}
            joined = join(new, world.robot_q(), t_now, world, held)
            conflict = grasp_conflict(joined.events, held)
            if conflict:  # the executed plan goes on (the target moved at most a few cm)
                raise RetargetError(f"re-plan not taken: {conflict}")
        except HsiError as exc:
            record["replan_errors"].append(f"{type(exc).__name__}: {exc}")
            _LOG.info("%s: re-plan failed: %s", case.tag, exc)
            return None
        finally:
            record["replan_wall_s"] += time.perf_counter() - t0
        record["replans"] += 1
        record["replan_ik_fps"].append(float(new.meta.get("ik_rate_fps", math.nan)))
        return joined

    def execute(world: Any, trajectory: Any, config: Any = None, **kwargs: Any) -> Any:
        goal = kwargs.get("goal")
        target = goal.object_name if goal is not None else ""
        roles["hand"] = grasping_hand(trajectory, target)
        roles["door"] = opening_hand(trajectory, case.spec, target)
        events = random_perturbations(world, trajectory, PerturbationConfig(seed=seed), target=target)
        record["events"] = [event_dict(e) for e in events]
        start = world.time
        kwargs.update(perturbations=events, on_perturbation=lambda w, e: hook(w, e, start))
        return original(world, trajectory, config, **kwargs)

    sim_check.execute = execute  # type: ignore[assignment]
    try:
        yield
    finally:
        sim_check.execute = original


def _ik(outcome: TaskOutcome) -> tuple[float, float, int]:
    """(IK time per frame [ms], frames/s, frames) of the outcome's retargeting (NaN, NaN, 0 without)."""
    meta = outcome.trajectory.meta if outcome.trajectory is not None else {}
    frames, secs = int(meta.get("frames", 0)), float(meta.get("ik_time_s", math.nan))
    if frames <= 0 or not math.isfinite(secs) or secs <= 0.0:
        return math.nan, math.nan, frames
    return 1000.0 * secs / frames, frames / secs, frames


def run_episode(
    case: Case, robot: str, planner_name: str, *, perturbed: bool, seed: int, checkpoint: str
) -> dict[str, Any]:
    """Run ``case`` on ``robot`` with ``planner_name`` (perturbations seeded by ``seed`` if ``perturbed``);
    the episode's JSON row."""
    t0 = time.perf_counter()
    row: dict[str, Any] = {
        "case": case.index,
        "tag": case.tag,
        "template": case.template.name,
        "family": case.template.family,
        "reshape": case.reshape,
        "layout_seed": case.seed,
        "layout_index": case.layout_index,
        "object": case.template.obj,
        "place_on": case.template.place_on,
        "place_click": list(case.place_click),
        "robot": robot,
        "planner": planner_name,
        "perturbed": perturbed,
        "perturbation_seed": seed if perturbed else None,
    }
    cfg = PipelineConfig(robot=robot, planner=planner_name, checkpoint=checkpoint)
    try:
        planner = planner_for(planner_name, checkpoint)
    except HsiError as exc:
        row.update(success=False, stage="planner", error=f"{type(exc).__name__}: {exc}", failures=[str(exc)])
        row["wall_s"] = time.perf_counter() - t0
        return row
    cloud = observe(case.spec)
    record: dict[str, Any] = {}
    reaim = REAIM_FIRST.get(cfg.robot, False)
    with (
        perturbed_execution(case, planner, cfg, seed, record, reaim_first=reaim)
        if perturbed
        else contextlib.nullcontext()
    ):
        outcome = run_task(
            demo_task(case), case.spec, cloud, planner, cfg, on_schedule=lambda s: record.update(schedule=s)
        )
    record.pop("schedule", None)
    rep = outcome.report
    ms, fps, frames = _ik(outcome)
    meta = outcome.trajectory.meta if outcome.trajectory is not None else {}
    search = float((meta.get("arm_branches") or {}).get("time_s", 0.0))  # [s] of the IK time
    recovered = [p.recovered for p in rep.perturbations if p.event.get("kind") == "push"]
    row.update(
        success=bool(rep.success),
        stage=outcome.stage,
        error=outcome.error,
        failures=list(rep.failures),
        diagnosis=outcome.diagnosis(),
        placement_error_m=rep.placement_error_m,
        place_shift_m=rep.place_shift_m,
        duration_s=rep.duration_s,
        collisions=rep.collisions,
        max_tracking_error_m=rep.max_tracking_error_m,
        limit_violations=len(rep.limit_violations),
        ik_ms_per_frame=ms,
        ik_fps=fps,
        ik_frames=frames,
        ik_search_s=search,
        timings_s={k: round(v, 3) for k, v in outcome.timings.items()},
        realtime_factor=rep.realtime_factor,
    )
    if perturbed:
        row["perturbation"] = {
            **record,
            "pushes_recovered": int(sum(recovered)),
            "pushes": len(recovered),
            "replanned_in_execution": rep.replans,
        }
    row["wall_s"] = time.perf_counter() - t0
    return row
