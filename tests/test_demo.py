"""``hsi demo --test`` end to end (as a subprocess), its files, reruns and errors; ``hsi scene cloud``."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import mujoco
import numpy as np
import pytest

from hsi_nodes.bag import bag_topics, read_bag
from hsi_nodes.cli import main as hsi_main
from hsi_nodes.cli.scene_cloud import add_cloud_command
from hsi_nodes.pointcloud2 import msg_to_cloud
from hsi_planning.errors import CloudError
from hsi_planning.perception import read_ply
from hsi_planning.scene import load_scene_spec, object_names, scene_labels


@pytest.fixture(scope="module")
def demo_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Output folder of one ``python -m hsi_nodes.cli demo --test`` run in a subprocess."""
    out = tmp_path_factory.mktemp("demo")
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(
        [sys.executable, "-m", "hsi_nodes.cli", "demo", "--test", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "last cloud:" in proc.stdout and "callback errors: none" in proc.stdout
    return out


def test_demo_writes_every_file(demo_out: Path) -> None:
    names = {p.name for p in demo_out.iterdir()}
    assert {"kitchen.xml", "kitchen", "kitchen_cloud.ply", "kitchen.png", "demo_summary.json"} <= names
    assert sorted(p.name for p in (demo_out / "kitchen").iterdir()) == ["kitchen.mcap", "metadata.yaml"]


def test_demo_bag_holds_the_launch_topics(demo_out: Path) -> None:
    topics = bag_topics(demo_out / "kitchen.mcap")
    assert topics["/scene/points"][0] == "sensor_msgs/msg/PointCloud2" and topics["/scene/points"][1] >= 1
    assert topics["/tf"] == ("tf2_msgs/msg/TFMessage", 10)  # 0.2 s at 50 Hz
    assert topics["/scene/labels"][1] == 1 and topics["/scene/joint_states"][1] == 10
    spec = load_scene_spec(Path(__file__).parents[1] / "sim" / "scenes" / "kitchen.yaml")
    last_tf = [m.msg for m in read_bag(demo_out / "kitchen.mcap", topics={"/tf"})][-1]
    assert [t.child_frame_id for t in last_tf.transforms] == object_names(spec)


def test_demo_cloud_ply_matches_the_recorded_cloud(demo_out: Path) -> None:
    summary = json.loads((demo_out / "demo_summary.json").read_text())
    clouds = [m.msg for m in read_bag(demo_out / "kitchen.mcap", topics={"/scene/points"})]
    assert summary["clouds"]["count"] == len(clouds) >= 2
    points, labels, _ = msg_to_cloud(clouds[-1])
    ply = read_ply(demo_out / "kitchen_cloud.ply")
    np.testing.assert_array_equal(ply.labels, labels)
    np.testing.assert_allclose(ply.points, points, atol=1e-6)
    assert len(ply.points) == summary["clouds"]["points"][-1] > 1000
    spec = load_scene_spec(Path(__file__).parents[1] / "sim" / "scenes" / "kitchen.yaml")
    table = scene_labels(spec)
    assert ply.label_names is not None and ply.label_names[table.by_name("counter1").id] == "counter1"
    per_label = {v["name"]: v["points"] for v in summary["labels"].values()}
    assert per_label["floor"] == int(np.count_nonzero(labels == 0)) and per_label["mug1"] > 0
    assert sum(per_label.values()) == len(points)
    assert summary["topics"]["/scene/points"] == {"type": "sensor_msgs/msg/PointCloud2", "count": len(clouds)}
    assert summary["simulated_s"] == pytest.approx(0.2) and summary["callback_errors"] == {}
    assert 0.0 < summary["wall_s"] < 60.0


def test_demo_png_and_mjcf(demo_out: Path) -> None:
    image = iio.imread(demo_out / "kitchen.png")
    assert image.shape == (240, 320, 3) and image.dtype == np.uint8
    assert float(image.std()) > 20.0  # not blank: furniture, objects, floor and sky
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 100
    model = mujoco.MjModel.from_xml_path(str(demo_out / "kitchen.xml"))  # standalone: no assets needed
    spec = load_scene_spec(Path(__file__).parents[1] / "sim" / "scenes" / "kitchen.yaml")
    assert model.nbody == len(scene_labels(spec)) + 1  # the world body + one body per label
    assert model.ncam == 2


def test_demo_reruns_into_the_same_folder_and_reports_errors(
    demo_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = (demo_out / "kitchen" / "kitchen.mcap").stat().st_mtime_ns
    assert hsi_main(["demo", "--test", "--out", str(demo_out), "--duration", "0.1"]) == 0
    assert (demo_out / "kitchen" / "kitchen.mcap").stat().st_mtime_ns > before
    assert json.loads((demo_out / "demo_summary.json").read_text())["simulated_s"] == pytest.approx(0.1)
    capsys.readouterr()
    assert hsi_main(["demo", "--test", "--scene", "moon_base", "--out", str(tmp_path)]) == 1
    assert "built-in scenes" in capsys.readouterr().err
    assert hsi_main(["demo", "--test", "--duration", "-1", "--out", str(tmp_path)]) == 1
    assert "duration" in capsys.readouterr().err
    foreign = tmp_path / "kitchen"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    assert hsi_main(["demo", "--test", "--out", str(tmp_path)]) == 1
    assert "not a bag" in capsys.readouterr().err and (foreign / "notes.txt").exists()


def test_scene_cloud_command_writes_labelled_ply(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser(prog="hsi scene")
    add_cloud_command(parser.add_subparsers(dest="scene_command"))
    out = tmp_path / "shelf.ply"
    args = parser.parse_args(
        ["cloud", "narrow_shelf", "--out", str(out), "--voxel", "0.02", "--width", "128"]
    )
    assert args.func(args) == 0
    text = capsys.readouterr().out
    cloud = read_ply(out)
    assert f"{len(cloud.points)} points" in text
    assert cloud.label_names is not None and cloud.label_names[0] == "floor"
    ids, counts = np.unique(cloud.labels, return_counts=True)
    for i, c in zip(ids, counts, strict=True):  # one line per label: id, name, points
        assert f"{cloud.label_names[int(i)]:<24} {int(c):>8}" in text
    full = tmp_path / "full.ply"
    args = parser.parse_args(["cloud", "narrow_shelf", "--out", str(full), "--voxel", "0", "--width", "128"])
    assert args.func(args) == 0
    assert len(read_ply(full).points) > 2 * len(cloud.points)  # the voxel grid thins the cloud
    bad = parser.parse_args(["cloud", "narrow_shelf", "--out", str(out), "--cameras", "nope"])
    with pytest.raises(CloudError, match="nope"):
        bad.func(bad)
