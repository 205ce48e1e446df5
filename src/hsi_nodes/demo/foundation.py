"""The demo's foundation: the simulated scene, its labelled cloud, a bag and a picture.

:func:`run_foundation` builds the scene's standalone MJCF (``OUT/<scene>.xml``); runs
``launch/sim_world.launch.yaml`` in this process on a simulated clock with a recorder attached (bag
``OUT/<scene>.mcap`` -> directory ``OUT/<scene>/``); reads the last ``/scene/points`` cloud and the label
table back from the bag and writes ``OUT/<scene>_cloud.ply``; renders an RGB image of the final simulated
state (object poses from the bag's last ``/tf``) with the scene's first camera into ``OUT/<scene>.png``;
writes ``OUT/demo_summary.json``. The recorded cloud is the scene cloud the pick-and-place tasks start from.
"""

from __future__ import annotations

import json
import logging
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hsi_planning.errors import ConfigError
from hsi_planning.perception import LabelledCloud

__all__ = ["DemoSettings", "run_foundation"]

_log = logging.getLogger(__name__)
_LAUNCH_FILE = "launch/sim_world.launch.yaml"
_CLOUD_TOPIC = "/scene/points"
_LABELS_TOPIC = "/scene/labels"


@dataclass(frozen=True)
class DemoSettings:
    """Sizes of one demo run (:meth:`for_run` picks them)."""

    #: Simulated time the launch file runs [s].
    duration_s: float = 1.0
    #: Cloud image width; the picture is twice as wide [px].
    width: int = 320
    #: Cloud image height; the picture is twice as high [px].
    height: int = 240
    #: Voxel edge of the cloud [m].
    voxel_size: float = 0.01

    def __post_init__(self) -> None:
        if not 0.0 < self.duration_s <= 60.0:
            raise ConfigError(
                f"demo duration must be in (0, 60] [s] of simulated time, got {self.duration_s}"
            )
        if self.width < 8 or self.height < 8 or not self.voxel_size > 0.0:
            raise ConfigError(f"demo images must be >= 8x8 px and voxel_size > 0 m, got {self}")

    @classmethod
    def for_run(cls, duration_s: float | None, test: bool) -> DemoSettings:
        """Full size (1 s simulated), or the smallest variant for ``test`` (0.2 s, 160x120 px, 2 cm)."""
        if test:
            return cls(0.2 if duration_s is None else duration_s, 160, 120, 0.02)
        return cls(1.0 if duration_s is None else duration_s)

    @property
    def cloud_period_s(self) -> float:
        """Re-render period of the cloud: two clouds after the first [s]."""
        return self.duration_s / 2.0


def _clear_old_bag(bag_dir: Path) -> None:
    """Delete a bag directory from an earlier demo run (only if it holds nothing but bag files)."""
    if not bag_dir.exists():
        return
    entries = list(bag_dir.iterdir()) if bag_dir.is_dir() else [bag_dir]
    if not all(p.is_file() and (p.suffix == ".mcap" or p.name == "metadata.yaml") for p in entries):
        from hsi_planning.errors import TransportError

        raise TransportError(f"{bag_dir} exists and is not a bag of an earlier demo; move or delete it")
    shutil.rmtree(bag_dir)


def _run_launch(scene_file: Path, bag: Path, settings: DemoSettings) -> Any:
    from hsi_nodes.launch import NodeSpec, package_share, parse_launch_file, run_launch

    overrides = {
        "scene": str(scene_file),
        "duration": repr(settings.duration_s),
        "cloud_period": repr(settings.cloud_period_s),
        "width": str(settings.width),
        "height": str(settings.height),
        "voxel_size": repr(settings.voxel_size),
    }
    description = parse_launch_file(package_share() / _LAUNCH_FILE, overrides)
    recorder = NodeSpec("recorder_node", "recorder", "/", {"out": str(bag)}, source="hsi demo")
    return run_launch(
        description, duration_s=settings.duration_s + 0.5, use_sim_time=True, extra_nodes=(recorder,)
    )


def _read_back(bag: Path) -> tuple[list[Any], dict[int, dict[str, Any]], Any]:
    """(clouds, label table, last TFMessage or None) recorded in ``bag``."""
    from hsi_nodes.bag import read_bag

    clouds: list[Any] = []
    table: dict[int, dict[str, Any]] = {}
    last_tf = None
    for rec in read_bag(bag, topics={_CLOUD_TOPIC, _LABELS_TOPIC, "/tf"}):
        if rec.topic == _CLOUD_TOPIC:
            clouds.append(rec.msg)
        elif rec.topic == _LABELS_TOPIC:
            table = {int(k): v for k, v in json.loads(rec.msg.data).items()}
        else:
            last_tf = rec.msg
    return clouds, table, last_tf


