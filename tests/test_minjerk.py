"""Minimum-jerk baseline: quintic maths, distance field, the IPOPT problem, the planner on built-in scenes."""

from __future__ import annotations

import time
from typing import Any

import casadi as ca
import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from hsi_planning.config import from_mapping
from hsi_planning.demos import ObstacleField, ReachRequest, generate_reach
from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.metrics.kinematics import integrated_squared_jerk
from hsi_planning.minjerk import (
    ClearanceSphere,
    MinJerkConfig,
    MinJerkPlanner,
    MinJerkPlannerConfig,
    contact_orientation,
    distance_grid,
    min_duration,
    rest_to_rest,
    solve_min_jerk,
)
from hsi_planning.minjerk.quintic import QuinticSpline
from hsi_planning.perception import LabelledCloud, scene_cloud
from hsi_planning.planning import PlanRequest, PlanResult
from hsi_planning.scene import opening_axis, scene_meshes
from hsi_planning.scene_paths import load_scene

HAND_RADIUS = 0.04
MARGIN = 0.02
RELAX_ZONE = 0.12  # [m] around the contact, where the clearance may relax to the contact's own
CASES = {  # scene, target, hand, action, start (wrist near the body, hand side)
    "kitchen_mug1": ("kitchen", "mug1", "left", "grasp", (0.2, 0.25, 1.0)),
    "narrow_bottle2": ("narrow_shelf", "bottle2", "right", "grasp", (0.2, -0.25, 1.0)),
    "drawer_mug2_place": ("cluttered_drawer", "mug2", "right", "place", (0.2, -0.25, 1.0)),
}


# ---------------------------------------------------------------------------------------------- maths


def test_rest_to_rest_is_the_analytic_minimum_jerk_motion() -> None:
    d, T = 0.8, 1.3
    line = rest_to_rest([0.0, 0.0, 0.0], [d, 0.0, 0.0], T, 7)
    assert line.jerk_cost() == pytest.approx(720.0 * d**2 / T**5, rel=1e-9)
    t = np.linspace(0.0, T, 41)
    tau = t / T
    assert np.allclose(line.evaluate(t)[:, 0], d * (10 * tau**3 - 15 * tau**4 + 6 * tau**5), atol=1e-12)
    assert np.allclose(
        line.evaluate(t, 1)[:, 0], d * (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / T, atol=1e-10
    )
    assert np.allclose(line.evaluate(t, 3)[:, 0], d * (60 - 360 * tau + 360 * tau**2) / T**3, atol=1e-8)


def test_quintic_derivatives_match_finite_differences() -> None:
    rng = np.random.default_rng(3)
    k = 6
    spline = QuinticSpline(2.0, rng.normal(size=(k, 3)), rng.normal(size=(k, 3)), rng.normal(size=(k, 3)))
    t = np.linspace(0.05, 1.95, 200)
    h = 1e-5
    for d in (1, 2):
        fd = (spline.evaluate(t + h, d - 1) - spline.evaluate(t - h, d - 1)) / (2 * h)
        assert np.allclose(spline.evaluate(t, d), fd, atol=1e-4)
    # C² at the knots: velocity and acceleration are continuous across a knot
    knot = spline.knot_times[2]
    for d in (0, 1, 2):
        left, right = spline.evaluate([knot - 1e-9], d), spline.evaluate([knot + 1e-9], d)
        assert np.allclose(left, right, atol=1e-6)


def test_min_duration_is_the_trapezoid_bound() -> None:
    assert min_duration(1.0, 1.5, 10.0) == pytest.approx(1.0 / 1.5 + 0.15)
    assert min_duration(0.1, 1.5, 10.0) == pytest.approx(2.0 * np.sqrt(0.1 / 10.0))


# ----------------------------------------------------------------------------------------- the field


def test_distance_grid_matches_kdtree_and_casadi_matches_numpy() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.5, 0.5, size=(400, 3))
    grid = distance_grid(pts, [-0.3, -0.3, -0.3], [0.3, 0.3, 0.3], resolution=0.025, cap=0.15)
    exact = cKDTree(pts).query(grid.points())[0]
    assert np.allclose(grid.values.reshape(-1), np.minimum(exact, 0.15), atol=1e-12)
    assert grid.contains(np.zeros((1, 3)))[0] and not grid.contains(np.full((1, 3), 0.5))[0]
    q = rng.uniform(grid.lower, grid.upper, size=(25, 3))
    f = grid.casadi_function(25)
    assert np.allclose(np.asarray(f(q.T)).reshape(-1), grid.interpolate(q), atol=1e-12)


