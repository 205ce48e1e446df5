"""``hsi scene``: build MuJoCo models from scene specs and generate randomized layouts.

Sub-commands: ``build`` (spec → MJCF), ``generate`` (spec → N layout specs, optionally MJCF too).
The point-cloud sub-command (``hsi scene cloud``) is registered in :func:`_register_cloud`.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

_log = logging.getLogger(__name__)


def cmd_build(args: argparse.Namespace) -> int:
    """``hsi scene build SPEC --out FILE``: write the scene's standalone MJCF."""
    from hsi_planning.scene import load_scene_spec, write_mjcf

    spec = load_scene_spec(args.spec)
    out = write_mjcf(spec, args.out)
    print(f"{out}: scene '{spec.name}' ({len(spec.furniture)} furniture, {len(spec.objects)} objects)")
    return 0


def cmd_generate(args: argparse.Namespace) -> int:
    """``hsi scene generate SPEC --count N --seed S --out DIR``: write one YAML spec per layout."""
    import yaml

    from hsi_planning.scene import load_scene_spec, write_mjcf
    from hsi_planning.scene.layout import LayoutConfig, generate_layouts

    spec = load_scene_spec(args.spec)
    config = LayoutConfig(reshape=args.reshape, target=args.target)
    layouts = generate_layouts(spec, args.count, args.seed, config)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    for layout in layouts:
        path = out_dir / f"{layout.name}.yaml"
        path.write_text(yaml.safe_dump(layout.to_dict(), sort_keys=False), encoding="utf-8")
        if args.mjcf:
            write_mjcf(layout, out_dir / f"{layout.name}.xml")
    print(f"{out_dir}: {len(layouts)} layouts of '{spec.name}' (seed {args.seed}, reshape={args.reshape})")
    return 0


def _register_cloud(scene_sub: argparse._SubParsersAction) -> None:
    """Add ``hsi scene cloud`` (rendered, labelled point clouds to PLY)."""
    from hsi_nodes.cli.scene_cloud import add_cloud_command

    add_cloud_command(scene_sub)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``hsi scene {build,generate}`` to the ``hsi`` parser."""
    scene = subparsers.add_parser("scene", help="scene specs: MuJoCo models and randomized layouts")
    scene_sub = scene.add_subparsers(dest="scene_command", metavar="SUBCOMMAND", required=True)

    build = scene_sub.add_parser("build", help="scene spec (YAML) -> standalone MJCF")
    build.add_argument("spec", type=Path, help="scene spec YAML, e.g. sim/scenes/kitchen.yaml")
    build.add_argument("--out", type=Path, required=True, help="MJCF file to write")
    build.set_defaults(func=cmd_build)

    gen = scene_sub.add_parser("generate", help="randomized layout variants of a scene spec")
    gen.add_argument("spec", type=Path, help="scene spec YAML")
    gen.add_argument("--count", type=int, default=10, help="number of layouts (default 10)")
    gen.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    gen.add_argument("--out", type=Path, required=True, help="directory for <name>_vNNN.yaml")
    gen.add_argument("--reshape", action="store_true", help="also reshape containers (70-150%%)")
    gen.add_argument("--target", default=None, help="object kept fixed and required reachable")
    gen.add_argument("--mjcf", action="store_true", help="also write <name>_vNNN.xml")
    gen.set_defaults(func=cmd_generate)

    _register_cloud(scene_sub)
