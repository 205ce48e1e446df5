"""Collision geometry of the IK: culling (:mod:`hsi_retarget.culling`; the scene distance's lower bound never
exceeds the exact distance, culled constraint rows and clearances equal the unculled ones on the kitchen
scene), the chassis' edge columns and floor exemption, and the opened part as an obstacle
(:mod:`hsi_retarget.part_scene`)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from hsi_planning.errors import RetargetError
from hsi_planning.scene import scene_meshes
from hsi_planning.scene_paths import load_scene
from hsi_retarget.candidates import find_candidates
from hsi_retarget.collision import collision_rows, min_gap
from hsi_retarget.culling import LinkBounds
from hsi_retarget.ik import IKConfig, IKSolver
from hsi_retarget.path_clearance import path_gaps
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance


@pytest.fixture(scope="module")
def kitchen() -> SceneDistance:
    return SceneDistance.from_spec(load_scene("kitchen"))


def test_lower_bound_never_exceeds_the_distance(kitchen: SceneDistance) -> None:
    rng = np.random.default_rng(3)
    points = rng.uniform([-1.0, -1.0, -0.5], [5.0, 5.0, 3.0], size=(4000, 3))  # inside and outside the grid
    exact, _ = kitchen.query(points)
    bound = kitchen.lower_bound(points)
    assert np.all(bound <= exact + 1e-5), float((bound - exact).max())
    on_grid = np.isfinite(bound)
    assert 0.5 < on_grid.mean() < 1.0  # points off the grid are left to the exact query
    assert np.mean(exact[on_grid] - bound[on_grid]) < 0.08  # useful: within a grid cell's reach on average
    again = kitchen.lower_bound(points)  # cached nodes give the same bound
    assert np.array_equal(bound, again)
    # points measured and bounded without the floor (a robot's base) get their own bound and exact distance
    meshes = scene_meshes(load_scene("kitchen"))
    lifted = SceneDistance({n: m for n, m in meshes.items() if n != "floor"})
    raised = np.arange(points.shape[0]) % 2 == 0
    dist, grad = kitchen.query(points, grounded=~raised)
    no_floor, _ = lifted.query(points)
    assert np.allclose(dist[raised], no_floor[raised], atol=1e-6)
    assert np.allclose(dist[~raised], exact[~raised], atol=1e-6)
    assert np.allclose(np.linalg.norm(grad, axis=1), 1.0)
    assert np.any(no_floor[raised] > exact[raised] + 0.1)  # the floor matters for some of them
    bound = kitchen.lower_bound(points, grounded=~raised)
    assert np.all(bound <= dist + 1e-5), float((bound - dist).max())
    assert np.mean((dist - bound)[np.isfinite(bound)]) < 0.08


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_collision_rows_are_the_gap_rates_by_finite_differences(name: str, kitchen: SceneDistance) -> None:
    """Each row n^T (J_a - J_b) is the rate at which its pair's centre distance along n (or a sphere's
    distance to the scene along its gradient) changes with the joint velocities: central differences over
    every velocity of the robot, its floating base included."""
    robot = RobotModel(name)
    solver = IKSolver(robot, scene=kitchen)
    spheres, pairs = solver.spheres, solver._pairs
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(6):
        q = np.clip(robot.random_configuration(rng, root_box=0.2), robot.q_lower, robot.q_upper)
        data = robot.model.createData()
        pin.computeJointJacobians(robot.model, data, q)
        pin.updateFramePlacements(robot.model, data)
        kwargs = {"margins": (0.02, 0.005, 0.015), "gain": 0.5, "max_rows": 40}
        rows, _, _ = collision_rows(robot.model, data, spheres, pairs, kitchen, activation=5.0, **kwargs)  # type: ignore[arg-type]
        centers = spheres.world(data)
        ia, ib, gaps, dirs = find_candidates(
            spheres,
            centers,
            pairs,
            [(kitchen, spheres.everyone)],
            spheres.grounded,
            margins=(0.02, 0.005, 0.015),
            activation=5.0,
            bounds=None,
            links=None,
        )
        order = np.argsort(gaps)[:40]  # the rows' candidates, closest first
        ia, ib, dirs = ia[order], ib[order], dirs[order]
        eps = 1e-6
        numeric = np.zeros_like(rows)
        for k in range(robot.nv):
            dq = np.zeros(robot.nv)
            dq[k] = eps
            ends = []
            for sign in (1.0, -1.0):
                d = robot.model.createData()
                pin.framesForwardKinematics(robot.model, d, robot.integrate(q, sign * dq))
                c = spheres.world(d)
                other = np.where(ib[:, None] >= 0, c[np.maximum(ib, 0)], 0.0)
                ends.append(np.einsum("kj,kj->k", dirs, c[ia] - other))
            numeric[:, k] = (ends[0] - ends[1]) / (2 * eps)
        np.testing.assert_allclose(rows, numeric, atol=1e-6)
        checked += int(rows.any(axis=1).sum())
    assert checked > 100  # scene and pair rows, most of them moving


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_culled_rows_and_clearance_equal_the_full_check(name: str, kitchen: SceneDistance) -> None:
    robot = RobotModel(name)
    config = IKConfig()
    solver = IKSolver(robot, config, kitchen)
    spheres, pairs = solver.spheres, solver.spheres.pairs()
    bounds = LinkBounds(spheres, pairs)  # culls these pairs when given bounds.pairs, the very array
    assert bounds.frame_ids.shape[0] < spheres.radii.shape[0]
    assert bounds.pairs is not None and bounds.pairs is not pairs and np.array_equal(bounds.pairs, pairs)
    data = robot.model.createData()
    rng = np.random.default_rng(11)
    margins = solver.margins
    compared = 0
    for _ in range(40):
        q = np.array(robot.q_home)
        for side in ("left", "right"):
            idx = robot.arm_q_indices(side)
            moved = q[idx] + rng.uniform(-1.2, 1.2, idx.shape[0])
            q[idx] = np.clip(moved, robot.q_lower[idx], robot.q_upper[idx])
        if not robot.floating:  # place the base among the kitchen's furniture
            for joint, value in zip(("base_x_joint", "base_y_joint"), rng.uniform(0.5, 3.0, 2), strict=True):
                if joint in robot.joint_names:
                    q[robot.q_index(joint)] = value
        pin.computeJointJacobians(robot.model, data, q)
        pin.updateFramePlacements(robot.model, data)
        kwargs = dict(margins=margins, activation=config.activation_distance, gain=0.5, max_rows=1000)
        full = collision_rows(robot.model, data, spheres, pairs, kitchen, **kwargs)  # type: ignore[arg-type]
        culled = collision_rows(robot.model, data, spheres, bounds.pairs, kitchen, bounds=bounds, **kwargs)  # type: ignore[arg-type]
        centres = spheres.world(data)  # the pairs' pre-filter keeps exactly the pairs within reach
        a, b = pairs[:, 0], pairs[:, 1]
        gaps = np.linalg.norm(centres[a] - centres[b], axis=1) - spheres.radii[a] - spheres.radii[b]
        assert np.array_equal(bounds.near_pairs(centres, 0.1), np.flatnonzero(gaps < 0.1))
        assert full[0].shape == culled[0].shape
        none = collision_rows(robot.model, data, spheres, pairs, kitchen, **{**kwargs, "max_rows": 0})  # type: ignore[arg-type]
        assert none[0].shape == (0, robot.model.nv) and none[2] == full[2]  # no rows, the same gap
        # the same rows in either order (rounded for the sort: batches of other sizes round differently)
        order_f, order_c = np.lexsort(np.round(full[0], 8).T), np.lexsort(np.round(culled[0], 8).T)
        assert np.allclose(full[0][order_f], culled[0][order_c], atol=1e-9)
        assert np.allclose(full[1][order_f], culled[1][order_c], atol=1e-9)
        exact = min_gap(spheres, spheres.world(data), pairs, kitchen, margins)
        fast = solver.clearance(q)
        cut = solver.clearance(q, within=0.0)  # only cuts into the margins measured
        assert cut == pytest.approx(exact, abs=1e-9) if exact < 0.0 else math.isinf(cut)
        if exact < config.activation_distance:
            assert fast == pytest.approx(exact, abs=1e-9)
            compared += 1
        else:
            assert math.isinf(fast)
    assert compared >= 10
    with pytest.raises(RetargetError, match="repeated"):
        LinkBounds(spheres, np.vstack([pairs, pairs[:1]]))


class _HalfSpace:
    """An obstacle filling the half-space beyond a plane through ``point`` facing ``-normal``: exact
    distances, and lower bounds equal to them (the tightest a scene's bound can be)."""

    def __init__(self, point: np.ndarray, normal: np.ndarray) -> None:
        self.point, self.normal = point, normal / np.linalg.norm(normal)

    def query(self, points: np.ndarray, grounded: object = None) -> tuple[np.ndarray, np.ndarray]:
        points = np.asarray(points).reshape(-1, 3)
        return (self.point - points) @ self.normal, np.tile(-self.normal, (points.shape[0], 1))

    def lower_bound(self, points: np.ndarray, grounded: object = None) -> np.ndarray:
        return self.query(points)[0]


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_a_link_is_kept_by_the_largest_margin_of_its_spheres(name: str) -> None:
    """A link's bounding sphere is culled only when none of its spheres can be within reach of its own
    margin: with the finger tips' smaller margin as the link's reach, a wrist sphere that cuts into its
    scene margin was culled (found on a cabinet top: reported clear, 3 mm inside)."""
    robot = RobotModel(name)
    config = IKConfig(candidate_slack=0.0)
    solver = IKSolver(robot, config)
    spheres, bounds = solver.spheres, solver._bounds
    pin.framesForwardKinematics(robot.model, solver._data, np.array(robot.q_home))
    links, centers = bounds.world(solver._data, spheres)
    margins = solver.margins
    reach, checked = 0.0, 0
    for f in range(links.shape[0]):
        own = np.flatnonzero(bounds.owner == f)
        off = np.linalg.norm(centers[own] - links[f], axis=1)
        k = int(own[np.argmax(off + spheres.radii[own])])  # the sphere on the bound's surface
        if spheres.tips[k] or off.max() < 1e-3:
            continue
        normal = (centers[k] - links[f]) / np.linalg.norm(centers[k] - links[f])
        wall = _HalfSpace(
            centers[k] + normal * (spheres.radii[k] + config.scene_margin + reach - 1e-3), normal
        )
        layers = [(wall, spheres.everyone)]
        kwargs = dict(margins=margins, activation=reach, links=links)
        full = find_candidates(
            spheres, centers, np.zeros((0, 2), np.int64), layers, spheres.grounded, bounds=None, **kwargs
        )  # type: ignore[arg-type]
        culled = find_candidates(
            spheres, centers, np.zeros((0, 2), np.int64), layers, spheres.grounded, bounds=bounds, **kwargs
        )  # type: ignore[arg-type]
        assert k in full[0] and set(full[0].tolist()) == set(culled[0].tolist()), spheres.frames[k]
        along = path_gaps(
            spheres,
            centers[None],
            links[None],
            np.zeros((0, 2), np.int64),
            wall,  # type: ignore[arg-type]
            margins=margins,
            reach=reach,
            bounds=bounds,
        )
        assert along[0] == pytest.approx(float(full[2].min()), abs=1e-12)  # the path check: the same rule
        checked += 1
    assert checked >= 4


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_tight_clearances_culled_alone_and_along_a_path_equal_the_full_check(
    name: str, kitchen: SceneDistance
) -> None:
    """Without the cache's extra reach (a superset) the culling alone must keep every sphere that may cut
    into its margin: a link is kept by the largest margin of its spheres (the scene margin, not the finger
    tips' smaller one). Whole paths (:meth:`IKSolver.clearances`) give the same numbers."""
    robot = RobotModel(name)
    config = IKConfig(candidate_slack=0.0)
    solver = IKSolver(robot, config, kitchen)
    assert solver._cache is None
    spheres, pairs = solver.spheres, solver.spheres.pairs()
    margins = solver.margins
    rng = np.random.default_rng(17)
    qs = np.tile(robot.q_home, (150, 1))
    for q in qs:
        for side in ("left", "right"):
            idx = robot.arm_q_indices(side)
            q[idx] = np.clip(
                q[idx] + rng.uniform(-1.2, 1.2, idx.shape[0]), robot.q_lower[idx], robot.q_upper[idx]
            )
        for joint in ("base_x_joint", "base_y_joint"):
            if joint in robot.joint_names:  # among the kitchen's furniture
                q[robot.q_index(joint)] = rng.uniform(0.5, 3.0)
    exact = np.array([min_gap(spheres, solver.sphere_centers(q), pairs, kitchen, margins) for q in qs])
    cuts = 0
    for within in (-0.002, 0.0, 0.01):
        expected = np.where(exact < within, exact, np.inf)
        alone = np.array([solver.clearance(q, within=within) for q in qs])
        np.testing.assert_allclose(alone, expected, atol=1e-9, rtol=0.0)
        np.testing.assert_array_equal(solver.clearances(qs, within=within), alone)
        cuts += int(np.isfinite(expected).sum())
    assert cuts > 30  # configurations that cut into a margin were checked
    np.testing.assert_array_equal(solver.clearances(qs[:0]), np.zeros(0))
    with pytest.raises(RetargetError, match="reach must be finite"):
        solver.clearances(qs[:2], within=math.inf)


def test_cached_candidates_give_the_same_rows_and_clearances_along_a_path(kitchen: SceneDistance) -> None:
    robot = RobotModel("dual_ur5e")
    cached = IKSolver(robot, IKConfig(candidate_slack=0.05), kitchen)
    fresh = IKSolver(robot, IKConfig(candidate_slack=0.0), kitchen)
    assert cached._cache is not None and fresh._cache is None
    rng = np.random.default_rng(5)
    q = np.array(robot.q_home)
    q[robot.q_index("base_x_joint")], q[robot.q_index("base_y_joint")] = 1.6, 1.0  # among the furniture
    arms = np.concatenate([robot.arm_q_indices(s) for s in ("left", "right")])
    near = 0
    for k in range(150):  # small steps (a few share one choice), and now and then a jump (a new one)
        q[arms] += rng.normal(0.0, 0.3 if k % 25 == 0 else 0.01, arms.shape[0])
        q[arms] = np.clip(q[arms], robot.q_lower[arms], robot.q_upper[arms])
        rows = []
        for solver in (cached, fresh):
            pin.computeJointJacobians(robot.model, solver._data, q)
            pin.updateFramePlacements(robot.model, solver._data)
            rows.append(solver._collision_rows(q))
        np.testing.assert_array_equal(rows[0][0], rows[1][0])
        np.testing.assert_array_equal(rows[0][1], rows[1][1])
        assert rows[0][2] == rows[1][2]
        assert cached.clearance(q, within=0.05) == fresh.clearance(q, within=0.05)
        near += rows[0][0].shape[0] > 0
    assert near > 50  # the rows were not all empty
    assert cached._cache.hits > 100 and 5 < cached._cache.misses < 150
    assert cached._cache.skipped > 100  # spheres the distances at the misses left unmeasured
    holder = SceneDistance.from_spec(load_scene("kitchen"))
    cached.set_part_scene(holder, "left")  # another scene layer: chosen anew
    misses = cached._cache.misses
    cached.clearance(q)
    assert cached._cache.misses == misses + 1


def test_body_box_corners_are_covered_and_the_floor_is_no_body_obstacle() -> None:
    import trimesh

    robot = RobotModel("dual_ur5e")
    spheres = IKSolver(robot).spheres
    base = robot.description.links[1]
    assert base.name == "base_link"
    own = [i for i, f in enumerate(spheres.frames) if f == base.name]
    for geom in base.geoms:
        half = np.asarray(geom.size)
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        corners = (np.asarray(geom.pose)[:3, :3] @ (signs * half).T).T + np.asarray(geom.pose)[:3, 3]
        gap = np.linalg.norm(corners[:, None] - spheres.centers[own][None], axis=2) - spheres.radii[own]
        if half.min() >= 0.1:  # the chassis: every corner within 6 mm of a sphere (scene margin: 20 mm)
            assert np.all(gap.min(axis=1) <= 0.006), gap.min(axis=1)
    floor = trimesh.creation.box(extents=(10.0, 10.0, 0.02))
    floor.apply_translation([0.0, 0.0, -0.01])
    wall = trimesh.creation.box(extents=(0.1, 2.0, 1.0))
    wall.apply_translation([0.4, 0.0, 0.5])  # 5 cm in front of the chassis' front face (x = 0.3 m)
    scene = SceneDistance({"floor": floor, "wall": wall})
    config = IKConfig()
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, robot.q_home)
    pin.updateFramePlacements(robot.model, data)
    margins = (config.scene_margin, config.tip_margin, config.self_margin)  # the dual arm (fixed base)
    kwargs = dict(margins=margins, activation=config.activation_distance, gain=0.5, max_rows=1000)
    rows, lower, _ = collision_rows(robot.model, data, spheres, spheres.pairs()[:0], scene, **kwargs)  # type: ignore[arg-type]
    base_x = robot.v_index("base_x_joint")
    assert rows.shape[0] > 0
    # every row is against the wall: the chassis may not drive forward into it, and no row is a floor row
    # (those would have no base or arm motion that helps: a zero row)
    assert np.all(np.abs(rows).sum(axis=1) > 1e-6)
    assert np.any(rows[:, base_x] < -0.5)
    assert np.all(lower > -0.5 * config.activation_distance)