def test_casadi_field_derivatives_are_exact_and_sparse() -> None:
    rng = np.random.default_rng(4)
    grid = distance_grid(
        rng.uniform(-0.5, 0.5, size=(300, 3)), [-0.3] * 3, [0.3] * 3, resolution=0.03, cap=0.2
    )
    n = 6
    f = grid.casadi_function(n)
    x = ca.MX.sym("x", 3 * n)
    y = f(ca.reshape(x, 3, n))
    lam = rng.uniform(0.5, 1.5, n)
    jac = ca.Function("J", [x], [ca.jacobian(y, x)])
    hess = ca.Function("H", [x], [ca.hessian(ca.dot(ca.DM(lam), y.T), x)[0]])
    x0 = rng.uniform(-0.25, 0.25, 3 * n)
    J = np.asarray(ca.densify(jac(x0)))
    H = hess(x0)
    assert H.nnz() <= 9 * n and jac(x0).nnz() == 3 * n  # block-diagonal: points are independent
    h = 1e-6
    val = lambda z: np.asarray(f(z.reshape(n, 3).T)).reshape(-1)  # noqa: E731
    fd_j = np.stack([(val(x0 + h * e) - val(x0 - h * e)) / (2 * h) for e in np.eye(3 * n)], axis=1)
    assert np.allclose(J, fd_j, atol=1e-6)

    def grad(z: np.ndarray) -> np.ndarray:
        return np.asarray(ca.densify(jac(z))).T @ lam

    fd_h = np.stack([(grad(x0 + h * e) - grad(x0 - h * e)) / (2 * h) for e in np.eye(3 * n)], axis=1)
    assert np.allclose(np.asarray(ca.densify(H)), fd_h, atol=1e-4 * max(1.0, np.abs(fd_h).max()))


def test_distance_grid_is_accurate_above_a_sampled_plane() -> None:
    xs = np.arange(-0.4, 0.4001, 0.01)
    plane = np.stack(np.meshgrid(xs, xs, [0.0], indexing="ij"), axis=-1).reshape(-1, 3)
    grid = distance_grid(plane, [-0.2, -0.2, 0.02], [0.2, 0.2, 0.3], resolution=0.02, cap=0.3)
    rng = np.random.default_rng(1)
    q = rng.uniform([-0.15, -0.15, 0.03], [0.15, 0.15, 0.2], size=(200, 3))
    assert np.abs(grid.interpolate(q) - q[:, 2]).max() < 3e-3


# ------------------------------------------------------------------------------------- the optimizer


def test_free_space_solution_is_the_minimum_jerk_line() -> None:
    a, b, T = np.array([0.1, -0.2, 0.9]), np.array([0.7, 0.1, 1.2]), 1.4
    sol = solve_min_jerk(a, b, T, ())
    ref = rest_to_rest(a, b, T, 40)
    t = np.linspace(0.0, T, 100)
    assert np.abs(sol.spline.evaluate(t) - ref.evaluate(t)).max() < 1e-5
    assert sol.jerk_cost == pytest.approx(ref.jerk_cost(), rel=1e-5)
    assert sol.status == "Solve_Succeeded"


