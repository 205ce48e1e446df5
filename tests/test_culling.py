"""Collision culling (:mod:`hsi_retarget.culling`): the scene distance's lower bound never exceeds the exact
distance, and culled IK constraint rows and clearances equal the unculled ones on the kitchen scene."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from hsi_planning.scene_paths import load_scene
from hsi_retarget.collision import collision_rows, min_gap
from hsi_retarget.culling import LinkBounds
from hsi_retarget.ik import IKConfig, IKSolver
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
    reach = np.full(points.shape[0], 0.1)
    dist, grad = kitchen.query_within(points, reach)
    near = exact < 0.1
    assert np.allclose(dist[near], exact[near], atol=1e-6)
    assert np.all(dist[~near] >= np.minimum(exact[~near], 0.1) - 1e-6)
    assert np.all(dist <= exact + 1e-5)
    assert np.allclose(np.linalg.norm(grad[dist < 0.1], axis=1), 1.0)


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_culled_rows_and_clearance_equal_the_full_check(name: str, kitchen: SceneDistance) -> None:
    robot = RobotModel(name)
    config = IKConfig()
    solver = IKSolver(robot, config, kitchen)
    spheres, pairs = solver.spheres, solver.spheres.pairs()
    bounds = LinkBounds(spheres, pairs)
    assert bounds.link_pairs.shape[0] < pairs.shape[0]
    data = robot.model.createData()
    rng = np.random.default_rng(11)
    margins = (config.scene_margin, config.tip_margin, config.self_margin)
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
        culled = collision_rows(robot.model, data, spheres, pairs, kitchen, bounds=bounds, **kwargs)  # type: ignore[arg-type]
        assert full[0].shape == culled[0].shape
        order_f, order_c = np.lexsort(full[0].T), np.lexsort(culled[0].T)
        assert np.allclose(full[0][order_f], culled[0][order_c], atol=1e-9)
        assert np.allclose(full[1][order_f], culled[1][order_c], atol=1e-9)
        exact = min_gap(spheres, spheres.world(data), pairs, kitchen, margins)
        fast = solver.clearance(q)
        if exact < config.activation_distance:
            assert fast == pytest.approx(exact, abs=1e-9)
            compared += 1
        else:
            assert math.isinf(fast)
    assert compared >= 10
