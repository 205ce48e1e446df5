"""Differential IK: convergence on reachable targets, limits, collision margins (scene wall, other arm),
humanoid feet and centre of mass, Jacobians against finite differences."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError, RetargetError
from hsi_planning.scheduler.body import wrist_quaternion
from hsi_retarget.collision import robot_spheres
from hsi_retarget.humanoid_ik import SupportConfig, com_inside, support_polygon
from hsi_retarget.ik import IKConfig, IKSolver, IKTargets, solve_cascade
from hsi_retarget.mapping import MappingConfig
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance

SIDES = ("left", "right")


@pytest.fixture(scope="module")
def robots() -> dict[str, RobotModel]:
    return {name: RobotModel(name) for name in ("dual_ur5e", "humanoid")}


def _feet(robot: RobotModel) -> dict[str, np.ndarray]:
    if not robot.floating:
        return {}
    return {s: robot.frame_pose(robot.q_home, f"{s}_sole") for s in SIDES}


def _root(robot: RobotModel) -> np.ndarray | None:
    return robot.frame_pose(robot.q_home, "pelvis") if robot.floating else None


def _com(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    return np.asarray(pin.centerOfMass(robot.model, robot.model.createData(), q))


def _random_targets(
    robot: RobotModel, solver: IKSolver, rng: np.random.Generator, count: int
) -> list[dict[str, np.ndarray]]:
    """TCP poses of random arm configurations near home that are collision-free and balanced."""
    out = []
    while len(out) < count:
        q = np.array(robot.q_home)
        for side in SIDES:
            idx = robot.arm_q_indices(side)
            q[idx] = np.clip(
                q[idx] + rng.uniform(-0.6, 0.6, idx.shape[0]), robot.q_lower[idx], robot.q_upper[idx]
            )
        if solver.clearance(q) < 0.01:
            continue
        if robot.floating and not com_inside(
            _com(robot, q)[:2], list(_feet(robot).values()), SupportConfig()
        ):
            continue
        out.append({s: robot.frame_pose(q, robot.tcp_frames[s]) for s in SIDES})
    return out


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_reaches_random_reachable_targets_within_1mm_1deg(robots: dict[str, RobotModel], name: str) -> None:
    robot = robots[name]
    solver = IKSolver(robot)
    rng = np.random.default_rng(7)
    for goal in _random_targets(robot, solver, rng, 5):
        result = solver.solve(robot.q_home, IKTargets(tcp=goal, root=_root(robot), feet=_feet(robot)))
        assert result.iterations < 100, (result.position_error, result.orientation_error)
        for side in SIDES:
            assert result.position_error[side] < 1e-3
            assert np.degrees(result.orientation_error[side]) < 1.0
        assert robot.within_limits(result.q)


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_limits_never_violated_for_random_goals(robots: dict[str, RobotModel], name: str) -> None:
    """Property: random goals (many out of reach) never drive a joint past its position limit, and one
    step with ``dt`` never exceeds the velocity limits."""
    robot = robots[name]
    solver = IKSolver(robot, IKConfig(max_step=0.5))
    rng = np.random.default_rng(11)
    dt = 1.0 / 60.0
    v_max = robot.v_max
    for _ in range(6):
        q = robot.random_configuration(rng) if not robot.floating else np.array(robot.q_home)
        if not robot.floating:
            q = np.clip(q, robot.q_lower, robot.q_upper)
        shoulder = robot.frame_pose(robot.q_home, robot.shoulder_frames["right"])[:3, 3]
        goal = np.eye(4)
        goal[:3, :3] = pin.exp3(rng.normal(size=3))
        goal[:3, 3] = shoulder + rng.uniform(-2.0, 2.0, 3)
        targets = IKTargets(tcp={"right": goal}, root=_root(robot), feet=_feet(robot))
        for _ in range(8):
            q_new, _info = solver.step(q, targets, dt)
            assert robot.within_limits(q_new, tol=1e-9)
            moved = pin.difference(robot.model, q, q_new)
            limited = np.isfinite(v_max)
            assert np.all(np.abs(moved[limited]) <= v_max[limited] * dt + 1e-9)
            q = q_new


def test_unreachable_target_leaves_a_residual_not_a_crash(robots: dict[str, RobotModel]) -> None:
    robot = robots["dual_ur5e"]
    solver = IKSolver(robot)
    goal = robot.frame_pose(robot.q_home, "right_tcp")
    goal[:3, 3] = [4.0, -0.25, 1.0]  # 4 m ahead; the base goal (origin) and the TCP goal compete
    result = solver.solve(robot.q_home, IKTargets(tcp={"right": goal}, root=np.eye(4)), iterations=80)
    assert not result.converged
    assert result.position_error["right"] > 1.0
    assert robot.within_limits(result.q)


def test_collision_margin_to_a_wall_in_front_of_the_arm(robots: dict[str, RobotModel]) -> None:
    robot = robots["dual_ur5e"]
    wall_x = 0.65  # the wall's near face [m]
    wall = trimesh.creation.box(extents=(0.05, 2.0, 2.0))
    wall.apply_translation([wall_x + 0.025, 0.0, 1.0])
    scene = SceneDistance({"wall": wall})
    config = IKConfig(scene_margin=0.03)
    goal = robot.frame_pose(robot.q_home, "right_tcp")
    goal[:3, 3] = [0.95, -0.25, 1.0]  # behind the wall
    targets = IKTargets(tcp={"right": goal}, root=np.eye(4), lift=0.225)
    free = IKSolver(robot, config).solve(robot.q_home, targets, iterations=150)
    assert free.position_error["right"] < 1e-3  # without the wall it is reachable
    walled = IKSolver(robot, config, scene)
    result = walled.solve(robot.q_home, targets, iterations=150)
    centers = walled.sphere_centers(result.q)
    dist, _ = scene.query(centers)
    clearance = dist - walled.spheres.radii
    tips = walled.spheres.tips
    body = clearance[~tips]
    far = config.tip_margin_far  # no contact here: the fingers keep the wider margin
    assert body.min() >= config.scene_margin - 2e-3, body.min()
    assert clearance[tips].min() >= far - 2e-3, clearance[tips].min()
    # it pressed up to the margin (the fingers or the gripper body stop it)
    assert min(body.min() - config.scene_margin, clearance[tips].min() - far) < 0.005
    tcp_x = robot.frame_pose(result.q, "right_tcp")[0, 3]
    assert tcp_x < wall_x - far
    assert result.position_error["right"] > 0.25
    # at a contact the fingers may close in to tip_margin (the goal behind the wall pulls them there)
    closing = IKTargets(tcp={"right": goal}, root=np.eye(4), lift=0.225, contact={"right": 1.0})
    near = walled.solve(robot.q_home, closing, iterations=150)
    tip_gap = (scene.query(walled.sphere_centers(near.q))[0] - walled.spheres.radii)[tips].min()
    assert config.tip_margin - 2e-3 <= tip_gap < far - 3e-3, tip_gap
    with pytest.raises(ConfigError, match="tip_margin_far"):
        IKConfig(tip_margin=0.01, tip_margin_far=0.005)


def test_a_humanoid_keeps_wider_margins_for_its_lag(robots: dict[str, RobotModel]) -> None:
    """A floating robot's fingers keep ``tip_margin_far_floating`` away from a contact and its body spheres
    ``scene_margin + body_margin_floating`` (its hands and trunk lag their command in MuJoCo); at a contact
    the fingers still close in to ``tip_margin``."""
    robot = robots["humanoid"]
    wall_x = 0.4  # the wall's near face [m], within arm's reach in front of the pelvis
    wall = trimesh.creation.box(extents=(0.05, 2.0, 2.0))
    wall.apply_translation([wall_x + 0.025, 0.0, 1.0])
    scene = SceneDistance({"wall": wall})
    config = IKConfig(max_step=0.01)  # small steps, as when tracking at 60 Hz (rows are linearized)
    assert config.tip_margin_far_floating > config.tip_margin_far
    solver = IKSolver(robot, config, scene)
    goal = robot.frame_pose(robot.q_home, "right_tcp")
    goal[:3, 3] = [0.7, -0.2, 1.1]  # behind the wall
    targets = IKTargets(tcp={"right": goal}, root=_root(robot), feet=_feet(robot))
    gaps = []
    for contact in (0.0, 1.0):
        closeness = dataclasses.replace(targets, contact={"right": contact})
        result = solver.solve(robot.q_home, closeness, iterations=400)
        clearance = scene.query(solver.sphere_centers(result.q))[0] - solver.spheres.radii
        tips, body = solver.spheres.tips, solver.spheres.groups == 2
        assert clearance[body].min() >= config.scene_margin + config.body_margin_floating - 2e-3
        gaps.append(float(clearance[tips].min()))
    assert gaps[0] >= config.tip_margin_far_floating - 2e-3, gaps
    assert config.tip_margin - 2e-3 <= gaps[1] < config.tip_margin_far - 3e-3, gaps


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_arms_keep_the_self_margin_when_their_goals_cross(robots: dict[str, RobotModel], name: str) -> None:
    robot = robots[name]
    config = IKConfig(self_margin=0.02, self_margin_floating=0.04)
    margin = config.self_margin_floating if robot.floating else config.self_margin
    solver = IKSolver(robot, config)
    left = robot.frame_pose(robot.q_home, "left_tcp")
    right = robot.frame_pose(robot.q_home, "right_tcp")
    height = 1.0 if name == "dual_ur5e" else 1.1
    x = 0.5 if name == "dual_ur5e" else 0.35
    left[:3, 3], right[:3, 3] = [x, -0.05, height], [x, 0.05, height]  # each hand beyond the other
    root = _root(robot) if robot.floating else np.eye(4)
    targets = IKTargets(tcp={"left": left, "right": right}, root=root, feet=_feet(robot))
    result = solver.solve(robot.q_home, targets, iterations=150)
    centers = solver.sphere_centers(result.q)
    sph = solver.spheres
    a, b = sph.of("left"), sph.of("right")
    gaps = (
        np.linalg.norm(centers[a][:, None] - centers[b][None], axis=2)
        - sph.radii[a][:, None]
        - sph.radii[b][None]
    )
    assert gaps.min() >= margin - 2e-3
    assert result.position_error["left"] > 0.01  # the crossing goals cannot both be met


def test_humanoid_feet_fixed_and_com_inside_while_wrists_track(robots: dict[str, RobotModel]) -> None:
    robot = robots["humanoid"]
    support = SupportConfig()
    solver = IKSolver(robot, support=support)
    feet = _feet(robot)
    q = np.array(robot.q_home)
    start = {s: robot.frame_pose(q, robot.tcp_frames[s]) for s in SIDES}
    dt = 1.0 / 60.0
    errors = []
    for k in range(90):  # wrists sweep forward/out and up/down by 25 cm
        phase = 2.0 * np.pi * k / 90.0
        tcp = {}
        for side, sign in (("left", 1.0), ("right", -1.0)):
            pose = np.array(start[side])
            pose[:3, 3] += [0.25 * np.sin(phase / 2), sign * 0.1 * np.sin(phase), 0.25 * np.sin(phase)]
            tcp[side] = pose
        targets = IKTargets(tcp=tcp, root=_root(robot), feet=feet)
        q_start = q
        for _ in range(3):
            q, _info = solver.step(q, targets, dt * 3.0, q_start)
        fk = robot.fk(q, ("left_sole", "right_sole"))
        for side in SIDES:
            assert np.linalg.norm(fk[f"{side}_sole"][:3, 3] - feet[side][:3, 3]) < 1e-3
        assert com_inside(_com(robot, q)[:2], list(feet.values()), support, tol=1e-4)
        pos, _ori = solver.errors(q, targets)
        errors.append(max(pos.values()))
    assert np.median(errors) < 0.01, np.median(errors)


def test_humanoid_side_grasp_with_the_forearm_about_neutral(robots: dict[str, RobotModel]) -> None:
    """A person's side grasp of an upright object in front at chest height (wrist x forward, thumb up,
    mapped with the default ``wrist_to_tcp``) is reached with the humanoid's forearm about neutral, as a
    person does it: its fingers close along a human palm's normal."""
    robot = robots["humanoid"]
    wrist = Rotation.from_quat(wrist_quaternion([1.0, 0.0, 0.0])).as_matrix()
    to_tcp = Rotation.from_rotvec(MappingConfig().wrist_to_tcp_rotvec).as_matrix()
    tcp = {}
    for side, y in (("left", 0.2), ("right", -0.2)):
        goal = np.eye(4)
        goal[:3, :3], goal[:3, 3] = wrist @ to_tcp, (0.45, y, 1.1)
        tcp[side] = goal
    result = IKSolver(robot).solve(robot.q_home, IKTargets(tcp=tcp, root=_root(robot), feet=_feet(robot)))
    for side in SIDES:
        assert result.position_error[side] < 5e-3 and np.degrees(result.orientation_error[side]) < 3.0
        assert abs(result.q[robot.q_index(f"{side}_wrist_yaw")]) < 0.2  # of +-1.4 rad