def test_speed_bound_is_enforced_when_active() -> None:
    cfg = MinJerkConfig(max_speed=1.5, max_acceleration=10.0)
    a, b, T = np.zeros(3), np.array([1.0, 0.0, 0.0]), 1.1  # free min-jerk would peak at 1.70 m/s
    sol = solve_min_jerk(a, b, T, (), cfg)
    t = np.linspace(0.0, T, 600)
    speed = np.linalg.norm(sol.spline.evaluate(t, 1), axis=1)
    acc = np.linalg.norm(sol.spline.evaluate(t, 2), axis=1)
    assert 1.45 < speed.max() <= 1.5 * 1.01
    assert acc.max() <= 10.0 * 1.02
    assert np.allclose(sol.spline.evaluate([0.0, T]), [a, b], atol=1e-9)


def test_budget_stop_keeps_a_feasible_iterate_and_refuses_an_infeasible_one() -> None:
    # out of wall time at once: the warm start (the free minimum-jerk line) satisfies every constraint
    a, b, T = np.array([0.1, -0.2, 0.9]), np.array([0.7, 0.1, 1.2]), 1.4
    sol = solve_min_jerk(a, b, T, (), MinJerkConfig(max_wall_time=1e-6))
    assert sol.status == "feasible (Maximum_WallTime_Exceeded)"
    assert np.allclose(sol.spline.evaluate([0.0, T]), [a, b], atol=1e-9)
    assert np.linalg.norm(sol.spline.evaluate(np.linspace(0.0, T, 300), 1), axis=1).max() <= 1.5 + 1e-3
    # here the warm start breaks the speed bound (it peaks at 1.70 m/s): no trajectory
    with pytest.raises(PlanningError, match=r"return status Maximum_WallTime_Exceeded after 0 iterations"):
        solve_min_jerk(np.zeros(3), np.array([1.0, 0.0, 0.0]), 1.1, (), MinJerkConfig(max_wall_time=1e-6))


def test_duration_too_short_for_the_bounds_is_refused() -> None:
    with pytest.raises(PlanningError, match=r"too short.*at least"):
        solve_min_jerk(np.zeros(3), np.array([1.0, 0.0, 0.0]), 0.5, ())


def test_enclosed_goal_fails_with_the_ipopt_status() -> None:
    rng = np.random.default_rng(2)
    shell = rng.normal(size=(6000, 3))
    shell = 0.2 * shell / np.linalg.norm(shell, axis=1, keepdims=True) + np.array([0.8, 0.0, 1.0])
    grid = distance_grid(shell, [0.0, -0.5, 0.5], [1.3, 0.5, 1.5], resolution=0.025, cap=0.2)
    hand = ClearanceSphere(grid, HAND_RADIUS, MARGIN, np.zeros(3))
    cfg = MinJerkConfig(max_iterations=60, max_wall_time=2.0)
    with pytest.raises(PlanningError, match=r"IPOPT .* return status \w+"):
        solve_min_jerk([0.2, 0.0, 1.0], [0.8, 0.0, 1.0], 1.5, (hand,), cfg)


def test_config_validation() -> None:
    with pytest.raises(ConfigError):
        MinJerkConfig(knots=2)
    with pytest.raises(ConfigError):
        MinJerkConfig(relax_slope=1.5)
    with pytest.raises(ConfigError):
        from_mapping(MinJerkPlannerConfig, {"optimizer": {"max_speed": -1.0}})
    with pytest.raises(ConfigError):
        from_mapping(MinJerkPlannerConfig, {"no_such_key": 1})
    cfg = from_mapping(MinJerkPlannerConfig, {"optimizer": {"knots": 30}, "segment": {"margin": 0.03}})
    assert cfg.optimizer.knots == 30 and cfg.segment.margin == 0.03


# ------------------------------------------------------------------------------------- the planner


@pytest.fixture(scope="module")
def scenes() -> dict[str, tuple[Any, LabelledCloud]]:
    out = {}
    for name in {c[0] for c in CASES.values()}:
        spec = load_scene(name)
        out[name] = (spec, scene_cloud(spec))
    return out


