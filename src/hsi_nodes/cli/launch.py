"""``hsi launch FILE [name:=value ...]``: run a ROS 2 YAML launch file with every node in this process."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["OverridesParser", "accept_trailing_overrides", "add_run_options", "register", "run_and_report"]

_log = logging.getLogger(__name__)


class OverridesParser(argparse.ArgumentParser):
    """Sub-command parser that also accepts ``name:=value`` items after options.

    argparse assigns positionals in one pass, so ``FILE --sim-time rate:=5`` would leave ``rate:=5``
    unrecognized; this parser appends such leftovers to ``args`` (the overrides list).
    """

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, extras = super().parse_known_args(args, namespace)
        overrides = [e for e in extras if ":=" in e and not e.startswith("-")]
        parsed.args = [*(getattr(parsed, "args", None) or []), *overrides]
        return parsed, [e for e in extras if e not in overrides]


def accept_trailing_overrides(parser: argparse.ArgumentParser) -> None:
    """Make a sub-command parser an :class:`OverridesParser`."""
    parser.__class__ = OverridesParser


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """Options shared by ``hsi launch`` and ``hsi record``."""
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="stop after S seconds of clock time (default: until Ctrl-C or every finite node is done)",
    )
    parser.add_argument(
        "--sim-time",
        action="store_true",
        help="simulated clock advanced as fast as possible (like use_sim_time; timers stay exact)",
    )
    parser.add_argument(
        "--transport",
        choices=("inproc", "dds"),
        default="inproc",
        help="message transport (default inproc: all nodes in this process; dds is not available yet)",
    )


def run_and_report(
    launch_file: Path, overrides: list[str], args: argparse.Namespace, extra_nodes: Any = ()
) -> int:
    """Parse, run and summarize a launch file; 0 = clean run, 1 = callbacks raised errors."""
    from hsi_nodes.launch import parse_launch_file, parse_overrides, run_launch
    from hsi_planning.errors import LaunchError

    if args.duration is not None and not args.duration > 0:
        raise LaunchError(f"--duration must be > 0 [s], got {args.duration}")
    description = parse_launch_file(launch_file, parse_overrides(overrides))
    if args.duration is None:
        _log.info("running until every finite node is done, or Ctrl-C")
    summary = run_launch(
        description,
        duration_s=args.duration,
        transport=args.transport,
        use_sim_time=args.sim_time,
        extra_nodes=extra_nodes,
    )
    print(summary.format())
    if summary.total_errors:
        print(f"hsi: {summary.total_errors} callback error(s); see the log above", file=sys.stderr)
        return 1
    return 0


def _run(args: argparse.Namespace) -> int:
    if args.show_args:
        from hsi_nodes.launch import declared_arguments

        for arg in declared_arguments(args.file):
            default = "(required)" if arg.default is None else f"(default: {arg.default!r})"
            print(f"{arg.name} {default}  {arg.description}".rstrip())
        return 0
    return run_and_report(args.file, args.args, args)


def register(sub: Any) -> None:
    """Add the ``launch`` sub-command."""
    parser = sub.add_parser(
        "launch",
        help="run a ROS 2 YAML launch file (all nodes in this process)",
        description=__doc__,
        epilog="example: hsi launch launch/demo.launch.yaml rate:=20 --duration 5",
    )
    parser.add_argument("file", type=Path, help="launch file (*.launch.yaml)")
    parser.add_argument("args", nargs="*", metavar="name:=value", help="launch argument overrides")
    parser.add_argument("--show-args", action="store_true", help="list the file's arguments and exit")
    add_run_options(parser)
    accept_trailing_overrides(parser)
    parser.set_defaults(func=_run)