def test_a_humanoid_hinges_at_the_hips_to_reach_low_and_far(robots: dict[str, RobotModel]) -> None:
    """Both hands 0.7 m in front at 0.45 m height (feet planted, a level pelvis goal): with the pelvis tilt
    weighted at ``root_tilt_factor`` 0.1 the pelvis tilts forward over the hips and the hands get closer
    than with the tilt weighted as the rest of the pelvis goal, the CoM staying over the feet."""
    robot = robots["humanoid"]
    feet, root = _feet(robot), _root(robot)
    tcp = {}
    for side, y in (("left", 0.15), ("right", -0.15)):
        goal = robot.frame_pose(robot.q_home, robot.tcp_frames[side])
        goal[:3, 3] = (0.7, y, 0.45)
        tcp[side] = goal
    reach, tilt = {}, {}
    for factor in (1.0, 0.1):
        solver = IKSolver(robot, IKConfig(root_tilt_factor=factor))
        result = solver.solve(robot.q_home, IKTargets(tcp=tcp, root=root, feet=feet))
        reach[factor] = max(result.position_error.values())
        tilt[factor] = np.degrees(np.arccos(robot.frame_pose(result.q, "pelvis")[2, 2]))
        fk = robot.fk(result.q, ("left_sole", "right_sole"))
        for side in SIDES:
            assert np.linalg.norm(fk[f"{side}_sole"][:3, 3] - feet[side][:3, 3]) < 1e-3
        assert com_inside(_com(robot, result.q)[:2], list(feet.values()), SupportConfig(), tol=1e-4)
    assert reach[0.1] < 0.7 * reach[1.0], reach
    assert tilt[0.1] > 5.0 > tilt[1.0] + 2.0, tilt
    with pytest.raises(ConfigError, match="root_tilt_factor"):
        IKConfig(root_tilt_factor=-0.1)


