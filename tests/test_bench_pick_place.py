"""``benchmarks/pick_place.py``: cases on unseen layouts, and a quick run (dual arm, implicit planner, with
and without perturbations) that writes a complete JSON/Markdown/plot with sane numbers."""

from __future__ import annotations

import importlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hsi_nodes.cli import bench
from hsi_planning.errors import ConfigError, PlanningError, RetargetError


def _bench_module(repo_root: Path, name: str) -> Any:
    """The benchmark helper module ``name`` (``benchmarks/`` is not a package)."""
    sys.path.insert(0, str(repo_root / "benchmarks"))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(repo_root / "benchmarks"))


def _cases_module(repo_root: Path) -> Any:
    return _bench_module(repo_root, "_pick_place_cases")


def _episode_module(repo_root: Path) -> Any:
    return _bench_module(repo_root, "_pick_place_episode")


def test_cases_are_unseen_layouts_with_a_free_place_spot(repo_root: Path) -> None:
    mod = _cases_module(repo_root)
    from hsi_planning.scene.model import object_pose

    cases = mod.make_cases(10, 100_000)
    assert [c.index for c in cases] == list(range(10))
    assert {(c.template.name, c.reshape) for c in cases} == {
        (t.name, r) for t in mod.TEMPLATES for r in (False, True)
    }
    again = mod.make_cases(10, 100_000)
    assert [c.place_click for c in again] == [c.place_click for c in cases]  # seeded
    for c in cases:
        assert c.seed >= 100_000 and c.spec.meta["layout"]["seed"] == c.seed
        spot = np.asarray(c.place_click)
        start = object_pose(c.spec, c.template.obj)[:3, 3]
        assert np.linalg.norm(spot[:2] - start[:2]) >= mod.MIN_MOVE - 1e-9
        radius = mod.footprint_radius(c.spec, c.template.obj)
        for o in c.spec.objects:
            if o.on == c.template.place_on and o.name != c.template.obj:
                gap = np.linalg.norm(spot[:2] - object_pose(c.spec, o.name)[:2, 3])
                assert gap >= radius + mod.footprint_radius(c.spec, o.name) + mod.GAP - 1e-9


def test_bench_command_for_pick_place(repo_root: Path, tmp_path: Path) -> None:
    argv = bench.benchmark_command("pick_place", repo_root, True, tmp_path, None, extra=["--workers", "2"])
    assert argv[1].endswith("benchmarks/pick_place.py")
    assert argv[2:] == ["--quick", "--out", str(tmp_path), "--workers", "2"]
    with pytest.raises(ConfigError, match="available"):
        bench.benchmark_command("pickplace", repo_root, True, None, None)