def _request(scenes: dict[str, tuple[Any, LabelledCloud]], case: str) -> tuple[Any, PlanRequest]:
    scene, target, hand, action, start = CASES[case]
    spec, cloud = scenes[scene]
    req = PlanRequest(
        cloud=cloud,
        target=target,
        hand=hand,  # type: ignore[arg-type]
        action=action,  # type: ignore[arg-type]
        start_position=np.array(start),
        approach_axis=opening_axis(spec, target),
    )
    return spec, req


@pytest.fixture(scope="module")
def plans(scenes: dict[str, tuple[Any, LabelledCloud]]) -> dict[str, tuple[Any, PlanRequest, PlanResult]]:
    planner = MinJerkPlanner()
    out = {}
    for case in CASES:
        spec, req = _request(scenes, case)
        out[case] = (spec, req, planner.plan(req))
    return out


def _gt_field(spec: Any, target: str) -> ObstacleField:
    return ObstacleField({k: v for k, v in scene_meshes(spec).items() if k != target})


@pytest.mark.parametrize("case", list(CASES))
def test_plan_endpoints_format_and_orientation(
    plans: dict[str, tuple[Any, PlanRequest, PlanResult]], case: str
) -> None:
    _, req, res = plans[case]
    a, lv = res.approach, res.leave
    assert a.planner == lv.planner == "minjerk"
    assert (a.segment, lv.segment, a.contact_index, lv.contact_index) == (
        "approach",
        "leave",
        a.t.size - 1,
        0,
    )
    assert np.allclose(a.position[0], req.start_position, atol=1e-9)
    assert np.allclose(a.position[-1], lv.position[0], atol=1e-9)
    assert np.allclose(lv.position[-1], req.start_position, atol=1e-9)  # retreat = start by default
    for traj in (a, lv):
        assert np.allclose(np.diff(traj.t), 1.0 / 120.0, rtol=0.01)
        speed = traj.speed()
        assert speed[0] < 0.02 and speed[-1] < 0.02  # rest to rest
    # SLERP from the start orientation to the contact orientation, back on the leave
    assert abs(abs(float(a.quaternion[0] @ req.quaternion)) - 1.0) < 1e-9
    assert abs(abs(float(a.quaternion[-1] @ lv.quaternion[0])) - 1.0) < 1e-9
    angles = (Rotation.from_quat(a.quaternion[1:]).inv() * Rotation.from_quat(a.quaternion[:-1])).magnitude()
    assert angles.max() < 0.05  # smooth: < 0.05 rad per sample
    assert res.timings["total"] > 0.0 and res.info["approach"]["status"] in (
        "Solve_Succeeded",
        "Solved_To_Acceptable_Level",
    )


@pytest.mark.parametrize("case", list(CASES))
def test_plan_is_collision_free_against_ground_truth(
    plans: dict[str, tuple[Any, PlanRequest, PlanResult]], case: str
) -> None:
    spec, req, res = plans[case]
    field = _gt_field(spec, req.target)
    contact = res.contact_position
    target_pts = np.asarray(req.cloud.points[req.cloud.mask(req.target)], dtype=np.float64)
    centre = 0.5 * (target_pts.min(axis=0) + target_pts.max(axis=0))
    radius = float(np.linalg.norm(target_pts - centre, axis=1).max())
    q_contact = Rotation.from_quat(res.approach.quaternion[-1])
    own = float(field.distance(contact[None])[0])
    for seg in ("approach", "leave"):
        traj = getattr(res, seg)
        far = np.linalg.norm(traj.position - contact, axis=1) > RELAX_ZONE
        d = field.distance(traj.position)
        # the hand sphere never goes deeper than the contact pose itself sits, and keeps radius +
        # margin (less 1 cm of cloud sampling and interpolation error) away from the contact
        assert d.min() >= min(HAND_RADIUS, own) - 0.005, f"{seg}: hand clearance {d.min():.3f} m"
        assert d[far].min() >= HAND_RADIUS + MARGIN - 0.01, f"{seg}: hand clearance {d[far].min():.3f} m"
        carrying = (req.action, seg) in (("grasp", "leave"), ("place", "approach"))
        if carrying:
            offset = Rotation.from_quat(traj.quaternion).apply(q_contact.inv().apply(centre - contact))
            held = field.distance(traj.position + offset) - radius
            assert held[far].min() >= -0.005, f"{seg}: held object clearance {held[far].min():.3f} m"