def _walking_pelvis(robot: RobotModel, x: np.ndarray) -> np.ndarray:
    """(T, 4, 4) upright pelvis goals at the home height, at forward positions ``x`` (T,) [m]."""
    pelvis = np.tile(np.eye(4), (x.shape[0], 1, 1))
    pelvis[:, 2, 3] = robot.q_home[2]
    pelvis[:, 0, 3] = x
    return pelvis


def test_footsteps_shift_the_weight_and_crouch_smoothly(robots: dict[str, RobotModel]) -> None:
    from hsi_retarget.humanoid_ik import _swing, plan_footsteps

    robot, cfg = robots["humanoid"], SupportConfig()
    t = np.arange(0.0, 6.0, 1.0 / 60.0)
    pelvis = _walking_pelvis(robot, np.clip(t - 0.5, 0.0, 0.6))  # the pelvis goal walks 60 cm forward
    steps = plan_footsteps(robot, t, pelvis, cfg)
    assert len(steps.steps) >= 4  # two step pairs at least (45 cm steps at most)
    xy = np.where(np.isfinite(steps.com), steps.com, pelvis[:, :2, 3])  # the pelvis xy goal the IK gets
    speed = np.linalg.norm(np.diff(xy, axis=0), axis=1) * 60.0
    # [m/s]: no jump between the feet or back under the pelvis: a min-jerk shift over the widest stance
    # peaks at 1.875 x its mean speed
    spread = np.linalg.norm(steps.feet["left"][:, :2, 3] - steps.feet["right"][:, :2, 3], axis=1).max()
    assert speed.max() < 1.9 * spread / cfg.shift_time, (speed.max(), spread)
    crouch_speed = np.abs(np.diff(steps.crouch)).max() * 60.0  # [m/s]: the pelvis lowers and rises gently
    assert crouch_speed < 1.9 * cfg.step_crouch / cfg.shift_time
    assert steps.crouch[-1] == 0.0 and np.isnan(steps.com[-1]).all()  # upright and free after the steps
    for j, sides in enumerate(steps.support):  # on one foot the weight is over it
        if len(sides) == 1:
            np.testing.assert_allclose(steps.com[j], steps.feet[sides[0]][j][:2, 3], atol=1e-9)
    u = 0.99999999  # the min-jerk polynomial rounds past 1 here: a swing's slerp must not see that
    assert 10 * u**3 - 15 * u**4 + 6 * u**5 > 1.0
    np.testing.assert_allclose(_swing(np.eye(4), np.eye(4), u, 0.05), np.eye(4), atol=1e-6)


