"""The implicit planner at run time: orientation transfer, path timing, descent, errors, CLI, benchmark.

Most tests use a tiny checkpoint trained here on a synthetic scene (:mod:`planner_fixture`); the last
runs the benchmark on a few unseen layouts with the committed checkpoint ``models/planner.pt``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from planner_fixture import AXIS, START, scene_cloud, shared_checkpoint
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.fields.descent import descend_field, prepare_descent
from hsi_planning.implicit import segment as segment_module
from hsi_planning.implicit.path import (
    Clearance,
    estimate_approach_axis,
    resample_uniform,
    select_start,
    smooth_path,
    time_path,
)
from hsi_planning.implicit.planner import ImplicitPlanner, ImplicitPlannerConfig
from hsi_planning.implicit.prior import contact_point, face_approach, rotation_between, transfer_orientation
from hsi_planning.implicit.problem import make_problem, problem_fields
from hsi_planning.implicit.runtime_field import (
    SegmentContext,
    fit_segment_latent,
    remaining_time,
    repair_field,
    wrist_free,
)
from hsi_planning.perception.cloud import LabelledCloud
from hsi_planning.planning import Planner, PlanRequest, PlanResult, make_planner


@pytest.fixture(scope="module")
def checkpoint() -> Path:
    return shared_checkpoint()


@pytest.fixture(scope="module")
def planner(checkpoint: Path) -> ImplicitPlanner:
    return ImplicitPlanner(checkpoint, ImplicitPlannerConfig(fit_steps=10))


def _curve(n: int, bend: float) -> np.ndarray:
    u = np.linspace(0.0, 1.0, n)
    return np.stack([0.2 + 0.5 * u, bend * np.sin(np.pi * u), 1.0 - 0.2 * u], axis=1)


# ------------------------------------------------------------------------------ orientation transfer


def test_rotation_between_maps_vectors_including_opposite() -> None:
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 3))
    b = rng.normal(size=(50, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    b[0] = -a[0]
    b[1] = a[1]
    np.testing.assert_allclose(rotation_between(a, b).apply(a), b, atol=1e-9)


def test_transfer_orientation_gives_orthonormal_frames_and_keeps_the_contact() -> None:
    prior = _curve(60, 0.15)
    rng = np.random.default_rng(1)
    q_prior = (Rotation.from_rotvec(np.linspace(0, 1, 60)[:, None] * [0.0, 0.8, 0.4])).as_quat()
    q_prior[::7] *= -1.0  # sign flips must not matter
    new = _curve(140, -0.05) + rng.normal(0.0, 0.001, (140, 3))
    quat = transfer_orientation(prior, q_prior, new, blend_fraction=0.2)
    assert quat.shape == (140, 4)
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-9)
    mats = Rotation.from_quat(quat).as_matrix()
    np.testing.assert_allclose(
        np.einsum("nij,nik->njk", mats, mats), np.broadcast_to(np.eye(3), mats.shape), atol=1e-9
    )
    np.testing.assert_allclose(np.linalg.det(mats), 1.0, atol=1e-9)
    assert (np.einsum("ij,ij->i", quat[1:], quat[:-1]) > 0.0).all()  # sign-continuous
    # the contact orientation is the prior's
    assert Rotation.from_quat(quat[-1]).inv() * Rotation.from_quat(q_prior[-1]) is not None
    angle = (Rotation.from_quat(quat[-1]).inv() * Rotation.from_quat(q_prior[-1])).magnitude()
    assert angle < 1e-6
    # consecutive frames turn smoothly (no jumps) [rad per sample]
    steps = (Rotation.from_quat(quat[1:]).inv() * Rotation.from_quat(quat[:-1])).magnitude()
    assert steps.max() < 0.1


def test_a_contact_pointing_off_the_approach_axis_is_turned_to_face_it() -> None:
    path = np.column_stack([np.linspace(0.0, 0.5, 51), np.zeros(51), np.full(51, 0.8)])
    down = Rotation.from_euler("y", 90, degrees=True)  # wrist x straight down: a top-down grasp
    quat = np.tile(down.as_quat(), (51, 1))
    front = np.array([-1.0, 0.0, 0.0])  # a cabinet's opening faces -x: the hand moves in along +x
    turned = face_approach(quat, path, front, np.radians(45.0), 0.2)
    x_axes = Rotation.from_quat(turned).apply([1.0, 0.0, 0.0])
    np.testing.assert_allclose(x_axes[-1], [1.0, 0.0, 0.0], atol=1e-9)  # the contact faces the front
    np.testing.assert_allclose(turned[:40], quat[:40], atol=1e-12)  # before the blend: as transferred
    steps = (Rotation.from_quat(turned[1:]).inv() * Rotation.from_quat(turned[:-1])).magnitude()
    assert steps.max() < 0.25 and (np.einsum("ij,ij->i", turned[1:], turned[:-1]) > 0.0).all()
    tilted = np.tile(Rotation.from_euler("y", 30, degrees=True).as_quat(), (51, 1))  # 30 deg off: kept
    np.testing.assert_array_equal(face_approach(tilted, path, front, np.radians(45.0), 0.2), tilted)


def test_transfer_orientation_on_the_prior_path_returns_the_prior() -> None:
    prior = _curve(80, 0.1)
    q_prior = Rotation.from_rotvec(np.linspace(0, 1, 80)[:, None] * [0.3, -0.5, 0.2]).as_quat()
    quat = transfer_orientation(prior, q_prior, prior, blend_fraction=0.0)
    err = (Rotation.from_quat(quat).inv() * Rotation.from_quat(q_prior)).magnitude()
    assert err.max() < 1e-6
    # a path turned by 90° about z: its tangents are rotated, so are the transferred frames (mid-path)
    turn = Rotation.from_euler("z", 90, degrees=True)
    moved = turn.apply(prior - prior[0]) + prior[0]
    q_new = transfer_orientation(prior, q_prior, moved, blend_fraction=0.0)
    heading_prior = Rotation.from_quat(q_prior[40]).apply([1.0, 0.0, 0.0])
    heading_new = Rotation.from_quat(q_new[40]).apply([1.0, 0.0, 0.0])
    assert abs(np.dot(turn.apply(heading_prior), heading_new)) > 0.9


def test_transfer_orientation_rejects_bad_input() -> None:
    with pytest.raises(PlanningError, match="NaN"):
        transfer_orientation(_curve(5, 0.1), np.tile([0, 0, 0, 1.0], (5, 1)), np.full((4, 3), np.nan))
    with pytest.raises(PlanningError, match="prior"):
        transfer_orientation(_curve(5, 0.1), np.zeros((4, 4)), _curve(5, 0.0))


# ------------------------------------------------------------------------------------- path tools


def test_smoothing_keeps_ends_and_timing_is_rest_to_rest() -> None:
    rng = np.random.default_rng(2)
    raw = _curve(80, 0.1) + rng.normal(0.0, 0.004, (80, 3))
    raw[[0, -1]] = _curve(80, 0.1)[[0, -1]]
    path = smooth_path(raw, 0.02)
    np.testing.assert_allclose(path[[0, -1]], raw[[0, -1]], atol=1e-12)
    assert np.abs(np.diff(path, 2, axis=0)).max() < np.abs(np.diff(raw, 2, axis=0)).max()
    times = time_path(path, np.full(len(path), 1.5), max_speed=2.0, min_speed=0.05, max_accel=8.0)
    t, pos = resample_uniform(times, path, 120.0)
    np.testing.assert_allclose(np.diff(t), 1.0 / 120.0, rtol=0.05)
    speed = np.linalg.norm(np.gradient(pos, t, axis=0), axis=1)
    assert speed[0] < 0.1 and speed[-1] < 0.1
    assert speed.max() <= 1.5 * 1.05
    np.testing.assert_allclose(pos[[0, -1]], path[[0, -1]], atol=1e-9)


def test_select_start_minimises_eq11_among_clear_connections() -> None:
    cand = np.array([[0.5, 0.0, 1.0], [0.6, 0.0, 1.0], [0.7, 0.0, 1.0]])
    phi = np.array([0.5, 0.45, 0.2])
    w = np.array([0.3, 0.0, 1.0])
    # cost = -phi + |x - w| / v: -0.3, -0.15, +0.2 with v = 1 m/s
    assert select_start(cand, phi, w, 1.0, lambda x: np.ones(len(x), bool)) == 0
    assert select_start(cand, phi, w, 1.0, lambda x: x[:, 0] > 0.55, batch=2) == 1
    assert select_start(cand, phi, w, 0.1, lambda x: np.ones(len(x), bool)) == 0  # slow: nearest wins
    with pytest.raises(PlanningError, match="no start point"):
        select_start(cand, phi, w, 1.0, lambda x: np.zeros(len(x), bool))
    with pytest.raises(PlanningError, match="corridor"):
        select_start(cand[:0], phi[:0], w, 1.0, lambda x: np.ones(len(x), bool))
    # segments through a wall of obstacle points are not clear
    wall = np.stack(np.meshgrid([0.4], np.arange(-0.3, 0.3, 0.01), np.arange(0.7, 1.3, 0.01)), -1).reshape(
        -1, 3
    )
    clear = Clearance(wall).segments_clear(w, np.vstack([cand, [[0.3, 0.5, 1.0]]]), 0.04)
    assert clear.tolist() == [False, False, False, True]


def test_a_tall_carried_box_connects_level_under_a_board_then_vertically_outside() -> None:
    # a board (underside at z = 1.0 m) from x = 0.5 m on; a held box 0.05..0.15 m ahead of the wrist and
    # +-0.1 m in height: at the candidate (wrist z 0.85 m) its top is 5 cm under the board, at the anchor
    # outside (z 0.95 m) it stands higher than the board's underside
    board = np.stack(
        np.meshgrid(np.arange(0.5, 1.0, 0.01), np.arange(-0.3, 0.3, 0.01), [1.0, 1.02]), -1
    ).reshape(-1, 3)
    carried = np.array([[x, y, z] for x in (0.05, 0.15) for y in (-0.03, 0.03) for z in (-0.1, 0.1)])
    config = argparse.Namespace(hand_radius=0.04)
    ctx: Any = argparse.Namespace(config=config, carried=carried, clearance=Clearance(board))
    anchor, x = np.array([0.2, 0.0, 0.95]), np.array([[0.8, 0.0, 0.85], [0.8, 0.0, 1.1]])
    corner = segment_module._waypoint(anchor, x)
    np.testing.assert_allclose(corner, [[0.2, 0.0, 0.85], [0.2, 0.0, 1.1]])  # vertical at the anchor
    straight = segment_module._connect_clear(ctx, anchor, True, 0.01)
    assert straight(x[:1]).tolist() == [False]  # the box's top front corner cuts the board's edge
    assert segment_module._connect_clear(ctx, anchor, True, 0.01, up=True)(x[:1]).tolist() == [True]
    over = segment_module._connect_clear(ctx, anchor, False, 0.01, up=True)  # the empty hand: up and over
    assert over(x[1:]).tolist() == [True]


def test_approach_axis_estimate_points_out_of_the_opening() -> None:
    cloud = scene_cloud()
    target = cloud.points[cloud.labels == 2]
    w = np.array(START["right"])
    # under the board, beside the box: the open front towards the person (-x)
    axis = estimate_approach_axis(target, Clearance(cloud.points[cloud.labels != 2]), w)
    np.testing.assert_allclose(axis, AXIS, atol=1e-12)
    # without the board the can stands on an open table: reached from above, like training's tables
    open_top = cloud.points[(cloud.labels != 2) & (cloud.labels != 5)]
    np.testing.assert_allclose(estimate_approach_axis(target, Clearance(open_top), w), [0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------------- the planner


def _can_context(cloud: LabelledCloud, planner: ImplicitPlanner) -> tuple[Any, SegmentContext]:
    """(problem, segment context) of the right hand grasping the fixture's can (label 2) along AXIS."""
    problem = make_problem(
        cloud.points, cloud.labels, [2], hand="right", action="grasp", segment="approach", approach_axis=AXIS
    )
    contact = contact_point(problem.target_points, AXIS, 0.06)
    clearance = Clearance(cloud.points[cloud.labels != 2])
    ctx = SegmentContext(
        fields=problem_fields(problem),
        clearance=clearance,
        contact=contact,
        contact_clear=float(clearance(contact)[0]),
        carried=np.zeros((1, 3)),
        lift=0.0,
        config=planner.config,
    )
    return problem, ctx


