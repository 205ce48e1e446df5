"""``hsi train planner``: build the planner's training data, train the auto-decoder, write the checkpoint.

``hsi train planner --config config/planner_train.yaml [--out models/planner.pt] [--quick] [--root DIR]``
Relative scene, cache and output paths in the config resolve against ``--root`` (default: the current
directory, i.e. the repository root). ``--quick`` trains a tiny model on one layout in seconds.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

_log = logging.getLogger(__name__)


def cmd_planner(args: argparse.Namespace) -> int:
    """Run the planner training; prints a JSON summary (dataset size, times, losses, checkpoint size)."""
    from hsi_planning.config import from_mapping, load_yaml
    from hsi_planning.errors import ConfigError
    from hsi_planning.implicit.planner_train import PlannerTrainConfig, quick_config, train_planner

    doc = load_yaml(args.config) if args.config is not None else {}
    if doc is not None and not isinstance(doc, dict):
        raise ConfigError(f"{args.config}: the planner training config must be a mapping")
    config = from_mapping(PlannerTrainConfig, doc or {}, where=str(args.config or "PlannerTrainConfig"))
    if args.channels is not None:
        config = from_mapping(
            PlannerTrainConfig,
            {**(doc or {}), "channels": [c.strip() for c in args.channels.split(",") if c.strip()]},
            where="--channels",
        )
    if args.quick:
        config = quick_config(config)
    summary = train_planner(config, root=args.root, out=args.out, progress=not args.no_progress)
    print(json.dumps(summary, indent=1))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``hsi train planner`` to the ``hsi`` parser."""
    train = subparsers.add_parser("train", help="train learned components (the implicit planner)")
    train_sub = train.add_subparsers(dest="train_command", metavar="SUBCOMMAND", required=True)
    planner = train_sub.add_parser(
        "planner", help="build field data from rendered clouds and train the planner"
    )
    planner.add_argument(
        "--config", type=Path, default=None, help="YAML config (e.g. config/planner_train.yaml)"
    )
    planner.add_argument("--out", type=Path, default=None, help="checkpoint path (default: the config's out)")
    planner.add_argument("--quick", action="store_true", help="tiny data and model, a few steps (seconds)")
    planner.add_argument("--channels", default=None, help="override channels, e.g. t,toa (ablation)")
    planner.add_argument("--root", type=Path, default=Path("."), help="repository root for relative paths")
    planner.add_argument("--no-progress", action="store_true", help="no progress bars")
    planner.set_defaults(func=cmd_planner)