def test_footsteps_turn_around_in_steps_the_hips_can_take(robots: dict[str, RobotModel]) -> None:
    from hsi_retarget.humanoid_ik import _yaw, plan_footsteps

    robot, cfg = robots["humanoid"], SupportConfig()
    t = np.arange(0.0, 8.0, 1.0 / 60.0)
    pelvis = _walking_pelvis(robot, np.zeros(t.shape[0]))
    heading = math.pi * np.clip((t - 0.5) / 1.5, 0.0, 1.0) * 0.999  # turns around on the spot in 1.5 s
    pelvis[:, 0, 0] = pelvis[:, 1, 1] = np.cos(heading)
    pelvis[:, 1, 0], pelvis[:, 0, 1] = np.sin(heading), -np.sin(heading)

    def spread(feet: dict[str, np.ndarray]) -> np.ndarray:  # (T,) [rad] heading of one sole from the other
        rel = np.array([_yaw(a) - _yaw(b) for a, b in zip(feet["left"], feet["right"], strict=True)])
        return np.abs((rel + math.pi) % (2.0 * math.pi) - math.pi)

    steps = plan_footsteps(robot, t, pelvis, cfg)
    assert spread(steps.feet).max() <= cfg.max_step_yaw + 1e-9
    for side in ("left", "right"):  # facing the new way in the end
        end = _yaw(steps.feet[side][-1]) - heading[-1]
        assert abs((end + math.pi) % (2.0 * math.pi) - math.pi) <= cfg.yaw_threshold
    # without the limit one step turned a foot by ~ 150 deg: more than the hips' yaw range (+-0.7 rad) allows
    free = plan_footsteps(robot, t, pelvis, SupportConfig(max_step_yaw=4.0))
    assert spread(free.feet).max() > 1.4
    assert len(free.steps) < len(steps.steps)


