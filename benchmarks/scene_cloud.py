"""Benchmark: fused labelled cloud generation from the kitchen scene's cameras.

Times ``CloudRenderer.render_cloud`` (2 cameras, 320x240, 1 cm voxels) after warm-up, excluding the
model build and the renderer (OpenGL context) creation, plus its stages and the unlabelled
segmentation of the same cloud. Then measures segmentation quality (best-cluster IoU of every clearly
visible object on a shelf or counter) on the scene and on randomized layout variants (with and
without container reshaping). Prints tables and writes ``benchmarks/results/scene_cloud.json``.

    MUJOCO_GL=egl python benchmarks/scene_cloud.py [--quick] [--scene sim/scenes/kitchen.yaml]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hsi_planning.gl import ensure_headless_gl

REPO = Path(__file__).resolve().parents[1]
#: Objects showing at least this much surface to one camera [m^2] count as clearly visible (as in tests).
CLEARLY_VISIBLE_AREA = 75e-4


def _times(fn: Callable[[], Any], repeats: int, warmup: int = 3) -> dict[str, float]:
    for _ in range(warmup):
        fn()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - start)
    ms = np.asarray(samples) * 1e3
    return {
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "min_ms": float(ms.min()),
        "max_ms": float(ms.max()),
        "repeats": repeats,
    }


def _segmentation_quality(spec: Any) -> dict[str, float]:
    """Best-cluster IoU per clearly visible shelf/counter object of one scene."""
    from hsi_planning.perception import CloudConfig, segment_unlabelled
    from hsi_planning.perception.render import scene_renderer

    _, data, renderer = scene_renderer(spec)
    with renderer:
        cloud = renderer.render_cloud(data, CloudConfig())
        views = [renderer.render_view(data, cam) for cam in renderer.camera_names()]
    labels, _ = segment_unlabelled(cloud.without_labels().points)
    kinds = {f.name: f.kind for f in spec.furniture}
    out = {}
    for obj in spec.objects:
        label = cloud.label_id(obj.name)
        area = max(v.projected_areas().get(label, 0.0) for v in views)
        if kinds[obj.on.split("/")[0]] not in ("shelf", "counter") or area < CLEARLY_VISIBLE_AREA:
            continue
        truth = cloud.mask(label)
        best = 0.0
        for cid in np.unique(labels[truth]):
            if cid >= 0:
                pred = labels == cid
                best = max(best, float(np.count_nonzero(truth & pred) / np.count_nonzero(truth | pred)))
        out[obj.name] = best
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="few repetitions (smoke run)")
    parser.add_argument("--scene", type=Path, default=REPO / "sim" / "scenes" / "kitchen.yaml")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "scene_cloud.json")
    args = parser.parse_args()
    backend = ensure_headless_gl()

    from hsi_planning.perception import (
        CloudConfig,
        SegmentConfig,
        scene_renderer,
        segment_unlabelled,
        voxel_downsample,
    )
    from hsi_planning.scene import load_scene_spec

    repeats = 5 if args.quick else 30
    spec = load_scene_spec(args.scene)
    start = time.perf_counter()
    _, data, renderer = scene_renderer(spec)
    setup_s = time.perf_counter() - start
    config = CloudConfig()
    with renderer:
        cameras = renderer.camera_names()
        cloud = renderer.render_cloud(data, config)
        raw = renderer.render_cloud(data, CloudConfig(voxel_size=0.0))
        rows = {
            "fused_cloud": _times(lambda: renderer.render_cloud(data, config), repeats),
            "render_view_x1": _times(lambda: renderer.render_view(data, cameras[0]), repeats),
            "voxel_downsample": _times(lambda: voxel_downsample(raw, config.voxel_size), repeats),
            "segment_unlabelled": _times(
                lambda: segment_unlabelled(cloud.points, SegmentConfig()), 2 if args.quick else 5, warmup=1
            ),
        }
    result = {
        "scene": spec.name,
        "cameras": cameras,
        "resolution": [config.width, config.height],
        "voxel_size_m": config.voxel_size,
        "points_per_cloud": len(cloud),
        "points_before_downsampling": len(raw),
        "labels_in_cloud": len(set(cloud.labels.tolist())),
        "model_build_and_renderer_s": setup_s,
        "gl_backend": backend,
        "machine": f"{platform.machine()} {platform.processor() or platform.system()}",
        "quick": args.quick,
        "timings": rows,
        "target_ms": 100.0,
        "meets_target": rows["fused_cloud"]["median_ms"] <= 100.0,
    }
    print(
        f"scene {spec.name}: {len(cameras)} cameras, {config.width}x{config.height} px, "
        f"voxel {config.voxel_size} m"
    )
    print(
        f"points per cloud: {len(cloud)} (before downsampling {len(raw)}); setup {setup_s:.2f} s ({backend})"
    )
    print(f"{'stage':<22}{'median ms':>10}{'p95 ms':>10}{'min ms':>10}{'n':>5}")
    for name, row in rows.items():
        print(
            f"{name:<22}{row['median_ms']:>10.1f}{row['p95_ms']:>10.1f}{row['min_ms']:>10.1f}{row['repeats']:>5}"
        )
    from hsi_planning.scene.layout import LayoutConfig, generate_layouts

    count = 2 if args.quick else 8
    scenes = [(spec.name, spec)]
    scenes += [
        (f"reshaped{i}", v)
        for i, v in enumerate(generate_layouts(spec, count, 1, LayoutConfig(reshape=True)))
    ]
    scenes += [
        (f"shifted{i}", v) for i, v in enumerate(generate_layouts(spec, count // 2, 2, LayoutConfig()))
    ]
    quality = {name: _segmentation_quality(variant) for name, variant in scenes}
    ious = [iou for per_scene in quality.values() for iou in per_scene.values()]
    result["segmentation"] = {
        "scenes": quality,
        "objects": len(ious),
        "min_iou": min(ious),
        "mean_iou": float(np.mean(ious)),
        "below_0.8": sum(iou < 0.8 for iou in ious),
    }
    print(f"{'scene':<14}{'objects':>8}{'min IoU':>9}{'mean IoU':>10}")
    for name, per_scene in quality.items():
        vals = list(per_scene.values())
        print(f"{name:<14}{len(vals):>8}{min(vals):>9.3f}{np.mean(vals):>10.3f}")
    below = result["segmentation"]["below_0.8"]
    print(f"segmentation: {len(ious)} objects, min IoU {min(ious):.3f}, below 0.8: {below}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
