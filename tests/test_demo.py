"""``hsi demo --test`` end to end (as a subprocess): the foundation files (scene MJCF, bag, cloud, picture),
the pick-and-place reports (``report.json`` keys per task, ``report.md``), the trajectory plot and the video;
reruns and errors; ``hsi scene cloud``. The demo runs with ``--planner reach_model`` (deterministic, no
checkpoint needed); the default planner's results are in the demo's own report."""

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
from hsi_nodes.demo.summary import REQUIRED_KEYS
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
        [
            sys.executable,
            "-m",
            "hsi_nodes.cli",
            "demo",
            "--test",
            "--planner",
            "reach_model",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "last cloud:" in proc.stdout and "callback errors: none" in proc.stdout
    assert "planner reach_model, 1/1 tasks succeeded" in proc.stdout  # the printed summary
    return out


def test_demo_writes_every_file(demo_out: Path) -> None:
    names = {p.name for p in demo_out.iterdir()}
    assert {"kitchen.xml", "kitchen", "kitchen_cloud.ply", "kitchen.png", "demo_summary.json"} <= names
    assert {"report.json", "report.md", "demo.mp4", "plots"} <= names
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


def test_demo_report_json_has_one_entry_per_task(demo_out: Path) -> None:
    entries = json.loads((demo_out / "report.json").read_text())
    assert isinstance(entries, list) and len(entries) == 1
    entry = entries[0]
    assert set(REQUIRED_KEYS) <= set(entry)
    assert entry["object"] == "can1" and entry["robot"] == "dual_ur5e" and entry["planner"] == "reach_model"
    assert entry["task"] == "counter_can" and entry["stage"] == "done"
    assert isinstance(entry["success"], bool) and isinstance(entry["collisions"], int)
    assert entry["duration_s"] > 5.0 and 0.0 <= entry["max_tracking_error_m"] < 0.1
    assert entry["success"] is True and entry["placement_error_m"] < 0.02 and entry["collisions"] == 0
    summary = json.loads((demo_out / "demo_summary.json").read_text())["pick_place"]
    assert summary["succeeded"] == 1 and summary["tasks"] == [
        {"task": "counter_can", "success": True, "stage": "done"}
    ]
    assert 0.0 < summary["wall_s"] < 120.0
    text = (demo_out / "report.md").read_text()
    assert "| counter_can | can1 | yes | done |" in text and "navigate to" in text


def test_demo_plot_and_video(demo_out: Path) -> None:
    plot = iio.imread(demo_out / "plots" / "counter_can.png")
    assert plot.ndim == 3 and plot.shape[1] > 2 * plot.shape[0]  # three panels side by side
    assert float(plot[..., :3].std()) > 10.0
    video = demo_out / "demo.mp4"
    assert video.stat().st_size > 10_000
    frames = iio.imread(video)
    assert frames.shape[1:] == (120, 160, 3) and frames.shape[0] > 40  # title card + the execution
    motion = np.abs(frames[-1].astype(np.int16) - frames[frames.shape[0] // 2].astype(np.int16))
    assert float(motion.mean()) > 0.5  # the robot moves between the frames


def test_demo_reruns_into_the_same_folder_and_reports_errors(
    demo_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = (demo_out / "kitchen" / "kitchen.mcap").stat().st_mtime_ns
    fast = ["--planner", "linear", "--no-video"]
    assert hsi_main(["demo", "--test", *fast, "--out", str(demo_out), "--duration", "0.1"]) == 0
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
    for bad, message in (
        (["--planner", "teleport"], "available"),
        (["--robot", "octopus"], "unknown robot"),
        (["--tasks", "nope"], "unknown demo task"),
    ):
        assert hsi_main(["demo", "--test", *bad, "--out", str(tmp_path / "x")]) == 1
        assert message in capsys.readouterr().err
        assert not (tmp_path / "x").exists()  # refused before anything runs


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
