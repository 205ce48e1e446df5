"""One pick-and-place task end to end, as plain function calls: scene cloud -> scheduler (+ wrist
planner) -> retargeting -> MuJoCo execution check.

:func:`run_task` takes a scene spec, its labelled cloud, a :class:`~hsi_nodes.demo.tasks.DemoTask`, a
planner and a robot and returns a :class:`TaskOutcome` with the schedule, the joint trajectory and the
:class:`~hsi_retarget.sim_check.ExecutionReport`. Every stage's failure (a click on nothing, a planner
or scheduling error, IK that cannot reach, a collision in MuJoCo) ends up in the report (``success``
false, ``failures`` naming the stage): nothing is retried with another planner.

Steps:

1. the clicks are resolved against the cloud (:func:`~hsi_planning.scheduler.resolve_click`; the place
   click with the picked object held, so its own points do not block the spot);
2. :class:`~hsi_planning.scheduler.Scheduler` with the robot's footprint radius as the body radius (the
   root path keeps the base clear of the furniture) schedules the pick-and-place;
3. :func:`~hsi_retarget.retarget.retarget` maps the schedule onto the robot (root keyframes -> base x,
   y, yaw and the torso lift from the hip for the dual arm; the pelvis for the humanoid) with gripper
   goals around the grasps (:mod:`hsi_retarget.grasp_depth`: into the objects, straight final approach
   and first retreat, carried objects turning smoothly), and the robot stands still while its fingers
   close or open (:mod:`hsi_retarget.gripper_dwell`);
4. :func:`~hsi_retarget.sim_check.execute` runs the trajectory in a fresh MuJoCo world of the scene at
   rest (each task is an episode of its own), judged against the placement; the largest opening of the
   door or drawer the schedule opens is recorded.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hsi_nodes.demo.tasks import DemoTask
from hsi_planning.errors import ConfigError, HsiError, PlanningError
from hsi_planning.perception import CloudConfig, LabelledCloud
from hsi_planning.planning import Planner
from hsi_planning.scene import SceneSpec
from hsi_planning.scheduler import PickGoal, SceneWorld, Schedule, Scheduler, SchedulerConfig, Task
from hsi_planning.scheduler.planners import SCHEDULER_PLANNERS, scheduler_planner
from hsi_retarget.grasp_depth import GraspDepthConfig
from hsi_retarget.gripper_dwell import DwellConfig, add_gripper_dwell
from hsi_retarget.joint_trajectory import JointTrajectory
from hsi_retarget.robots import robot_name
from hsi_retarget.sim_check import ExecutionConfig, ExecutionReport, SimWorld

__all__ = [
    "DEMO_PLANNERS",
    "ROBOT_BODY_RADIUS",
    "ROBOT_HAND_RADIUS",
    "ROBOT_WRIST_CLEARANCE",
    "PipelineConfig",
    "TaskOutcome",
    "make_demo_planner",
    "resolve_task",
    "robot_trajectory",
    "run_task",
]

_log = logging.getLogger(__name__)

#: Footprint radius of each robot's base [m]: the scheduler's body radius, so the planned root path keeps
#: the base clear of the furniture (dual arm: half diagonal of the 0.6 x 0.5 m base box, rounded up).
ROBOT_BODY_RADIUS: dict[str, float] = {"dual_ur5e": 0.4, "humanoid": 0.25}
#: Hand sphere of the scheduler's blocker check around the wrist [m], for both robots: a robot's gripper
#: (palms 11–15 cm wide) needs more room than a human hand (the planner's default 3.5 cm) to reach past a
#: neighbour.
ROBOT_HAND_RADIUS = 0.05
#: Radius of the straight approach corridor out of a cabinet's or shelf's front that the scheduler keeps
#: free of neighbours [m] (:class:`~hsi_planning.scheduler.AuxiliaryConfig`): the grippers follow the
#: straight final approach, and a planned wrist path winding past a neighbour leaves their palm and
#: wrist no room.
ROBOT_CORRIDOR_RADIUS = 0.05
#: Free space the scheduler keeps around a wrist resting on the body at a stance [m]
#: (:attr:`~hsi_planning.scheduler.StanceConfig.wrist_clearance`). The humanoid's hands start where the
#: human's do: a crouch that put the ready wrist inside a counter left no planned reach (4 more humanoid
#: episodes schedule). The dual arm's grippers start at their own home pose, not the human's ready wrist,
#: and on its benchmark the stances this moved lost 9 episodes: off there.
ROBOT_WRIST_CLEARANCE: dict[str, float] = {"dual_ur5e": 0.0, "humanoid": 0.05}
#: Planner names of the demo: the scheduler's, plus the minimum-jerk baseline.
DEMO_PLANNERS: tuple[str, ...] = tuple(dict.fromkeys((*SCHEDULER_PLANNERS, "minjerk")))

#: Frame callback of an execution (e.g. a video recorder).
FrameHook = Callable[[SimWorld], None]


@dataclass(frozen=True)
class PipelineConfig:
    """Robot, planner and the knobs of :func:`run_task`."""

    robot: str = "dual_ur5e"  #: robot name (``dual_ur5e``/``dual_arm`` or ``humanoid``) [-]
    planner: str = "implicit"  #: wrist planner (:data:`DEMO_PLANNERS`) [-]
    checkpoint: str = "models/planner.pt"  #: implicit planner checkpoint [path]
    voxel_size: float = 0.01  #: voxel size of the scheduler's predicted clouds (opened parts) [m]
    body_radius: float = 0.0  #: scheduler body radius; 0 = the robot's :data:`ROBOT_BODY_RADIUS` [m]
    sample_rate: float = 60.0  #: retargeting sample rate of the schedule [Hz]
    grasp: GraspDepthConfig = field(default_factory=GraspDepthConfig)  #: gripper goals around grasps [m]
    dwell: DwellConfig = field(default_factory=DwellConfig)  #: standstills at gripper events [s]
    execution: ExecutionConfig = field(default_factory=ExecutionConfig)  #: MuJoCo check settings

    def __post_init__(self) -> None:
        object.__setattr__(self, "robot", robot_name(self.robot))
        if self.planner not in DEMO_PLANNERS:
            raise ConfigError(f"PipelineConfig.planner={self.planner!r}; available: {list(DEMO_PLANNERS)}")
        if not (self.voxel_size > 0.0 and self.sample_rate > 0.0 and 0.0 <= self.body_radius < 1.0):
            raise ConfigError(
                "PipelineConfig: voxel_size > 0 m, sample_rate > 0 Hz, body_radius in [0, 1) m; "
                f"got {self.voxel_size}, {self.sample_rate}, {self.body_radius}"
            )

    @property
    def root_radius(self) -> float:
        """[m] the body radius the scheduler uses."""
        return self.body_radius or ROBOT_BODY_RADIUS.get(self.robot, 0.25)

    def scheduler_config(self) -> SchedulerConfig:
        """The scheduler's config: defaults with the robot's body radius and hand sphere."""
        from hsi_planning.config import from_mapping

        overrides = {
            "body": {"body_radius": self.root_radius},
            "stance": {"wrist_clearance": ROBOT_WRIST_CLEARANCE.get(self.robot, 0.0)},
            "auxiliary": {"hand_radius": ROBOT_HAND_RADIUS, "corridor_radius": ROBOT_CORRIDOR_RADIUS},
        }
        return from_mapping(SchedulerConfig, overrides, where="demo")


def make_demo_planner(name: str, checkpoint: str = "models/planner.pt") -> Planner:
    """The planner called ``name``: :func:`~hsi_planning.scheduler.planners.scheduler_planner`'s, or the
    minimum-jerk baseline built directly while the planning front does not list it.

    Raises:
        ConfigError: unknown name. PlanningError: the implicit planner's checkpoint cannot be read.
    """
    if name in SCHEDULER_PLANNERS:
        return scheduler_planner(name, checkpoint)
    if name == "minjerk":
        from hsi_planning.minjerk import MinJerkPlanner

        planner: Planner = MinJerkPlanner()
        return planner
    raise ConfigError(f"unknown planner {name!r}; available: {list(DEMO_PLANNERS)}")


@dataclass
class TaskOutcome:
    """What one task produced; ``stage`` is where it stopped (``done`` when it was executed)."""

    task: DemoTask
    report: ExecutionReport
    stage: str = "done"  #: ``resolve``, ``schedule``, ``retarget``, ``execute`` or ``done``
    error: str = ""  #: the failure message of ``stage`` ('' when done)
    target: str = ""  #: the object picked
    placement: tuple[float, float, float] | None = None  #: [m] bottom centre goal of the object
    schedule: Schedule | None = None
    trajectory: JointTrajectory | None = None
    timings: dict[str, float] = field(default_factory=dict)  #: [s] wall time per stage
    opening_max: float | None = None  #: largest opening of the schedule's door [rad] / drawer [m]

    def diagnosis(self, ik_error_m: float = 0.02) -> list[str]:
        """What went wrong on the way, beyond the judge's failures: unreachable goals, IK misses larger
        than ``ik_error_m`` [m] (also at a grasp, where the hand then closed off the object), failed grasps,
        a door or drawer that did not open."""
        out: list[str] = []
        meta = self.trajectory.meta if self.trajectory is not None else {}
        for u in meta.get("unreachable", []):
            out.append(
                f"{u['side']} TCP goal beyond the robot's reach by {u['max_excess_m']:.3f} m "
                f"({u['t_start']:.1f}-{u['t_end']:.1f} s of the schedule)"
            )
        for u in meta.get("ik_unreached", []):
            if u["max_error_m"] > ik_error_m:
                out.append(
                    f"IK missed the {u['side']} TCP goal by up to {u['max_error_m']:.3f} m "
                    f"({u['t_start']:.1f}-{u['t_end']:.1f} s of the schedule)"
                )
        for c in meta.get("carry_corrections", []):  # the IK ended short of a grasp: the hand closed there
            if c["position_m"] > ik_error_m:
                out.append(
                    f"the {c['hand']} hand closed {c['position_m']:.3f} m and {c['angle_deg']:.0f} deg off "
                    f"its planned grasp of {c['object']} at {c['time_s']:.1f} s of the schedule (the IK "
                    "ended short; the carry follows from there)"
                )
        for g in self.report.grasps:
            if g.kind == "failed":
                out.append(f"grasp of {g.target} by the {g.hand} hand failed at {g.time_s:.1f} s")
        part = str(self.schedule.info.get("part", "")) if self.schedule is not None else ""
        if part and self.stage == "done" and self.opening_max is not None:
            limits = ExecutionConfig()  # the check's defaults: door >= 60 deg, drawer >= 0.2 m
            required = limits.drawer_open_m if "/drawer" in part else limits.door_open_rad
            if self.opening_max < required:
                out.append(f"{part} opened at most {self.opening_max:.3f} (needs {required:.3f})")
        return out

    def entry(self) -> dict[str, Any]:
        """The ``report.json`` entry: the execution report plus task, scene, stage and diagnostics."""
        out = self.report.to_dict()
        out.update(
            task=self.task.name,
            scene=self.task.scene,
            description=self.task.description,
            stage=self.stage,
            error=self.error,
            placement=list(self.placement) if self.placement is not None else None,
            timings_s={k: round(v, 3) for k, v in self.timings.items()},
            opening_max=self.opening_max,
            diagnosis=self.diagnosis(),
        )
        if self.schedule is not None:
            info = self.schedule.info
            out["schedule"] = {
                "duration_s": self.schedule.duration,
                "steps": list(self.schedule.steps),
                **{k: info.get(k) for k in ("assignment", "strategy", "part", "blockers", "planner")},
            }
        if self.trajectory is not None:
            meta = self.trajectory.meta
            out["retarget"] = {
                k: meta.get(k)
                for k in ("unreachable", "ik_unreached", "tracking", "time_scaling", "ik_rate_fps")
            }
        from hsi_retarget.joint_trajectory import plain

        clean: dict[str, Any] = plain(out)
        return clean


def failed_report(task: DemoTask, target: str, config: PipelineConfig, reason: str) -> ExecutionReport:
    """The report of a task that never reached the MuJoCo check."""
    return ExecutionReport(
        object=target or task.label,
        robot=config.robot,
        planner=config.planner,
        success=False,
        placement_error_m=None,
        duration_s=0.0,
        collisions=0,
        max_tracking_error_m=float("nan"),
        rms_tracking_error_m=float("nan"),
        max_joint_error=float("nan"),
        failures=(reason,),
    )


def resolve_task(task: DemoTask, world: SceneWorld, config: SchedulerConfig) -> Task:
    """The scheduler :class:`Task` of ``task``'s clicks in ``world`` (its observed cloud).

    Raises:
        PlanningError: the pick click designates no object, or the place click no free surface.
    """
    from hsi_planning.scheduler import PlaceGoal, WorldState, resolve_click

    rest = world.cloud()
    if task.click is not None:
        goal = resolve_click(task.click, rest, world.spec, config.goals)
        if not isinstance(goal, PickGoal):
            raise PlanningError(f"task {task.name}: the pick click designates a place, not an object")
        target = goal.object_name
    else:
        target = task.object_name
        if not world.is_object(target):
            raise PlanningError(f"task {task.name}: {target!r} is not an object of {world.spec.name!r}")
    size = world.object_size(target)
    radius = 0.5 * (float(np.hypot(size[0], size[1])) if len(size) == 3 else float(size[0]))
    held = world.state_cloud(WorldState(held=frozenset({target})))
    spot = resolve_click(task.place_click, held, world.spec, config.goals, footprint=(radius, size[-1]))
    if not isinstance(spot, PlaceGoal):
        raise PlanningError(
            f"task {task.name}: the place click is on {spot.object_name!r}, not a free surface"
        )
    return Task(
        target=target,
        place=spot.position,
        place_support=spot.support,
        hand=task.hand,
        door_hand=task.door_hand,
        task_id=task.name,
    )


def robot_trajectory(
    schedule: Schedule, spec: SceneSpec, config: PipelineConfig, moved: Mapping[str, Any] | None = None
) -> JointTrajectory:
    """``schedule`` on ``config.robot`` in ``spec``: retargeted with the gripper goals around its grasps
    (``config.grasp``), standing still at the gripper events (``config.dwell``); the grasps of ``moved``
    objects (name -> (3,) [m] displacement since ``schedule`` was planned) re-aimed at where they are
    (:mod:`hsi_retarget.moved_target`).

    Raises:
        RetargetError: the robot cannot follow the schedule (see :func:`~hsi_retarget.retarget.retarget`).
    """
    from hsi_retarget.retarget import RetargetConfig, retarget

    retarget_config = RetargetConfig(sample_rate=config.sample_rate, grasp=config.grasp)
    trajectory = retarget(schedule, config.robot, spec, retarget_config, moved=moved)
    return add_gripper_dwell(trajectory, config.dwell)


def _opening_hook(world: SimWorld, part: str, inner: FrameHook | None) -> tuple[FrameHook, list[float]]:
    best = [0.0]

    def hook(w: SimWorld) -> None:
        if part:
            best[0] = max(best[0], abs(w.opening(part)))
        if inner is not None:
            inner(w)

    return hook, best


def run_task(
    task: DemoTask,
    spec: SceneSpec,
    cloud: LabelledCloud,
    planner: Planner,
    config: PipelineConfig,
    *,
    on_world: Callable[[SimWorld, str], FrameHook | None] | None = None,
    on_schedule: Callable[[Schedule], None] | None = None,
) -> TaskOutcome:
    """Run ``task`` in ``spec`` observed as ``cloud`` (see the module docstring).

    Args:
        on_world: called with the task's MuJoCo world and its target before the execution; may return a
            per-frame callback (e.g. a video recorder).
        on_schedule: called with the schedule as soon as it exists, before retargeting and execution
            (e.g. to draw the keyframes and planned wrist paths while the robot moves).
    """
    from hsi_retarget.sim_check import TaskGoal, WorldConfig, build_world, execute

    timings: dict[str, float] = {}
    stage, target = "resolve", ""
    schedule: Schedule | None = None
    trajectory: JointTrajectory | None = None
    placement: tuple[float, float, float] | None = None
    t0 = time.perf_counter()
    try:
        sched_cfg = config.scheduler_config()
        world = SceneWorld(spec, cloud, CloudConfig(voxel_size=config.voxel_size))
        request = resolve_task(task, world, sched_cfg)
        target = request.target
        assert request.place is not None
        placement = (float(request.place[0]), float(request.place[1]), float(request.place[2]))
        stage = "schedule"
        schedule = Scheduler(world, planner, sched_cfg).schedule(request)
        timings["schedule"] = time.perf_counter() - t0
        if on_schedule is not None:
            on_schedule(schedule)
        stage = "retarget"
        t1 = time.perf_counter()
        trajectory = robot_trajectory(schedule, spec, config)
        timings["retarget"] = time.perf_counter() - t1
        stage = "execute"
        t2 = time.perf_counter()
        sim = build_world(WorldConfig(scene=task.scene, robot=config.robot), spec)
        part = str(schedule.info.get("part", ""))
        hook, best = _opening_hook(sim, part, on_world(sim, target) if on_world is not None else None)
        goal = TaskGoal(target, placement=placement, planner=config.planner)
        report = execute(sim, trajectory, config.execution, goal=goal, on_frame=hook)
        timings["execute"] = time.perf_counter() - t2
    except Exception as exc:  # any stage's failure is reported, and the demo goes on
        if not isinstance(exc, HsiError):
            _log.exception("task %s: unexpected error in stage %s", task.name, stage)
        reason = f"{stage}: {type(exc).__name__}: {exc}"
        _log.warning("task %s failed in stage %s: %s", task.name, stage, exc)
        timings["total"] = time.perf_counter() - t0
        return TaskOutcome(
            task,
            failed_report(task, target, config, reason),
            stage,
            str(exc),
            target,
            placement,
            schedule,
            trajectory,
            timings,
        )
    timings["total"] = time.perf_counter() - t0
    return TaskOutcome(
        task,
        report,
        "done",
        "",
        target,
        placement,
        schedule,
        trajectory,
        timings,
        best[0] if part else None,
    )
