"""Completion of partly seen boards and objects (``hsi_planning.implicit.scene_completion``) and the held
object's hidden top (``hsi_planning.implicit.completion``), on synthetic clouds with known geometry."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hsi_planning.implicit.completion import class_height, completed_bounds, top_seen, top_slack
from hsi_planning.implicit.scene_completion import PANEL, complete_cloud, round_bounds
from hsi_planning.perception import LabelledCloud
from hsi_planning.planning import PlanRequest

NAMES = {0: "shelf1", 1: "shelf1/board2", 2: "bottle1", 3: "can1", 4: "floor"}
CLASSES = {0: "shelf", 1: "shelf_board", 2: "bottle", 3: "can", 4: "floor"}


def _plane(x: tuple[float, float], y: tuple[float, float], z: float, step: float) -> np.ndarray:
    xs, ys = np.arange(x[0], x[1] + 1e-9, step), np.arange(y[0], y[1] + 1e-9, step)
    g = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    return np.column_stack([g, np.full(len(g), z)])


def _shelf_scene() -> tuple[np.ndarray, np.ndarray]:
    """A shelf (side panels at y = ±0.4, back at x = 1.0, x 0.6..1.0) whose board at z = 1.0 is seen only
    along its front edge and at a few scattered points (edge-on view); a lower board at z = 0.6 seen
    fully, a bottle standing on it seen only by its neck (z 0.70..0.75), a floor."""
    rng = np.random.default_rng(0)
    sides = [
        np.column_stack([rng.uniform(0.6, 1.0, 400), np.full(400, s), rng.uniform(0.0, 1.4, 400)])
        for s in (-0.4, 0.4)
    ]
    back = np.column_stack([np.full(400, 1.0), rng.uniform(-0.4, 0.4, 400), rng.uniform(0.0, 1.4, 400)])
    shelf = np.vstack([*sides, back])
    edge = np.column_stack([np.full(60, 0.6), np.linspace(-0.39, 0.39, 60), np.full(60, 1.0)])
    scattered = np.column_stack([rng.uniform(0.6, 0.99, 12), rng.uniform(-0.39, 0.39, 12), np.full(12, 1.0)])
    board = np.vstack([edge, scattered])
    lower = _plane((0.6, 1.0), (-0.4, 0.4), 0.6, 0.01)  # labelled shelf1 (the shelf's fixed bottom)
    angle = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    neck = np.vstack(
        [
            np.column_stack([0.8 + 0.012 * np.cos(angle), 0.012 * np.sin(angle), np.full(24, z)])
            for z in np.arange(0.70, 0.75 + 1e-9, 0.005)
        ]
    )
    floor = _plane((0.0, 1.5), (-1.0, 1.0), 0.0, 0.05)
    points = np.vstack([shelf, lower, board, neck, floor])
    labels = np.concatenate(
        [
            np.zeros(len(shelf) + len(lower)),
            np.ones(len(board)),
            np.full(len(neck), 2),
            np.full(len(floor), 4),
        ]
    ).astype(np.int64)
    return points, labels


def test_a_board_seen_edge_on_becomes_a_solid_slab_bounded_by_its_furniture() -> None:
    points, labels = _shelf_scene()
    before = cKDTree(points[labels == 1])
    out, lab = complete_cloud(points, labels, CLASSES, exclude=[3], label_names=NAMES)
    assert np.array_equal(out[: len(points)], points) and np.array_equal(lab[: len(labels)], labels)
    board = out[lab == 1]
    after = cKDTree(board)
    middle = np.array([[0.8, 0.1, 1.0], [0.95, -0.3, 1.0], [0.7, 0.35, 1.0]])
    assert (before.query(middle)[0] > 0.03).any()  # the observed board has holes a hand passes through
    assert (after.query(middle)[0] <= 0.01).all()  # the completed one has none
    assert board[:, 2].max() == pytest.approx(1.0) and board[:, 2].min() == pytest.approx(1.0 - PANEL)
    assert board[:, 0].min() >= 0.6 - 1e-9 and board[:, 0].max() <= 1.0 + 1e-9  # inside the shelf's hull
    assert np.abs(board[:, 1]).max() <= 0.4 + 1e-9


def test_an_object_seen_by_its_top_is_extruded_to_its_support_with_its_class_width() -> None:
    points, labels = _shelf_scene()
    out, lab = complete_cloud(points, labels, CLASSES, label_names=NAMES)
    bottle = out[lab == 2]
    added = bottle[len(points[labels == 2]) :]
    below = added[added[:, 2] < 0.70 - 1e-9]
    assert below.shape[0] > 0
    assert below[:, 2].min() == pytest.approx(0.6, abs=0.011)  # down to the lower board
    radius = np.linalg.norm(below[:, :2] - [0.8, 0.0], axis=1).max()
    assert 0.03 <= radius <= 0.5 * 1.25 * 0.07 + 1e-9  # the widest bottle, not the 12 mm neck
    beside = added[added[:, 2] > 0.70 + 1e-9]  # the fitted cylinder over the visible height
    assert beside[:, 2].max() <= 0.75 + 1e-9
    r = np.linalg.norm(beside[:, :2] - [0.8, 0.0], axis=1)
    assert r.max() <= 0.5 * 0.8 * 0.07 + 1e-9  # the 12 mm neck fits the class's thinnest body


def test_a_round_object_seen_from_one_side_gets_its_far_side() -> None:
    rng = np.random.default_rng(1)
    angle = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, 300) + np.pi  # the half facing a camera at -x
    z = rng.uniform(0.6, 0.72, 300)
    can = np.column_stack([0.8 + 0.033 * np.cos(angle), 0.033 * np.sin(angle), z])
    points = np.vstack([can, _plane((0.6, 1.0), (-0.4, 0.4), 0.6, 0.01)])
    labels = np.concatenate([np.full(len(can), 3), np.zeros(len(points) - len(can))]).astype(np.int64)
    out, lab = complete_cloud(points, labels, CLASSES, label_names=NAMES)
    far_side = np.array([[0.8 + 0.033, 0.0, 0.66], [0.8 + 0.02, 0.02, 0.66]])
    assert (cKDTree(can).query(far_side)[0] > 0.02).all()
    assert (cKDTree(out[lab == 3]).query(far_side)[0] <= 0.012).all()


def test_the_held_box_of_a_round_object_seen_by_a_sliver_covers_its_cylinder() -> None:
    rng = np.random.default_rng(4)
    angle = rng.uniform(-0.35 * np.pi, 0.35 * np.pi, 200)  # the inner back wall of a packed mug
    z = rng.uniform(0.45, 0.53, 200)
    radius, centre = 0.039, np.array([0.5, 0.02])
    rim = np.column_stack([centre[0] + radius * np.cos(angle), centre[1] + radius * np.sin(angle), z])
    box = (rim.min(axis=0), rim.max(axis=0))
    assert box[1][0] - box[0][0] < 0.025  # the visible box misses most of the body
    lo, hi = round_bounds(rim, "mug", box)
    assert lo[:2] == pytest.approx(centre - radius, abs=0.006)
    assert hi[:2] == pytest.approx(centre + radius, abs=0.006)
    assert (lo[2], hi[2]) == (box[0][2], box[1][2])  # heights as completed before
    assert lo is not box[0]
    # A neighbour standing where the fit puts the body: the arc's other side (mirror image) is taken.
    gx, gy = np.meshgrid(np.arange(0.47, 0.53, 0.01), np.arange(-0.01, 0.05, 0.01))
    neighbour = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 0.5)])
    lo, hi = round_bounds(rim, "mug", box, neighbour)
    mirror = 2.0 * rim[:, :2].mean(axis=0) - centre
    assert lo[:2] == pytest.approx(np.minimum(box[0][:2], mirror - radius), abs=0.006)
    assert hi[:2] == pytest.approx(np.maximum(box[1][:2], mirror + radius), abs=0.006)
    assert hi[0] > centre[0] + radius + 0.01  # grown away from the neighbour
    same = round_bounds(rim, "box", box)  # not a round class: unchanged
    assert np.array_equal(same[0], box[0]) and np.array_equal(same[1], box[1])


def test_excluded_labels_and_clouds_without_classes_are_left_as_observed() -> None:
    points, labels = _shelf_scene()
    out, lab = complete_cloud(points, labels, CLASSES, exclude=[1, 2], label_names=NAMES)
    for i in (1, 2, 4):  # excluded, and the floor (no underside)
        assert (lab == i).sum() == (labels == i).sum()
    assert len(out) > len(points)
    out, _ = complete_cloud(points, labels, None)
    assert np.array_equal(out, points) and out is not points


def test_the_held_bottle_with_a_hidden_top_reaches_its_class_height_under_the_ceiling() -> None:
    points, labels = _shelf_scene()
    neck = points[labels == 2]
    furniture = points[np.isin(labels, [0, 1])]
    assert not top_seen(neck)  # a ring: the cut-off view of a bottle
    lo, hi = completed_bounds(neck, furniture, "bottle", points[labels != 2])
    assert lo[2] == pytest.approx(0.6, abs=0.011)
    assert hi[2] == pytest.approx(0.6 + class_height("bottle")[1], abs=1e-9)  # 0.9125 < 1.0 - 0.03
    low_board = points.copy()
    low_board[labels == 1, 2] = 0.88  # a board right above: the top stops below it (once completed)
    done, lab = complete_cloud(low_board, labels, CLASSES, exclude=[2], label_names=NAMES)
    lo, hi = completed_bounds(neck, furniture, "bottle", done[lab != 2])
    assert hi[2] == pytest.approx(0.88 - PANEL - 0.06, abs=1e-9)  # under the board's underside
    # The top is still hidden: it may reach the class's largest height (what the lift must allow for).
    assert top_slack(neck, (lo, hi), "bottle") == pytest.approx(lo[2] + class_height("bottle")[1] - hi[2])
    assert top_slack(neck, (lo, hi), None) == 0.0


def test_a_seen_top_face_is_not_extended() -> None:
    top = _plane((0.5, 0.6), (0.0, 0.06), 0.55, 0.01)
    side = np.column_stack([np.full(30, 0.5), np.linspace(0.0, 0.06, 30), np.linspace(0.43, 0.55, 30)])
    box = np.vstack([top, side])
    assert top_seen(box)
    lo, hi = completed_bounds(box, np.zeros((0, 3)), "box", None)
    assert hi[2] == pytest.approx(0.55)
    assert top_slack(box, (lo, hi), "box") == 0.0  # its top was seen: no more height to allow for


def test_plan_requests_complete_the_cloud_unless_told_not_to() -> None:
    points, labels = _shelf_scene()
    cloud = LabelledCloud(points, labels.astype(np.int32), label_names=NAMES, label_classes=CLASSES)
    done, _, ids = PlanRequest(cloud=cloud, target="bottle1").target_points()
    raw, _, _ = PlanRequest(cloud=cloud, target="bottle1", complete=False).target_points()
    assert len(raw) == len(points) and len(done) > len(points)
    assert ids == [2]


def test_panels_seen_from_above_get_their_underside() -> None:
    points, labels = _shelf_scene()
    region = ([0.5, -0.5, 0.5], [1.1, 0.5, 0.7])
    out, lab = complete_cloud(points, labels, CLASSES, label_names=NAMES, region=region)
    shelf = out[lab == 0]
    under = cKDTree(shelf).query([[0.8, 0.0, 0.6 - PANEL], [0.7, 0.2, 0.6 - PANEL]])[0]
    assert (under <= 1e-9).all()
    added = out[(lab == 0) & (np.arange(len(out)) >= len(points))]
    assert (added[:, 2] <= 0.7 - PANEL + 1e-9).all()  # only what lies in the region is thickened


def test_a_held_object_with_a_hidden_bottom_reaches_down_its_class_height() -> None:
    rng = np.random.default_rng(2)
    top = np.column_stack(
        [rng.uniform(0.5, 0.56, 200), rng.uniform(0.0, 0.06, 200), rng.uniform(0.6, 0.68, 200)]
    )
    top[:40, 2] = 0.68  # a seen top face
    deep_floor = _plane((0.4, 0.7), (-0.1, 0.2), 0.3, 0.01)  # far below: not a support in reach
    lo, hi = completed_bounds(top, np.zeros((0, 3)), "bottle", deep_floor)
    assert hi[2] == pytest.approx(0.68)
    assert lo[2] == pytest.approx(0.68 - class_height("bottle")[1])
    shelf = _plane((0.4, 0.7), (-0.1, 0.2), 0.45, 0.01)  # an obstacle under it: not lower than that
    lo, _ = completed_bounds(top, np.zeros((0, 3)), "bottle", shelf)
    assert lo[2] == pytest.approx(0.45)


def test_clipping_the_completion_keeps_exactly_the_points_inside_the_clip_box() -> None:
    points, labels = _shelf_scene()
    box = (np.array([0.55, -0.2, 0.5]), np.array([0.9, 0.3, 1.05]))
    full, full_lab = complete_cloud(points, labels, CLASSES, exclude=[2], label_names=NAMES)
    clipped, clip_lab = complete_cloud(points, labels, CLASSES, exclude=[2], label_names=NAMES, clip=box)
    assert np.array_equal(clipped[: len(points)], points)  # observed points are all kept
    added = clipped[len(points) :]
    assert len(added) > 0 and ((added >= box[0]) & (added <= box[1])).all()
    inside = ((full >= box[0]) & (full <= box[1])).all(axis=1)
    inside_clip = ((clipped >= box[0]) & (clipped <= box[1])).all(axis=1)
    assert np.array_equal(full[inside], clipped[inside_clip])  # the same points in the same order
    assert np.array_equal(full_lab[inside], clip_lab[inside_clip])
    assert len(clipped) < len(full)
