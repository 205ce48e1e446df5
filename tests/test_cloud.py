"""Labelled clouds: container, PLY files, voxel downsampling, rendering from MuJoCo cameras."""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hsi_planning.errors import CloudError, ConfigError
from hsi_planning.perception import (
    CameraView,
    CloudConfig,
    CloudRenderer,
    LabelledCloud,
    read_ply,
    render_cloud,
    render_rgb,
    voxel_downsample,
    write_ply,
)

# A small world with the scene conventions: one body per label, floor geom of the world body, two cameras.
SMALL_XML = """<mujoco><worldbody><light pos="0 0 3"/>
<geom name="floor" type="plane" size="3 3 .1"/>
<body name="table" pos="0.8 0 0.35"><geom type="box" size="0.3 0.4 0.35"/></body>
<body name="mug1" pos="0.8 0.1 0.75"><geom type="cylinder" size="0.04 0.05"/>
  <body name="mug1/handle_part"><geom type="box" size="0.01 0.02 0.03" pos="0 0.05 0"/></body></body>
<body name="ball1" pos="0.7 -0.15 0.76"><freejoint/><geom type="sphere" size="0.06"/></body>
<body name="robot_link" pos="0 0 0.5"><geom type="capsule" size="0.05 0.2"/></body>
<camera name="cam_left" pos="-0.2 0.8 1.7" mode="targetbody" target="table"/>
<camera name="cam_right" pos="-0.2 -0.8 1.7" mode="targetbody" target="table"/>
</worldbody></mujoco>"""
SMALL_LABELS = {"floor": 0, "table": 1, "mug1": 2, "ball1": 3}


def _small_world() -> tuple[Any, Any]:
    import mujoco

    model = mujoco.MjModel.from_xml_string(SMALL_XML)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def _analytic_error(cloud: LabelledCloud) -> dict[int, float]:
    """Max distance [m] of each label's points to the analytic surface of its body."""
    p = cloud.points.astype(np.float64)
    out = {}
    out[0] = float(np.abs(p[cloud.labels == 0, 2]).max())
    q = np.abs(p[cloud.labels == 1] - [0.8, 0, 0.35]) - [0.3, 0.4, 0.35]
    out[1] = float(np.abs(q.max(axis=1)).max())
    b = p[cloud.labels == 3]
    out[3] = float(np.abs(np.linalg.norm(b - [0.7, -0.15, 0.76], axis=1) - 0.06).max())
    return out


def _cloud(n: int = 50, seed: int = 0, dtype: type = np.float32) -> LabelledCloud:
    rng = np.random.default_rng(seed)
    return LabelledCloud(
        rng.normal(size=(n, 3)).astype(dtype), rng.integers(-1, 5, n), {0: "floor", 3: "mug1"}, {3: "mug"}
    )


# -- container -----------------------------------------------------------------------------------
def test_cloud_copies_inputs_and_is_read_only() -> None:
    pts = np.zeros((4, 3))
    lab = np.array([0, 1, 1, -1])
    cloud = LabelledCloud(pts, lab, {1: "mug1"})
    pts[0, 0] = 9.0
    lab[0] = 7
    assert cloud.points[0, 0] == 0.0 and cloud.labels[0] == 0
    assert cloud.labels.dtype == np.int32 and len(cloud) == 4
    with pytest.raises(ValueError):
        cloud.points[0, 0] = 1.0
    assert cloud.mask("mug1").tolist() == [False, True, True, False]
    assert cloud.select(cloud.labels >= 0).labels.tolist() == [0, 1, 1]
    assert (cloud.without_labels().labels == -1).all()
    with pytest.raises(CloudError, match="known"):
        cloud.label_id("bowl1")


@pytest.mark.parametrize(
    ("points", "labels", "match"),
    [
        (np.zeros((3, 2)), np.zeros(3, int), "shape"),
        (np.zeros((3, 3)), np.zeros(2, int), "labels must have shape"),
        (np.array([[0, 0, np.nan]] * 2), np.zeros(2, int), "finite"),
        (np.zeros((2, 3)), np.zeros(2), "integers"),
        (np.array([["a", "b", "c"]]), np.zeros(1, int), "real numbers"),
        (np.zeros((1, 3)), np.array([2**40]), "int32"),
    ],
)
def test_cloud_rejects_bad_input(points: np.ndarray, labels: np.ndarray, match: str) -> None:
    with pytest.raises(CloudError, match=match):
        LabelledCloud(points, labels)


