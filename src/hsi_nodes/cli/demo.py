"""``hsi demo``: the simulated bimanual pick-and-place demo from clicked goals.

1. Foundation (:mod:`hsi_nodes.demo.foundation`): ``launch/sim_world.launch.yaml`` runs the scene in
   MuJoCo with ``scene_cloud_node`` on a simulated clock and a recorder: ``OUT/<scene>.xml``, the bag
   ``OUT/<scene>.mcap`` (folder ``OUT/<scene>/``), the cloud ``OUT/<scene>_cloud.ply``, a picture
   ``OUT/<scene>.png`` and ``OUT/demo_summary.json``. The recorded cloud is the scene cloud.
2. Pick-and-place (:mod:`hsi_nodes.demo.runner`): the scripted clicks of the variant
   (:mod:`hsi_nodes.demo.tasks`; ``kitchen``: door-cabinet pick-and-place, drawer pick, narrow-shelf pick
   with a blocker) each go through scheduler + planner -> retargeting -> the MuJoCo check, either through
   the nodes of ``launch/sim_pick_place.launch.yaml`` (default; ``click_player`` sends the clicks) or as
   plain function calls (``--functions``; same stages, plus per-stage wall times).
   Writes ``OUT/report.json`` (one entry per task), ``OUT/report.md``, ``OUT/plots/<task>.png`` and the
   video ``OUT/demo.mp4``, and prints a summary.

``--test`` is the smallest, fastest variant (one counter task, small images; used by the tests). A task
that fails (planner error, unreachable goal, collision, missed placement) is reported, and the demo goes
on; the exit code is 0 when the demo ran (1 on a usage error or a failed foundation launch).
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path
from typing import Any

__all__ = ["register", "run_demo"]

_log = logging.getLogger(__name__)
#: Free camera of the video: behind the robot on its left, looking down at the task's target.
_VIEW: dict[str, Any] = {"distance": 2.8, "azimuth": -25.0, "elevation": -45.0}


def _config(args: argparse.Namespace) -> Any:
    from hsi_nodes.demo.pipeline import PipelineConfig
    from hsi_nodes.demo.runner import RunnerConfig
    from hsi_retarget.sim_check import VideoConfig

    pipeline = PipelineConfig(robot=args.robot, planner=args.planner, checkpoint=str(args.checkpoint))
    if args.no_video:
        video = None
    elif args.test:
        video = VideoConfig(width=160, height=120, every=20, fps=10.0, **_VIEW)
    else:  # 4 frames per simulated second played at 8 frames/s: rendering costs ~50 ms a frame on a CPU
        video = VideoConfig(width=320, height=240, every=25, fps=8.0, **_VIEW)
    return RunnerConfig(pipeline=pipeline, video=video)


def run_demo(args: argparse.Namespace) -> dict[str, Any]:
    """Run the whole demo for parsed ``args``; returns the summary (also in ``OUT/demo_summary.json``)."""
    from hsi_nodes.demo.foundation import DemoSettings, run_foundation
    from hsi_nodes.demo.runner import run_tasks
    from hsi_nodes.demo.summary import format_summary, write_summary
    from hsi_nodes.demo.tasks import demo_tasks

    t0 = time.perf_counter()
    out: Path = args.out
    variant = args.variant or ("test" if args.test else "kitchen")
    tasks = demo_tasks(variant, tuple(t for t in (args.tasks or "").split(",") if t))
    config = _config(args)  # validate robot and planner before the foundation runs
    settings = DemoSettings.for_run(args.duration, args.test)
    summary, cloud = run_foundation(args.scene, out, settings, echo=print)
    launch = not args.functions
    if launch:
        from hsi_nodes.demo.launch_path import run_launch_tasks

        run = run_launch_tasks(tasks, out, config, echo=print)
    else:
        run = run_tasks(tasks, out, config, {summary["scene"]: cloud}, echo=print)
    wall = time.perf_counter() - t0
    files = {"report_json": str(out / "report.json"), "report_md": str(out / "report.md")}
    files |= {f"plot_{p.stem}": str(p) for p in run.plots}
    if run.video is not None:
        files["video"] = str(run.video)
    info = {
        "robot": config.pipeline.robot,
        "planner": config.pipeline.planner,
        "variant": variant,
        "path": "launch" if launch else "pipeline",
        "wall_s": wall,
        "files": files,
    }
    json_path, md_path = write_summary(run.outcomes, out, info)
    summary["pick_place"] = {
        **info,
        "tasks_wall_s": round(run.wall_s, 3),
        "wall_s": round(wall, 3),
        "succeeded": sum(o.report.success for o in run.outcomes),
        "tasks": [{"task": o.task.name, "success": o.report.success, "stage": o.stage} for o in run.outcomes],
    }
    summary["files"].update(files)
    (out / "demo_summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(format_summary(run.outcomes, info))
    print(f"wrote {json_path}, {md_path}, {len(run.plots)} plots, {run.video}; demo wall time {wall:.1f} s")
    return summary


def _run(args: argparse.Namespace) -> int:
    summary = run_demo(args)
    return 1 if summary["callback_errors"] else 0


def register(sub: Any) -> None:
    """Add the ``demo`` sub-command."""
    parser = sub.add_parser(
        "demo",
        help="simulated pick-and-place demo from scripted clicks (reports, plots, video in OUT)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples: hsi demo --out out | hsi demo --robot humanoid --planner minjerk | hsi demo --test",
    )
    parser.add_argument(
        "--scene", default="kitchen", help="scene of the foundation run (built-in name or spec path)"
    )
    parser.add_argument("--out", type=Path, default=Path("out"), help="output folder (default out/)")
    parser.add_argument(
        "--robot", default="dual_ur5e", help="dual_ur5e (alias dual_arm, default) or humanoid"
    )
    parser.add_argument(
        "--planner", default="implicit", help="implicit (default), minjerk, reach_model or linear"
    )
    parser.add_argument(
        "--checkpoint", type=Path, default=Path("models/planner.pt"), help="implicit planner checkpoint"
    )
    parser.add_argument("--variant", default="", help="task list: kitchen (default) or test (with --test)")
    parser.add_argument("--tasks", default="", metavar="A,B", help="run only these tasks (by name)")
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="simulated time of the foundation run [s] (default 1.0; 0.2 with --test)",
    )
    path = parser.add_mutually_exclusive_group()
    path.add_argument(
        "--launch", action="store_true", help="run the tasks through the node launch file (the default)"
    )
    path.add_argument(
        "--functions",
        action="store_true",
        help="run the tasks as function calls instead of through the nodes",
    )
    parser.add_argument("--no-video", action="store_true", help="skip the video")
    parser.add_argument("--test", action="store_true", help="smallest, fastest variant (for the tests)")
    parser.set_defaults(func=_run)
