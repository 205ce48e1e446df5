"""End-to-end pick-and-place benchmark (issue #6 acceptance): randomized layouts, both robots, both
planners, with and without perturbations, executed in MuJoCo.

Cases (:mod:`_pick_place_cases`): layouts from the seeded generator (seeds ≥ 100000, never used in
training) of the demo's task templates — kitchen counter, door cabinet and drawer, the narrow shelf with a
blocker, the cluttered drawer — without and with reshaped containers, each with a free place spot drawn on
the template's support. Every case runs in every cell (robot × planner × perturbation; paired
comparison) through the demo's pipeline (``hsi_nodes.demo.pipeline.run_task``: resolve, schedule,
retarget, MuJoCo check; :mod:`_pick_place_episode`). ``--episodes N`` is the number of cases, i.e. episodes
per cell; the default 25 gives 100 episodes per robot (200 in all).

Per cell: episodes, success rate, executed rate, placement error median, duration, collisions, max tracking
error, IK time per frame [ms] and frames/s, wall time per episode; per robot the issue's targets
(dual-arm success ≥ 90 %, humanoid ≥ 80 %, IK ≥ 500 frames/s dual-arm). Each episode's row (failure
stage, reasons, diagnosis, perturbation events and re-plans) is in the JSON. Writes ``pick_place.json``,
``pick_place.md`` and ``pick_place.png`` (success per cell, IK time histogram) to ``--out``.

Usage: ``python benchmarks/pick_place.py [--quick] [--episodes 25] [--workers 1] [--out benchmarks/results]``
(also ``hsi bench pick_place``); ``--robots``, ``--planners`` and ``--perturbation`` select cells;
``--merge A/pick_place.json B/pick_place.json --out DIR`` writes one report of cells run separately.
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing
import os
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
ROBOTS = ("dual_ur5e", "humanoid")
PLANNERS = ("implicit", "minjerk")
PERTURBATION = ("off", "on")
DEFAULT_EPISODES = 25  #: [-] cases = episodes per cell; 4 cells per robot -> 100 episodes per robot
QUICK_EPISODES = 1  #: [-] cases of ``--quick``
TEST_SEED_START = 100_000  #: first layout seed never used in training (hsi_planning.implicit.problem)
#: [s] rough wall time of one episode per (robot, planner) on one of the 2 shared cores. Measured: the
#: counter case 6-12 s (both robots and planners), the door-cabinet case ~70 s; a minimum-jerk schedule
#: took up to ~2 min on a loaded machine. Tasks that stop at scheduling take a few seconds.
EPISODE_S = {
    ("dual_ur5e", "implicit"): 25.0,
    ("dual_ur5e", "minjerk"): 40.0,
    ("humanoid", "implicit"): 25.0,
    ("humanoid", "minjerk"): 40.0,
}
REPLAN_S = {"implicit": 10.0, "minjerk": 15.0}  #: [s] extra time of a perturbed episode (re-plan, pushes)
_LOG = logging.getLogger("pick_place")

Job = tuple[Any, str, str, bool, int, str]


def expected_s(robot: str, planner: str, perturbed: bool) -> float:
    """[s] expected wall time of one episode (:data:`EPISODE_S`, :data:`REPLAN_S`)."""
    return EPISODE_S[(robot, planner)] + (REPLAN_S[planner] if perturbed else 0.0)


def _init_worker() -> None:
    """One thread per worker (the pool shares 2 cores), headless MuJoCo rendering."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("MUJOCO_GL", "egl")
    logging.basicConfig(level=logging.WARNING)
    import torch

    torch.set_num_threads(1)


def _run(job: Job) -> dict[str, Any]:
    from _pick_place_episode import run_episode

    case, robot, planner, perturbed, seed, checkpoint = job
    try:
        return run_episode(case, robot, planner, perturbed=perturbed, seed=seed, checkpoint=checkpoint)
    except Exception as exc:  # an episode's crash is a failed episode, not the end of the benchmark
        _LOG.exception("episode %s %s %s crashed", case.tag, robot, planner)
        return {
            "case": case.index,
            "tag": case.tag,
            "template": case.template.name,
            "robot": robot,
            "planner": planner,
            "perturbed": perturbed,
            "success": False,
            "stage": "crash",
            "error": f"{type(exc).__name__}: {exc}",
            "failures": [str(exc)],
            "wall_s": 0.0,
        }


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--episodes", type=int, default=DEFAULT_EPISODES, help="cases = episodes per cell")
    parser.add_argument("--quick", action="store_true", help=f"{QUICK_EPISODES} case per cell")
    parser.add_argument("--seed", type=int, default=TEST_SEED_START, help="layout seed (≥ 100000: unseen)")
    parser.add_argument("--robots", nargs="+", choices=ROBOTS, default=list(ROBOTS))
    parser.add_argument("--planners", nargs="+", choices=PLANNERS, default=list(PLANNERS))
    parser.add_argument("--perturbation", nargs="+", choices=PERTURBATION, default=list(PERTURBATION))
    parser.add_argument("--workers", type=int, default=1, help="worker processes (2 cores: at most 2)")
    parser.add_argument("--checkpoint", type=Path, default=REPO / "models" / "planner.pt")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    parser.add_argument("--verbose", action="store_true")
    parser.add_argument(
        "--merge",
        nargs="+",
        type=Path,
        metavar="JSON",
        help="write one report of earlier runs' pick_place.json files (cells run separately) and exit",
    )
    return parser