def test_quick_run_writes_the_tables(repo_root: Path, tmp_path: Path) -> None:
    cmd = [
        sys.executable,
        str(repo_root / "benchmarks" / "pick_place.py"),
        "--quick",
        "--robots",
        "dual_ur5e",
        "--planners",
        "implicit",
        "--out",
        str(tmp_path),
    ]
    env = {**os.environ, "MUJOCO_GL": "egl"}
    done = subprocess.run(
        cmd, cwd=repo_root, capture_output=True, text=True, timeout=400, env=env, check=False
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "expected" in done.stderr  # the time estimate
    results = json.loads((tmp_path / "pick_place.json").read_text())
    assert (tmp_path / "pick_place.png").stat().st_size > 1000
    md = (tmp_path / "pick_place.md").read_text()
    assert "dual_ur5e/implicit/plain" in md and "dual_ur5e/implicit/perturbed" in md and "IK [ms/frame]" in md
    assert "IK w/o arm search [frames/s]" in md
    assert results["episodes"] == len(results["rows"]) == 2 and results["cases"] == 1
    (load,) = results["load_average"]  # how busy the machine was: the timings depend on it
    assert load["start"] >= 0.0 and load["end"] >= 0.0 and load["cores"] >= 1
    assert "Load average before / at the end of each run" in md
    rows = {r["perturbed"]: r for r in results["rows"]}
    assert set(rows) == {False, True}
    for row in rows.values():
        assert row["stage"] in ("resolve", "schedule", "retarget", "execute", "done")
        assert isinstance(row["success"], bool) and isinstance(row["failures"], list)
        assert row["success"] or row["failures"]  # a failure says why
        assert math.isfinite(row["wall_s"]) and row["wall_s"] > 0.0
        if row["stage"] == "done":
            assert row["ik_frames"] > 0 and 0.0 < row["ik_ms_per_frame"] < 1000.0
            assert math.isclose(row["ik_fps"], 1000.0 / row["ik_ms_per_frame"], rel_tol=1e-6)
            ik_s = row["ik_frames"] / row["ik_fps"]
            assert 0.0 <= row["ik_search_s"] < ik_s  # the arm-branch search is part of the IK time
            assert row["duration_s"] > 0.0 and row["collisions"] >= 0
    pert = rows[True]["perturbation"]
    assert pert["events"] and all(e["kind"] in ("push", "target_move") for e in pert["events"])
    assert rows[False].get("perturbation") is None
    summary = results["summary"]
    for stats in [*summary["cells"].values(), *summary["robots"].values()]:
        for key in ("success_rate", "executed_rate", "collision_free_rate"):
            value = stats[key]
            assert value is None or 0.0 <= value <= 1.0 or math.isnan(value)
        assert 0.0 <= stats["success_rate"] <= 1.0
        assert stats["wall_per_episode_s"] > 0.0
        if stats["ik_fps"] is not None:  # without the arm search: at least as fast
            assert stats["ik_fps_without_search"] >= stats["ik_fps"] and 0.0 <= stats["ik_search_share"] < 1.0
    assert set(summary["cells"]) == {"dual_ur5e/implicit/plain", "dual_ur5e/implicit/perturbed"}
    target = summary["targets"]["dual_ur5e_success"]
    assert target["target"] == 0.9 and isinstance(target["met"], bool)
    _check_merge(repo_root, tmp_path / "pick_place.json", tmp_path / "merged")


def _check_merge(repo_root: Path, run: Path, out: Path) -> None:
    """``--merge`` of two runs writes one report of all their episodes; runs of other seeds are refused."""
    script = [sys.executable, str(repo_root / "benchmarks" / "pick_place.py")]

    def merge(*paths: Path) -> subprocess.CompletedProcess[str]:
        argv = [*script, "--merge", *map(str, paths), "--out", str(out)]
        return subprocess.run(argv, capture_output=True, text=True, check=False)

    done = merge(run, run)
    assert done.returncode == 0, done.stderr[-2000:]
    merged = json.loads((out / "pick_place.json").read_text())
    single = json.loads(run.read_text())
    assert merged["episodes"] == 2 * single["episodes"] == len(merged["rows"])
    assert merged["summary"]["cells"].keys() == single["summary"]["cells"].keys()
    assert merged["load_average"] == 2 * single["load_average"]
    assert "dual_ur5e/implicit/plain" in (out / "pick_place.md").read_text()
    other = out / "other_seed.json"
    other.write_text(json.dumps({**single, "seed": single["seed"] + 1}))
    refused = merge(run, other)
    assert refused.returncode != 0 and "different layout seeds" in refused.stderr
    missing = merge(out / "none.json")
    assert missing.returncode != 0 and "not found" in missing.stderr


def test_a_replan_must_follow_what_the_hands_hold(repo_root: Path) -> None:
    from hsi_retarget.joint_trajectory import ContactEvent

    episode = _episode_module(repo_root)
    door, bottle = "cabinet1/door1", "bottle2"
    opens_then_grasps = [  # right opens and holds the door, left grasps, right closes the door
        ContactEvent(1.0, "right", "grasp", door),
        ContactEvent(3.0, "left", "grasp", bottle),
        ContactEvent(5.0, "right", "release", door),
    ]

    class _Traj:
        events = opens_then_grasps

    assert episode.grasping_hand(_Traj(), bottle) == "left" and episode.grasping_hand(_Traj(), "mug1") == ""
    assert episode.grasp_conflict(opens_then_grasps, {}) == ""  # before anything is held
    assert episode.grasp_conflict(opens_then_grasps[1:], {"right": door}) == ""  # joined after the door grasp
    swapped = [ContactEvent(3.0, "right", "grasp", bottle), ContactEvent(5.0, "left", "release", door)]
    assert episode.grasp_conflict(swapped, {"right": door})
    why = episode.grasp_conflict(swapped[:1], {"right": door})
    assert "right hand grasps bottle2 while it holds cabinet1/door1" in why
    assert "left hand releases" in episode.grasp_conflict(swapped[1:], {"right": door})


def test_a_replan_joins_where_its_hands_hold_what_they_hold_now(repo_root: Path) -> None:
    from hsi_planning.scene_paths import load_scene
    from hsi_retarget.joint_trajectory import ContactEvent, JointTrajectory
    from hsi_retarget.robots import RobotModel

    episode = _episode_module(repo_root)
    spec = load_scene("kitchen")
    door, bottle = "cabinet1/door1", "bottle2"
    events = (
        ContactEvent(1.0, "right", "grasp", door),
        ContactEvent(3.0, "left", "grasp", bottle),
        ContactEvent(5.0, "right", "release", door),
    )
    assert episode.holds_at(events, 0.5) == {} and episode.holds_at(events, 2.0) == {"right": door}
    assert episode.holds_at(events, 4.0) == {"right": door, "left": bottle}
    assert episode.holds_at(events, 6.0) == {"left": bottle}

    class _Traj:
        pass

    traj = _Traj()
    traj.events = events  # type: ignore[attr-defined]
    assert episode.opening_hand(traj, spec, bottle) == "right"
    traj.events = events[1:]  # type: ignore[attr-defined]  # the bottle grasped first: nothing opened before
    assert episode.opening_hand(traj, spec, bottle) == ""

    robot = RobotModel("dual_ur5e")

    class _World:
        pass

    world = _World()
    world.robot = robot  # type: ignore[attr-defined]
    t = np.linspace(0.0, 6.0, 61)
    qs = np.repeat(robot.q_home[None, :], t.shape[0], axis=0)
    qs[:, robot.q_index("left_shoulder_pan_joint")] += np.linspace(0.0, 0.6, t.shape[0])
    new = JointTrajectory("dual_ur5e", t, qs, robot.joint_names, events, {}, None)
    q_now = qs[10].copy()  # the configuration of 1.0 s: before the re-plan's right hand holds the door
    free = episode.join(new, q_now, 2.0, world)  # closest configuration anywhere within the window
    assert free.meta["replan_join_time_s"] == pytest.approx(1.0)
    held = episode.join(new, q_now, 2.0, world, {"right": door})  # only where the right hand holds the door
    assert held.meta["replan_join_time_s"] > 1.0
    assert episode.holds_at(events, held.meta["replan_join_time_s"]) == {"right": door}
    with pytest.raises(RetargetError, match="never hold what they hold now"):
        episode.join(new, q_now, 2.0, world, {"left": door})  # the re-plan opens with the other hand


def test_the_contact_miss_of_a_replan_is_what_its_arm_branch_search_left(repo_root: Path) -> None:
    episode = _episode_module(repo_root)

    class _Traj:
        def __init__(self, report: dict[str, object] | None) -> None:
            self.meta = {} if report is None else {"arm_branches": report}

    assert episode.contact_miss(_Traj(None)) == 0.0  # every grasp and release within the trigger
    kept = {"kept": True, "contact_error_before_m": 0.3, "contact_error_after_m": 0.05}
    assert episode.contact_miss(_Traj(kept)) == pytest.approx(0.05)
    dropped = {"kept": False, "contact_error_before_m": 0.3, "contact_error_after_m": None}
    assert episode.contact_miss(_Traj(dropped)) == pytest.approx(0.3)


def test_the_reaimed_schedule_comes_first_and_the_replan_only_where_it_misses(repo_root: Path) -> None:
    episode = _episode_module(repo_root)

    class _Traj:
        def __init__(self, miss: float) -> None:
            report = {"kept": True, "contact_error_before_m": 0.3, "contact_error_after_m": miss}
            self.meta = {"arm_branches": report} if miss > 0.0 else {}

    def record() -> dict[str, object]:
        return {"replan_errors": [], "reaimed": 0, "reaim_compared": 0, "replans_full": 0}

    def never() -> _Traj:
        raise AssertionError("the full re-plan is not needed when the re-aimed grasp is within reach")

    def broken() -> _Traj:
        raise PlanningError("no schedule on the new layout")

    aimed, full = _Traj(0.0), _Traj(0.0)
    rec = record()
    assert episode._reaimed_or_replanned(lambda: aimed, never, rec) is aimed
    assert rec["reaimed"] == 1 and rec["reaim_compared"] == 0 and rec["replans_full"] == 0
    rec = record()  # the re-aimed grasp is out of reach and the re-plan reaches it
    assert episode._reaimed_or_replanned(lambda: _Traj(0.05), lambda: full, rec) is full
    assert rec["reaimed"] == 0 and rec["reaim_compared"] == 1 and rec["replans_full"] == 1
    rec = record()  # the re-plan misses more: the re-aimed one stays
    short = _Traj(0.04)
    assert episode._reaimed_or_replanned(lambda: short, lambda: _Traj(0.06), rec) is short
    rec = record()  # the re-plan fails: the re-aimed one stays, the error is kept
    assert episode._reaimed_or_replanned(lambda: short, broken, rec) is short
    assert rec["reaimed"] == 1 and "no schedule" in str(rec["replan_errors"])

    def unaimable() -> _Traj:
        raise RetargetError("the re-aimed grasp is off the robot's reach")

    rec = record()  # the re-aiming fails: the re-plan is taken
    assert episode._reaimed_or_replanned(unaimable, lambda: full, rec) is full
    with pytest.raises(PlanningError):  # neither gives a trajectory
        episode._reaimed_or_replanned(unaimable, broken, record())
    assert episode.REAIM_FIRST == {"dual_ur5e": True, "humanoid": False}