def _render_picture(mjcf: Path, last_tf: Any, camera: str, size: tuple[int, int], path: Path) -> float:
    """Render ``camera`` of the MJCF file at the recorded object poses to ``path``; returns pixel std."""
    import imageio.v3 as iio
    import numpy as np

    from hsi_planning.gl import ensure_headless_gl

    ensure_headless_gl()
    import mujoco

    from hsi_planning.perception import CloudRenderer

    model = mujoco.MjModel.from_xml_path(str(mjcf))
    data = mujoco.MjData(model)
    for tf in [] if last_tf is None else last_tf.transforms:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, tf.child_frame_id)
        if jid >= 0 and model.jnt_type[jid] == mujoco.mjtJoint.mjJNT_FREE:
            t, r = tf.transform.translation, tf.transform.rotation
            adr = int(model.jnt_qposadr[jid])
            data.qpos[adr : adr + 7] = [t.x, t.y, t.z, r.w, r.x, r.y, r.z]
    mujoco.mj_forward(model, data)
    with CloudRenderer(model) as renderer:
        image = renderer.render_rgb(data, camera, *size)
    iio.imwrite(path, image)
    return float(np.asarray(image, dtype=np.float64).std())


def run_foundation(
    scene: str, out: Path, settings: DemoSettings, echo: Callable[[str], None] = _log.info
) -> tuple[dict[str, Any], LabelledCloud]:
    """Run the foundation for ``scene`` into folder ``out``; returns the summary (also written as JSON)
    and the last recorded cloud with the label names and classes of the recorded label table. Progress
    lines (launch summary, label counts, files) go to ``echo``.

    Raises:
        HsiError: unknown scene, a bag directory that cannot be replaced, or no cloud recorded.
    """
    import numpy as np

    from hsi_nodes.bag import bag_paths, bag_topics
    from hsi_nodes.cli.scene_cloud import format_label_counts
    from hsi_nodes.pointcloud2 import msg_to_cloud
    from hsi_planning.errors import CloudError
    from hsi_planning.perception import write_ply
    from hsi_planning.scene import write_mjcf
    from hsi_planning.scene_paths import load_scene, resolve_scene

    t0 = time.perf_counter()
    scene_file = resolve_scene(scene)
    spec = load_scene(scene_file)
    if not spec.cameras:
        raise CloudError(f"scene {spec.name!r} has no cameras; the demo renders its cloud from them")
    out.mkdir(parents=True, exist_ok=True)
    mjcf = write_mjcf(spec, out / f"{spec.name}.xml")
    bag = out / f"{spec.name}.mcap"
    bag_dir, mcap_file = bag_paths(bag)
    _clear_old_bag(bag_dir)
    launch = _run_launch(scene_file, bag, settings)
    clouds, table, last_tf = _read_back(bag)
    if not clouds:
        raise CloudError(
            f"no {_CLOUD_TOPIC} message in {mcap_file}; the launch summary was:\n{launch.format()}"
        )
    points, labels, _ = msg_to_cloud(clouds[-1])
    assert labels is not None  # scene_cloud_node always sends labels
    names = {i: str(v["name"]) for i, v in table.items()}
    classes = {i: str(v["semantic_class"]) for i, v in table.items()}
    cloud = LabelledCloud(points, labels, names, classes)
    ply = write_ply(out / f"{spec.name}_cloud.ply", cloud)
    png = out / f"{spec.name}.png"
    size = (2 * settings.width, 2 * settings.height)
    pixel_std = _render_picture(mjcf, last_tf, spec.cameras[0].name, size, png)
    ids, counts = np.unique(labels, return_counts=True)
    summary: dict[str, Any] = {
        "scene": spec.name,
        "scene_file": str(scene_file),
        "files": {"mjcf": str(mjcf), "bag": str(mcap_file), "cloud_ply": str(ply), "image": str(png)},
        "simulated_s": round(launch.duration_s, 6),
        "launch_wall_s": round(launch.wall_s, 3),
        "stop_reason": launch.stop_reason,
        "callback_errors": launch.callback_errors,
        "clouds": {"count": len(clouds), "points": [int(c.width) * int(c.height) for c in clouds]},
        "labels": {
            str(int(i)): {"name": names.get(int(i), "?"), "points": int(c)}
            for i, c in zip(ids, counts, strict=True)
        },
        "label_table_size": len(table),
        "topics": {t: {"type": ty, "count": n} for t, (ty, n) in sorted(bag_topics(bag).items())},
        "image": {"camera": spec.cameras[0].name, "size": list(size), "pixel_std": round(pixel_std, 3)},
        "wall_s": round(time.perf_counter() - t0, 3),
    }
    (out / "demo_summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    echo(launch.format())
    echo(f"last cloud: {len(points)} points")
    echo("\n".join(format_label_counts(labels, names)))
    echo(f"wrote {mjcf}, {mcap_file}, {ply}, {png}, {out / 'demo_summary.json'} in {summary['wall_s']:.1f} s")
    return summary, cloud