def merge(paths: list[Path], out: Path) -> dict[str, Any]:
    """One report (``pick_place.{json,md,png}`` in ``out``) of the episodes of earlier runs' JSON files.

    Raises:
        SystemExit: a file is missing, or the runs used different layout seeds (not the same cases).
    """
    from _pick_place_report import finite, markdown, plot, summarize

    runs = []
    for path in paths:
        if not path.is_file():
            raise SystemExit(f"--merge: {path} not found (a pick_place.json of an earlier run)")
        runs.append(json.loads(path.read_text()))
    seeds = {r["seed"] for r in runs}
    if len(seeds) != 1:
        raise SystemExit(
            f"--merge: the runs used different layout seeds {sorted(seeds)}; merge runs of one seed"
        )
    rows = [row for r in runs for row in r["rows"]]
    results: dict[str, Any] = {
        "command": " + ".join(r["command"].strip() for r in runs),
        "seed": runs[0]["seed"],
        "cases": max(r["cases"] for r in runs),
        "episodes": len(rows),
        "workers": max(r["workers"] for r in runs),
        "cells": [c for r in runs for c in r["cells"]],
        "templates": sorted({t for r in runs for t in r["templates"]}),
        "wall_time_s": sum(r["wall_time_s"] for r in runs),
        "load_average": [a for r in runs for a in r.get("load_average", [])],
        "summary": summarize(rows),
        "rows": rows,
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "pick_place.json").write_text(json.dumps(finite(results), indent=1, allow_nan=False) + "\n")
    (out / "pick_place.md").write_text(markdown(results))
    plot(out / "pick_place.png", results, rows)
    return results


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING)
    if args.merge:
        merged = merge(args.merge, args.out)
        print(f"wrote {args.out}/pick_place.{{json,md,png}} ({merged['episodes']} episodes)")
        return 0
    os.environ.setdefault("MUJOCO_GL", "egl")
    if args.seed < TEST_SEED_START:
        parser.error(f"--seed must be ≥ {TEST_SEED_START}: lower seeds are used for training")
    if args.episodes < 1 or args.workers < 1:
        parser.error("--episodes and --workers must be ≥ 1")
    if "implicit" in args.planners and not args.checkpoint.is_file():
        parser.error(
            f"{args.checkpoint} not found (the implicit planner's checkpoint; or --planners minjerk)"
        )
    from _pick_place_cases import make_cases
    from _pick_place_report import BUSY_LOAD, finite, markdown, plot, summarize
    from tqdm import tqdm

    t_start = time.perf_counter()
    load_start = os.getloadavg()[0]
    if load_start > BUSY_LOAD:
        _LOG.warning(
            "load average %.1f before the start: other processes share the %d cores, the timings (IK "
            "frames/s, wall / episode) will be lower than on an idle machine",
            load_start,
            os.cpu_count() or 0,
        )
    n_cases = QUICK_EPISODES if args.quick else args.episodes
    cases = make_cases(n_cases, args.seed)
    cells = [(r, p, pert == "on") for r in args.robots for p in args.planners for pert in args.perturbation]
    jobs: list[Job] = [
        (case, r, p, pert, args.seed + case.index, str(args.checkpoint))
        for case in cases
        for r, p, pert in cells
    ]
    every = [(r, p, pert) for r in ROBOTS for p in PLANNERS for pert in (False, True)]
    full_s = DEFAULT_EPISODES * sum(expected_s(*cell) for cell in every)
    estimate = sum(expected_s(j[1], j[2], j[3]) for j in jobs) / min(args.workers, len(jobs))
    n_full = DEFAULT_EPISODES * len(every)
    print(
        f"{len(jobs)} episodes ({len(cases)} layouts × {len(cells)} cells): expected ≈ "
        f"{estimate / 60:.0f} min with {args.workers} worker(s); the full default run ({n_full} "
        f"episodes) ≈ {full_s / 3600:.1f} h on 1 worker, {full_s / 7200:.1f} h on 2",
        file=sys.stderr,
    )
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(jobs), desc="episodes", unit="ep", file=sys.stderr)
    args.out.mkdir(parents=True, exist_ok=True)
    partial = args.out / "pick_place.partial.json"

    def keep(row: dict[str, Any]) -> None:  # a long run that is stopped keeps what it measured
        rows.append(row)
        bar.update()
        partial.write_text(json.dumps(finite({"rows": rows}), allow_nan=False) + "\n")

    if args.workers == 1:
        _init_worker()
        for job in jobs:
            keep(_run(job))
    else:
        context = multiprocessing.get_context("spawn")
        with context.Pool(args.workers, initializer=_init_worker) as pool:
            for row in pool.imap(_run, jobs):
                keep(row)
    bar.close()
    wall = time.perf_counter() - t_start
    results: dict[str, Any] = {
        "command": "python benchmarks/pick_place.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "seed": args.seed,
        "cases": len(cases),
        "episodes": len(rows),
        "workers": args.workers,
        "cells": [list(c) for c in cells],
        "templates": sorted({c.template.name for c in cases}),
        "wall_time_s": wall,
        #: 1-min load averages before the start and at the end (the workers' own load included at the end)
        "load_average": [{"start": load_start, "end": os.getloadavg()[0], "cores": os.cpu_count() or 0}],
        "summary": summarize(rows),
        "rows": rows,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "pick_place.json").write_text(json.dumps(finite(results), indent=1, allow_nan=False) + "\n")
    text = markdown(results)
    (args.out / "pick_place.md").write_text(text)
    plot(args.out / "pick_place.png", results, rows)
    partial.unlink(missing_ok=True)
    print(text)
    per = wall / max(len(rows), 1)
    print(f"wrote {args.out}/pick_place.{{json,md,png}} ({wall:.0f} s, {per:.1f} s/episode)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