def test_footsteps_keep_up_with_a_walking_pelvis(robots: dict[str, RobotModel]) -> None:
    from hsi_retarget.humanoid_ik import _stance, plan_footsteps

    robot, cfg = robots["humanoid"], SupportConfig()
    t = np.arange(0.0, 6.0, 1.0 / 60.0)
    pelvis = _walking_pelvis(robot, np.clip((t - 0.5) / 1.5, 0.0, 1.0))  # 1 m at 0.67 m/s, stops at 2.0 s
    steps = plan_footsteps(robot, t, pelvis, cfg)
    final = _stance(robot, pelvis[-1])
    after = np.flatnonzero(t >= 4.0)  # 2 s after the pelvis stopped: on both feet, under it
    for j in after:
        assert steps.support[j] == ("left", "right")
        for side, pose in final.items():
            assert np.linalg.norm(steps.feet[side][j][:2, 3] - pose[:2, 3]) <= cfg.step_threshold
    assert max(float(s["length_m"]) for s in steps.steps) <= cfg.max_step_length + 1e-9
    # with the former 25 cm steps of 0.7 s the feet were still 0.7 m behind at 4 s (0.5 m at 5 s)
    former = SupportConfig(max_step_length=0.25, shift_time=0.3, swing_time=0.4, lookahead=0.0)
    slow = plan_footsteps(robot, t, pelvis, former)
    assert np.linalg.norm(slow.feet["left"][after[0]][:2, 3] - final["left"][:2, 3]) > 0.3


def test_footsteps_leave_before_the_pelvis_goal_moves_on(robots: dict[str, RobotModel]) -> None:
    """With the look-ahead the first step starts before the pelvis goal has moved the step threshold
    (a door swinging after the hand finds the feet gone), and the feet arrive no later than without it."""
    from hsi_retarget.humanoid_ik import _stance, plan_footsteps

    robot = robots["humanoid"]
    t = np.arange(0.0, 6.0, 1.0 / 60.0)
    pelvis = _walking_pelvis(robot, np.clip((t - 1.5) / 1.5, 0.0, 1.0) * 0.6)  # 60 cm from 1.5 s to 3 s
    late = plan_footsteps(robot, t, pelvis, SupportConfig(lookahead=0.0))
    early = plan_footsteps(robot, t, pelvis, SupportConfig(lookahead=1.1))
    first_late, first_early = float(late.steps[0]["t_start"]), float(early.steps[0]["t_start"])
    moved = np.linalg.norm(pelvis[:, :2, 3] - pelvis[0, :2, 3], axis=1)
    assert moved[int(np.searchsorted(t, first_late))] > SupportConfig().step_threshold - 0.02
    assert first_early < 1.5 < first_late  # the feet leave before the body does
    final = _stance(robot, pelvis[-1])

    def arrived(steps: Any) -> float:  # [s] both soles within 5 cm of the final stance from then on
        near = np.ones(t.shape[0], dtype=bool)
        for side, pose in final.items():
            near &= np.linalg.norm(steps.feet[side][:, :2, 3] - pose[:2, 3], axis=1) < 0.05
        assert near[-1]
        return float(t[np.flatnonzero(~near).max() + 1])

    assert arrived(early) <= arrived(late)
    with pytest.raises(ConfigError, match="lookahead"):
        SupportConfig(lookahead=-0.1)


