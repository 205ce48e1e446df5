"""``hsi record --out F.mcap --launch FILE``: run a launch file with a recorder attached.

The in-process transport lives inside one process, so ``record`` runs the system it records: it starts
every node of the launch file plus a ``recorder_node`` and writes all topics (or ``--topics``) to a
rosbag2 MCAP bag (``F.mcap`` -> directory ``F/`` holding ``F.mcap`` and ``metadata.yaml``, readable by
``ros2 bag``, Foxglove and the ``mcap`` tools).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from hsi_nodes.bag import bag_paths
    from hsi_nodes.cli.launch import run_and_report
    from hsi_nodes.launch import NodeSpec
    from hsi_planning.errors import TransportError

    overrides = list(args.args)
    topics: list[str] = []
    for item in args.topics or []:  # argparse puts trailing name:=value after --topics into the list
        (overrides if ":=" in item else topics).append(item)
    bag_dir, mcap_file = bag_paths(args.out)
    if bag_dir.exists():
        raise TransportError(f"bag directory {bag_dir} exists already; choose a new --out or delete it")
    recorder = NodeSpec(
        "recorder_node",
        "hsi_record",
        "/",
        {"out": str(args.out), "topics": topics},
        source="hsi record",
    )
    code = run_and_report(args.launch, overrides, args, extra_nodes=(recorder,))
    print(f"bag: {mcap_file} (directory {bag_dir})")
    return code


def register(sub: Any) -> None:
    """Add the ``record`` sub-command."""
    from hsi_nodes.cli.launch import accept_trailing_overrides, add_run_options

    parser = sub.add_parser(
        "record",
        help="run a launch file in this process and record its topics to an MCAP bag",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: hsi record --out out/run.mcap --launch launch/demo.launch.yaml --duration 5 rate:=5",
    )
    parser.add_argument("--out", type=Path, required=True, help="bag path, e.g. out/run.mcap")
    parser.add_argument("--launch", type=Path, required=True, help="launch file (*.launch.yaml) to run")
    parser.add_argument(
        "--topics", nargs="+", metavar="TOPIC", help="record only these topics (default: all)"
    )
    parser.add_argument("args", nargs="*", metavar="name:=value", help="launch argument overrides")
    add_run_options(parser)
    accept_trailing_overrides(parser)
    parser.set_defaults(func=_run)
