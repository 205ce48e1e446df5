"""Scene specs: loading, validation errors, round trips, labels, meshes and geometric helpers."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from hsi_planning.errors import SceneError
from hsi_planning.scene import (
    SceneSpec,
    container_of,
    handle_position,
    load_scene_spec,
    object_names,
    object_pose,
    opening_axis,
    scene_labels,
    scene_meshes,
    support_of,
    support_surfaces,
)
from hsi_planning.scene.objects import DEFAULTS, object_mass

SCENES = ("kitchen", "narrow_shelf", "cluttered_drawer")


def _spec(repo_root: Path, name: str) -> SceneSpec:
    return load_scene_spec(repo_root / "sim" / "scenes" / f"{name}.yaml")


def _doc(repo_root: Path) -> dict[str, Any]:
    return _spec(repo_root, "kitchen").to_dict()


@pytest.mark.parametrize("name", SCENES)
def test_scene_round_trips_through_dict_and_yaml(repo_root: Path, name: str) -> None:
    spec = _spec(repo_root, name)
    assert SceneSpec.from_dict(spec.to_dict()) == spec
    text = yaml.safe_dump(spec.to_dict(), sort_keys=False)
    assert SceneSpec.from_dict(yaml.safe_load(text)) == spec
    assert len(spec.cameras) >= 2
    assert all(c.resolution == (320, 240) for c in spec.cameras)


def test_kitchen_has_required_content(repo_root: Path) -> None:
    spec = _spec(repo_root, "kitchen")
    kinds = {f.kind for f in spec.furniture}
    assert {"cabinet", "drawer_unit", "shelf", "counter"} <= kinds
    assert len(spec.objects) >= 8
    assert {o.kind for o in spec.objects} == {"bottle", "mug", "bowl", "can", "box", "teapot"}
    shelf = spec.furniture_by_name("shelf1")
    assert len(shelf.boards) >= 2 and all(0.85 <= b <= 1.65 for b in shelf.boards)
    containers = {container_of(spec, n) for n in object_names(spec)}
    assert {"cabinet1", "drawer_unit1", "shelf1", "counter1"} <= containers
    assert spec.furniture_by_name("counter1").size[2] == pytest.approx(0.9)
    # furniture in front of the robot: fronts at x = 0.6 .. 1.0
    for f in spec.furniture:
        assert 0.55 <= f.pos[0] - f.size[1] / 2 <= 1.0


def test_narrow_shelf_hides_can_behind_bottle(repo_root: Path) -> None:
    spec = _spec(repo_root, "narrow_shelf")
    assert spec.furniture_by_name("shelf1").size[0] == pytest.approx(0.8 * 0.8)
    bottle, can = object_pose(spec, "bottle1"), object_pose(spec, "can1")
    axis = opening_axis(spec, "can1")
    assert np.allclose(axis, [-1.0, 0.0, 0.0])
    assert bottle[1, 3] == pytest.approx(can[1, 3], abs=1e-9)  # same lateral position
    assert float((can[:3, 3] - bottle[:3, 3]) @ -axis) > 0.1  # further in


def test_cluttered_drawer_objects_are_close(repo_root: Path) -> None:
    spec = _spec(repo_root, "cluttered_drawer")
    inside = [o.name for o in spec.objects if o.on == "drawer_unit1/drawer1"]
    assert len(inside) >= 5
    from hsi_planning.scene.validate import footprint, object_points, polygon_gap

    supports = support_surfaces(spec)
    from hsi_planning.scene.model import object_pose_on

    prints = {
        n: footprint(
            object_points(
                spec.object_by_name(n),
                object_pose_on(spec.object_by_name(n), supports["drawer_unit1/drawer1"]),
            )
        )
        for n in inside
    }
    nearest = [min(polygon_gap(prints[a], prints[b]) for b in inside if b != a) for a in inside]
    assert max(nearest) < 0.04 and min(nearest) >= 0.0


def _expect(doc: dict[str, Any], *fragments: str) -> None:
    with pytest.raises(SceneError) as info:
        SceneSpec.from_dict(doc)
    for fragment in fragments:
        assert fragment in str(info.value), str(info.value)


def test_unknown_keys_and_kinds_are_rejected(repo_root: Path) -> None:
    doc = _doc(repo_root)
    bad = copy.deepcopy(doc)
    bad["lights"] = []
    _expect(bad, "unknown key", "lights", "furniture")
    bad = copy.deepcopy(doc)
    bad["furniture"][0]["widht"] = 1.0
    _expect(bad, "shelf1", "widht", "size")
    bad = copy.deepcopy(doc)
    bad["furniture"][1]["kind"] = "sofa"
    _expect(bad, "counter1", "sofa", "cabinet")
    bad = copy.deepcopy(doc)
    bad["objects"][0]["kind"] = "banana"
    _expect(bad, "mug1", "banana", "teapot")


def test_bad_sizes_and_supports_are_rejected(repo_root: Path) -> None:
    doc = _doc(repo_root)
    bad = copy.deepcopy(doc)
    bad["furniture"][1]["size"] = [1.0, -0.6, 0.9]
    _expect(bad, "counter1", "positive")
    bad = copy.deepcopy(doc)
    bad["objects"][1]["size"] = [0.0, 0.05]
    _expect(bad, "bowl1", "positive")
    bad = copy.deepcopy(doc)
    bad["objects"][0]["on"] = "shelf1/board9"
    _expect(bad, "mug1", "shelf1/board9", "shelf1/board1")
    bad = copy.deepcopy(doc)
    bad["objects"][0]["xy"] = [0.0, 0.9]
    _expect(bad, "mug1", "sticks out", "shelf1/board1")
    bad = copy.deepcopy(doc)
    bad["objects"][3]["scale"] = 1.6  # can3 under the shelf top: 0.195 m > 0.182 m free
    _expect(bad, "can3", "free height")
    bad = copy.deepcopy(doc)
    bad["objects"][1]["name"] = "mug1"
    _expect(bad, "mug1", "twice")


def test_overlapping_objects_are_rejected(repo_root: Path) -> None:
    doc = _doc(repo_root)
    bad = copy.deepcopy(doc)
    can1 = next(o for o in bad["objects"] if o["name"] == "can1")
    can1["xy"] = [0.1, 0.34]  # into box1 on the counter
    _expect(bad, "can1", "box1", "overlaps")
    bad = copy.deepcopy(doc)
    bad["furniture"][1]["pos"] = [0.9, 0.8]  # counter into the shelf
    _expect(bad, "counter1", "shelf1", "overlaps")


def test_yaml_file_errors_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("name: x\nfurniture: [\n", encoding="utf-8")
    with pytest.raises(SceneError, match=r"broken\.yaml"):
        load_scene_spec(path)
    path.write_text("name: x\nfurniture:\n  - {name: c, kind: counter, pos: [1, 0], size: [1, 1, 1]}\n"
                    "objects:\n  - {name: m, kind: mug, on: nowhere}\n", encoding="utf-8")  # fmt: skip
    with pytest.raises(SceneError, match=r"broken\.yaml.*'m'.*nowhere"):
        load_scene_spec(path)


def test_labels_are_dense_deterministic_and_named_like_bodies(repo_root: Path) -> None:
    spec = _spec(repo_root, "kitchen")
    labels = scene_labels(spec)
    assert [lab.id for lab in labels] == list(range(len(labels)))
    assert labels.by_id(0).name == "floor" and labels.by_id(0).kind == "floor"
    assert scene_labels(_spec(repo_root, "kitchen")) == labels
    assert labels.by_name("cabinet1/door1").semantic_class == "cabinet_door"
    assert labels.by_name("cabinet1/door1").parent == "cabinet1"
    assert labels.by_name("drawer_unit1/drawer1").semantic_class == "drawer"
    assert labels.by_name("shelf1").semantic_class == "shelf"
    assert labels.by_name("counter1").semantic_class == "counter"
    assert labels.by_name("mug1").semantic_class == "mug" and labels.by_name("mug1").kind == "object"
    objects = [lab.name for lab in labels if lab.kind == "object"]
    assert objects == object_names(spec)
    with pytest.raises(SceneError, match="valid"):
        labels.by_name("sofa1")
    with pytest.raises(SceneError, match=r"valid: 0\.\."):
        labels.by_id(len(labels))


def test_meshes_rest_exactly_on_supports(repo_root: Path) -> None:
    spec = _spec(repo_root, "kitchen")
    meshes = scene_meshes(spec)
    assert set(meshes) == set(scene_labels(spec).names)
    assert meshes["floor"].bounds[1, 2] == pytest.approx(0.0)
    for name in object_names(spec):
        support = support_of(spec, name)
        bottom = meshes[name].bounds[0, 2]
        assert bottom == pytest.approx(support.top_z, abs=1e-9), name
        # the support body's mesh reaches exactly the surface height
        assert meshes[support.body].bounds[1, 2] >= support.top_z - 1e-9
    # a closed drawer's mesh lies inside the carcass footprint except its front and handle
    drawer = meshes["drawer_unit1/drawer1"].bounds
    carcass = meshes["drawer_unit1"].bounds
    assert drawer[1, 0] < carcass[1, 0] and drawer[0, 0] < carcass[0, 0]
    # object meshes are watertight compounds with the expected volume order
    assert meshes["box1"].volume > meshes["can1"].volume > 0.0


def test_masses_are_realistic(repo_root: Path) -> None:
    spec = _spec(repo_root, "kitchen")
    masses = {o.kind: object_mass(o) for o in spec.objects if o.mass is None and o.scale == 1.0}
    assert masses["bottle"] == pytest.approx(0.5)
    assert masses["mug"] == pytest.approx(0.3)
    assert masses["can"] == pytest.approx(0.35)
    assert masses["teapot"] == pytest.approx(0.8)
    assert 0.6 <= DEFAULTS["box"].mass <= 1.0


def test_opening_axes_and_handles(repo_root: Path) -> None:
    spec = _spec(repo_root, "kitchen")
    assert np.allclose(opening_axis(spec, "shelf1"), [-1.0, 0.0, 0.0])
    assert np.allclose(opening_axis(spec, "bottle2"), [-1.0, 0.0, 0.0])  # in cabinet1
    assert np.allclose(opening_axis(spec, "counter1"), [0.0, 0.0, 1.0])
    assert np.allclose(opening_axis(spec, "drawer_unit1/drawer1"), [-1.0, 0.0, 0.0])
    rotated = dict(_doc(repo_root))
    rotated["furniture"] = [dict(f) for f in rotated["furniture"]]
    rotated["furniture"][0].update(yaw=90.0, pos=[0.5, 2.0])
    turned = SceneSpec.from_dict(rotated)
    assert np.allclose(opening_axis(turned, "mug1"), [0.0, -1.0, 0.0], atol=1e-12)
    door = handle_position(spec, "cabinet1/door1")
    cabinet = spec.furniture_by_name("cabinet1")
    assert door[0] < cabinet.pos[0] - cabinet.size[1] / 2 - 0.02  # handle stands off the front
    assert 0.5 < door[2] < cabinet.size[2]
    with pytest.raises(SceneError, match="no handle"):
        handle_position(spec, "shelf1")