def test_support_polygon_is_the_hull_of_both_soles(robots: dict[str, RobotModel]) -> None:
    robot = robots["humanoid"]
    cfg = SupportConfig(com_margin=0.0)
    normals, offsets = support_polygon(list(_feet(robot).values()), cfg)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0) and offsets.shape == (normals.shape[0],)
    # soles at x 0.045 +/- 0.13, y +/-(0.09 + 0.05)
    assert com_inside(np.array([0.17, 0.13]), list(_feet(robot).values()), cfg)
    assert not com_inside(np.array([0.18, 0.0]), list(_feet(robot).values()), cfg)
    assert not com_inside(np.array([0.0, 0.15]), list(_feet(robot).values()), cfg)


@pytest.mark.parametrize("name", ["dual_ur5e", "humanoid"])
def test_tcp_jacobian_matches_finite_differences(robots: dict[str, RobotModel], name: str) -> None:
    robot = robots[name]
    rng = np.random.default_rng(3)
    q = np.clip(robot.random_configuration(rng, root_box=0.2), robot.q_lower, robot.q_upper)
    jac = robot.jacobian(q, "right_tcp")
    pose0 = robot.frame_pose(q, "right_tcp")
    eps = 1e-6
    numeric = np.zeros_like(jac)
    for k in range(robot.nv):
        dq = np.zeros(robot.nv)
        dq[k] = eps
        pose = robot.frame_pose(robot.integrate(q, dq), "right_tcp")
        numeric[:3, k] = (pose[:3, 3] - pose0[:3, 3]) / eps
        numeric[3:, k] = pin.log3(pose[:3, :3] @ pose0[:3, :3].T) / eps
    assert np.allclose(jac, numeric, atol=1e-5)


def test_spheres_cover_the_arms_gripper_and_finger_tips(robots: dict[str, RobotModel]) -> None:
    for robot in robots.values():
        spheres = robot_spheres(robot)
        frames = np.array(spheres.frames)
        assert "right_gripper_link" in frames and any(f.startswith("right_forearm") for f in frames)
        upper = {f for f, p in zip(frames, spheres.proximal, strict=True) if p}  # upper arm (and shoulder)
        assert any("upper_arm" in f for f in upper) and not any("forearm" in f for f in upper)
        pairs = spheres.pairs()  # the upper arm is kept off the other arm, not off the body it hangs from
        body = set(spheres.of("body").tolist())
        assert not any(spheres.proximal[a] and b in body for a, b in pairs.tolist())
        assert any(spheres.proximal[a] and spheres.proximal[b] for a, b in pairs.tolist())
        assert set(frames[spheres.tips]) == {f"{s}_finger_{k}" for s in SIDES for k in "ab"}
        assert all(len(spheres.of(g)) > 0 for g in ("left", "right", "body"))
        assert np.all(spheres.radii > 0.0)


def test_finger_boxes_stick_out_of_their_spheres_by_at_most_the_allowance(
    robots: dict[str, RobotModel],
) -> None:
    from hsi_retarget.collision import FINGER_UNCOVERED

    rng = np.random.default_rng(2)
    for robot in robots.values():
        spheres = robot_spheres(robot)
        for link in robot.description.links:
            own = [i for i, f in enumerate(spheres.frames) if f == link.name]
            boxes = [g for g in link.geoms if g.kind == "box"]
            if not (own and boxes and spheres.tips[own[0]]):
                continue
            for geom in boxes:  # points on the box's faces: outside the spheres by at most the allowance
                half, pose = np.asarray(geom.size), np.asarray(geom.pose)
                u = rng.uniform(-1.0, 1.0, (5000, 3))
                face = rng.integers(0, 3, 5000)
                u[np.arange(5000), face] = np.sign(u[np.arange(5000), face])
                pts = (pose[:3, :3] @ (u * half).T).T + pose[:3, 3]
                gap = np.linalg.norm(pts[:, None] - spheres.centers[own][None], axis=2) - spheres.radii[own]
                assert gap.min(axis=1).max() <= FINGER_UNCOVERED + 1e-6, (robot.name, geom.name)
                # and the finger stays thin: the spheres bulge past its thin faces by a few mm only
                thin = int(np.argmin(half))
                local = (spheres.centers[own] - pose[:3, 3]) @ pose[:3, :3]
                bulge = np.abs(local[:, thin]) + spheres.radii[own] - half[thin]
                assert bulge.max() < 0.004, (robot.name, geom.name, bulge.max())


def test_bad_config_is_rejected() -> None:
    with pytest.raises(ConfigError, match="collision_gain"):
        IKConfig(collision_gain=0.0)
    with pytest.raises(ConfigError, match="position_weight"):
        IKConfig(position_weight=-1.0)
    with pytest.raises(ConfigError, match="com_margin"):
        SupportConfig(com_margin=0.2)


