"""``hsi ui [--scene kitchen] [--robot dual_arm|humanoid] [--port 8080] [--host 127.0.0.1] [--fast]``.

A local web UI (viser): the scene cloud, furniture, objects and the robot, updated live from the
simulation. Click an object (the target), click a free spot on a surface (the placement), press
*Start task*: the task runs through scheduler + planner -> retargeting -> MuJoCo in a worker thread, and
the keyframes, planned wrist paths, the robot's motion, the report and speed profiles are shown. The UI
publishes ``/clicked_point`` and ``/hsi/goal`` on its transport. Stop it with Ctrl-C.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from hsi_nodes.ui.app import UiApp, UiConfig

    config = UiConfig(
        scene=args.scene,
        robot=args.robot,
        planner=args.planner,
        checkpoint=str(args.checkpoint),
        host=args.host,
        port=args.port,
        fast=args.fast,
    )
    app = UiApp(config)
    print(f"hsi ui: open http://{config.host}:{app.port} (Ctrl-C to stop)", flush=True)
    try:
        while True:
            time.sleep(1.0)
    finally:
        app.close()


def register(sub: Any) -> None:
    """Add the ``ui`` sub-command."""
    parser = sub.add_parser(
        "ui",
        help="web UI: click an object and a place, watch the robot do it (viser)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples: hsi ui | hsi ui --robot humanoid --port 8081 | hsi ui --fast",
    )
    parser.add_argument("--scene", default="kitchen", help="built-in scene name or scene spec YAML path")
    parser.add_argument("--robot", default="dual_arm", help="dual_arm (alias dual_ur5e, default) or humanoid")
    parser.add_argument(
        "--planner", default="implicit", help="default wrist planner: implicit, minjerk, reach_model, linear"
    )
    parser.add_argument(
        "--checkpoint", type=Path, default=Path("models/planner.pt"), help="implicit planner checkpoint"
    )
    parser.add_argument("--port", type=int, default=8080, help="web server port (default 8080)")
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    parser.add_argument("--fast", action="store_true", help="reach-model planner (fast; used by the tests)")
    parser.set_defaults(func=_run)