def test_an_opened_drawer_is_an_obstacle_while_it_stands_open_except_for_its_holder() -> None:
    from types import SimpleNamespace

    from hsi_retarget.part_scene import opened_part

    spec = load_scene("kitchen")
    part = "drawer_unit1/drawer1"

    def key(t: float, hand: str, action: str, obj: str = "") -> SimpleNamespace:
        return SimpleNamespace(time=t, hand=hand, action=action, object_name=obj, contact_event="")

    keys = [key(0.0, "right", "idle"), key(1.0, "right", "reach", part), key(1.5, "right", "open", part)]
    keys += [
        key(2.0, "right", "open", part),
        key(2.5, "right", "hold", part),
        key(3.0, "left", "grasp", "mug1"),
    ]
    keys += [key(4.0, "right", "close", part), key(5.0, "right", "idle")]
    schedule = SimpleNamespace(info={"part": part, "door_hand": "right"}, keyframes=keys)
    phase = opened_part(schedule, spec, exclude=("mug1",))  # type: ignore[arg-type]
    assert phase is not None
    assert (phase.t_open, phase.t_close, phase.t_free, phase.holder) == (2.0, 4.0, 5.0, "right")
    assert phase.at(1.0)[0] is None and phase.at(4.5)[0] is None
    assert phase.at(3.0) == (phase.scene, "right")
    # the opened drawer's front stands ~0.23 m (0.9 of its travel) in front of the closed one
    meshes = scene_meshes(spec)
    centre = np.asarray(meshes[part].bounds).mean(axis=0)
    moved = np.asarray(phase.scene.query(centre[None])[0])
    assert moved[0] > 0.01  # the closed drawer's centre is outside the opened drawer
    robot = RobotModel("dual_ur5e")
    solver = IKSolver(robot, IKConfig(), SceneDistance.from_spec(spec, exclude=[part]))
    solver.set_part_scene(phase.scene, "right")
    assert solver._layer is not None
    heed, spheres = solver._layer[1], solver.spheres
    right = np.zeros(spheres.radii.shape[0], dtype=bool)
    right[spheres.of("right")] = True
    hand = spheres.tips | spheres.palm
    assert not heed[right & hand].any()  # the holding hand closes on the part's handle
    arm = [spheres.frames[i] for i in np.flatnonzero(right & heed)]
    assert {"right_upper_arm_link", "right_forearm_link"} <= set(arm)  # its arm keeps clear of the part
    assert heed[spheres.of("left")].all()
    with pytest.raises(RetargetError, match="holder"):
        solver.set_part_scene(phase.scene, "middle")
    assert opened_part(SimpleNamespace(info={}, keyframes=keys), spec) is None  # type: ignore[arg-type]