# -- PLY -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["binary", "ascii"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_ply_round_trip(tmp_path: Path, fmt: str, dtype: type) -> None:
    cloud = _cloud(dtype=dtype)
    path = write_ply(tmp_path / "c.ply", cloud, fmt=fmt)  # type: ignore[arg-type]
    back = read_ply(path)
    assert back.points.dtype == dtype
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_array_equal(back.labels, cloud.labels)
    assert back.label_names == cloud.label_names and back.label_classes == cloud.label_classes
    header = path.read_bytes().split(b"end_header")[0].decode()
    assert "property int label" in header
    assert ("binary_little_endian" in header) == (fmt == "binary")


def test_ply_reads_foreign_files_and_open3d_reads_ours(tmp_path: Path) -> None:
    import open3d as o3d

    cloud = _cloud(20, seed=1)
    o3d_pts = o3d.io.read_point_cloud(str(write_ply(tmp_path / "ours.ply", cloud)))
    np.testing.assert_allclose(np.asarray(o3d_pts.points), cloud.points, atol=1e-6)
    # A big-endian file with extra properties and no labels, and a leading face-less element.
    body = np.array(
        [(1.0, 2.0, 3.0, 7), (4.0, 5.0, 6.0, 8)],
        dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("i", ">u1")],
    )
    header = "ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
    header += "property double z\nproperty uchar i\nelement face 0\n"
    header += "property list uchar int vertex_indices\nend_header\n"
    (tmp_path / "be.ply").write_bytes(header.encode() + body.tobytes())
    back = read_ply(tmp_path / "be.ply")
    np.testing.assert_array_equal(back.points, [[1, 2, 3], [4, 5, 6]])
    assert back.labels.tolist() == [-1, -1]


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (b"hello\n", "not a PLY"),
        (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n", "x, y, z"),
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
         b"property float z\nend_header\n\x00\x00", "truncated"),
        (b"ply\nformat weird 1.0\nelement vertex 0\nend_header\n", "unsupported"),
        (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
         b"end_header\n1 2 3\n4 5\n", "vertex"),
        (b"ply\nformat ascii 1.0\nelement face 1\nend_header\n", "no 'vertex'"),
    ],
)  # fmt: skip
def test_ply_rejects_malformed_files(tmp_path: Path, content: bytes, match: str) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(CloudError, match=match):
        read_ply(path)
    with pytest.raises(CloudError, match="no such"):
        read_ply(tmp_path / "missing.ply")


# -- voxel downsampling --------------------------------------------------------------------------
def test_voxel_downsample_majority_label_and_centroid_match_brute_force() -> None:
    rng = np.random.default_rng(3)
    pts = rng.uniform(0.0, 0.1, size=(3000, 3))
    labels = rng.integers(-1, 3, size=3000)
    size = 0.02
    out = voxel_downsample(LabelledCloud(pts, labels), size)
    cells = np.floor((pts - pts.min(axis=0)) / size).astype(int)
    groups: dict[tuple[int, ...], list[int]] = {}
    for i, c in enumerate(map(tuple, cells)):
        groups.setdefault(c, []).append(i)
    assert len(out) == len(groups)
    expected = {}
    for members in groups.values():
        counts = Counter(int(labels[i]) for i in members)
        best = max(counts.values())
        lab = min(k for k, v in counts.items() if v == best)
        sel = [i for i in members if labels[i] == lab]
        expected[tuple(np.round(pts[sel].mean(axis=0), 9))] = lab
    got = {tuple(np.round(p, 9)): int(lab) for p, lab in zip(out.points, out.labels, strict=True)}
    assert got == expected
    with pytest.raises(CloudError, match="voxel_size"):
        voxel_downsample(out, 0.0)


# -- rendering -----------------------------------------------------------------------------------
def test_config_validation() -> None:
    with pytest.raises(ConfigError):
        CloudConfig(width=0)
    with pytest.raises(ConfigError):
        CloudConfig(min_depth=2.0, max_depth=1.0)
    with pytest.raises(ConfigError):
        CloudConfig(cameras=("a", "a"))
    with pytest.raises(ConfigError):
        CloudConfig(voxel_size=-0.1)


