"""A grasped object as collision geometry of its hand: surface points that cover a real scene object, rows
that match finite differences, an IK that keeps the held object off a shelf top, and the carries of a
retargeted schedule that hold it."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import trimesh

from hsi_planning.errors import RetargetError
from hsi_planning.scene import scene_meshes
from hsi_planning.scene_paths import load_scene
from hsi_retarget.held_object import (
    SPACING,
    HeldObject,
    attach,
    held_rows,
    inner_spheres,
    near_spheres,
    surface_points,
)
from hsi_retarget.ik import IKSolver, IKTargets
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance


@pytest.fixture(scope="module")
def dual() -> RobotModel:
    return RobotModel("dual_ur5e")


@pytest.fixture(scope="module")
def kitchen_meshes() -> dict[str, trimesh.Trimesh]:
    return scene_meshes(load_scene("kitchen"))


@pytest.mark.parametrize("name", ["can1", "mug1", "box1"])
def test_surface_points_lie_on_and_cover_the_object(
    kitchen_meshes: dict[str, trimesh.Trimesh], name: str
) -> None:
    mesh = kitchen_meshes[name]
    points = surface_points(mesh)
    assert 8 <= points.shape[0] <= 96
    dist, _ = SceneDistance({name: mesh}, ground=()).query(points)
    assert np.abs(dist).max() < 1e-5  # on the surface
    probe = np.asarray(trimesh.sample.sample_surface(mesh, 500, seed=1)[0])
    gaps = np.linalg.norm(probe[:, None] - points[None], axis=2).min(axis=1)
    assert gaps.max() < 2.0 * SPACING  # every part of the surface has a point near it
    np.testing.assert_array_equal(points, surface_points(mesh))  # seeded: the same points every time


def test_bad_meshes_and_spacings_are_rejected() -> None:
    with pytest.raises(RetargetError, match="empty"):
        surface_points(trimesh.Trimesh())
    with pytest.raises(RetargetError, match="spacing"):
        surface_points(trimesh.creation.box((0.1, 0.1, 0.1)), spacing=0.0)


def test_attached_points_ride_with_the_tcp(kitchen_meshes: dict[str, trimesh.Trimesh]) -> None:
    rng = np.random.default_rng(3)
    mesh = kitchen_meshes["can1"]
    tcp = np.eye(4)
    tcp[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0] * np.array([1.0, 1.0, 1.0])
    if np.linalg.det(tcp[:3, :3]) < 0:
        tcp[:3, 0] *= -1.0
    tcp[:3, 3] = rng.uniform(-1.0, 1.0, 3)
    shift = np.eye(4)
    shift[:3, 3] = [0.0, 0.2, 0.0]  # e.g. the drawer it stands in pulled out 20 cm
    held = attach("can1", "right", mesh, tcp, shift)
    world = held.points @ tcp[:3, :3].T + tcp[:3, 3]
    centres, radii = inner_spheres(mesh)
    np.testing.assert_allclose(world, np.vstack([surface_points(mesh), centres]) + shift[:3, 3], atol=1e-12)
    assert held.radii is not None
    np.testing.assert_array_equal(held.radii, np.concatenate([np.zeros(world.shape[0] - radii.size), radii]))


@pytest.mark.parametrize("name", ["can1", "bottle1", "box1"])
def test_inner_spheres_stay_inside_and_stop_a_thin_board(
    kitchen_meshes: dict[str, trimesh.Trimesh], name: str
) -> None:
    """The spheres along the object's long axis lie inside it, and an 18 mm board through the object's
    middle, which can pass between its surface points, cuts into them."""
    mesh = kitchen_meshes[name]
    centres, radii = inner_spheres(mesh)
    assert centres.shape[0] >= 1 and np.all(radii > 0.0)
    dist, _ = SceneDistance({name: mesh}, ground=()).query(centres)
    assert np.all(dist <= -radii + 1e-6)  # each sphere inside the mesh (its centre at least r deep)
    middle = mesh.bounding_box_oriented.primitive.transform[:3, 3]
    board = trimesh.creation.box((2.0, 2.0, 0.018))
    board.apply_translation(middle)
    scene = SceneDistance({"board": board}, ground=())
    surface = surface_points(mesh)
    d_surface, _ = scene.query(surface)
    d_spheres, _ = scene.query(centres)
    assert np.min(d_spheres - radii) < -0.005  # the spheres see the board deep inside the object
    assert np.min(d_surface) > -0.02  # (the surface points at best graze it)
    with pytest.raises(RetargetError, match="radii"):
        HeldObject(name, "left", centres, radii[:-1] if radii.size > 1 else np.zeros(2))


def _distance(robot: RobotModel, q: np.ndarray, held: HeldObject, scene: SceneDistance) -> float:
    """[m] the scene distance of the first point of ``held`` at ``q``."""
    pose = robot.fk(q, (robot.tcp_frames[held.side],))[robot.tcp_frames[held.side]]
    return float(scene.query(held.points @ pose[:3, :3].T + pose[:3, 3])[0][0])


def test_held_rows_match_finite_differences(dual: RobotModel) -> None:
    rng = np.random.default_rng(0)
    solver = IKSolver(dual)
    frame = dual.tcp_frames["right"]
    slab = trimesh.creation.box((0.4, 0.4, 0.02))
    q = dual.q_home.copy()
    for _ in range(5):
        for i in dual.arm_q_indices("right"):
            q[i] = dual.q_home[i] + rng.uniform(-0.3, 0.3)
        tcp = dual.fk(q, (frame,))[frame]
        moved = slab.copy()
        moved.apply_translation(tcp[:3, 3] + [0.0, 0.0, 0.25])
        scene = SceneDistance({"slab": moved}, ground=())
        point = HeldObject("box", "right", np.array([[0.05, -0.03, 0.04]]))  # one point in the TCP frame
        jac = dual.jacobian(q, frame)  # world-aligned, linear rows first
        rows, lower = held_rows(point, tcp, jac, [scene], margin=0.0, activation=1.0, gain=1.0, max_rows=1)
        assert rows.shape == (1, dual.nv)

        assert lower[0] == pytest.approx(-_distance(dual, q, point, scene))
        dq = rng.normal(size=dual.nv) * 1e-6
        dq[solver.act[~np.isin(solver.act, dual.arm_v_indices("right"))]] = 0.0
        numeric = _distance(dual, dual.integrate(q, dq), point, scene) - _distance(dual, q, point, scene)
        assert rows[0] @ dq == pytest.approx(numeric, rel=1e-3, abs=1e-10)


def test_ik_keeps_a_held_object_under_a_shelf_top(dual: RobotModel) -> None:
    q = dual.q_home.copy()
    frames = dual.tcp_frames
    tcp = dual.fk(q, (frames["right"],))[frames["right"]]
    left = dual.fk(q, (frames["left"],))[frames["left"]]
    bottle = trimesh.creation.box((0.05, 0.05, 0.3))  # held upright, 25 cm above the TCP
    bottle.apply_translation(tcp[:3, 3] + [0.0, 0.0, 0.1])
    top = trimesh.creation.box((0.3, 0.3, 0.3))  # a thick top, its underside 1 cm above the bottle's top
    top.apply_translation(tcp[:3, 3] + [0.0, 0.0, 0.41])
    scene = SceneDistance({"top": top}, ground=())
    goal = tcp.copy()
    goal[2, 3] += 0.12  # lifts the hand 12 cm: the hand itself stays clear of the top
    held = attach("bottle", "right", bottle, tcp)
    reached = {}
    for holding in (False, True):
        solver = IKSolver(dual, scene=scene)
        if holding:
            solver.hold(held)
            assert set(solver.held) == {"right"}
        result = solver.solve(q, IKTargets(tcp={"right": goal, "left": left}))
        pose = dual.fk(result.q, (frames["right"],))[frames["right"]]
        reached[holding] = float(scene.query(held.points @ pose[:3, :3].T + pose[:3, 3])[0].min())
        assert solver.clearance(result.q) > -1e-3  # the robot's own margins hold either way
        solver.release()
        assert solver.held == {}
    assert reached[False] < -0.05  # without it, the bottle goes 5+ cm into the top
    assert reached[True] == pytest.approx(solver.config.held_margin, abs=1e-3)  # with it, it stops at 1 cm


def test_hold_rejects_an_unknown_hand(dual: RobotModel) -> None:
    solver = IKSolver(dual)
    with pytest.raises(RetargetError, match="valid"):
        solver.hold(HeldObject("can1", "middle", np.zeros((1, 3))))


def test_held_object_rows_against_the_other_arm_match_finite_differences(dual: RobotModel) -> None:
    """A held object keeps the self-collision margin from the other arm and the body: its rows are the
    derivative of the point-to-sphere gaps (both arms moving)."""
    rng = np.random.default_rng(5)
    solver = IKSolver(dual)
    right, left = dual.tcp_frames["right"], dual.tcp_frames["left"]
    q = dual.q_home.copy()
    tcp = dual.fk(q, (right,))[right]
    target = dual.fk(q, (left,))[left][:3, 3] + [0.0, 0.0, 0.12]  # a point 12 cm above the left TCP
    point = HeldObject("box", "right", (np.linalg.inv(tcp) @ np.append(target, 1.0))[None, :3])
    solver.hold(point)
    others = solver._not_arm["right"]

    pin.computeJointJacobians(solver._model, solver._data, q)
    pin.updateFramePlacements(solver._model, solver._data)
    rows, lower = solver._held_rows(IKTargets(), q)
    assert rows.shape[0] == solver.config.max_held_rows  # the closest pairs only
    _, idx, _, gap = near_spheres(
        point,
        tcp,
        solver.sphere_centers(q)[others],
        solver.spheres.radii[others],
        margin=solver.margins[2],
        activation=solver.config.activation_distance,
        max_rows=solver.config.max_held_rows,
    )
    np.testing.assert_allclose(lower, -solver.config.collision_gain * gap)
    assert gap.min() < 0.1  # the left gripper's spheres are near the point
    dq = np.zeros(dual.nv)
    dq[solver.act] = rng.normal(size=solver.act.shape[0]) * 1e-6
    moved = dual.integrate(q, dq)
    pose = dual.fk(moved, (right,))[right]
    world = point.points @ pose[:3, :3].T + pose[:3, 3]
    centers = solver.sphere_centers(moved)[others][idx]
    after = np.linalg.norm(world - centers, axis=1)
    radii = solver.spheres.radii[others][idx]
    origin = np.linalg.norm(target - solver.sphere_centers(q)[others][idx], axis=1) - radii
    np.testing.assert_allclose(rows @ dq, after - radii - origin, rtol=1e-3, atol=1e-10)