@pytest.mark.parametrize("case", list(CASES))
def test_plan_respects_speed_and_acceleration_bounds(
    plans: dict[str, tuple[Any, PlanRequest, PlanResult]], case: str
) -> None:
    _, _, res = plans[case]
    for traj in (res.approach, res.leave):
        vel = np.gradient(traj.position, traj.t, axis=0)
        acc = np.gradient(vel, traj.t, axis=0)
        assert np.linalg.norm(vel, axis=1).max() <= 1.5 * 1.02
        assert np.linalg.norm(acc, axis=1).max() <= 10.0 * 1.05


def test_lower_jerk_than_a_human_like_reach_with_the_same_endpoints_and_duration(
    scenes: dict[str, tuple[Any, LabelledCloud]],
) -> None:
    spec, req = _request(scenes, "kitchen_mug1")
    from hsi_planning.implicit.prior import contact_point

    axis = opening_axis(spec, req.target)
    contact = contact_point(req.cloud.points[req.cloud.mask(req.target)], axis, 0.06)
    q_contact = contact_orientation(axis, req.start_position - contact)
    human = generate_reach(
        ReachRequest(
            start_position=req.start_position,
            start_quaternion=req.quaternion,
            contact_position=contact,
            contact_quaternion=q_contact,
            approach_axis=-axis,
            hand=req.hand,
            object_name=req.target,
        ),
        _gt_field(spec, req.target),
        rng=np.random.default_rng(7),
    )
    res = MinJerkPlanner().plan(req, duration=human.duration, contact_pose=np.r_[contact, q_contact])
    mj = res.approach
    assert mj.duration == pytest.approx(human.duration, abs=1e-9)
    assert np.allclose(mj.position[[0, -1]], human.position[[0, -1]], atol=1e-6)
    isj_mj = integrated_squared_jerk(mj.position, mj.t)
    isj_human = integrated_squared_jerk(human.position, human.t)
    assert isj_mj < isj_human, f"min-jerk {isj_mj:.1f} vs human-like {isj_human:.1f} m²/s⁵"


def test_reference_plan_fixes_contact_durations_and_warm_start(
    plans: dict[str, tuple[Any, PlanRequest, PlanResult]],
) -> None:
    _, req, ref = plans["kitchen_mug1"]
    res = MinJerkPlanner().plan(req, reference=ref)
    assert res.approach.duration == pytest.approx(ref.approach.duration)
    assert res.leave.duration == pytest.approx(ref.leave.duration)
    assert np.allclose(res.contact_position, ref.contact_position, atol=1e-9)
    assert res.info["approach"]["warm_start"] == "given"
    # started at the optimum, it stays there
    assert res.info["approach"]["jerk_cost"] == pytest.approx(ref.info["approach"]["jerk_cost"], rel=0.02)


# -------------------------------------------------------------------------------------------- errors


def test_bad_requests_fail_with_clear_errors(scenes: dict[str, tuple[Any, LabelledCloud]]) -> None:
    _, req = _request(scenes, "kitchen_mug1")
    planner = MinJerkPlanner()
    with pytest.raises(PlanningError, match="too short"):
        planner.plan(req, duration=0.2)
    board = req.cloud.points[req.cloud.mask("shelf1/board1")]
    inside = board[
        np.argmin(np.linalg.norm(board - req.cloud.points[req.cloud.mask("mug1")].mean(0), axis=1))
    ]
    with pytest.raises(PlanningError, match=r"contact position .* inside an obstacle"):
        planner.plan(req, contact_pose=inside)
    with pytest.raises(PlanningError, match="not a label"):
        planner.plan(req.cloud, "no_such_object", start_pose=[0.2, 0.25, 1.0])
    with pytest.raises(PlanningError, match="start_pose"):
        planner.plan(req.cloud, "mug1", start_pose=[0.2, 0.25])


