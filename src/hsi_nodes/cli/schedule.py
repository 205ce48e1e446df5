"""``hsi schedule SCENE (--target NAME | --click X,Y,Z) [--place X,Y,Z] [--holding left:OBJ] --out F.json``.

Schedules picking an object (named, or the one under a clicked point) and optionally putting it down at
a clicked place, in a scene spec rendered to a labelled cloud: which hand does what, doors and drawers
to open, objects in the way, where to stand. Writes the keyframes (time, key joint, position, quaternion,
hand, action, object) and the planned wrist segments as JSON, and prints one line per step.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["parse_point", "register"]


def parse_point(text: str) -> tuple[float, float, float]:
    """``'x,y,z'`` [m] → a 3-tuple; raises ``argparse.ArgumentTypeError`` otherwise."""
    parts = [p for p in text.replace(" ", "").split(",") if p]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected x,y,z in metres (3 numbers), got {text!r}")
    return values[0], values[1], values[2]


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    from hsi_planning.errors import PlanningError
    from hsi_planning.perception import CloudConfig
    from hsi_planning.scene_paths import load_scene
    from hsi_planning.scheduler import (
        HandState,
        PickGoal,
        PlaceGoal,
        SceneWorld,
        Scheduler,
        Task,
        WorldState,
        resolve_click,
    )
    from hsi_planning.scheduler.planners import scheduler_planner

    spec = load_scene(args.scene)
    hands = HandState.parse(args.holding or [])
    world = SceneWorld(spec, cloud_config=CloudConfig(voxel_size=args.voxel))
    cloud = world.cloud()
    if args.click is not None:
        goal = resolve_click(args.click, cloud, spec)
        if not isinstance(goal, PickGoal):
            raise PlanningError(
                f"--click {args.click} designates a place on {goal.support!r}, not an object; "
                "use --place for places"
            )
        target = goal.object_name
    else:
        target = args.target
    place, support = None, ""
    if args.place is not None:
        size = world.object_size(target) if world.is_object(target) else (0.1, 0.15)
        radius = 0.5 * (float(np.hypot(size[0], size[1])) if len(size) == 3 else size[0])
        spot = resolve_click(
            args.place,
            world.state_cloud(WorldState(held=frozenset([target]))),
            spec,
            footprint=(radius, size[-1]),
        )
        if not isinstance(spot, PlaceGoal):
            raise PlanningError(
                f"--place {args.place} is on object {spot.object_name!r}, not on a free surface"
            )
        place, support = spot.position, spot.support
    planner = scheduler_planner(args.planner, args.checkpoint)
    schedule = Scheduler(world, planner).schedule(
        Task(
            target=target,
            place=place,
            place_support=support,
            hands=hands,
            hand=args.hand,
            task_id=args.task_id,
        )
    )
    out = schedule.write_json(args.out, segments=not args.no_segments)
    print("\n".join(schedule.steps))
    info = schedule.info
    print(
        f"{out}: {len(schedule.keyframes)} keyframes, {len(schedule.segments)} planned segments, "
        f"{schedule.duration:.2f} s; {info.get('assignment')} (cost {info.get('deviation_cost', 0.0):.2f}); "
        f"planner {planner.name}"
    )
    return 0


def register(subparsers: Any) -> None:
    """Add ``schedule`` to the ``hsi`` sub-commands."""
    parser = subparsers.add_parser(
        "schedule",
        help="pick (and place) goal -> keyframe schedule for both wrists, hip and root (JSON)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: hsi schedule kitchen --target bottle2 --place 0.8,0.2,0.9 --out out/schedule.json",
    )
    parser.add_argument("scene", help="built-in scene name (e.g. kitchen) or scene spec YAML path")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--target", help="name of the object to pick")
    what.add_argument("--click", type=parse_point, metavar="X,Y,Z", help="a clicked point on the object [m]")
    parser.add_argument(
        "--place", type=parse_point, metavar="X,Y,Z", help="a clicked point on a free surface [m]"
    )
    parser.add_argument(
        "--holding", action="append", metavar="HAND:OBJECT", help="an object already in a hand (left:mug1)"
    )
    parser.add_argument("--hand", default="", choices=["", "left", "right", "both"], help="grasping hand")
    parser.add_argument("--planner", default="reach_model", help="reach_model (default), linear or implicit")
    parser.add_argument("--checkpoint", type=Path, default=None, help="implicit planner checkpoint")
    parser.add_argument("--voxel", type=float, default=0.01, metavar="M", help="cloud voxel size [m]")
    parser.add_argument("--task-id", default="cli", help="task id written into the schedule")
    parser.add_argument("--no-segments", action="store_true", help="leave the planned trajectories out")
    parser.add_argument("--out", type=Path, required=True, help="schedule JSON file to write")
    parser.set_defaults(func=_run)
