"""Layout generator: determinism, variation ranges, validity in MuJoCo, reachability, CLI."""

from __future__ import annotations

import argparse
import copy
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

from hsi_nodes.cli import scene as scene_cli
from hsi_planning.config import from_mapping
from hsi_planning.errors import ConfigError, SceneError
from hsi_planning.scene import SceneSpec, build_mjcf, load_scene_spec, object_names
from hsi_planning.scene.layout import LayoutConfig, generate_layouts
from hsi_planning.scene.reach import ReachConfig, target_reachable


def _spec(repo_root: Path, name: str) -> SceneSpec:
    return load_scene_spec(repo_root / "sim" / "scenes" / f"{name}.yaml")


@pytest.fixture(scope="module")
def kitchen_50(repo_root: Path) -> tuple[SceneSpec, list[SceneSpec]]:
    spec = _spec(repo_root, "kitchen")
    return spec, generate_layouts(spec, 50, seed=3, config=LayoutConfig(reshape=True, target="can2"))


def test_same_seed_gives_identical_layouts(repo_root: Path) -> None:
    spec = _spec(repo_root, "cluttered_drawer")
    config = LayoutConfig(reshape=True)
    first = generate_layouts(spec, 4, seed=11, config=config)
    assert generate_layouts(spec, 4, seed=11, config=config) == first
    assert [s.to_dict() for s in generate_layouts(spec, 2, seed=11, config=config)] == [
        s.to_dict() for s in first[:2]
    ]
    other = generate_layouts(spec, 4, seed=12, config=config)
    assert [s.objects for s in other] != [s.objects for s in first]
    assert len({s.name for s in first}) == 4


def test_ranges_are_respected_and_covered(kitchen_50: tuple[SceneSpec, list[SceneSpec]]) -> None:
    spec, layouts = kitchen_50
    shifts, yaws, scales, factors = [], [], [], []
    for layout in layouts:
        meta = layout.meta["layout"]
        assert meta["source"] == "kitchen" and meta["reshape"] is True and meta["target"] == "can2"
        for name, var in meta["objects"].items():
            if name == "can2":
                assert var == {"shift": [0.0, 0.0], "yaw": 0.0, "scale": 1.0}
                continue
            shifts += var["shift"]
            yaws.append(var["yaw"])
            scales.append(var["scale"])
            # the spec really carries the variation
            assert layout.object_by_name(name).scale == pytest.approx(
                spec.object_by_name(name).scale * var["scale"]
            )
            assert layout.object_by_name(name).yaw == pytest.approx(
                spec.object_by_name(name).yaw + var["yaw"]
            )
        for name, var in meta["furniture"].items():
            factors.append([var["width"], var["depth"], var["height"]])
            before, after = spec.furniture_by_name(name), layout.furniture_by_name(name)
            ratio = np.divide(after.size, before.size)
            assert ratio == pytest.approx([var["width"], var["depth"], var["height"]])
            # reshaped about the front face: the front stays at the same depth
            assert after.pos[0] - after.size[1] / 2 == pytest.approx(before.pos[0] - before.size[1] / 2)
        assert set(meta["furniture"]) == {"shelf1", "cabinet1", "drawer_unit1"}  # containers only
    shifts_a, yaws_a, scales_a, fac = map(np.asarray, (shifts, yaws, scales, factors))
    assert np.abs(shifts_a).max() <= 0.05 and shifts_a.min() < -0.045 and shifts_a.max() > 0.045
    assert np.abs(yaws_a).max() <= 90.0 and yaws_a.min() < -80.0 and yaws_a.max() > 80.0
    assert (
        scales_a.min() >= 0.8 and scales_a.max() <= 1.25 and scales_a.min() < 0.83 and scales_a.max() > 1.22
    )
    assert fac.min() >= 0.7 and fac.max() <= 1.5
    assert np.all(fac.min(axis=0) < 0.76) and np.all(fac.max(axis=0) > 1.42)


def test_without_reshape_containers_are_unchanged(repo_root: Path) -> None:
    spec = _spec(repo_root, "kitchen")
    for layout in generate_layouts(spec, 5, seed=0, config=LayoutConfig(target="bottle1")):
        assert layout.furniture == spec.furniture
        assert layout.meta["layout"]["furniture"] == {}
        assert layout.object_by_name("bottle1") == spec.object_by_name("bottle1")
        assert layout.objects != spec.objects


def test_targets_stay_reachable(kitchen_50: tuple[SceneSpec, list[SceneSpec]], repo_root: Path) -> None:
    _, layouts = kitchen_50
    assert all(target_reachable(layout, "can2") for layout in layouts)
    hidden = generate_layouts(
        _spec(repo_root, "narrow_shelf"), 10, seed=5, config=LayoutConfig(target="can1")
    )
    assert all(target_reachable(layout, "can1") for layout in hidden)


def _walled_doc(repo_root: Path) -> dict[str, Any]:
    doc = _spec(repo_root, "narrow_shelf").to_dict()
    for o in doc["objects"]:
        if o["name"] == "bottle1":
            o["xy"] = [-0.03, 0.0]
        if o["name"] == "can1":
            o["xy"] = [0.12, 0.0]
    doc["objects"].append({"name": "can9", "kind": "can", "on": "shelf1/board1", "xy": [-0.12, 0.0]})
    return doc


