"""Run the demo's scripted tasks through :func:`~hsi_nodes.demo.pipeline.run_task`, one after the other,
with a trajectory plot per task and one video of all executions.

The cloud of a task's scene comes from ``clouds`` (the foundation's recorded cloud of the main scene) or
is rendered from the scene spec once per scene. A planner that cannot be built (e.g. a missing
checkpoint) fails every task with that reason; nothing falls back to another planner.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hsi_nodes.demo.pipeline import (
    FrameHook,
    PipelineConfig,
    TaskOutcome,
    failed_report,
    make_demo_planner,
    run_task,
)
from hsi_nodes.demo.plots import plot_task
from hsi_nodes.demo.tasks import DemoTask
from hsi_nodes.demo.video import DemoVideo
from hsi_planning.errors import ConfigError, HsiError
from hsi_planning.perception import CloudConfig, LabelledCloud
from hsi_planning.planning import Planner
from hsi_planning.scene import SceneSpec
from hsi_retarget.sim_check import SimWorld, VideoConfig, VideoRecorder

__all__ = ["DemoRun", "RunnerConfig", "run_tasks", "scene_cloud"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunnerConfig:
    """The pipeline plus the outputs of a demo run."""

    pipeline: PipelineConfig = field(default_factory=PipelineConfig)  #: robot, planner, knobs
    video: VideoConfig | None = field(default_factory=VideoConfig)  #: None = no video
    video_name: str = "demo.mp4"  #: video file in the output folder [-]
    cloud_voxel: float = 0.01  #: voxel of clouds rendered for scenes without a recorded one [m]

    def __post_init__(self) -> None:
        if not self.cloud_voxel > 0.0 or not self.video_name:
            raise ConfigError("RunnerConfig: cloud_voxel > 0 m and a video file name are required")


@dataclass
class DemoRun:
    """The outcomes of a run and the files it wrote."""

    outcomes: list[TaskOutcome]
    plots: list[Path] = field(default_factory=list)
    video: Path | None = None
    wall_s: float = 0.0  #: [s]


def scene_cloud(scene: str, voxel: float) -> LabelledCloud:
    """The labelled cloud of ``scene`` rendered from its cameras (the scheduler's observed cloud)."""
    from hsi_planning.scene_paths import load_scene
    from hsi_planning.scheduler import SceneWorld

    return SceneWorld(load_scene(scene), cloud_config=CloudConfig(voxel_size=voxel)).cloud()


def _lookat(target: str, task: DemoTask, spec: SceneSpec) -> tuple[float, float, float]:
    """[m] camera target: between the object's rest position and its placement, at counter height."""
    from hsi_planning.scene.model import object_pose

    place = np.asarray(task.place_click, dtype=np.float64)
    try:
        start = np.asarray(object_pose(spec, target)[:3, 3], dtype=np.float64)
    except (HsiError, KeyError):
        start = place
    mid = 0.5 * (start + place)
    return float(mid[0]), float(mid[1]), 0.9


def run_tasks(
    tasks: Sequence[DemoTask],
    out: Path,
    config: RunnerConfig,
    clouds: Mapping[str, LabelledCloud] | None = None,
    echo: Callable[[str], None] = _log.info,
) -> DemoRun:
    """Run ``tasks`` in order (see the module docstring); plots ``OUT/plots/<task>.png``, video
    ``OUT/<video_name>``. Progress lines go to ``echo``."""
    from hsi_planning.scene_paths import load_scene

    t0 = time.perf_counter()
    cfg = config.pipeline
    known = dict(clouds or {})
    planner: Planner | None = None
    planner_error = ""
    try:
        planner = make_demo_planner(cfg.planner, cfg.checkpoint)
    except HsiError as exc:
        planner_error = f"planner: {type(exc).__name__}: {exc}"
        echo(f"planner {cfg.planner!r} is not available: {exc}")
    video = DemoVideo(out / config.video_name, config.video) if config.video is not None else None
    run = DemoRun([])
    for i, task in enumerate(tasks, 1):
        echo(f"[{i}/{len(tasks)}] {task.name}: {task.description or task.label}")
        if planner is None:
            report = failed_report(task, task.object_name, cfg, planner_error)
            outcome = TaskOutcome(task, report, "planner", planner_error, task.object_name)
            run.outcomes.append(outcome)
            if video is not None:
                video.add([task.name, "not run: " + planner_error[:60]], None)
            continue
        spec = load_scene(task.scene)
        if task.scene not in known:
            known[task.scene] = scene_cloud(task.scene, config.cloud_voxel)
        recorders: list[VideoRecorder] = []

        def on_world(
            world: SimWorld, target: str, task: DemoTask = task, kept: list[VideoRecorder] = recorders
        ) -> FrameHook | None:
            if video is None:
                return None
            recorder = video.recorder(world, _lookat(target, task, world.spec))
            kept.append(recorder)
            return recorder

        outcome = run_task(task, spec, known[task.scene], planner, cfg, on_world=on_world)
        run.outcomes.append(outcome)
        verdict = "success" if outcome.report.success else f"FAILED ({outcome.stage})"
        echo(f"    {verdict}; " + "; ".join(outcome.report.failures[:3]))
        plot = plot_task(outcome, out / "plots" / f"{task.name}.png")
        if plot is not None:
            run.plots.append(plot)
        if video is not None:
            lines = [f"{task.name}: {verdict}", task.description[:70], f"{cfg.robot} / {cfg.planner}"]
            video.add(lines, recorders[0] if recorders else None)
    if video is not None:
        run.video = video.close()
    run.wall_s = time.perf_counter() - t0
    return run
