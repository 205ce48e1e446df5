"""Scenes in MuJoCo: compile, settle, articulate; MJCF geoms agree with the meshes; CLI build."""

from __future__ import annotations

import argparse
from pathlib import Path

import mujoco
import numpy as np
import pytest
import trimesh

from hsi_nodes.cli import scene as scene_cli
from hsi_planning.scene import (
    build_mjcf,
    handle_position,
    load_scene_spec,
    object_names,
    opening_axis,
    scene_labels,
    scene_meshes,
    write_mjcf,
)

SCENES = ("kitchen", "narrow_shelf", "cluttered_drawer")


def _model(repo_root: Path, name: str) -> tuple[mujoco.MjModel, mujoco.MjData]:
    spec = load_scene_spec(repo_root / "sim" / "scenes" / f"{name}.yaml")
    model = mujoco.MjModel.from_xml_string(build_mjcf(spec))
    return model, mujoco.MjData(model)


@pytest.mark.parametrize("name", SCENES)
def test_scene_settles_without_warnings(repo_root: Path, name: str) -> None:
    spec = load_scene_spec(repo_root / "sim" / "scenes" / f"{name}.yaml")
    model = mujoco.MjModel.from_xml_string(build_mjcf(spec))
    data = mujoco.MjData(model)
    assert model.opt.timestep == pytest.approx(0.002)
    mujoco.mj_forward(model, data)
    start = {n: data.body(n).xpos.copy() for n in object_names(spec)}
    for _ in range(round(2.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    moved = {n: float(np.linalg.norm(data.body(n).xpos - p)) for n, p in start.items()}
    assert max(moved.values()) < 0.002, moved
    assert data.ncon > 0  # objects rest on contacts, not in mid-air
    assert all(data.warning[i].number == 0 for i in range(len(data.warning)))
    # every label is a body, every camera exists
    for label in scene_labels(spec):
        assert model.body(label.name).id >= 1
    assert [model.camera(i).name for i in range(model.ncam)] == [c.name for c in spec.cameras]
    assert tuple(model.cam_resolution[0]) == (320, 240)


def _push(
    model: mujoco.MjModel, data: mujoco.MjData, body: str, point_w: np.ndarray, force_w: np.ndarray
) -> None:
    """Pull for 0.6 s at a point fixed on ``body`` (given in the world at rest) with a world force."""
    bid = model.body(body).id
    mujoco.mj_forward(model, data)
    local = data.xmat[bid].reshape(3, 3).T @ (point_w - data.xpos[bid])
    for _ in range(300):
        data.qfrc_applied[:] = 0.0
        point = data.xpos[bid] + data.xmat[bid].reshape(3, 3) @ local
        mujoco.mj_applyFT(model, data, force_w, np.zeros(3), point, bid, data.qfrc_applied)
        mujoco.mj_step(model, data)


def test_door_and_drawer_are_articulated(repo_root: Path) -> None:
    spec = load_scene_spec(repo_root / "sim" / "scenes" / "kitchen.yaml")
    model = mujoco.MjModel.from_xml_string(build_mjcf(spec))
    door = model.joint("cabinet1/door1")
    assert door.type[0] == mujoco.mjtJoint.mjJNT_HINGE
    assert door.range[1] == pytest.approx(np.radians(110.0))
    data = mujoco.MjData(model)
    out = opening_axis(spec, "cabinet1")
    _push(model, data, "cabinet1/door1", handle_position(spec, "cabinet1/door1"), 15.0 * out)
    assert data.qpos[door.qposadr[0]] > 0.3  # swung open [rad]

    drawer = model.joint("drawer_unit1/drawer1")
    assert drawer.type[0] == mujoco.mjtJoint.mjJNT_SLIDE
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mug0 = data.body("mug2").xpos.copy()
    _push(model, data, "drawer_unit1/drawer1", handle_position(spec, "drawer_unit1/drawer1"), 8.0 * out)
    opened = data.qpos[drawer.qposadr[0]]
    assert 0.05 < opened < drawer.range[1]
    # the mug inside rides out with the drawer
    assert float((data.body("mug2").xpos - mug0) @ out) == pytest.approx(opened, abs=0.02)
    assert all(data.warning[i].number == 0 for i in range(len(data.warning)))


def test_rendered_points_lie_on_their_label_mesh(repo_root: Path) -> None:
    spec = load_scene_spec(repo_root / "sim" / "scenes" / "kitchen.yaml")
    model = mujoco.MjModel.from_xml_string(build_mjcf(spec))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    meshes = scene_meshes(spec)
    cam = spec.cameras[0]
    w, h = 160, 120
    with mujoco.Renderer(model, h, w) as renderer:
        renderer.enable_depth_rendering()
        renderer.update_scene(data, camera=cam.name)
        depth = renderer.render().copy()
        renderer.disable_depth_rendering()
        renderer.enable_segmentation_rendering()
        renderer.update_scene(data, camera=cam.name)
        seg = renderer.render()[..., 0].copy()
    cid = model.camera(cam.name).id
    f = 0.5 * h / np.tan(np.radians(model.cam_fovy[cid]) / 2)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    pts_cam = np.stack([(u - w / 2) / f * depth, -(v - h / 2) / f * depth, -depth], axis=-1).reshape(-1, 3)
    pts = pts_cam @ data.cam_xmat[cid].reshape(3, 3).T + data.cam_xpos[cid]
    geom = seg.reshape(-1)
    ok = geom >= 0
    bodies = model.geom_bodyid[geom[ok]]
    pts = pts[ok]
    rng = np.random.default_rng(0)
    pick = rng.choice(len(pts), size=min(3000, len(pts)), replace=False)
    near, seen = 0, set()
    for i in pick:
        name = model.body(bodies[i]).name
        seen.add(name)
        _, dist, _ = trimesh.proximity.closest_point(meshes[name], pts[i : i + 1])
        near += int(dist[0] < 0.01)
    assert near / len(pick) >= 0.99
    assert {"shelf1", "counter1", "mug1"} <= seen


def test_cli_build_writes_a_loadable_model(repo_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "scene.xml"
    args = argparse.Namespace(spec=repo_root / "sim" / "scenes" / "kitchen.yaml", out=out)
    assert scene_cli.cmd_build(args) == 0
    model = mujoco.MjModel.from_xml_path(str(out))
    assert (
        model.body("cabinet1/door1").id > 0
        and model.nbody == len(scene_labels(load_scene_spec(args.spec))) + 1
    )
    parser = argparse.ArgumentParser()
    scene_cli.register(parser.add_subparsers(dest="command"))
    ns = parser.parse_args(["scene", "build", str(args.spec), "--out", str(tmp_path / "b.xml")])
    assert ns.func(ns) == 0 and (tmp_path / "b.xml").is_file()
    spec = load_scene_spec(args.spec)
    path = write_mjcf(spec, tmp_path / "sub" / "w.xml")
    assert mujoco.MjModel.from_xml_path(str(path)).nbody == model.nbody