def test_reachability_rejects_enclosed_targets(repo_root: Path) -> None:
    assert target_reachable(_spec(repo_root, "narrow_shelf"), "can1")  # the bottle in front can go first
    walled = SceneSpec.from_dict(_walled_doc(repo_root))
    assert not target_reachable(walled, "can1")  # two objects deep
    assert target_reachable(walled, "can9")
    with pytest.raises(SceneError, match="not reachable"):
        generate_layouts(walled, 2, seed=0, config=LayoutConfig(target="can1"))
    # top access: a can boxed in on the counter
    doc: dict[str, Any] = {
        "name": "boxed",
        "furniture": [{"name": "counter1", "kind": "counter", "pos": [0.9, 0.0], "size": [1.0, 0.6, 0.9]}],
        "objects": [{"name": "can1", "kind": "can", "on": "counter1", "xy": [0.0, 0.0]}],
    }
    for gap, expected in ((0.005, False), (0.03, True)):
        ring = copy.deepcopy(doc)
        off = 0.033 + gap + 0.03
        for k, (x, y) in enumerate(((off, 0.0), (-off, 0.0), (0.0, off), (0.0, -off))):
            ring["objects"].append({"name": f"b{k}", "kind": "box", "on": "counter1", "xy": [x, y],
                                    "size": [0.06, 0.06, 0.1]})  # fmt: skip
        assert target_reachable(SceneSpec.from_dict(ring), "can1", ReachConfig()) is expected
    tall = copy.deepcopy(_spec(repo_root, "kitchen").to_dict())
    next(o for o in tall["objects"] if o["name"] == "can3")["scale"] = 1.45  # 0.177 m under 0.182 m
    assert not target_reachable(SceneSpec.from_dict(tall), "can3")


@pytest.mark.parametrize("name", ["kitchen", "cluttered_drawer"])
def test_layouts_are_collision_free_and_settle(repo_root: Path, name: str) -> None:
    spec = _spec(repo_root, name)
    for layout in generate_layouts(spec, 3, seed=21, config=LayoutConfig(reshape=True)):
        model = mujoco.MjModel.from_xml_string(build_mjcf(layout))
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        objects = {model.body(n).id for n in object_names(layout)}
        for c in data.contact[: data.ncon]:
            b1, b2 = model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]
            assert c.dist > -1e-4 or not (b1 in objects and b2 in objects), (layout.name, c.dist)
        start = {n: data.body(n).xpos.copy() for n in object_names(layout)}
        for _ in range(250):
            mujoco.mj_step(model, data)
        moved = max(float(np.linalg.norm(data.body(n).xpos - p)) for n, p in start.items())
        assert moved < 0.002, (layout.name, moved)
        assert all(data.warning[i].number == 0 for i in range(len(data.warning)))


def test_layout_config_validates() -> None:
    assert from_mapping(LayoutConfig, {"reshape": True, "shift": 0.03}).shift == 0.03
    with pytest.raises(ConfigError, match="scale_min"):
        LayoutConfig(scale_min=1.3)
    with pytest.raises(ConfigError, match="valid"):
        from_mapping(LayoutConfig, {"shfit": 0.1})


def test_unknown_target_and_bad_count(repo_root: Path) -> None:
    spec = _spec(repo_root, "kitchen")
    with pytest.raises(SceneError, match="no object 'ghost'"):
        generate_layouts(spec, 1, seed=0, config=LayoutConfig(target="ghost"))
    with pytest.raises(SceneError, match="count"):
        generate_layouts(spec, -1, seed=0)


def test_cli_generate_writes_specs_and_models(repo_root: Path, tmp_path: Path) -> None:
    spec_path = repo_root / "sim" / "scenes" / "narrow_shelf.yaml"
    args = argparse.Namespace(
        spec=spec_path, count=3, seed=4, out=tmp_path / "gen", reshape=True, target="can1", mjcf=True
    )
    assert scene_cli.cmd_generate(args) == 0
    expected = generate_layouts(
        load_scene_spec(spec_path), 3, seed=4, config=LayoutConfig(reshape=True, target="can1")
    )
    for layout in expected:
        assert load_scene_spec(tmp_path / "gen" / f"{layout.name}.yaml") == layout
        model = mujoco.MjModel.from_xml_path(str(tmp_path / "gen" / f"{layout.name}.xml"))
        assert model.body("can1").id > 0


def test_drawer_is_pulled_as_far_as_the_object_needs(repo_root: Path) -> None:
    from hsi_planning.implicit.data_scene import render_opened
    from hsi_planning.scene import exposing_fraction

    spec = _spec(repo_root, "cluttered_drawer")
    front = 0.875 - 0.55 / 2  # drawer_unit1's carcass front [m]
    front_can, mid_box = (exposing_fraction(spec, n, 0.01, 1.0) for n in ("can1", "box1"))
    assert 0.01 < front_can < mid_box < 1.0
    assert exposing_fraction(spec, "bowl1", 0.01, 1.0) == 1.0  # at the back: never all out
    for name, fraction in (("can1", front_can), ("box1", mid_box)):  # real slide joint in MuJoCo
        opened = render_opened(spec, ["drawer_unit1/drawer1"], drawer_fraction=fraction)
        back_edge = float(np.asarray(opened.meshes[name].bounds)[1, 0])
        assert back_edge == pytest.approx(front - 0.05, abs=2e-3)  # out from under the carcass, 5 cm spare
    assert exposing_fraction(spec, "can1", 0.6, 0.9) == 0.6  # clipped to the range
    assert exposing_fraction(spec, "bowl1", 0.1, 0.5) == 0.5
    assert exposing_fraction(spec, "mug2", 0.6, 0.9) == 0.6  # on the counter: nothing to pull
    with pytest.raises(ConfigError, match="least"):
        exposing_fraction(spec, "can1", 0.9, 0.6)
    with pytest.raises(SceneError):
        exposing_fraction(spec, "nothing", 0.6, 0.9)
