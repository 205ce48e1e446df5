"""``hsi bench``: run a benchmark script of the source checkout (:data:`BENCHMARKS`).

``hsi bench planners [--quick] [--out benchmarks/results] [--layouts 168] [--root DIR]`` runs the planner
comparison (``benchmarks/planners.py``; writes ``planners.{json,md}`` and the plots);
``hsi bench pick_place [--quick] [--out DIR] [--episodes 25] [--workers 1] [--root DIR]`` the end-to-end
pick-and-place benchmark (``benchmarks/pick_place.py``; writes ``pick_place.{json,md,png}``). The script
of the checkout at ``--root`` (default: the checkout this package was installed from in editable mode,
else the current directory) runs in a child Python process; the command returns its exit code.
"""

from __future__ import annotations

import argparse
import logging
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

_log = logging.getLogger(__name__)

#: benchmark name -> script path relative to the repository root
BENCHMARKS: dict[str, str] = {
    "planners": "benchmarks/planners.py",
    "pick_place": "benchmarks/pick_place.py",
}


def _default_root() -> Path:
    """[path] the source checkout holding ``benchmarks/`` (editable install), else the current directory."""
    checkout = Path(__file__).resolve().parents[3]
    return checkout if (checkout / "benchmarks").is_dir() else Path.cwd()


def benchmark_command(
    name: str,
    root: Path,
    quick: bool,
    out: Path | None,
    layouts: int | None,
    *,
    extra: Sequence[str] = (),
) -> list[str]:
    """The child command line [argv] running benchmark ``name`` of the checkout at ``root``; ``layouts``
    becomes ``--layouts`` (planners), ``extra`` is appended as is.

    Raises:
        ConfigError: unknown benchmark or its script missing under ``root``.
    """
    from hsi_planning.errors import ConfigError

    if name not in BENCHMARKS:
        raise ConfigError(f"unknown benchmark {name!r}; available: {sorted(BENCHMARKS)}")
    script = root / BENCHMARKS[name]
    if not script.is_file():
        raise ConfigError(f"{script} not found; pass --root DIR of a source checkout with benchmarks/")
    argv = [sys.executable, str(script)]
    if quick:
        argv.append("--quick")
    if out is not None:
        argv += ["--out", str(out)]
    if layouts is not None:
        if layouts < 1:
            raise ConfigError(f"--layouts must be ≥ 1, got {layouts}")
        argv += ["--layouts", str(layouts)]
    return argv + list(extra)


def cmd_planners(args: argparse.Namespace) -> int:
    """Run ``benchmarks/planners.py``; returns its exit code."""
    root = args.root if args.root is not None else _default_root()
    argv = benchmark_command("planners", root, args.quick, args.out, args.layouts)
    _log.info("running %s", " ".join(argv))
    return subprocess.run(argv, cwd=root, check=False).returncode


def cmd_pick_place(args: argparse.Namespace) -> int:
    """Run ``benchmarks/pick_place.py``; returns its exit code."""
    from hsi_planning.errors import ConfigError

    root = args.root if args.root is not None else _default_root()
    extra: list[str] = []
    for flag, value in (("--episodes", args.episodes), ("--workers", args.workers)):
        if value is not None:
            if value < 1:
                raise ConfigError(f"{flag} must be ≥ 1, got {value}")
            extra += [flag, str(value)]
    argv = benchmark_command("pick_place", root, args.quick, args.out, None, extra=extra)
    _log.info("running %s", " ".join(argv))
    return subprocess.run(argv, cwd=root, check=False).returncode


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``hsi bench planners`` and ``hsi bench pick_place`` to the ``hsi`` parser."""
    bench = subparsers.add_parser("bench", help="run benchmarks (planner comparison, pick-and-place)")
    bench_sub = bench.add_subparsers(dest="bench_command", metavar="BENCHMARK", required=True)
    planners = bench_sub.add_parser(
        "planners", help="learned vs minimum-jerk vs ablation vs teacher on 168 unseen layouts"
    )
    planners.add_argument("--quick", action="store_true", help="6 layouts (≤ 3 min)")
    planners.add_argument(
        "--out", type=Path, default=None, help="output folder (default: benchmarks/results)"
    )
    planners.add_argument("--layouts", type=int, default=None, help="number of layouts (default 168)")
    planners.add_argument("--root", type=Path, default=None, help="source checkout holding benchmarks/")
    planners.set_defaults(func=cmd_planners)
    pick = bench_sub.add_parser(
        "pick_place", help="end-to-end pick-and-place in MuJoCo: robots x planners x perturbations"
    )
    pick.add_argument("--quick", action="store_true", help="1 layout per cell (8 episodes)")
    pick.add_argument("--out", type=Path, default=None, help="output folder (default: benchmarks/results)")
    pick.add_argument(
        "--episodes", type=int, default=None, help="layouts = episodes per cell (default 25: 100 per robot)"
    )
    pick.add_argument("--workers", type=int, default=None, help="worker processes (default 1)")
    pick.add_argument("--root", type=Path, default=None, help="source checkout holding benchmarks/")
    pick.set_defaults(func=cmd_pick_place)