def test_scene_distance_is_signed_and_robust_next_to_edges() -> None:
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    points = np.array(
        [[0.0, 0.0, 0.0], [0.4, 0.0, 0.0], [0.50001, 0.0, 0.8], [0.9, 0.0, 0.0], [0.5, 0.5, 1.0]]
    )
    dist, grad = SceneDistance({"box": box}).query(points)
    assert np.allclose(dist, [-0.5, -0.1, 0.3, 0.4, 0.5], atol=1e-4)
    assert np.allclose(np.linalg.norm(grad, axis=1), 1.0)
    step = points + 1e-3 * grad  # moving along the gradient increases the distance
    assert np.all(SceneDistance({"box": box}).query(step)[0] > dist)
    with pytest.raises(RetargetError, match="no scene mesh"):
        SceneDistance({"box": box}, exclude=["box"])


def test_a_hand_at_a_contact_wins_over_the_base_goal(robots: dict[str, RobotModel]) -> None:
    """Contact weights: with the base held at its goal, a TCP goal out of reach is closed further when the
    hand is at a contact, and further still when it holds a handle; invalid factors are rejected."""
    robot = robots["dual_ur5e"]
    solver = IKSolver(robot, IKConfig(self_collision=False))
    goal = robot.frame_pose(robot.q_home, robot.tcp_frames["right"])
    goal[:3, 3] += [0.45, -0.1, -0.35]  # farther than the arm reaches with the base at its goal
    root = np.eye(4)
    errors = []
    for contact, holding in ((0.0, ()), (1.0, ()), (1.0, ("right",))):
        targets = IKTargets(
            tcp={"right": goal}, root=root, contact={"right": contact} if contact else {}, holding=holding
        )
        result = solver.solve(np.array(robot.q_home), targets, 150)
        errors.append(result.position_error["right"])
    assert errors[1] < 0.5 * errors[0] and errors[0] > 0.01
    assert errors[2] < 0.5 * errors[1]  # a hand holding a door's or drawer's handle wins more
    with pytest.raises(ConfigError):
        IKConfig(contact_position_factor=0.5)
    with pytest.raises(ConfigError, match="hold_factor"):
        IKConfig(hold_factor=0.5)


def test_the_base_turns_the_long_way_round_when_the_short_way_ends_past_its_yaw_limit(
    robots: dict[str, RobotModel],
) -> None:
    robot = robots["dual_ur5e"]
    yaw = robot.q_index("base_yaw_joint")
    lower = float(robot.q_lower[yaw])
    q = np.array(robot.q_home)
    q[yaw] = lower + 0.1  # near the lower limit; the goal is 0.3 rad short of it the short way round
    goal = np.eye(4)
    goal[:3, :3] = Rotation.from_euler("z", lower - 0.2).as_matrix()
    solver = IKSolver(robot, IKConfig(self_collision=False))
    targets = IKTargets(root=goal)
    turned = []
    for _ in range(40):
        q, _ = solver.step(q, targets, dt=1.0 / 60.0)
        turned.append(q[yaw])
        assert robot.within_limits(q)
    assert turned[-1] > lower + 0.5  # under way the long way round, not pressed against the limit
    assert np.all(np.diff(turned) > -1e-9)


def test_a_humanoid_keeps_its_thighs_off_the_furniture(robots: dict[str, RobotModel]) -> None:
    """The thighs carry spheres (body group: measured without the floor, kept off the distal arms); a
    counter front 3 cm before a thigh is the closest obstacle, and IK steps move the thigh away from it."""
    from hsi_retarget.collision import GROUPS

    robot = robots["humanoid"]
    spheres = robot_spheres(robot)
    thighs = np.array([i for i, f in enumerate(spheres.frames) if f.endswith("_thigh")])
    assert thighs.size and np.all(spheres.groups[thighs] == GROUPS.index("body"))
    assert not spheres.grounded[thighs].any()
    assert not any("thigh" in f for f in robot_spheres(robots["dual_ur5e"]).frames)
    solver = IKSolver(robot)
    centres = solver.sphere_centers(robot.q_home)
    front = float((centres[thighs, 0] + spheres.radii[thighs]).max())
    counter = trimesh.creation.box(extents=(0.6, 2.0, 0.6))
    counter.apply_translation((front + 0.03 + 0.3, 0.0, 0.3))  # its front 3 cm before the thighs, 60 cm high
    targets = IKTargets(root=_root(robot), feet=_feet(robot))
    pelvis = np.array(_root(robot))
    pelvis[0, 3] += 0.05  # the pelvis goal 5 cm into the counter: the thighs' rows hold the body back
    gaps = {}
    for body_margin in (0.0, 0.02):  # the body's extra margin (its lag in MuJoCo) holds it 2 cm farther
        config = IKConfig(self_collision=False, body_margin_floating=body_margin)
        solver = IKSolver(robot, config, SceneDistance({"counter": counter}))
        q = np.array(robot.q_home)
        start = solver.clearance(q)
        assert start == pytest.approx(0.03 - config.scene_margin, abs=0.002)  # a thigh is the closest
        for _ in range(30):
            q, _ = solver.step(q, dataclasses.replace(targets, root=pelvis), 1.0 / 60.0)
        gaps[body_margin] = solver.clearance(q)  # beyond scene_margin
        assert gaps[body_margin] > body_margin - 0.003
    assert gaps[0.0] < 0.01 and gaps[0.02] > gaps[0.0] + 0.01


