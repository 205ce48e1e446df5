"""The planner's problem definition, training-data build, prior bank and ``hsi train planner``."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from hsi_planning.config import from_mapping, load_yaml
from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.implicit import predict_fields, to_unit_cube
from hsi_planning.implicit.data_build import DataBuildConfig, build_planner_data
from hsi_planning.implicit.data_scene import contact_pose, parts_to_open, render_opened, wrist_frame
from hsi_planning.implicit.planner_train import PlannerTrainConfig, load_planner
from hsi_planning.implicit.prior_bank import PriorBank, decode_array, encode_array, resample_demo
from hsi_planning.implicit.problem import (
    CONDITION_FEATURE_SCALE,
    PLANNER_FIELD_CONFIG,
    TEST_SEED_START,
    TRAIN_SEEDS,
    Condition,
    approach_axis_for,
    condition_vector,
    feature_dim,
    from_grid_local,
    local_feature,
    make_problem,
    move_label_to,
    problem_fields,
    problem_grid,
    to_grid_local,
    unit_points,
)
from hsi_planning.scene import load_scene_spec
from hsi_planning.trajectory import WristTrajectory

TARGET_CENTRE = np.array([0.8, 0.0, 0.93])


def _box_surface(centre: np.ndarray, half: float, step: float) -> np.ndarray:
    g = np.arange(-half, half + 1e-9, step)
    a, b = np.meshgrid(g, g, indexing="ij")
    a, b = a.ravel(), b.ravel()
    faces = []
    for axis in range(3):
        for sign in (-half, half):
            p = np.zeros((a.size, 3))
            p[:, axis] = sign
            p[:, (axis + 1) % 3] = a
            p[:, (axis + 2) % 3] = b
            faces.append(p)
    return np.concatenate(faces) + centre


def _cloud() -> tuple[np.ndarray, np.ndarray]:
    """Target (label 5) on a board (2) above a floor (0), a held mug (3), unlabelled noise (-1)."""
    rng = np.random.default_rng(0)
    target = _box_surface(TARGET_CENTRE, 0.03, 0.01)
    board = np.column_stack([rng.uniform(0.6, 1.0, 2000), rng.uniform(-0.4, 0.4, 2000), np.full(2000, 0.9)])
    floor = np.column_stack([rng.uniform(-0.5, 1.5, 2000), rng.uniform(-1, 1, 2000), np.zeros(2000)])
    held = _box_surface(np.array([0.3, 0.3, 1.0]), 0.03, 0.01)
    noise = rng.uniform([0.9, 0.3, 1.2], [1.0, 0.4, 1.3], (50, 3))
    points = np.concatenate([target, board, floor, held, noise])
    labels = np.concatenate(
        [np.full(len(target), 5), np.full(2000, 2), np.zeros(2000), np.full(len(held), 3), np.full(50, -1)]
    ).astype(np.int64)
    return points, labels


def _demo(segment: str = "approach") -> WristTrajectory:
    t = np.linspace(0.0, 0.8, 97)
    s = 0.5 - 0.5 * np.cos(np.pi * t / t[-1])
    start, contact = np.array([0.45, -0.05, 1.05]), TARGET_CENTRE + np.array([-0.08, 0.0, 0.0])
    pos = start + s[:, None] * (contact - start)
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (t.size, 1))
    if segment == "leave":
        pos = pos[::-1].copy()
    return WristTrajectory(t, pos, quat, segment=segment, contact_index=-1 if segment == "approach" else 0)


def _problem(**kw: object) -> object:
    points, labels = _cloud()
    args = {"hand": "right", "action": "grasp", "segment": "approach", "approach_axis": [-1.0, 0.0, 0.0]}
    args.update(kw)
    return make_problem(points, labels, [5], held_labels=[3], **args)  # type: ignore[arg-type]


# --- problem definition ---------------------------------------------------------------------------


def test_condition_vector_encoding_and_errors() -> None:
    c = condition_vector(0.93, "left", "place", "leave")
    assert c.dtype == np.float32 and c.shape == (4,)
    np.testing.assert_allclose(c, [0.93, -1.0, 1.0, 1.0], atol=1e-7)
    np.testing.assert_array_equal(condition_vector(1.2, "right", "grasp", "approach")[1:], [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(Condition(0.5, "left", "grasp", "leave").vector(), [0.5, -1.0, 0.0, 1.0])
    for bad in (("middle", "grasp", "approach"), ("left", "push", "approach"), ("left", "grasp", "retreat")):
        with pytest.raises(PlanningError, match="not valid"):
            condition_vector(1.0, *bad)  # type: ignore[arg-type]
    with pytest.raises(PlanningError, match="finite"):
        condition_vector(float("nan"), "left", "grasp", "approach")


def test_problem_obstacles_are_everything_but_target_and_held_object() -> None:
    p = _problem()
    assert p.target_labels == (5,)
    assert p.obstacle_labels == (-1, 0, 2)  # unlabelled points and the floor are obstacles; held mug is not
    np.testing.assert_allclose(p.target_centre, TARGET_CENTRE, atol=1e-9)
    assert p.goal_height == pytest.approx(0.93)
    np.testing.assert_allclose(p.condition_vector(), [0.93, 1.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(p.approach_axis, [-1.0, 0.0, 0.0])
    points, labels = _cloud()
    with pytest.raises(PlanningError, match="no point carries a target label"):
        make_problem(
            points, labels, [9], hand="left", action="grasp", segment="approach", approach_axis=[0, 0, 1]
        )
    with pytest.raises(PlanningError, match="non-zero"):
        make_problem(
            points, labels, [5], hand="left", action="grasp", segment="approach", approach_axis=[0, 0, 0]
        )
    with pytest.raises(PlanningError, match="hand"):
        make_problem(
            points, labels, [5], hand="both", action="grasp", segment="approach", approach_axis=[0, 0, 1]
        )  # type: ignore[arg-type]
    points[0, 0] = np.nan
    with pytest.raises(PlanningError, match="NaN"):
        make_problem(
            points, labels, [5], hand="left", action="grasp", segment="approach", approach_axis=[0, 0, 1]
        )


def test_problem_keeps_copies_of_caller_arrays() -> None:
    points, labels = _cloud()
    p = make_problem(
        points, labels, [5], hand="left", action="grasp", segment="approach", approach_axis=[0, 0, 1]
    )
    points[:] = 0.0
    labels[:] = 5
    assert p.obstacle_labels == (-1, 0, 2, 3)
    np.testing.assert_allclose(p.target_centre, TARGET_CENTRE, atol=1e-9)


def test_grid_centred_on_target_shifted_out_of_opening_and_independent_of_demo() -> None:
    p = _problem()
    grid = problem_grid(p)
    expected = TARGET_CENTRE + PLANNER_FIELD_CONFIG.approach_shift * np.array([-1.0, 0.0, 0.0])
    np.testing.assert_allclose(grid.centre, expected, atol=1e-9)
    assert grid.n == 33 and grid.size == pytest.approx(0.8)
    plain = problem_fields(p)
    with_demo = problem_fields(p, _demo())
    assert plain.grid == with_demo.grid == grid
    np.testing.assert_array_equal(plain.d_t, with_demo.d_t)
    np.testing.assert_array_equal(plain.d_o, with_demo.d_o)
    assert with_demo.d_toa is not None and with_demo.d_toa.max() > 1.0
    assert plain.d_t.max() <= 1.0 / PLANNER_FIELD_CONFIG.epsilon + 1e-4


def test_grid_local_frame_and_unit_points() -> None:
    grid = problem_grid(_problem())
    u = unit_points(grid)
    assert u.shape == (33**3, 3) and u.dtype == np.float32
    assert u.min() == pytest.approx(-1.0) and u.max() == pytest.approx(1.0)
    np.testing.assert_allclose(u, to_unit_cube(grid.points(), grid.centre, 0.4), atol=1e-6)
    np.testing.assert_allclose(u[0], [-1, -1, -1]) and np.testing.assert_allclose(u[-1], [1, 1, 1])
    x = np.array([[0.5, 0.1, 1.0], [0.8, -0.2, 0.7]])
    local = to_grid_local(x, grid)
    np.testing.assert_allclose(local, x - np.asarray(grid.centre))
    np.testing.assert_allclose(from_grid_local(local, grid), x)


def test_local_feature_layout_scaling_and_condition_separation() -> None:
    p = _problem()
    fs = problem_fields(p)
    c_right = condition_vector(0.93, "right", "grasp", "approach")
    f = local_feature(fs, c_right)
    assert f.shape == (feature_dim(),) == (2 * 6**3 + 4,) and f.dtype == np.float32
    field = f[:-4]
    assert field.min() >= 0.0 and field.max() <= 1.0 + 1e-6
    np.testing.assert_allclose(f[-4:], c_right * np.asarray(CONDITION_FEATURE_SCALE), rtol=1e-6)
    # block means: the mean over all blocks (weighted by block size) is the grid mean
    sizes = np.array([len(a) for a in np.array_split(np.arange(33), 6)], dtype=float)
    w = (sizes[:, None, None] * sizes[None, :, None] * sizes[None, None, :]).ravel() / 33**3
    assert float(w @ field[:216]) == pytest.approx(float(fs.d_o.mean() * fs.config.epsilon), rel=1e-4)
    assert float(w @ field[216:432]) == pytest.approx(float(fs.d_t.mean() * fs.config.epsilon), rel=1e-4)
    f_left = local_feature(fs, condition_vector(0.93, "left", "grasp", "approach"))
    assert np.linalg.norm(f_left - f) == pytest.approx(20.0, rel=1e-6)
    np.testing.assert_array_equal(local_feature(fs, c_right), f)
    with pytest.raises(PlanningError):
        local_feature(fs, np.zeros(3))


def test_move_label_to_places_held_object_bottom_centre() -> None:
    points, labels = _cloud()
    moved = move_label_to(points, labels, 3, [0.9, 0.2, 0.9])
    sel = labels == 3
    p = moved[sel]
    np.testing.assert_allclose(
        [*(0.5 * (p.min(0) + p.max(0)))[:2], p[:, 2].min()], [0.9, 0.2, 0.9], atol=1e-9
    )
    np.testing.assert_array_equal(moved[~sel], points[~sel])
    with pytest.raises(PlanningError):
        move_label_to(points, labels, 42, [0, 0, 0])


def test_approach_axis_rules(repo_root: Path) -> None:
    spec = load_scene_spec(repo_root / "sim/scenes/kitchen.yaml")
    np.testing.assert_allclose(approach_axis_for(spec, "mug1"), [-1.0, 0.0, 0.0], atol=1e-9)  # shelf
    np.testing.assert_allclose(approach_axis_for(spec, "bottle2"), [-1.0, 0.0, 0.0], atol=1e-9)  # cabinet
    np.testing.assert_allclose(approach_axis_for(spec, "can1"), [0.0, 0.0, 1.0])  # counter: from above
    np.testing.assert_allclose(approach_axis_for(spec, "mug2"), [0.0, 0.0, 1.0])  # drawer: from above
    pos, q = contact_pose(__import__("trimesh").creation.box([0.1, 0.1, 0.2]), np.array([-1.0, 0, 0]), 0.06)
    np.testing.assert_allclose(pos, [-0.11, 0.0, 0.0], atol=1e-9)
    from scipy.spatial.transform import Rotation

    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix()[:, 0], [1.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(wrist_frame(np.array([0.0, 0.0, -1.0]))), 1.0)


# --- seeds ------------------------------------------------------------------------------------------


def test_training_and_test_seed_ranges_are_disjoint(repo_root: Path) -> None:
    assert TRAIN_SEEDS.stop <= TEST_SEED_START
    assert set(range(TEST_SEED_START, TEST_SEED_START + 1000)).isdisjoint(TRAIN_SEEDS)
    cfg = from_mapping(PlannerTrainConfig, load_yaml(repo_root / "config/planner_train.yaml"))
    assert cfg.data.layout_seed in TRAIN_SEEDS
    with pytest.raises(ConfigError, match="training range"):
        DataBuildConfig(layout_seed=TEST_SEED_START)
    with pytest.raises(ConfigError, match="hands"):
        DataBuildConfig(hands=("left", "left"))


# --- scenes with opened containers -------------------------------------------------------------------


def test_render_opened_door_and_drawer_match_posed_meshes(repo_root: Path) -> None:
    spec = load_scene_spec(repo_root / "sim/scenes/kitchen.yaml")
    assert parts_to_open(spec, "bottle2") == ("cabinet1/door1",)
    assert parts_to_open(spec, "mug2") == ("drawer_unit1/drawer1",)
    assert parts_to_open(spec, "mug1") == ()
    rest = render_opened(spec, ())
    scene = render_opened(spec, ("cabinet1/door1", "drawer_unit1/drawer1"), drawer_fraction=0.6)
    for name in ("cabinet1/door1", "drawer_unit1/drawer1", "mug2"):
        pts = scene.cloud.points[scene.cloud.labels == scene.label_ids[name]]
        assert len(pts) > 20, name
        lo, hi = scene.meshes[name].bounds
        assert np.all(pts.min(0) >= lo - 0.02) and np.all(pts.max(0) <= hi + 0.02), name
        moved = np.abs(np.asarray(scene.meshes[name].bounds) - np.asarray(rest.meshes[name].bounds)).max()
        assert moved > 0.1, name  # the door swung open, the drawer and the mug in it slid out
    shift = scene.meshes["mug2"].bounds[0] - rest.meshes["mug2"].bounds[0]
    drawer = scene.meshes["drawer_unit1/drawer1"].bounds[0] - rest.meshes["drawer_unit1/drawer1"].bounds[0]
    np.testing.assert_allclose(shift, drawer, atol=1e-6)


# --- prior bank --------------------------------------------------------------------------------------


def test_resample_demo_keeps_endpoints_and_unit_quaternions() -> None:
    demo = _demo()
    t, pos, quat = resample_demo(demo, 60)
    assert t.shape == (60,) and pos.shape == (60, 3) and quat.shape == (60, 4)
    assert t[0] == 0.0 and t[-1] == pytest.approx(demo.duration)
    np.testing.assert_allclose(pos[[0, -1]], demo.position[[0, -1]], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-9)


def test_array_encoding_round_trip() -> None:
    a = np.random.default_rng(1).normal(size=(3, 4, 2)).astype(np.float32)
    doc = encode_array(a)
    assert isinstance(doc["data"], str) and doc["shape"] == [3, 4, 2]
    np.testing.assert_array_equal(decode_array(doc), a)
    with pytest.raises(PlanningError):
        decode_array({"dtype": "<f4"})


# --- data build ---------------------------------------------------------------------------------------


def _tiny_build_config() -> DataBuildConfig:
    return DataBuildConfig(
        scenes=("sim/scenes/kitchen.yaml",),
        reshape_groups=(False,),
        layouts_per_group=1,
        targets_per_layout=1,
        hands=("right",),
        actions=("grasp",),
        workers=1,
        bank_samples=30,
    )


def test_data_build_is_deterministic_and_consistent(repo_root: Path) -> None:
    a = build_planner_data(_tiny_build_config(), root=repo_root, progress=False)
    b = build_planner_data(_tiny_build_config(), root=repo_root, progress=False)
    ds, bank = a.dataset, a.bank
    assert len(ds) == len(bank) == 2 and ds.n_scenes == 1  # approach + leave of one target
    np.testing.assert_array_equal(ds.targets, b.dataset.targets)
    np.testing.assert_array_equal(bank.features, b.bank.features)
    np.testing.assert_array_equal(bank.position, b.bank.position)
    assert ds.channels == ("t", "o", "toa") and ds.n_points == 33**3
    assert np.isfinite(ds.targets).all() and ds.targets.min() >= 0.0 and ds.targets.max() <= 40.0 + 1e-3
    np.testing.assert_array_equal(ds.cond[:, 1:], [[1, 0, 0], [1, 0, 1]])  # right, grasp, approach / leave
    np.testing.assert_allclose(bank.cond, ds.cond)
    assert bank.features.shape == (2, feature_dim())
    assert bank.contact_index.tolist() == [29, 0]
    for k in range(2):
        # the demonstration's contact lies inside the grid, near the target, in the grid-local frame
        contact = bank.position[k, bank.contact_index[k]]
        assert np.abs(contact).max() < 0.4
        assert np.linalg.norm(contact - bank.target_centre[k]) < 0.25
        world = bank.trajectory(k)
        np.testing.assert_allclose(world.position, bank.position[k] + bank.grid_centre[k])
    assert re.fullmatch(r"kitchen/plain/s0/v000", bank.layout[0])
    restored = PriorBank.from_meta(bank.to_meta())
    np.testing.assert_allclose(restored.position, bank.position, atol=1e-6)
    np.testing.assert_array_equal(restored.scene_id, bank.scene_id)
    assert restored.target == bank.target


# --- the training command -----------------------------------------------------------------------------


def test_train_planner_quick_end_to_end(repo_root: Path, tmp_path: Path) -> None:
    from hsi_nodes.cli import train as train_cli

    doc = yaml.safe_load((repo_root / "config/planner_train.yaml").read_text())
    doc["cache_dir"] = str(tmp_path / "cache")
    cfg_path = tmp_path / "planner_train.yaml"
    cfg_path.write_text(yaml.safe_dump(doc))
    parser = argparse.ArgumentParser()
    train_cli.register(parser.add_subparsers(dest="command"))
    out = tmp_path / "planner.pt"
    args = parser.parse_args(
        [
            "train",
            "planner",
            "--config",
            str(cfg_path),
            "--out",
            str(out),
            "--quick",
            "--root",
            str(repo_root),
        ]
    )
    args.no_progress = True
    assert args.func(args) == 0
    assert out.is_file() and out.stat().st_size < 10 * 1024 * 1024
    assert any((tmp_path / "cache").glob("*.npz"))  # fields cached
    raw = torch.load(out, map_location="cpu", weights_only=True)
    assert raw["meta"]["kind"] == "hsi-implicit-planner"
    loaded = load_planner(out)
    ckpt, bank = loaded.checkpoint, loaded.bank
    assert len(bank) == 2 and ckpt.latents.shape == (1, 8)
    assert loaded.field_config == PLANNER_FIELD_CONFIG
    meta = ckpt.meta
    assert meta["dataset"]["samples"] == 2 and meta["train_seeds"] == [0, 9999]
    assert meta["train"]["total_seconds"] >= meta["train"]["train_seconds"] > 0.0
    assert np.isfinite(meta["train"]["final_losses"]["loss"])
    grid_u = unit_points(problem_grid(_problem()))
    pred = predict_fields(ckpt.model, ckpt.latents[0], bank.cond[0], grid_u[:500])
    assert set(pred) == {"t", "o", "toa"}
    for v in pred.values():
        assert v.shape == (500,) and np.isfinite(v).all() and v.min() >= 0.0


def test_train_config_rejects_bad_channels_and_keys() -> None:
    with pytest.raises(ConfigError, match="channels"):
        PlannerTrainConfig(channels=("o", "toa"))
    with pytest.raises(ConfigError, match="unknown"):
        from_mapping(PlannerTrainConfig, {"epochs": 3})
    ablation = from_mapping(PlannerTrainConfig, {"channels": ["t", "toa"]})
    assert ablation.train_config.model.channels == ("t", "toa")


def test_shipped_checkpoint_loads_with_bank(repo_root: Path) -> None:
    path = repo_root / "models/planner.pt"
    assert path.is_file(), "run `hsi train planner --config config/planner_train.yaml` to produce it"
    assert path.stat().st_size <= 10 * 1024 * 1024
    loaded = load_planner(path)
    bank, ckpt = loaded.bank, loaded.checkpoint
    assert bank.features.shape[1] == feature_dim()
    assert len(bank) >= 100 and ckpt.latents.shape[0] == int(bank.scene_id.max()) + 1
    seeds = {int(m.group(1)) for m in (re.search(r"/s(\d+)/", s) for s in bank.layout) if m}
    assert seeds and seeds <= set(TRAIN_SEEDS)
    families = {s.split("/")[0] for s in bank.layout}
    assert families == {"kitchen", "narrow_shelf", "cluttered_drawer"}
    assert {s.split("/")[1] for s in bank.layout} == {"plain", "reshape"}
