"""Segmentation of unlabelled clouds: plane removal + DBSCAN recovers the objects of a scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_cloud import CLEARLY_VISIBLE_AREA, SMALL_LABELS, _small_world

from hsi_planning.errors import CloudError, ConfigError
from hsi_planning.perception import (
    CloudConfig,
    CloudRenderer,
    LabelledCloud,
    SegmentConfig,
    segment_unlabelled,
)

MIN_IOU = 0.8


def _best_iou(truth: np.ndarray, clusters: np.ndarray) -> float:
    """Best IoU of a ground-truth mask (N,) against any cluster id >= 0 of ``clusters`` (N,)."""
    best = 0.0
    for cid in np.unique(clusters[truth]):
        if cid < 0:
            continue
        pred = clusters == cid
        best = max(best, float(np.count_nonzero(truth & pred) / np.count_nonzero(truth | pred)))
    return best


@pytest.fixture(scope="module")
def small_cloud() -> LabelledCloud:
    model, data = _small_world()
    with CloudRenderer(model, SMALL_LABELS) as renderer:
        return renderer.render_cloud(data, CloudConfig())


def test_config_validation() -> None:
    with pytest.raises(ConfigError, match="together"):
        SegmentConfig(roi_min=(0.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match="below"):
        SegmentConfig(roi_min=(0.0, 0.0, 1.0), roi_max=(1.0, 1.0, 0.5))
    with pytest.raises(ConfigError, match="dbscan_eps"):
        SegmentConfig(dbscan_eps=0.0)
    with pytest.raises(ConfigError, match="max_tilt_deg"):
        SegmentConfig(max_tilt_deg=60.0)
    with pytest.raises(ConfigError, match="min_cluster_points"):
        SegmentConfig(min_cluster_points=0)


def test_rejects_bad_points() -> None:
    with pytest.raises(CloudError, match="shape"):
        segment_unlabelled(np.zeros((5, 2)))
    with pytest.raises(CloudError, match="finite"):
        segment_unlabelled(np.array([[0.0, 0.0, np.nan]]))
    labels, info = segment_unlabelled(np.zeros((0, 3)))
    assert labels.shape == (0,) and info.cluster_sizes == []


def test_small_world_objects_are_recovered(small_cloud: LabelledCloud) -> None:
    labels, info = segment_unlabelled(small_cloud.without_labels().points)
    assert labels.dtype == np.int32 and labels.shape == (len(small_cloud),)
    assert _best_iou(small_cloud.mask("mug1"), labels) >= 0.9
    assert _best_iou(small_cloud.mask("ball1"), labels) >= 0.9
    # The floor and the table top are removed as horizontal planes, the table sides as vertical ones.
    heights = sorted(-p.offset * p.normal[2] for p in info.planes if p.orientation == "horizontal")
    assert heights[0] == pytest.approx(0.0, abs=2e-3) and any(abs(h - 0.7) < 2e-3 for h in heights)
    assert np.mean(labels[small_cloud.mask("floor")] == -1) > 0.99
    assert sorted(info.cluster_sizes, reverse=True) == info.cluster_sizes
    again, _ = segment_unlabelled(small_cloud.points)
    np.testing.assert_array_equal(again, labels)  # seeded RANSAC: deterministic


def test_region_of_interest_and_voxel_options(small_cloud: LabelledCloud) -> None:
    roi = SegmentConfig(roi_min=(0.5, -0.4, 0.69), roi_max=(1.1, 0.4, 1.0))
    labels, _ = segment_unlabelled(small_cloud.points, roi)
    inside = np.all((small_cloud.points >= roi.roi_min) & (small_cloud.points <= roi.roi_max), axis=1)
    assert (labels[~inside] == -1).all()
    assert _best_iou(small_cloud.mask("mug1"), labels) >= 0.9
    assert _best_iou(small_cloud.mask("ball1"), labels) >= 0.9
    coarse, info = segment_unlabelled(small_cloud.points, SegmentConfig(voxel_size=0.015))
    assert coarse.shape == (len(small_cloud),)  # every input point gets its voxel's label
    assert _best_iou(small_cloud.mask("ball1"), coarse) >= 0.85
    assert sum(info.cluster_sizes) < np.count_nonzero(coarse >= 0)  # clustering ran on fewer points


@pytest.mark.parametrize("scene", ["kitchen", "narrow_shelf"])
def test_scene_objects_on_shelf_and_counter_are_recovered(repo_root: Path, scene: str) -> None:
    from hsi_planning.perception import scene_renderer
    from hsi_planning.scene import load_scene_spec

    spec = load_scene_spec(repo_root / "sim" / "scenes" / f"{scene}.yaml")
    _, data, renderer = scene_renderer(spec)
    with renderer:
        cloud = renderer.render_cloud(data, CloudConfig())
        views = [renderer.render_view(data, cam) for cam in renderer.camera_names()]
    labels, info = segment_unlabelled(cloud.without_labels().points)
    kinds = {f.name: f.kind for f in spec.furniture}
    checked = []
    for obj in spec.objects:
        support = obj.on.split("/")[0]
        label = cloud.label_id(obj.name)
        area = max(v.projected_areas().get(label, 0.0) for v in views)
        if kinds[support] not in ("shelf", "counter") or area < CLEARLY_VISIBLE_AREA:
            continue
        iou = _best_iou(cloud.mask(label), labels)
        checked.append((obj.name, round(iou, 3)))
        assert iou >= MIN_IOU, (obj.name, iou, info.cluster_sizes)
    assert len(checked) >= 4, checked