def test_an_infeasible_foot_row_softens_before_the_collision_rows_go() -> None:
    """A swing foot that cannot make its step inside the box (an equality row) must not take the collision
    rows with it: the cascade softens the foot first and keeps "do not get closer"."""
    hess, grad = np.eye(2), np.array([1.0, 0.0])  # the task pulls x down, towards the obstacle
    rows = np.array([[1.0, 0.0], [0.0, 1.0]])  # x: clearance row (inequality), y: the foot (equality)
    lo, hi = np.array([0.5, 1.0]), np.array([np.inf, 1.0])  # 0.5: the step starts inside the margin
    box = (np.full(2, -0.1), np.full(2, 0.1))
    dx, ok, level = solve_cascade(hess, grad, rows, (lo, hi), box)
    assert ok and level == 2
    assert dx[0] == pytest.approx(0.0, abs=1e-9)  # no closer, though the task pulls
    assert dx[1] == pytest.approx(0.1, abs=1e-6)  # the foot goes as far as the box lets it
    without_foot = solve_cascade(hess, grad, rows[:1], (lo[:1], hi[:1]), box)
    assert without_foot[1] and without_foot[2] == 1 and without_foot[0][0] == pytest.approx(0.0, abs=1e-9)
    feasible = solve_cascade(hess, grad, rows, (np.array([-0.05, 0.05]), np.array([np.inf, 0.05])), box)
    assert feasible[2] == 0 and feasible[0] == pytest.approx([-0.05, 0.05], abs=1e-9)


def test_face_planes_hold_a_sphere_off_the_face_it_was_inside_the_margin_of(
    robots: dict[str, RobotModel],
) -> None:
    """A board 1 cm over the humanoid's head: the head's plane is the board's underside; the next step
    gets a row pushing it down by ``gain`` of its depth in the margin, and none once it has moved away."""
    import trimesh

    from hsi_retarget.face_planes import FacePlanes

    robot = robots["humanoid"]
    solver = IKSolver(robot)
    q = np.array(robot.q_home)
    centers = solver.sphere_centers(q)
    head = np.flatnonzero(np.array(solver.spheres.frames) == "head")
    top = int(head[np.argmax(centers[head, 2] + solver.spheres.radii[head])])
    board = trimesh.creation.box(extents=(0.6, 0.6, 0.02))
    board.apply_translation(centers[top] + [0.0, 0.0, solver.spheres.radii[top] + 0.01 + 0.01])
    scene = SceneDistance({"board": board}, ground=())
    margin = np.full(centers.shape[0], 0.04)
    planes = FacePlanes(solver.spheres, reach=0.05)
    dist, normal = scene.query(centers)
    gap = dist - solver.spheres.radii - margin
    inside = np.flatnonzero(gap < 0.0)
    planes.remember(centers, margin, inside, gap[inside], normal[inside])
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    rows, lower = planes.rows(robot.model, data, centers, margin, gain=0.5)
    assert rows.shape == (lower.shape[0], robot.nv) and lower.shape[0] >= 1
    assert lower.max() == pytest.approx(0.5 * (0.04 - 0.01), abs=1e-4)  # 1 cm below the underside
    dq = np.zeros(robot.nv)
    dq[robot.v_index("waist_pitch")] = 0.1  # bending forward lowers the head: away from the underside
    assert (rows @ dq)[np.argmax(lower)] > 0.0
    moved = centers - np.array([0.0, 0.0, 0.2])  # far from where the planes were taken: no rows
    assert planes.rows(robot.model, data, moved, margin, gain=0.5)[0].shape[0] == 0
    planes.clear()
    assert planes.rows(robot.model, data, centers, margin, gain=0.5)[0].shape[0] == 0
    assert IKSolver(robot, scene=scene)._planes is not None  # on for a floating base
    assert IKSolver(robots["dual_ur5e"], scene=scene)._planes is None  # off on a fixed one
    assert IKSolver(robots["dual_ur5e"], IKConfig(face_planes=True), scene=scene)._planes is not None