def test_render_small_world_is_accurate_and_labelled() -> None:
    model, data = _small_world()
    with CloudRenderer(model, SMALL_LABELS) as renderer:
        raw = renderer.render_cloud(data, CloudConfig(voxel_size=0.0))
        fused = renderer.render_cloud(data, CloudConfig(voxel_size=0.01))
        one = renderer.render_cloud(data, CloudConfig(cameras=("cam_left",), voxel_size=0.0))
        view = renderer.render_view(data, "cam_right", keep_unlabelled=True)
        with pytest.raises(CloudError, match="cam_left"):
            renderer.render_view(data, "nope")
    # Every pixel of the two views shows a geom; back-projection lands on the analytic surfaces.
    assert set(raw.present_labels().tolist()) == {0, 1, 2, 3}  # robot_link dropped: not in the mapping
    assert len(raw) > 1.5 * len(one) and len(fused) < len(raw)
    for label, err in _analytic_error(raw).items():
        assert err < 2e-3, (label, err)  # sphere/cylinder tessellation < 1 mm; depth error ~1e-5 m
    for label, err in _analytic_error(fused).items():
        assert err < 5e-3, (label, err)
    # The handle body inherits its mapped ancestor's label; an unmapped body gives -1 when kept.
    handle = raw.points[(raw.labels == 2) & (raw.points[:, 1] > 0.1 + 0.04 + 1e-3)]
    assert len(handle) > 0
    assert (view.label == -1).any()
    assert raw.label_names == {0: "floor", 1: "table", 2: "mug1", 3: "ball1"}


def test_render_follows_the_simulation_state() -> None:
    import mujoco

    model, data = _small_world()
    raw = CloudConfig(voxel_size=0.0)
    with CloudRenderer(model, SMALL_LABELS) as renderer:
        before = renderer.render_cloud(data, raw)
        data.qpos[:3] += [0.0, -0.1, 0.0]  # slide the free ball 10 cm towards -y
        mujoco.mj_forward(model, data)
        after = renderer.render_cloud(data, raw)
    for cloud, centre in ((before, [0.7, -0.15, 0.76]), (after, [0.7, -0.25, 0.76])):
        ball = cloud.points[cloud.mask("ball1")]
        assert len(ball) > 100
        assert np.abs(np.linalg.norm(ball - centre, axis=1) - 0.06).max() < 2e-3


def test_render_rgb_and_one_shot_helpers() -> None:
    model, data = _small_world()
    img = render_rgb(model, data, "cam_left", 160, 120)
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8
    assert img.std() > 5.0  # not a blank image
    cloud = render_cloud(model, data, CloudConfig(width=160, height=120))
    assert set(cloud.present_labels().tolist()) == {1, 2, 3, 4, 5}  # default: body ids of named bodies
    assert cloud.label_names is not None and cloud.label_names[5] == "robot_link"
    with CloudRenderer(model) as renderer, pytest.raises(CloudError, match="offscreen buffer"):
        renderer.render_rgb(data, "cam_left", 4000, 3000)
    with pytest.raises(CloudError, match="after close"):
        renderer.render_rgb(data, "cam_left")


# -- the kitchen scene (acceptance) --------------------------------------------------------------
#: An object counts as clearly visible when one camera shows at least this much of its surface
#: [m^2] (fronto-parallel pixel footprint, a lower bound of the true area). A surface of area A
#: crosses at least A / (sqrt(2) s^2) voxels of edge s (sqrt(2) s^2 is the largest planar section of
#: a cube), so 75 cm^2 at s = 1 cm crosses >= 53 voxels: such an object must get >= 50 points.
CLEARLY_VISIBLE_AREA = 75e-4

#: (scene spec, label table, fused cloud, per-camera views)
Kitchen = tuple[Any, Any, LabelledCloud, list[CameraView]]


@pytest.fixture(scope="module")
def kitchen(repo_root: Path) -> Kitchen:
    from hsi_planning.perception import scene_renderer
    from hsi_planning.scene import load_scene_spec, scene_labels

    spec = load_scene_spec(repo_root / "sim" / "scenes" / "kitchen.yaml")
    _, data, renderer = scene_renderer(spec)
    with renderer:
        cloud = renderer.render_cloud(data, CloudConfig())
        views = [renderer.render_view(data, cam) for cam in renderer.camera_names()]
    return spec, scene_labels(spec), cloud, views


