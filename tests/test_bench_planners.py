"""``hsi bench planners --quick``: the planner comparison runs end to end and writes a complete table."""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from hsi_nodes.cli import bench
from hsi_planning.errors import ConfigError

GROUPS = ("without reshaping", "with reshaping and novel furniture")
PLANNERS = ("learned (t, o, toa)", "minimum jerk", "teacher")
ABLATION = "learned 2-ch (t, toa)"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hsi")
    bench.register(parser.add_subparsers(dest="command"))
    return parser


def test_benchmark_command_errors(tmp_path: Path, repo_root: Path) -> None:
    with pytest.raises(ConfigError, match="unknown benchmark"):
        bench.benchmark_command("nope", repo_root, True, None, None)
    with pytest.raises(ConfigError, match="not found"):
        bench.benchmark_command("planners", tmp_path, True, None, None)
    with pytest.raises(ConfigError, match="--layouts"):
        bench.benchmark_command("planners", repo_root, False, None, 0)
    argv = bench.benchmark_command("planners", repo_root, True, tmp_path, 12)
    assert argv[1].endswith("benchmarks/planners.py")
    assert argv[2:] == ["--quick", "--out", str(tmp_path), "--layouts", "12"]


def test_bench_planners_quick(tmp_path: Path, repo_root: Path) -> None:
    args = _parser().parse_args(
        ["bench", "planners", "--quick", "--out", str(tmp_path), "--root", str(repo_root)]
    )
    t0 = time.perf_counter()
    assert args.func(args) == 0
    assert time.perf_counter() - t0 < 180.0  # the --quick budget
    results = json.loads((tmp_path / "planners.json").read_text())
    md = (tmp_path / "planners.md").read_text()
    assert results["cases"] == 6
    assert results["hdm05"]["n"] >= 10  # HDM05 grabHighR: 16 clips of 3 actors
    with_ablation = results["ablation_checkpoint"] is not None
    expected = [*PLANNERS, ABLATION] if with_ablation else list(PLANNERS)
    for group in (*GROUPS, "all"):
        assert sorted(results["table"][group]) == sorted(expected)
        assert f"## {group}" in md
        for name, stats in results["table"][group].items():
            assert 0.0 <= stats["success_rate"] <= stats["planned_rate"] <= 1.0, name
            plans = 3 * 3 if name == PLANNERS[0] else 3  # 3 layouts per group, learned run 3x
            assert stats["plans"] == (2 * plans if group == "all" else plans), (group, name)
    for name in expected:
        assert md.count(f"| {name} |") == 4  # three group tables + the human-likeness table
    if not with_ablation:
        assert md.count(f"| {ABLATION} | missing") == 3
    # every case planned by every run; learned plans are scored with finite numbers
    runs = {r["run"] for r in results["rows"]}
    assert len(results["rows"]) == 6 * len(runs)
    learned = [r for r in results["rows"] if r["planner"] == PLANNERS[0] and r["planned"]]
    assert learned, "the learned planner planned no case"
    for row in learned:
        assert math.isfinite(row["safety"]) and row["safety"] > 0.0
        assert math.isfinite(row["dtw"]) and 0.0 < row["dtw"] < 1.0
        assert 0.0 <= row["peak_time_ratio"] <= 1.0
    for key, value in results["hdm05"]["medians"].items():
        assert math.isfinite(value), key
    assert 0.15 < results["hdm05"]["medians"]["peak_time_ratio"] < 0.5  # HDM05: peak at ≈ 30 %
    assert set(results["targets"]) == {
        "learned_success_each_group",
        "safety_ratio_learned_over_minjerk",
        "human_likeness_wins",
    }
    for name in ("planners_speed.png", "planners_paths.png"):
        image = np.asarray(iio.imread(tmp_path / name))
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 400, name
        assert image[..., :3].std() > 5.0, name  # not blank


def test_the_contact_clearance_rule_allows_for_the_contact_tolerance(repo_root: Path) -> None:
    import sys

    import trimesh

    from hsi_planning.demos import ObstacleField
    from hsi_planning.trajectory import WristTrajectory

    sys.path.insert(0, str(repo_root / "benchmarks"))
    try:
        from _common import CONTACT_TOLERANCE, check_segment
    finally:
        sys.path.remove(str(repo_root / "benchmarks"))
    wall = trimesh.creation.box((0.1, 1.0, 1.0))  # faces at x = ±0.05
    field = ObstacleField({"wall": wall})
    contact = np.array([0.065, 0.0, 0.0])  # the reference contact: 15 mm from the wall

    def margin(end_x: float) -> float:
        xs = np.linspace(0.5, end_x, 60)  # a straight approach along -x
        pos = np.column_stack([xs, np.zeros(60), np.zeros(60)])
        quat = np.tile([0.0, 0.0, 0.0, 1.0], (60, 1))
        traj = WristTrajectory(np.linspace(0.0, 1.0, 60), pos, quat)
        return check_segment(traj, field, contact, 0.04, None)["hand"]

    assert margin(0.065) >= 0.0  # at the reference contact: its own clearance is allowed
    assert CONTACT_TOLERANCE > 0.005
    assert margin(0.060) >= 0.0  # 5 mm off (within the tolerance), 5 mm nearer: allowed (was a failure)
    assert margin(0.080) >= 0.0  # 15 mm short of it, farther from the wall: fine
    # A path that dips nearer the wall before its end is still caught:
    xs = np.linspace(0.5, 0.065, 60)
    pos = np.column_stack([xs, np.zeros(60), np.zeros(60)])
    pos[45:55, 0] = 0.052  # 2 mm from the wall, short of the contact
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (60, 1))
    traj = WristTrajectory(np.linspace(0.0, 1.0, 60), pos, quat)
    assert check_segment(traj, field, contact, 0.04, None)["hand"] < 0.0