def test_descent_on_the_predicted_field_reaches_the_goal(planner: ImplicitPlanner) -> None:
    cloud = scene_cloud()
    problem, ctx = _can_context(cloud, planner)
    fields, contact = ctx.fields, ctx.contact
    cond = problem.condition_vector()
    from hsi_planning.implicit.problem import local_feature

    match = planner.matcher.match(local_feature(fields, cond), fields.grid.centre)
    z, loss = fit_segment_latent(planner.model, ctx, cond, match.demo, match.z_init)
    assert np.isfinite(loss)
    phi = remaining_time(planner.model, z, cond, ctx)
    # the learned remaining time grows away from the contact along the demonstration
    prior_pts = match.demo.position[:: len(match.demo.position) // 6]
    inside = fields.grid.contains(prior_pts)
    along = fields.grid.interpolate(phi, prior_pts[inside])
    assert along[0] > along[-1]
    fixed = repair_field(phi, ctx, wrist_free(ctx, carrying=False)(0.01))
    start = np.array([0.45, -0.2, 1.0])
    desc = descend_field(fields.grid, fixed, start, contact, blocked_value=fields.config.unreachable_time)
    assert desc.reached
    assert np.linalg.norm(desc.positions[-1] - contact) <= 0.0125 + 1e-9
    assert np.all(np.diff(desc.remaining) <= 1e-6)


@pytest.mark.parametrize("hand", ["right", "left"])
def test_plan_reaches_the_contact_collision_free(planner: ImplicitPlanner, hand: str) -> None:
    cloud = scene_cloud()
    result = planner.plan(cloud, "can", hand, "grasp", START[hand])  # type: ignore[arg-type]
    assert isinstance(planner, Planner)
    a, lv = result.approach, result.leave
    contact = contact_point(cloud.points[cloud.labels == 2], AXIS, 0.06)
    np.testing.assert_allclose(a.position[0], START[hand], atol=1e-9)
    np.testing.assert_allclose(a.position[-1], contact, atol=1e-9)
    np.testing.assert_allclose(lv.position[0], contact, atol=1e-9)
    np.testing.assert_allclose(lv.quaternion[0], a.quaternion[-1], atol=1e-9)
    early = lv.position[: len(lv.position) // 4]
    assert early[:, 2].max() > contact[2] + 0.01  # lifted while carrying
    assert np.linalg.norm(early[5, :2] - contact[:2]) < 0.002  # straight up first
    for traj, rate in ((a, 120.0), (lv, 120.0)):
        np.testing.assert_allclose(np.diff(traj.t), 1.0 / rate, rtol=0.05)
        speed = traj.speed()
        assert speed.max() < 2.5 and speed[0] < 0.15 and speed[-1] < 0.15
        np.testing.assert_allclose(np.linalg.norm(traj.quaternion, axis=1), 1.0, atol=1e-9)
    # hand sphere clear of the obstacle points (relaxed within 10 cm of the contact)
    obstacles = Clearance(cloud.points[cloud.labels != 2])
    far = np.linalg.norm(a.position - contact, axis=1) > 0.1
    assert obstacles(a.position[far]).min() >= 0.04 - 0.005
    assert set(result.timings) >= {"fields", "fit_approach", "path_approach", "path_leave", "total"}
    assert result.timings["total"] > 0.0
    json.dumps(result.to_dict())


@pytest.mark.parametrize("refit_leave", [False, True])
def test_planning_the_leave_in_a_second_thread_gives_the_same_plan(
    checkpoint: Path, refit_leave: bool
) -> None:
    cloud = scene_cloud()
    results = []
    for parallel in (False, True):
        cfg = ImplicitPlannerConfig(fit_steps=4, refit_leave=refit_leave, parallel_segments=parallel)
        results.append(ImplicitPlanner(checkpoint, cfg).plan(cloud, "can", "left", "grasp", START["left"]))
    for seg in ("approach", "leave"):
        a, b = (getattr(r, seg) for r in results)
        np.testing.assert_array_equal(a.position, b.position)
        np.testing.assert_array_equal(a.quaternion, b.quaternion)
        np.testing.assert_array_equal(a.t, b.t)
    keys = list(results[1].timings)
    assert keys[:3] == ["prepare", "fields", "match_approach"] and keys[-2:] == ["path_leave", "total"]
    assert set(keys) == set(results[0].timings)


def test_a_path_short_of_the_clearance_is_returned_only_within_relaxed_margin(checkpoint: Path) -> None:
    cloud = scene_cloud()
    strict = ImplicitPlannerConfig(fit_steps=5, check_margin=0.4, relaxed_margin=0.0)  # no path keeps it
    with pytest.raises(PlanningError, match="no collision-free path"):
        ImplicitPlanner(checkpoint, strict).plan(cloud, "can", "right", "grasp", START["right"])
    loose = dataclasses.replace(strict, relaxed_margin=0.45)
    result = ImplicitPlanner(checkpoint, loose).plan(cloud, "can", "right", "grasp", START["right"])
    info = result.info["path_approach"]
    assert info["relaxed"] and -0.45 <= info["clearance_margin"] < 0.0
    assert info["failed_attempts"]  # every attempt was tried first
    default = ImplicitPlanner(checkpoint, ImplicitPlannerConfig(fit_steps=5))
    assert not default.plan(cloud, "can", "right", "grasp", START["right"]).info["path_approach"]["relaxed"]


def test_each_safety_margin_is_repaired_once_per_segment(
    checkpoint: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The learned attempt's fast-marching repair (where its descent stalls) is the field the first
    repaired attempt uses: same margin, same free nodes, one fast marching."""
    calls: list[tuple[bool, float]] = []  # (carrying: the leave of a grasp, margin [m])
    real = segment_module._repair

    def counted(phi: np.ndarray, ctx: Any, free: np.ndarray, **kw: Any) -> np.ndarray:
        calls.append((kw["carrying"], round(kw["margin"], 6)))
        return real(phi, ctx, free, **kw)

    monkeypatch.setattr(segment_module, "_repair", counted)
    strict = ImplicitPlannerConfig(check_margin=0.4, relaxed_margin=0.45, parallel_segments=False)
    result = ImplicitPlanner(checkpoint, strict).plan(scene_cloud(), "can", "right", "grasp", START["right"])
    attempts = len(result.info["path_approach"]["failed_attempts"])
    assert attempts == strict.repair_retries + 2  # the learned one and every repaired margin failed
    assert len(calls) >= strict.repair_retries + 1
    assert len(calls) == len(set(calls)), f"a margin was repaired twice: {calls}"


def test_the_lift_stops_under_a_board_above_the_held_object_not_beside_a_packed_neighbour() -> None:
    from hsi_planning.implicit.runtime_field import box_samples, free_lift

    contact = np.array([0.44, 0.0, 0.6])  # wrist in front of a 20 cm bottle (top at 0.70)
    held = box_samples(np.array([[0.47, -0.03, 0.5], [0.53, 0.03, 0.7]]), 0.01) - contact
    ys, zs = np.meshgrid(np.arange(-0.1, 0.1, 0.005), np.arange(0.5, 0.75, 0.005))
    wall = np.column_stack([np.full(ys.size, 0.546), ys.ravel(), zs.ravel()])  # 6 mm beside the box
    floor = np.column_stack([np.random.default_rng(0).uniform(0.3, 0.7, (400, 2)), np.full(400, 0.5)])

    def lift(points: np.ndarray, slack: float = 0.0) -> float:
        clearance = Clearance(points)
        ctx = SegmentContext(
            fields=None,  # type: ignore[arg-type]  # not used by free_lift
            clearance=clearance,
            contact=contact,
            contact_clear=float(clearance(contact)[0]),
            carried=held,
            lift=0.0,
            config=ImplicitPlannerConfig(),
        )
        return free_lift(ctx, points, 0.15, 0.0075, slack=slack)

    assert lift(np.vstack([wall, floor])) == pytest.approx(0.15)  # a packed neighbour does not stop it
    xs, ys = np.meshgrid(np.arange(0.3, 0.7, 0.01), np.arange(-0.2, 0.2, 0.01))
    board = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, 0.75)])  # 4 cm over the bottle
    room = 0.75 - 0.71 - 0.0075  # under the board, less the margin (box padded by 1 cm)
    assert room - 0.005 <= lift(np.vstack([wall, floor, board])) <= room
    # A hidden top that may reach 1 cm higher keeps that top under the board too ...
    assert room - 0.015 <= lift(np.vstack([wall, floor, board]), slack=0.01) <= room - 0.01
    # ... and one that may reach the board slides out just off its support (never above the room).
    hidden = ImplicitPlannerConfig().hidden_top_lift
    assert hidden - 0.005 <= lift(np.vstack([wall, floor, board]), slack=0.2) <= hidden
    assert lift(np.vstack([wall, floor]), slack=0.2) == pytest.approx(0.15)  # nothing above: no cap


def test_plan_request_form_and_make_planner(checkpoint: Path) -> None:
    planner = make_planner("implicit", checkpoint, fit_steps=5)
    request = PlanRequest(cloud=scene_cloud(), target="can", hand="right", start_position=START["right"])
    result = planner.plan(request)
    assert isinstance(result, PlanResult)
    assert result.approach.planner == "implicit" and result.approach.object_name == "can"
    with pytest.raises(ConfigError, match="unknown planner"):
        make_planner("rrt", checkpoint)
    with pytest.raises(ConfigError, match="fit_step"):
        make_planner("implicit", checkpoint, fit_step=3)


def test_errors_on_bad_input(planner: ImplicitPlanner) -> None:
    cloud = scene_cloud()
    with pytest.raises(PlanningError, match="not a label"):
        planner.plan(cloud, "teapot", "right", "grasp", START["right"])
    no_can = cloud.select(cloud.labels != 2)
    with pytest.raises(PlanningError, match="no point"):
        planner.plan(no_can, "can", "right", "grasp", START["right"])
    with pytest.raises(PlanningError, match="inside an obstacle"):
        planner.plan(cloud, "can", "right", "grasp", [0.85, 0.2, 0.85])  # inside the box
    with pytest.raises(PlanningError, match="empty"):
        planner.plan(LabelledCloud(np.zeros((0, 3)), np.zeros(0, np.int32), {0: "can"}), "can")
    with pytest.raises(PlanningError, match="NaN"):
        PlanRequest.from_arrays(np.full((3, 3), np.nan), [2, 2, 2], {2: "can"}, "can")
    with pytest.raises(PlanningError, match="start_position"):
        planner.plan(cloud, "can", "right", "grasp", [np.nan, 0.0, 1.0])
    with pytest.raises(PlanningError, match="hand"):
        planner.plan(cloud, "can", "both", "grasp", START["right"])  # type: ignore[arg-type]
    # the can enclosed in a closed box of obstacle points
    c, s = np.array([0.78, 0.0, 0.81]), 0.1
    g = np.arange(-s, s + 1e-9, 0.01)
    shell = (
        np.array([[x, y, z] for x in g for y in g for z in g if max(abs(x), abs(y), abs(z)) > s - 1e-9]) + c
    )
    boxed = LabelledCloud(
        np.vstack([cloud.points, shell]),
        np.concatenate([cloud.labels, np.full(len(shell), 3, np.int32)]),
        cloud.label_names,
    )
    with pytest.raises(PlanningError, match="enclosed"):
        planner.plan(boxed, "can", "right", "grasp", START["right"])


def test_checkpoint_without_toa_or_bank_is_rejected(tmp_path: Path, checkpoint: Path) -> None:
    from hsi_planning.implicit import load_checkpoint, save_checkpoint

    ckpt = load_checkpoint(checkpoint)
    bare = tmp_path / "bare.pt"
    save_checkpoint(bare, ckpt.model, ckpt.latents, ckpt.config, {})
    with pytest.raises(PlanningError, match="prior_bank"):
        ImplicitPlanner(bare)
    with pytest.raises(PlanningError, match="no such checkpoint"):
        ImplicitPlanner(tmp_path / "missing.pt")


def test_cli_plan_writes_json(tmp_path: Path, checkpoint: Path, repo_root: Path) -> None:
    from hsi_nodes.cli import plan as plan_cli

    parser = argparse.ArgumentParser()
    plan_cli.register(parser.add_subparsers())
    out = tmp_path / "traj.json"
    args = parser.parse_args(
        [
            "plan",
            str(repo_root / "sim/scenes/kitchen.yaml"),
            "--target",
            "can1",
            "--checkpoint",
            str(checkpoint),
            "--out",
            str(out),
        ]
    )
    try:
        code = args.func(args)
    except PlanningError as exc:  # the tiny synthetic checkpoint may not find a path in the kitchen
        pytest.fail(f"hsi plan failed on the kitchen: {exc}")
    assert code == 0
    doc = json.loads(out.read_text())
    for seg in ("approach", "leave"):
        n = len(doc[seg]["t"])
        assert n > 10 and len(doc[seg]["position"]) == n and len(doc[seg]["quaternion"]) == n
    assert doc["approach"]["contact_index"] == len(doc["approach"]["t"]) - 1
    assert doc["leave"]["contact_index"] == 0
    assert doc["timings"]["total"] > 0


def test_benchmark_quick_with_the_committed_checkpoint(tmp_path: Path, repo_root: Path) -> None:
    ckpt = repo_root / "models" / "planner.pt"
    assert ckpt.is_file(), "the committed checkpoint models/planner.pt is missing (hsi train planner)"
    proc = subprocess.run(
        [
            sys.executable,
            str(repo_root / "benchmarks" / "planner.py"),
            "--quick",
            "--checkpoint",
            str(ckpt),
            "--ablation",
            str(tmp_path / "none.pt"),
            "--paper",
            str(tmp_path / "none.pt"),
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = json.loads((tmp_path / "planner.json").read_text())
    summary = results["models"]["implicit (t, o, toa)"]
    assert summary["cases"] == 6
    assert summary["success_rate"] >= 0.8, proc.stdout
    assert list(results["networks"]) == ["implicit (t, o, toa)"]  # the absent variants are not run
    net = results["networks"]["implicit (t, o, toa)"]
    assert net["parameters"] > 10_000 and 0.0 < net["checkpoint_mb"] <= 10.0
    assert (tmp_path / "planner.md").read_text().startswith("# Implicit planner benchmark")


# ------------------------------------------------------------------------------ target completion


def _drawer_points() -> np.ndarray:
    """A 40 × 40 cm drawer floor at z = 0.4 with 10 cm walls (1 cm spacing), seen from above."""
    g = np.arange(0.0, 0.401, 0.01)
    fx, fy = np.meshgrid(g, g, indexing="ij")
    floor = np.stack([fx.ravel(), fy.ravel(), np.full(fx.size, 0.4)], axis=1)
    h = np.arange(0.4, 0.501, 0.01)
    wx, wz = np.meshgrid(g, h, indexing="ij")
    walls = [np.stack([wx.ravel(), np.full(wx.size, y), wz.ravel()], axis=1) for y in (0.0, 0.4)] + [
        np.stack([np.full(wx.size, x), wx.ravel(), wz.ravel()], axis=1) for x in (0.0, 0.4)
    ]
    return np.vstack([floor, *walls])


def test_completion_extends_a_hidden_bottom_down_to_the_support_only() -> None:
    from hsi_planning.implicit.completion import completed_bounds, furniture_mask, support_height

    drawer = _drawer_points()
    # Only the top cap (z 0.52..0.53) of a 13 cm can standing on the floor is seen; the floor right
    # around it is hidden by packed neighbours (removed from the cloud).
    rng = np.random.default_rng(0)
    cap = np.column_stack([rng.uniform(0.17, 0.23, (40, 2)), rng.uniform(0.52, 0.53, 40)])
    hidden = (np.abs(drawer[:, 0] - 0.2) < 0.07) & (np.abs(drawer[:, 1] - 0.2) < 0.07)
    seen = drawer[~hidden]
    assert support_height(cap, seen) == pytest.approx(0.4, abs=1e-6)
    lo, hi = completed_bounds(cap, seen)
    assert lo[2] == pytest.approx(0.4, abs=1e-6) and hi[2] == pytest.approx(cap[:, 2].max())
    # Standing on observed furniture (the floor seen right below it): the visible bottom is kept.
    low_can = cap - [0.0, 0.0, 0.115]
    assert support_height(low_can, drawer) is None
    # Furniture only: objects (by class) and the target itself are not support candidates.
    labels = np.array([0, 1, 2, 2])
    mask = furniture_mask(labels, {0: "drawer", 1: "can", 2: "bottle"}, [2])
    assert mask.tolist() == [True, False, False, False]
    assert furniture_mask(labels, None, [2]).tolist() == [True, True, False, False]


def _bottle_under_a_board(front: float) -> tuple[Any, SegmentContext]:
    """(fields, segment context) of a wrist in front of a 20 cm bottle on a floor with a board 4 cm above it,
    both from x = ``front`` [m]; the bottle is held (its padded box carried)."""
    from hsi_planning.fields import compute_fields
    from hsi_planning.implicit.runtime_field import box_samples

    rng = np.random.default_rng(3)
    contact = np.array([0.44, 0.0, 0.6])
    bottle = np.column_stack([rng.uniform(0.47, 0.53, (300, 2)) - [0.0, 0.5], rng.uniform(0.5, 0.7, 300)])
    xs, ys = np.meshgrid(np.arange(front, 0.8, 0.01), np.arange(-0.3, 0.3, 0.01))
    floor = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, 0.5)])
    board = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, 0.74)])
    points = np.vstack([bottle, floor, board])
    labels = np.repeat([1, 2, 3], [len(bottle), len(floor), len(board)])
    fields = compute_fields(points, labels, [1], [2, 3], approach_direction=[-1.0, 0.0, 0.0])
    obstacles = Clearance(np.vstack([floor, board]))
    cfg = ImplicitPlannerConfig()
    ctx = SegmentContext(
        fields=fields,
        clearance=obstacles,
        contact=contact,
        contact_clear=float(obstacles(contact)[0]),
        carried=box_samples(bottle, cfg.carried_padding) - contact,
        lift=0.02,
        config=cfg,
    )
    return fields, ctx


def test_the_point_checked_free_mask_changes_only_nodes_near_the_contact_and_keeps_the_box_clear() -> None:
    from hsi_planning.implicit.runtime_field import point_checked_free, wrist_free

    fields, ctx = _bottle_under_a_board(0.2)
    contact, cfg = ctx.contact, ctx.config
    free = wrist_free(ctx, carrying=True)(0.01)
    checked = point_checked_free(ctx, free, 0.01)
    nodes = fields.grid.points()
    far = np.linalg.norm(nodes - contact, axis=1) > cfg.clearance_relax
    assert np.array_equal(checked.reshape(-1)[far], free.reshape(-1)[far])  # only near the contact
    near_free = np.flatnonzero(checked.reshape(-1) & ~far)
    assert near_free.size > 0
    assert (ctx.carried_clearance(nodes[near_free]) >= 0.5 * cfg.carried_margin).all()
    assert not (fields.obstacle_mask.reshape(-1)[near_free]).any()
    # Reaching down into a container, no node under the contact is freed (as in wrist_free).
    down = dataclasses.replace(ctx, approach_axis=np.array([0.0, 0.0, 1.0]))
    checked_down = point_checked_free(down, wrist_free(down, carrying=True)(0.01), 0.01).reshape(-1)
    rel = nodes - contact
    under = (np.linalg.norm(rel[:, :2], axis=1) <= 0.3) & (rel[:, 2] < -2.0 * fields.grid.resolution)
    assert under.any() and not (checked_down & under).any()
    assert (checked_down & ~far).any()


def test_a_slot_the_cell_mask_closes_is_opened_by_the_point_check_on_the_way_to_the_wrist() -> None:
    from hsi_planning.implicit.runtime_field import point_checked_free

    fields, ctx = _bottle_under_a_board(0.3)  # placed in a slot from x = 0.3 m, 4 cm of room above
    contact = ctx.contact
    grid, far = fields.grid, fields.config.unreachable_time
    phi = np.minimum(fields.dist_t.astype(np.float64) / 0.3, far)  # any time field: only its speed is used
    free = wrist_free(ctx, carrying=True)(0.01)
    anchor = np.array([0.15, 0.0, 0.62])  # the wrist in front of the slot
    near = repair_field(phi, ctx, point_checked_free(ctx, free, 0.01))
    assert not segment_module._descends_from(grid, near, anchor, far)  # a pocket around the contact
    kwargs: dict[str, Any] = {"margin": 0.01, "carrying": True, "prep": prepare_descent(grid, phi, far)}
    fixed = segment_module._repair(phi, ctx, free, anchor=anchor, **kwargs)
    desc = descend_field(grid, fixed, anchor, contact, blocked_value=far)
    assert desc.reached
    assert (ctx.carried_clearance(desc.positions[:-3]) > 0.0).all()  # the box clear of both boards
    # A wrist outside the grid cannot be judged: the near point check stands.
    outside = segment_module._repair(phi, ctx, free, anchor=np.array([-2.0, 0.0, 0.6]), **kwargs)
    np.testing.assert_array_equal(outside, near)


def test_the_empty_hand_is_kept_from_reaching_past_its_target(planner: ImplicitPlanner) -> None:
    """Beyond the contact along the approach axis, a path may not come nearer the target than the contact
    (less ``target_slack``); in front of the contact it may, and a carrying path is not held to it."""
    cloud = scene_cloud()
    problem, ctx = _can_context(cloud, planner)
    ctx = dataclasses.replace(
        ctx, approach_axis=np.asarray(AXIS, dtype=np.float64), target=Clearance(problem.target_points)
    )
    contact = ctx.contact
    axis = np.asarray(AXIS, dtype=np.float64)
    straight = contact + np.linspace(0.15, 0.0, 16)[:, None] * axis  # straight in along the axis
    clear_in, _ = segment_module._violation(straight, ctx, carrying=False)
    past = np.vstack([straight[:-1], contact - 0.05 * axis, contact])  # 5 cm deeper, then back out
    clear_past, where = segment_module._violation(past, ctx, carrying=False)
    assert clear_past < 0.0 and "nearer the target" in where
    assert clear_past < clear_in
    no_rule = dataclasses.replace(ctx, target=None)
    assert segment_module._violation(past, no_rule, carrying=False)[0] > clear_past
    # the planner's own approach keeps the rule
    result = planner.plan(cloud, "can", "right", "grasp", START["right"])  # type: ignore[arg-type]
    a = result.approach.position
    depth = (a - contact) @ axis
    near = Clearance(problem.target_points)(a)
    beyond = depth < 0.0
    assert np.all(near[beyond] >= ctx.target_clear - planner.config.target_slack - 1e-9)