def test_kitchen_points_lie_on_the_mesh_of_their_label(kitchen: Kitchen) -> None:
    import open3d as o3d

    from hsi_planning.scene import scene_meshes

    spec, table, cloud, _ = kitchen
    meshes = scene_meshes(spec)
    assert (cloud.labels >= 0).all() and len(cloud) > 20_000
    within = np.zeros(len(cloud), bool)
    for label in cloud.present_labels():
        name = table.by_id(int(label)).name
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor(np.asarray(meshes[name].vertices, np.float32)),
            o3d.core.Tensor(np.asarray(meshes[name].faces, np.uint32)),
        )
        sel = cloud.labels == label
        dist = scene.compute_distance(o3d.core.Tensor(cloud.points[sel].astype(np.float32))).numpy()
        within[sel] = dist <= 0.01
        assert within[sel].mean() >= 0.99, (name, float(within[sel].mean()), float(dist.max()))
    assert within.mean() >= 0.99


def test_kitchen_every_clearly_visible_object_gets_points(kitchen: Kitchen) -> None:
    _, table, cloud, views = kitchen
    assert len(views) >= 2
    counts = Counter(cloud.labels.tolist())
    visible = 0
    for label in table:
        if label.kind != "object":
            continue
        pixels = sum(v.pixel_counts().get(label.id, 0) for v in views)
        area = max(v.projected_areas().get(label.id, 0.0) for v in views)
        if pixels == 0:
            assert counts[label.id] == 0, label.name  # hidden (inside a closed container): no points
            continue
        assert counts[label.id] >= 1, label.name
        if area >= CLEARLY_VISIBLE_AREA:
            visible += 1
            assert counts[label.id] >= 50, (label.name, counts[label.id], pixels, area)
    assert visible >= 6  # the shelf and counter objects are in view


def test_kitchen_cloud_carries_the_label_table_and_round_trips(kitchen: Kitchen, tmp_path: Path) -> None:
    from hsi_planning.perception import scene_cloud

    spec, table, cloud, _ = kitchen
    assert cloud.label_names == {lab.id: lab.name for lab in table}
    assert cloud.label_classes == {lab.id: lab.semantic_class for lab in table}
    again = scene_cloud(spec)
    np.testing.assert_array_equal(again.points, cloud.points)  # deterministic
    np.testing.assert_array_equal(again.labels, cloud.labels)
    back = read_ply(write_ply(tmp_path / "kitchen.ply", cloud))
    np.testing.assert_array_equal(back.points, cloud.points)
    assert back.label_names == cloud.label_names and back.label_classes == cloud.label_classes


def test_unnamed_and_orthographic_cameras() -> None:
    import mujoco

    xml = SMALL_XML.replace(
        '<camera name="cam_right"', '<camera pos="0 0 3" xyaxes="1 0 0 0 1 0"/><camera name="cam_right"'
    ).replace(
        '<camera name="cam_left"',
        '<camera name="ortho" projection="orthographic" fovy="2" pos="0 0 3"/>\n<camera name="cam_left"',
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with CloudRenderer(model, SMALL_LABELS) as renderer:
        names = renderer.camera_names()
        assert names[0] == "ortho" and "#2" in names
        top = renderer.render_view(data, "#2").points()  # looking straight down from 3 m
        assert set(top.present_labels().tolist()) >= {0, 1, 2, 3}
        table_z = top.points[top.labels == 1, 2]
        assert table_z.max() < 0.7 + 1e-3  # nothing above the table top...
        assert abs(np.median(table_z) - 0.7) < 1e-3  # ...which fills most of the view from above
        with pytest.raises(CloudError, match="orthographic"):
            renderer.render_view(data, "ortho")
        with pytest.raises(CloudError, match="not in the model"):
            renderer.render_view(data, "#9")


def test_headless_backend_choice(monkeypatch: pytest.MonkeyPatch) -> None:
    from hsi_planning import gl

    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    assert gl.ensure_headless_gl() == "osmesa"  # a user's choice is kept
    monkeypatch.delenv("MUJOCO_GL")
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    expected = "egl" if gl._library_available("EGL") else "osmesa"
    assert gl.ensure_headless_gl() == expected
    assert os.environ["MUJOCO_GL"] == expected
    monkeypatch.delenv("MUJOCO_GL")
    monkeypatch.setattr(gl, "_library_available", lambda name: name == "OSMesa")
    assert gl.ensure_headless_gl() == "osmesa" and os.environ["PYOPENGL_PLATFORM"] == "osmesa"
