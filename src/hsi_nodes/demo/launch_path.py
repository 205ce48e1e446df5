"""The demo through the nodes: ``launch/sim_pick_place.launch.yaml`` run in this process on a simulated
clock, once per scene of the tasks, with ``click_player`` sending the scripted goals.

The run's topics are tapped to rebuild each task's :class:`~hsi_nodes.demo.pipeline.TaskOutcome`: the
schedule (keyframes of ``/hsi/schedule``), the joint trajectory (``/robot/joint_trajectory``) and the
``sim`` report of ``sim_check_node`` (its ``details_json`` is the full execution report); a task that
stopped earlier gets the failing stage's report. The video is written by ``sim_check_node``
(``OUT/demo.mp4``, ``OUT/demo_<scene>.mp4`` for further scenes).
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from hsi_nodes.demo.pipeline import TaskOutcome, failed_report
from hsi_nodes.demo.plots import plot_task
from hsi_nodes.demo.runner import DemoRun, RunnerConfig
from hsi_nodes.demo.tasks import DemoTask
from hsi_retarget.sim_check import ExecutionReport

__all__ = ["LAUNCH_FILE", "run_launch_tasks"]

_log = logging.getLogger(__name__)

LAUNCH_FILE = "launch/sim_pick_place.launch.yaml"
_STAGES = ("schedule", "retarget", "sim")
#: Retargeting diagnostics the ``retarget`` report carries into the trajectory's ``meta``.
_RETARGET_META = ("unreachable", "ik_unreached", "time_scaling", "ik_rate_fps")


def _report_from_dict(data: dict[str, Any]) -> ExecutionReport:
    """The :class:`ExecutionReport` of a ``to_dict`` dict, every record included (grasps, collisions, limit
    violations, perturbations, final object poses)."""
    return ExecutionReport.from_dict(data)


class _Taps:
    """Messages of one run, by task."""

    def __init__(self, robot: str) -> None:
        self.robot = robot
        self.schedules: dict[str, Any] = {}
        self.trajectories: list[Any] = []
        self.reports: dict[str, dict[str, Any]] = {}
        self.order: list[str] = []

    def on_schedule(self, msg: Any) -> None:
        from hsi_nodes.msgs import pose_to_arrays
        from hsi_planning.scheduler import Keyframe, Schedule

        frames = []
        for k in msg.keyframes:
            position, quat = pose_to_arrays(k.pose)
            frames.append(
                Keyframe(
                    float(k.time),
                    str(k.key_joint),  # type: ignore[arg-type]
                    position,
                    quat,
                    str(k.action),
                    str(k.contact_event),  # type: ignore[arg-type]
                    str(k.hand),
                    str(k.object_name),
                )
            )
        part = next(
            (k.object_name for k in frames if k.contact_event == "grasp" and "/" in k.object_name), ""
        )
        info = {"part": part} if part else {}  # the door or drawer the schedule opens (for the diagnosis)
        self.schedules[str(msg.task_id)] = Schedule(
            str(msg.task_id), tuple(frames), steps=tuple(msg.steps), info=info
        )

    def on_trajectory(self, msg: Any) -> None:
        from hsi_nodes.nodes.retarget_node import joint_trajectory_from_msg

        self.trajectories.append(joint_trajectory_from_msg(msg, self.robot))

    def on_report(self, msg: Any) -> None:
        task = str(msg.task_id)
        if task not in self.reports:
            self.order.append(task)
        self.reports.setdefault(task, {})[str(msg.stage)] = msg
        if str(msg.stage) == "retarget" and self.trajectories:
            trajectory = self.trajectories[-1]
            try:  # the retargeting diagnostics (unreachable goals, IK misses) for the task's diagnosis
                details = json.loads(str(msg.details_json) or "{}")
            except ValueError:
                details = {}
            meta = {k: details[k] for k in _RETARGET_META if k in details}
            self.reports[task]["trajectory"] = replace(trajectory, meta={**trajectory.meta, **meta})


def _outcome(task: DemoTask, taps: _Taps, config: RunnerConfig) -> TaskOutcome:
    cfg = config.pipeline
    got = taps.reports.get(task.name, {})
    schedule = taps.schedules.get(task.name)
    trajectory = got.get("trajectory")
    target = str(got["schedule"].object_name) if "schedule" in got else task.object_name
    if "sim" in got and str(got["sim"].details_json):
        details = json.loads(str(got["sim"].details_json))
        if "object" in details:
            # the demo's planner name (the nodes report the planner object's, e.g. human_reach_model)
            report = replace(_report_from_dict(details), planner=cfg.planner)
            opening = details.get("opening_max")
            return TaskOutcome(
                task, report, "done", "", target, None, schedule, trajectory,
                opening_max=None if opening is None else float(opening),
            )  # fmt: skip
    for stage in reversed(_STAGES):
        if stage in got and not bool(got[stage].success):
            reason = f"{stage}: {got[stage].message}"
            return TaskOutcome(
                task, failed_report(task, target, cfg, reason), stage, str(got[stage].message), target,
                None, schedule, trajectory,
            )  # fmt: skip
    done = [s for s in _STAGES if s in got]
    after = f"after the {done[-1]} stage" if done else "before any report"
    reason = f"the task stopped {after} in the launch run (no final report)"
    report = failed_report(task, target, cfg, reason)
    return TaskOutcome(task, report, "launch", reason, target, None, schedule, trajectory)


def run_launch_tasks(
    tasks: Sequence[DemoTask], out: Path, config: RunnerConfig, echo: Callable[[str], None] = _log.info
) -> DemoRun:
    """Run ``tasks`` through the launch file, one launch per scene (see the module docstring)."""
    from hsi_nodes.launch import LaunchRunner, package_share, parse_launch_file

    t0 = time.perf_counter()
    cfg = config.pipeline
    run = DemoRun([])
    scenes = list(dict.fromkeys(t.scene for t in tasks))
    for i, scene in enumerate(scenes):
        names = [t.name for t in tasks if t.scene == scene]
        video = "" if config.video is None else str(out / ("demo.mp4" if i == 0 else f"demo_{scene}.mp4"))
        overrides = {
            "scene": scene,
            "robot": cfg.robot,
            "planner": cfg.planner,
            "body_radius": repr(cfg.root_radius),
            "variant": "kitchen",  # the task names below select the tasks, from any variant
            "tasks": "[" + ", ".join(names) + "]",
            "video": video,
        }
        if config.video is not None:
            v = config.video
            overrides |= {
                f"video_{k}": repr(getattr(v, k))
                for k in ("width", "height", "every", "fps", "distance", "azimuth", "elevation")
            }
        description = parse_launch_file(package_share() / LAUNCH_FILE, overrides)
        taps = _Taps(cfg.robot)
        with LaunchRunner(description, use_sim_time=True) as runner:
            assert runner.transport is not None
            runner.transport.subscribe("/hsi/schedule", "hsi/msg/Schedule", taps.on_schedule)
            runner.transport.subscribe(
                "/robot/joint_trajectory", "trajectory_msgs/msg/JointTrajectory", taps.on_trajectory
            )
            runner.transport.subscribe("/hsi/report", "hsi/msg/TaskReport", taps.on_report)
            reason = runner.spin(None)
        summary = runner.shutdown()
        echo(f"launch run of {scene}: {summary.stop_reason} ({reason}), {summary.wall_s:.1f} s wall")
        if summary.callback_errors:
            echo(f"  callback errors: {summary.callback_errors}")
        if video and Path(video).exists():
            run.video = run.video or Path(video)
        for task in (t for t in tasks if t.scene == scene):
            outcome = _outcome(task, taps, config)
            run.outcomes.append(outcome)
            verdict = "success" if outcome.report.success else f"FAILED ({outcome.stage})"
            echo(f"  {task.name}: {verdict}; " + "; ".join(outcome.report.failures[:3]))
            plot = plot_task(outcome, out / "plots" / f"{task.name}.png")
            if plot is not None:
                run.plots.append(plot)
    run.wall_s = time.perf_counter() - t0
    return run
