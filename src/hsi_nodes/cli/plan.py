"""``hsi plan``: plan the wrist trajectories of one grasp or place in a scene and write them as JSON.

``hsi plan SCENE --target NAME [--hand left|right] [--action grasp|place] [--planner implicit]
[--checkpoint models/planner.pt] [--start X Y Z] [--seed S] --out traj.json``

The scene (a spec YAML or a built-in name) is rendered to a labelled cloud from its cameras, with the
target's container opened (door swung open / drawer pulled out, as the scheduler would); the approach
axis comes from the spec. The JSON holds ``approach`` and ``leave`` (each
:meth:`~hsi_planning.trajectory.WristTrajectory.to_dict`: ``t`` [s], ``position`` [m], ``quaternion``
[x y z w] per sample, ``contact_index``), per-stage ``timings`` [s] and ``info``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def cmd_plan(args: argparse.Namespace) -> int:
    """Run ``hsi plan`` (see the module doc)."""
    import numpy as np

    from hsi_planning.errors import ConfigError
    from hsi_planning.implicit.data_build import DataBuildConfig
    from hsi_planning.implicit.data_scene import parts_to_open, render_opened
    from hsi_planning.implicit.problem import approach_axis_for
    from hsi_planning.planning import PlanRequest, make_planner
    from hsi_planning.scene import object_names
    from hsi_planning.scene_paths import load_scene

    spec = load_scene(args.scene)
    if args.target not in object_names(spec):
        raise ConfigError(
            f"--target {args.target!r} is no object of scene {spec.name!r}; have {object_names(spec)}"
        )
    data = DataBuildConfig()  # opened as far as in the training data
    scene = render_opened(
        spec,
        parts_to_open(spec, args.target),
        door_fraction=data.door_fraction,
        drawer_fraction=data.drawer_fraction,
    )
    if args.start is not None:
        start = np.asarray(args.start, dtype=np.float64)
    else:  # near the body, on the hand's side, facing the target (as the training demonstrations)
        y = float(np.asarray(scene.meshes[args.target].bounds).mean(axis=0)[1])
        start = np.array([0.2, y + (0.25 if args.hand == "left" else -0.25), 1.0])
    planner = make_planner(args.planner, args.checkpoint, seed=args.seed)
    request = PlanRequest(
        cloud=scene.cloud,
        target=args.target,
        hand=args.hand,
        action=args.action,
        start_position=start,
        approach_axis=approach_axis_for(spec, args.target),
    )
    result = planner.plan(request)
    doc = {"scene": spec.name, "target": args.target, **result.to_dict()}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1, default=float), encoding="utf-8")
    a, lv = result.approach, result.leave
    print(
        f"{out}: {args.hand} {args.action} {args.target!r} in '{spec.name}': approach {a.duration:.2f} s / "
        f"{a.path_length():.2f} m, leave {lv.duration:.2f} s / {lv.path_length():.2f} m, "
        f"planned in {1e3 * result.total_seconds:.0f} ms"
    )
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``hsi plan`` to the ``hsi`` parser."""
    p = subparsers.add_parser("plan", help="plan approach and leave wrist trajectories in a scene")
    p.add_argument("scene", help="scene spec YAML or built-in scene name (e.g. kitchen)")
    p.add_argument("--target", required=True, help="object to grasp or place (label name, e.g. mug1)")
    p.add_argument("--hand", choices=("left", "right"), default="right", help="moving hand (default right)")
    p.add_argument("--action", choices=("grasp", "place"), default="grasp", help="default grasp")
    p.add_argument("--planner", default="implicit", help="planner name (default implicit)")
    p.add_argument(
        "--checkpoint", type=Path, default=Path("models/planner.pt"), help="implicit planner weights"
    )
    p.add_argument("--start", type=float, nargs=3, metavar=("X", "Y", "Z"), help="start wrist position [m]")
    p.add_argument("--seed", type=int, default=0, help="seed of the planner's latent fit (default 0)")
    p.add_argument("--out", type=Path, required=True, help="JSON file to write")
    p.set_defaults(func=cmd_plan)
