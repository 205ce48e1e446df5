"""The ``hsi`` command line: one sub-command module per concept.

Each module in :data:`_COMMAND_MODULES` defines ``register(subparsers)``, which adds its sub-command(s)
and sets ``func`` (taking the parsed namespace, returning an exit code). Heavy imports happen inside
those functions so that ``hsi --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from hsi_planning.errors import HsiError

_COMMAND_MODULES = (
    "scene",
    "launch",
    "record",
    "demo",
    "schedule",
    "plan",
    "train",
    "retarget",
    "ui",
    "bench",
)


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every registered sub-command."""
    parser = argparse.ArgumentParser(prog="hsi", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _COMMAND_MODULES:
        module = importlib.import_module(f"hsi_nodes.cli.{name}")
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``hsi`` console script; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s [%(name)s] %(message)s",
        datefmt="%H:%M:%S",
    )
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args))
    except HsiError as exc:
        print(f"hsi {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