def test_the_opened_part_constrains_the_ik_steps_of_the_spheres_that_heed_it() -> None:
    import trimesh

    robot = RobotModel("dual_ur5e")
    config = IKConfig()
    solver = IKSolver(robot, config)  # no scene: only the part layer can add scene rows
    q = np.array(robot.q_home)
    centres = solver.sphere_centers(q)
    left = solver.spheres.of("left")
    tip = int(left[np.argmax(centres[left, 0])])  # the left arm's foremost sphere
    box = trimesh.creation.box(extents=(0.05, 0.3, 0.3))
    box.apply_translation(centres[tip] + [solver.spheres.radii[tip] + config.scene_margin + 0.05, 0.0, 0.0])
    part = SceneDistance({"door": box})
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    margins = solver.margins
    kwargs = dict(margins=margins, activation=config.activation_distance, gain=0.5, max_rows=1000)
    none = np.zeros((0, 2), dtype=np.int64)
    heed_all = np.ones(solver.spheres.radii.shape[0], dtype=bool)
    rows, lower, gap = collision_rows(
        robot.model, data, solver.spheres, none, None, extra=(part, heed_all), **kwargs
    )  # type: ignore[arg-type]
    assert rows.shape[0] >= 1 and gap == pytest.approx(0.05, abs=0.02)  # the part is ~5 cm beyond the margin
    assert np.all(lower < 0.0)  # a velocity damper: the step may close part of the gap, not more
    heed_right = solver.spheres.groups != 0  # the left hand holds it: its spheres are exempt
    assert (
        rows.shape[0]
        > collision_rows(robot.model, data, solver.spheres, none, None, extra=(part, heed_right), **kwargs)[
            0
        ].shape[0]
    )  # type: ignore[arg-type]
    assert collision_rows(robot.model, data, solver.spheres, none, None, **kwargs)[0].shape[0] == 0  # type: ignore[arg-type]