def test_target_in_a_closed_cage_fails_with_the_ipopt_status() -> None:
    rng = np.random.default_rng(5)
    target = np.array([0.8, 0.0, 1.0]) + rng.uniform(-0.03, 0.03, size=(200, 3))
    shell = rng.normal(size=(8000, 3))
    shell = 0.22 * shell / np.linalg.norm(shell, axis=1, keepdims=True) + np.array([0.8, 0.0, 1.0])
    cloud = LabelledCloud(
        np.vstack([target, shell]),
        np.r_[np.zeros(200, np.int32), np.ones(8000, np.int32)],
        label_names={0: "obj", 1: "cage"},
    )
    cfg = from_mapping(MinJerkPlannerConfig, {"optimizer": {"max_iterations": 60, "max_wall_time": 2.0}})
    req = PlanRequest(
        cloud=cloud, target="obj", start_position=np.array([0.2, 0.0, 1.0]), approach_axis=[-1, 0, 0]
    )
    t0 = time.perf_counter()
    with pytest.raises(PlanningError, match=r"approach of obj: .*return status \w+"):
        MinJerkPlanner(cfg).plan(req)
    assert time.perf_counter() - t0 < 10.0


def test_carrying_leave_corridor_checks_the_held_object_in_its_pose_there(
    scenes: dict[str, tuple[Any, LabelledCloud]],
) -> None:
    """Regression (issue 4): the corridor warm start of a carrying leave from a shelf board used to ask
    every grid node to be free for the held object's start, middle and end offsets at once, so the nodes
    around the support (where the object still has its start pose) were blocked and no corridor was found."""
    from hsi_planning.minjerk.segment import SegmentSettings, SegmentSpec, build_fields, build_spheres
    from hsi_planning.minjerk.warm_start import corridor_path

    spec_scene, req = _request(scenes, "narrow_bottle2")
    planner = MinJerkPlanner()
    points, is_target, _ = planner._points(req)
    contact, q_contact, _ = planner._contact(req, points, is_target, None, None)
    start = np.asarray(req.start_position, dtype=np.float64)
    target = points[is_target]
    centre = 0.5 * (target.min(axis=0) + target.max(axis=0))
    radius = float(np.linalg.norm(target - centre, axis=1).max())
    settings = SegmentSettings()
    grid, _ = build_fields(
        points[~is_target],
        target,
        np.vstack([start, contact]),
        settings,
        reach=float(np.linalg.norm(centre - contact)),
        held_radius=radius,
    )
    spec = SegmentSpec(
        start=contact,
        goal=start,
        q_start=q_contact,
        q_goal=req.quaternion,
        duration=None,
        grid=grid,
        contact=contact,
        q_contact=q_contact,
        hand=req.hand,
        action="grasp",
        segment="leave",
        held_centre=centre,
        held_radius=radius,
    )
    spheres = build_spheres(spec, settings)
    path = corridor_path(contact, start, spheres, MinJerkConfig())
    assert path is not None
    assert np.allclose(path[0], contact) and np.allclose(path[-1], start)
    # against the ground truth: the held sphere (turning with the wrist) along the corridor, away from
    # the support, keeps its radius less 1 cm of cloud sampling / grid error
    field = _gt_field(spec_scene, req.target)
    tau = np.linspace(0.0, 1.0, path.shape[0])
    held = field.distance(spheres[1].centres(path, tau)) - radius
    far = np.linalg.norm(path - contact, axis=1) > RELAX_ZONE
    assert held[far].min() >= -0.01
