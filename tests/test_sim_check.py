"""MuJoCo execution check: tracking, collisions, limits, weld grasps, doors and drawers, perturbations, the
humanoid on its pelvis anchor, reports and video.

Trajectories are scripted here with a small damped-least-squares IK on the pinocchio model (a test helper,
not library code): straight TCP segments through IK waypoints, linear in time between them.
"""

from __future__ import annotations

import dataclasses
import json
import math

import imageio.v2 as imageio
import mujoco
import numpy as np
import pinocchio as pin
import pytest

from hsi_planning.errors import ConfigError, MessageError, RetargetError
from hsi_planning.scene import handle_position, moved_object
from hsi_planning.scene.validate import validate_scene
from hsi_retarget.gripper_dwell import DwellConfig
from hsi_retarget.joint_trajectory import ContactEvent, JointTrajectory
from hsi_retarget.robots import RobotModel
from hsi_retarget.sim_check import (
    MAX_TARGET_SHIFT_M,
    ExecutionConfig,
    ExecutionReport,
    PerturbationConfig,
    PerturbationEvent,
    PlaceFeedback,
    PlaceFeedbackConfig,
    Push,
    SimWorld,
    TargetMove,
    TaskGoal,
    VideoConfig,
    VideoRecorder,
    WorldConfig,
    arm_links,
    build_world,
    execute,
    mp4_available,
    random_perturbations,
    reports_markdown,
    weld_name,
    write_reports,
)
from hsi_retarget.sim_check.world import KIND_FURNITURE, KIND_OBJECT, KIND_ROBOT

#: TCP orientations (columns: TCP x, y, z in the world): approach from above with the fingers closing along
#: world y; approach along +x with the fingers closing along y (vertical bar) or along z (horizontal bar).
TOP = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
FRONT = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
SIDE = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
COUNTER_BASE = (0.2, 0.0, 0.0)  #: dual UR5e in front of the kitchen counter [m, m, rad]
PLACE = (0.85, 0.12, 0.9)  #: can1 placement on the counter [m]


def _pose(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, pos
    return out


def _up(point: np.ndarray, dz: float) -> np.ndarray:
    """``point`` (3,) raised by ``dz`` [m]."""
    return np.asarray(point, dtype=float) + np.array([0.0, 0.0, dz])


def _rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ik(robot: RobotModel, q0: np.ndarray, frame: str, goal: np.ndarray, joints: list[str]) -> np.ndarray:
    """Damped least squares on ``joints`` for the (4, 4) pose ``goal`` of ``frame`` (robot frame)."""
    q, cols = q0.copy(), np.array([robot.v_index(j) for j in joints])
    for _ in range(200):
        pose = robot.frame_pose(q, frame)
        err = np.concatenate([goal[:3, 3] - pose[:3, 3], pin.log3(goal[:3, :3] @ pose[:3, :3].T)])
        if np.linalg.norm(err[:3]) < 1e-5 and np.linalg.norm(err[3:]) < 1e-4:
            break
        jac = robot.jacobian(q, frame)[:, cols]
        step = np.zeros(robot.nv)
        step[cols] = np.clip(jac.T @ np.linalg.solve(jac @ jac.T + 1e-3 * np.eye(6), err), -0.3, 0.3)
        q = np.clip(robot.integrate(q, step), robot.q_lower, robot.q_upper)
    return q


class Script:
    """A joint trajectory built from IK waypoints (TCP poses in the world)."""

    def __init__(self, world: SimWorld, q0: np.ndarray | None = None) -> None:
        self.robot, self.base_inv = world.robot, np.linalg.inv(world.base)
        self.t, self.q = [0.0], [np.array(world.robot.q_home if q0 is None else q0)]
        self.events: list[ContactEvent] = []
        self.residual = 0.0

    def move(self, hand: str, goal: np.ndarray, duration: float, n: int = 8) -> Script:
        """Straight TCP segment of ``hand`` to world pose ``goal`` (4, 4) in ``duration`` [s]."""
        frame, joints = f"{hand}_tcp", list(self.robot.arm_joints[hand])
        start = self.robot.frame_pose(self.q[-1], frame)
        goal = self.base_inv @ goal
        t0 = self.t[-1]
        for k in range(1, n + 1):
            s = k / n
            way = _pose(
                start[:3, :3] @ pin.exp3(s * pin.log3(start[:3, :3].T @ goal[:3, :3])),
                (1 - s) * start[:3, 3] + s * goal[:3, 3],
            )
            self.q.append(_ik(self.robot, self.q[-1], frame, way, joints))
            self.t.append(t0 + duration * s)
        reached = self.robot.frame_pose(self.q[-1], frame)[:3, 3]
        self.residual = max(self.residual, float(np.linalg.norm(reached - goal[:3, 3])))
        return self

    def joints(self, q: np.ndarray, duration: float) -> Script:
        """Linear joint-space move to ``q``."""
        self.t.append(self.t[-1] + duration)
        self.q.append(np.array(q))
        return self

    def hold(self, duration: float) -> Script:
        return self.joints(self.q[-1], duration)

    def event(self, hand: str, kind: str, name: str) -> Script:
        self.events.append(ContactEvent(self.t[-1], hand, kind, name))
        return self

    def build(self) -> JointTrajectory:
        assert self.residual < 1e-3, f"scripted IK did not reach a waypoint ({self.residual} m)"
        return JointTrajectory(
            self.robot.name, np.array(self.t), np.array(self.q), self.robot.joint_names, tuple(self.events)
        )


def _pick_script(
    world: SimWorld, obj: str, place: tuple[float, float, float], q0: np.ndarray | None = None
) -> Script:
    """Top-down pick with the left hand: above, down, close, lift 10 cm, carry, lower, release 2 cm up."""
    grip = _up(world.object_pose(obj)[:3], 0.09)
    goal = _up(np.asarray(place), 0.09)
    s = Script(world, q0)
    s.move("left", _pose(TOP, _up(grip, 0.12)), 1.5).move("left", _pose(TOP, grip), 1.0)
    s.event("left", "grasp", obj).hold(0.6)
    s.move("left", _pose(TOP, _up(grip, 0.1)), 1.0).move("left", _pose(TOP, _up(goal, 0.1)), 1.2)
    s.move("left", _pose(TOP, _up(goal, 0.02)), 0.8).event("left", "release", obj).hold(0.5)
    return s.move("left", _pose(TOP, _up(goal, 0.12)), 0.8)


@pytest.fixture(scope="module")
def counter_world() -> SimWorld:
    return build_world(WorldConfig(base_pose=COUNTER_BASE))


@pytest.fixture()
def world(counter_world: SimWorld) -> SimWorld:
    counter_world.reset()
    return counter_world


def test_world_declares_grasp_welds_and_classifies_geoms(world: SimWorld) -> None:
    m = world.model
    assert set(world.objects) >= {"can1", "mug1"} and "cabinet1/door1" in world.parts
    for hand in ("left", "right"):
        for body in (*world.objects, *world.parts):
            eq = m.equality(weld_name(hand, body)).id
            assert m.eq_type[eq] == mujoco.mjtEq.mjEQ_WELD and world.data.eq_active[eq] == 0
        probe = world.tcp_probe[hand]
        assert m.geom_contype[probe] == 0 and m.geom_conaffinity[probe] == 0
    kind = world.geom_kind
    assert kind[m.geom("counter1:block").id] == KIND_FURNITURE
    assert kind[m.geom("cabinet1/door1:handle").id] == KIND_FURNITURE
    assert kind[m.geom("can1:body").id] == KIND_OBJECT
    pad = m.geom("left_finger_a:pad").id
    assert kind[pad] == KIND_ROBOT and world.geom_hand[pad] == 0
    assert world.geom_owner[m.geom("cabinet1/door1:handle").id] == "cabinet1/door1"
    np.testing.assert_allclose(world.robot_q(), world.robot.q_home, atol=1e-12)
    np.testing.assert_allclose(world.object_pose("can1")[:3], (0.9, 0.3, 0.9), atol=1e-9)
    with pytest.raises(ConfigError, match="base_pose"):
        WorldConfig(base_pose=(0.0, math.nan, 0.0))
    with pytest.raises(ConfigError, match="placement"):
        TaskGoal(placement=(0.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match="control_rate_hz"):
        ExecutionConfig(control_rate_hz=0.0)


def test_dual_arm_tracks_a_scripted_trajectory(world: SimWorld) -> None:
    can = world.object_pose("can1")[:3]
    script = Script(world).move("left", _pose(TOP, _up(can, 0.25)), 1.5)
    script.move("right", _pose(FRONT, np.array([0.55, -0.35, 1.1])), 1.0).hold(0.3)
    traj = script.build()
    report = execute(world, traj)
    print(
        f"dual_ur5e tracking: max {report.max_tracking_error_m * 1000:.2f} mm, rms "
        f"{report.rms_tracking_error_m * 1000:.2f} mm, real-time factor {report.realtime_factor:.1f}"
    )
    assert report.success and report.collisions == 0 and not report.limit_violations
    assert report.max_tracking_error_m < 0.005 and report.rms_tracking_error_m < 0.002
    assert report.duration_s == pytest.approx(traj.duration + 0.5, abs=0.02)
    tcp = world.tcp_position("left")
    np.testing.assert_allclose(tcp, _up(can, 0.25), atol=0.003)
    world.reset()
    lagging = execute(world, traj, ExecutionConfig(feedforward=False))
    assert lagging.max_tracking_error_m > 2.0 * report.max_tracking_error_m  # damping lag + gravity sag


def test_gripper_driven_into_the_counter_is_a_collision(world: SimWorld) -> None:
    spot = np.array([0.8, 0.05, 0.9])
    traj = (
        Script(world)
        .move("left", _pose(TOP, _up(spot, 0.15)), 1.2)
        .move("left", _pose(TOP, spot), 0.8)
        .build()
    )
    report = execute(world, traj)
    assert not report.success and report.collisions >= 1
    hit = [c for c in report.collision_details if c.other_geom == "counter1:block"]
    assert hit and hit[0].robot_geom.startswith("left_") and hit[0].max_depth_m > 5e-5
    assert 1.2 < hit[0].first_time_s < 2.1
    assert report.max_tracking_error_m > 0.01  # the counter stops the hand
    assert any("colliding" in f for f in report.failures)


def test_trajectory_beyond_joint_limits_is_reported(world: SimWorld) -> None:
    robot = world.robot
    q = robot.q_home.copy()
    wrist = robot.q_index("left_wrist_3_joint")
    q[wrist] = robot.q_upper[wrist] + 0.4
    traj = Script(world).joints(q, 1.0).hold(0.5).build()
    report = execute(world, traj, ExecutionConfig(settle_s=0.1))
    kinds = {(v.joint, v.quantity, v.source) for v in report.limit_violations}
    assert ("left_wrist_3_joint", "position", "command") in kinds
    assert ("left_wrist_3_joint", "velocity", "command") in kinds  # 4.3 rad in 1 s > 180 deg/s
    pos = next(v for v in report.limit_violations if v.quantity == "position")
    assert (
        pos.worst_value == pytest.approx(robot.q_upper[wrist] + 0.4, abs=1e-6)
        and pos.upper == robot.q_upper[wrist]
    )
    assert 0.8 < pos.first_time_s < 1.0
    assert world.robot_q()[wrist] <= robot.q_upper[wrist] + 0.01  # MuJoCo keeps the joint inside
    other = RobotModel("humanoid")
    wrong = JointTrajectory(other.name, np.array([0.0]), other.q_home[None], other.joint_names)
    with pytest.raises(RetargetError, match="does not match"):
        execute(world, wrong)


def test_pick_lifts_by_weld_on_contact_and_release_places(world: SimWorld) -> None:
    can0 = world.object_pose("can1")[:3]
    traj = _pick_script(world, "can1", PLACE).build()
    heights: list[tuple[float, float]] = []
    report = execute(
        world,
        traj,
        goal=TaskGoal("can1", PLACE, planner="scripted"),
        on_frame=lambda w: heights.append((w.time, float(w.object_pose("can1")[2]))),
    )
    grasp, release = report.grasps[0], report.grasps[1]
    assert (grasp.kind, grasp.how, grasp.target, release.kind) == ("grasp", "contact", "can1", "release")
    t, z = np.array(heights).T
    t -= t[0]
    assert z[(t > grasp.time_s) & (t < release.time_s)].max() - can0[2] >= 0.08  # lifted 10 cm
    before = z[np.searchsorted(t, release.time_s) - 1]
    assert before - PLACE[2] > 0.01 and abs(z[-1] - PLACE[2]) < 0.002  # released 2 cm up: it drops
    assert report.success and report.placement_error_m is not None and report.placement_error_m < 0.02
    assert report.collisions == 0 and report.max_tracking_error_m < 0.01


def test_a_hand_may_touch_its_target_on_the_approach_and_until_it_has_let_go(world: SimWorld) -> None:
    from hsi_retarget.sim_check.grasp import GraspConfig, GraspController

    grasp = GraspController(world, GraspConfig(approach_s=1.0, release_grace_s=0.5))
    grasp.expect(
        (ContactEvent(2.0, "left", "grasp", "can1"), ContactEvent(4.0, "left", "release", "can1")), 1.0
    )
    assert grasp.allowed(0, 1.5) == set() and grasp.allowed(0, 2.1) == {"can1"}  # the grasp is at 3 s
    assert grasp.allowed(1, 2.1) == set()  # the other hand approaches nothing
    grasp.command(ContactEvent(2.0, "left", "grasp", "can1"), 3.0)
    assert grasp.allowed(0, 3.2) == {"can1"}  # closing on it
    touching = world.tcp_position("left") + np.array([-0.03, 0.0, -0.05])  # against the palm
    world.move_object("can1", touching - world.object_pose("can1")[:3])
    grasp._weld("left", "can1")
    grasp.command(ContactEvent(4.0, "left", "release", "can1"), 5.0)
    grasp.update(5.6)  # past the grace, still touching it: still allowed
    assert grasp._hand_touches("left", "can1") and grasp.allowed(0, 5.6) == {"can1"}
    world.move_object("can1", np.array([0.0, 0.0, 0.5]))  # let go of
    grasp.update(5.7)
    assert not grasp._hand_touches("left", "can1") and grasp.allowed(0, 5.7) == set()


def test_the_fingers_stop_on_the_object_when_the_weld_is_made(world: SimWorld) -> None:
    """A force-limited gripper: once welded, the finger targets stay where the fingers met the can (they
    do not squeeze on to the closed stop against the weld), and the held can stays upright."""
    traj = _pick_script(world, "can1", PLACE).build()
    fingers = np.flatnonzero(np.isin(np.asarray(world.map.ctrl_q), world.finger_q["left"]))
    act = np.asarray(world.map.ctrl_adr)[fingers]
    closed = float(world.robot.q_lower[world.finger_q["left"][0]])
    log: list[tuple[float, float, float]] = []

    def record(w: SimWorld) -> None:
        _, qx, qy, _ = w.object_pose("can1")[3:]
        tilt = math.degrees(math.acos(min(1.0, max(-1.0, 1.0 - 2.0 * (qx * qx + qy * qy)))))
        log.append((w.time, float(w.data.ctrl[act].min()), tilt))

    report = execute(world, traj, goal=TaskGoal("can1", PLACE), on_frame=record)
    grasp, release = report.grasps[0], report.grasps[1]
    t, ctrl, tilt = np.array(log).T
    t -= t[0]
    held = (t > grasp.time_s + 0.05) & (t < release.time_s - 0.05)
    assert held.any() and np.ptp(ctrl[held]) < 1e-9  # the targets stopped at the weld
    assert ctrl[held].min() > closed + 0.01  # on the can (6.6 cm), not at the closed stop
    assert tilt[held].max() < 3.0
    assert report.success


def test_a_held_object_stays_held_across_executions(world: SimWorld) -> None:
    grip, goal = _up(world.object_pose("can1")[:3], 0.09), _up(np.asarray(PLACE), 0.09)
    first = Script(world).move("left", _pose(TOP, _up(grip, 0.1)), 1.2).move("left", _pose(TOP, grip), 0.8)
    first.event("left", "grasp", "can1").hold(0.6).move("left", _pose(TOP, _up(grip, 0.1)), 0.8)
    lifted = execute(world, first.build(), ExecutionConfig(settle_s=0.2))
    assert [g.kind for g in lifted.grasps] == ["grasp"] and world.object_pose("can1")[2] > 0.98
    second = Script(world, world.robot_q()).move("left", _pose(TOP, _up(goal, 0.02)), 1.2)
    second.hold(0.3).event("left", "release", "can1").hold(0.4)  # stop before letting go
    placed = execute(world, second.build(), goal=TaskGoal("can1", PLACE))
    assert [g.kind for g in placed.grasps] == ["release"] and placed.grasps[0].time_s == pytest.approx(
        1.5, abs=0.02
    )
    assert placed.success and placed.placement_error_m is not None and placed.placement_error_m < 0.01


def test_door_opened_by_pulling_the_handle() -> None:
    world = build_world(WorldConfig(base_pose=(0.0, -0.12, 0.0)))
    part, robot = "cabinet1/door1", world.robot
    handle = handle_position(world.spec, part)
    hinge = np.array([0.58, -1.018, handle[2]])  # cabinet1 at (0.875, -0.72) + hinge (-0.295, -0.298)
    low = robot.q_home.copy()
    low[robot.q_index("torso_lift_joint")] = 0.0
    s = Script(world).joints(low, 2.5)
    s.move("right", _pose(FRONT, handle - (0.12, 0, 0)), 1.5).move("right", _pose(FRONT, handle), 1.0)
    s.event("right", "grasp", part).hold(DwellConfig().after_s)  # as the retargeter dwells
    angle = math.radians(68.0)
    for k in range(1, 15):  # arc of the TCP about the hinge axis, gripper turning with the door
        rot = _rz(angle * k / 14)
        s.move("right", _pose(rot @ FRONT, hinge + rot @ (handle - hinge)), 3.0 / 14, n=1)
    s.event("right", "release", part).hold(0.3)
    report = execute(world, s.build(), goal=TaskGoal(open_part=part))
    assert report.grasps[0].kind == "grasp" and report.grasps[0].target == part
    assert report.grasps[0].hold == "weld" and f"grasps {part} at" in report.to_markdown()  # the dual arm
    assert report.opening is not None and report.opening >= math.radians(60.0)
    assert report.opening_required == pytest.approx(math.radians(60.0))
    assert report.success and report.collisions == 0, report.failures


def test_drawer_pulled_by_its_handle() -> None:
    world = build_world(WorldConfig(base_pose=(0.0, -0.75, 0.0)))
    part, robot = "drawer_unit1/drawer1", world.robot
    handle = handle_position(world.spec, part)
    low = robot.q_home.copy()
    low[robot.q_index("torso_lift_joint")] = 0.0
    s = Script(world).joints(low, 2.5)
    s.move("right", _pose(SIDE, handle - (0.12, 0, 0)), 1.5).move("right", _pose(SIDE, handle), 1.0)
    s.event("right", "grasp", part).hold(DwellConfig().after_s)  # as the retargeter dwells
    s.move("right", _pose(SIDE, handle - (0.25, 0, 0)), 2.0).event("right", "release", part).hold(0.3)
    report = execute(world, s.build(), goal=TaskGoal(open_part=part))
    assert report.opening is not None and 0.2 <= report.opening <= 0.3
    assert report.success and report.collisions == 0, report.failures
    world.reset()
    assert world.opening(part) == pytest.approx(0.0, abs=1e-9)
    closed = execute(
        world, Script(world).hold(0.5).build(), ExecutionConfig(settle_s=0.0), goal=TaskGoal(open_part=part)
    )
    assert not closed.success and "opened" in closed.failures[0]


def test_a_part_is_welded_at_the_tcp_and_a_free_object_at_its_origin() -> None:
    """Without handle pivots a door's or drawer's weld point is the TCP (the point the trajectory moves
    along its arc), a free object's its origin; both ends of each weld are that point when it is made (no
    jump). (With them, the default, a part is held by its pivot pair: tests/test_handle_grip.py.)"""
    from hsi_retarget.sim_check.grasp import GraspController

    world = build_world(WorldConfig(base_pose=COUNTER_BASE, handle_pivot=False))
    assert world.pivots == {}
    grasp = GraspController(world)
    m, d = world.model, world.data
    for hand, target in (("right", "drawer_unit1/drawer1"), ("left", "can1")):
        assert grasp._weld(hand, target) == "weld"
        eq = world.welds[(hand, target)]
        b1, b2 = world.gripper_body[hand], world.body_ids[target]
        on_gripper = d.xmat[b1].reshape(3, 3) @ m.eq_data[eq, 3:6] + d.xpos[b1]
        on_target = d.xmat[b2].reshape(3, 3) @ m.eq_data[eq, 0:3] + d.xpos[b2]
        point = d.geom_xpos[world.tcp_probe[hand]] if target != "can1" else d.xpos[b2]
        np.testing.assert_allclose(on_gripper, point, atol=1e-9)
        np.testing.assert_allclose(on_target, point, atol=1e-9)
        assert d.eq_active[eq] == 1 and grasp.held[hand] == target


def test_push_spikes_tracking_error_and_execution_recovers(world: SimWorld) -> None:
    traj = Script(world).hold(2.5).build()
    calm = execute(world, traj, ExecutionConfig(settle_s=0.0))
    world.reset()
    push = Push(0.8, "left_forearm_link", (0.0, 250.0, 0.0), 0.1)
    seen: list[PerturbationEvent] = []
    report = execute(
        world,
        traj,
        ExecutionConfig(settle_s=0.0, recovery_error_m=0.002),
        perturbations=[push],
        on_perturbation=lambda w, e: seen.append(e),
    )
    assert seen == [push]
    rec = report.perturbations[0]
    assert rec.event["kind"] == "push" and not rec.replanned
    assert rec.peak_error_m > 0.005 and rec.peak_error_m > 20 * max(
        rec.baseline_error_m, calm.max_tracking_error_m
    )
    assert rec.recovered and rec.recovery_time_s is not None and rec.recovery_time_s < 1.0
    assert report.trace is not None and report.trace.tcp_error[-1].max() < 0.001
    assert np.all(world.data.xfrc_applied == 0.0)  # the push ended


def test_random_perturbations_are_seeded_and_bounded(world: SimWorld) -> None:
    traj = _pick_script(world, "can1", PLACE).build()
    cfg = PerturbationConfig(seed=4, pushes=3, target_shift_m=0.05)
    events = random_perturbations(world, traj, cfg, target="can1")
    assert events == random_perturbations(world, traj, cfg, target="can1")
    assert events != random_perturbations(world, traj, PerturbationConfig(seed=5, pushes=3), target="can1")
    pushes = [e for e in events if isinstance(e, Push)]
    moves = [e for e in events if isinstance(e, TargetMove)]
    assert len(pushes) == 3 and len(moves) == 1
    assert all(e.body in arm_links(world) and 40.0 <= e.magnitude <= 120.0 for e in pushes)
    assert all(0.15 * traj.duration <= e.time_s <= 0.85 * traj.duration for e in pushes)
    grasp_time = next(e.time for e in traj.events if e.kind == "grasp")
    assert 0.025 <= moves[0].magnitude <= MAX_TARGET_SHIFT_M and moves[0].time_s < grasp_time
    with pytest.raises(ConfigError, match="longer than"):
        TargetMove(0.0, "can1", (0.04, 0.04, 0.0))
    with pytest.raises(ConfigError, match="target_shift_m"):
        PerturbationConfig(target_shift_m=0.08)


def test_random_target_moves_keep_the_object_clear_of_its_neighbours(world: SimWorld) -> None:
    # kitchen's box1 stands close to its neighbours: about 1 in 3 directions of a 5 cm move hit one
    traj = _pick_script(world, "can1", PLACE).build()
    redrawn = 0
    for seed in range(20):
        cfg = PerturbationConfig(seed=seed, pushes=0, target_shift_m=0.05)
        (move,) = random_perturbations(world, traj, cfg, target="box1")
        assert isinstance(move, TargetMove) and 0.025 <= move.magnitude <= MAX_TARGET_SHIFT_M
        validate_scene(moved_object(world.spec, "box1", move.offset))  # raises if it does not fit
        rng = np.random.default_rng(seed)  # the first draw, as the generator makes it
        angle, dist = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(0.5, 1.0) * 0.05
        first = (dist * math.cos(angle), dist * math.sin(angle), 0.0)
        redrawn += int(not np.allclose(first, move.offset))
    assert redrawn >= 2


def test_target_moves_before_the_first_free_object_is_grasped(world: SimWorld) -> None:
    traj = _pick_script(world, "can1", PLACE).build()
    can_grasp = next(e.time for e in traj.events if e.kind == "grasp")
    cfg = PerturbationConfig(seed=1, pushes=0)
    (alone,) = random_perturbations(world, traj, cfg, target="can1")
    assert alone.time_s == pytest.approx(cfg.target_shift_at * can_grasp)
    # a blocker grasped first (here box1, by the other hand): the move comes before it, hands still empty
    blocker = ContactEvent(0.4 * can_grasp, "right", "grasp", "box1")
    door = ContactEvent(0.2 * can_grasp, "right", "grasp", "cabinet1/door1")  # a door handle does not count
    events = tuple(sorted((blocker, door, *traj.events), key=lambda e: e.time))
    (moved,) = random_perturbations(world, dataclasses.replace(traj, events=events), cfg, target="can1")
    assert moved.time_s == pytest.approx(cfg.target_shift_at * blocker.time)


def test_moved_target_triggers_replanning_and_the_pick_still_succeeds(world: SimWorld) -> None:
    traj = _pick_script(world, "can1", PLACE).build()
    move = TargetMove(0.5, "can1", (0.04, 0.0, 0.0))  # 4 cm after planning, before the grasp
    calls: list[PerturbationEvent] = []

    def replan(w: SimWorld, event: PerturbationEvent) -> JointTrajectory | None:
        calls.append(event)
        return _pick_script(w, "can1", PLACE, q0=w.robot_q()).build()

    report = execute(world, traj, goal=TaskGoal("can1", PLACE), perturbations=[move], on_perturbation=replan)
    assert calls == [move] and report.replans == 1 and report.perturbations[0].replanned
    assert report.duration_s > 0.5 + traj.duration  # the new plan started at the move
    assert report.success and report.placement_error_m is not None and report.placement_error_m < 0.005
    world.reset()
    open_loop = ExecutionConfig(place_feedback=PlaceFeedbackConfig(enabled=False))
    blind = execute(world, traj, open_loop, goal=TaskGoal("can1", PLACE), perturbations=[move])
    assert not blind.success and blind.replans == 0 and not blind.perturbations[0].replanned
    assert blind.placement_error_m is not None and blind.placement_error_m > 0.02
    assert blind.place_shift_m == 0.0


def test_the_carry_is_corrected_from_where_the_object_sits_in_the_hand(world: SimWorld) -> None:
    # the can moved 4 cm after planning and no re-plan: the hand closes 4 cm off its planned grasp, and the
    # in-hand feedback shifts the carry so that the can still lands on its placement
    traj = _pick_script(world, "can1", PLACE).build()
    move = TargetMove(0.5, "can1", (0.04, 0.0, 0.0))
    report = execute(world, traj, goal=TaskGoal("can1", PLACE), perturbations=[move])
    assert report.success, report.failures
    assert report.placement_error_m is not None and report.placement_error_m < 0.006
    assert 0.03 < report.place_shift_m <= PlaceFeedbackConfig().max_shift_m + 1e-9
    world.reset()  # more than the feedback may correct: it stops at its bound and says so
    small = ExecutionConfig(place_feedback=PlaceFeedbackConfig(max_shift_m=0.01))
    bounded = execute(world, traj, small, goal=TaskGoal("can1", PLACE), perturbations=[move])
    assert bounded.place_shift_m == pytest.approx(0.01, abs=1e-6)
    assert bounded.placement_error_m is not None and 0.02 < bounded.placement_error_m < 0.04
    world.reset()  # without a perturbation the shift stays small (the plan puts the can where it should)
    plain = execute(world, traj, goal=TaskGoal("can1", PLACE))
    assert plain.success and plain.place_shift_m < 0.005
    with pytest.raises(ConfigError, match=r"PlaceFeedbackConfig\.max_shift_m"):
        PlaceFeedbackConfig(max_shift_m=-0.01)


def test_the_placement_feedback_sees_when_the_object_touches_the_scene(world: SimWorld) -> None:
    # standing on the counter it touches the scene (its pose in the hand then says nothing about the
    # grasp); lifted clear of everything it does not
    feedback = PlaceFeedback(world, "can1", PLACE)
    world.move_object("can1", np.array([0.0, 0.0, -0.002]))  # pressed 2 mm into the counter
    mujoco.mj_forward(world.model, world.data)
    assert feedback._touching()
    world.move_object("can1", np.array([0.0, 0.0, 0.3]))
    mujoco.mj_forward(world.model, world.data)
    assert not feedback._touching()
    idle = PlaceFeedback(world, "", None)  # no placement goal: the commands pass through unchanged
    q = world.robot_q()
    assert np.array_equal(idle.command(q, 0.0, 0.0, {"left": "can1"}, 0.01), q)


def test_humanoid_on_its_pelvis_anchor_stands_and_tracks_an_arm_motion() -> None:
    world = build_world(WorldConfig(robot="humanoid"))
    robot = world.robot
    assert world.data.eq_active[world.anchor_weld] == 1
    left = robot.frame_pose(robot.q_home, "left_tcp")
    left[:3, 3] += (0.2, 0.0, 0.2)
    right = robot.frame_pose(robot.q_home, "right_tcp")
    right[:3, 3] += (0.2, -0.05, 0.1)
    traj = Script(world).move("left", left, 1.5).move("right", right, 1.5).hold(0.5).build()
    report = execute(world, traj)
    print(
        f"humanoid tracking: max {report.max_tracking_error_m * 1000:.2f} mm, rms "
        f"{report.rms_tracking_error_m * 1000:.2f} mm, real-time factor {report.realtime_factor:.1f}"
    )
    assert report.success and report.collisions == 0
    assert report.max_tracking_error_m < 0.015 and report.rms_tracking_error_m < 0.003
    pelvis = world.robot_q()[:3]
    np.testing.assert_allclose(pelvis, robot.q_home[:3], atol=0.01)
    for sole in ("left_sole", "right_sole"):  # feet still flat on the floor
        assert abs(world.data.site_xpos[world.model.site(sole).id][2]) < 0.01


def test_the_pelvis_anchor_stiffness_comes_from_the_config() -> None:
    world = build_world(WorldConfig(robot="humanoid", anchor_solref=(0.01, 0.9)))
    np.testing.assert_allclose(world.model.eq_solref[world.anchor_weld], (0.01, 0.9))
    for bad in ((0.0, 1.0), (0.01, -1.0), (0.01,)):
        with pytest.raises(ConfigError, match="anchor_solref"):
            WorldConfig(robot="humanoid", anchor_solref=bad)  # type: ignore[arg-type]


def test_report_json_markdown_and_files(world: SimWorld, tmp_path: object) -> None:
    traj = Script(world).hold(0.3).event("left", "grasp", "mug1").hold(1.7).build()
    report = execute(
        world, traj, ExecutionConfig(settle_s=0.0), goal=TaskGoal("can1", (0.9, 0.0, 0.9), planner="minjerk")
    )
    assert report.grasps[-1].kind == "failed" and report.grasps[-1].target == "mug1"  # nothing in the hand
    data = json.loads(report.to_json())
    for key in (
        "object",
        "robot",
        "planner",
        "success",
        "placement_error_m",
        "duration_s",
        "collisions",
        "max_tracking_error_m",
        "limit_violations",
        "perturbations",
        "opening",
    ):
        assert key in data
    assert (data["object"], data["robot"], data["planner"], data["success"]) == (
        "can1",
        "dual_ur5e",
        "minjerk",
        False,
    )
    assert data["placement_error_m"] == pytest.approx(0.3, abs=1e-3) and "trace" not in data
    assert "placement error" in report.to_markdown() and "**failure**" in report.to_markdown()
    json_path, md_path = write_reports([report, report], tmp_path)  # type: ignore[arg-type]
    assert len(json.loads(json_path.read_text())) == 2
    assert "Success: 0/2" in md_path.read_text() and reports_markdown([report]).count("| can1 |") == 1
    assert isinstance(report, ExecutionReport)
    back = ExecutionReport.from_dict(json.loads(json_path.read_text())[0])  # every record survives JSON
    assert back.to_dict() == json.loads(json.dumps(report.to_dict()))
    assert back.grasps == report.grasps and back.grasps[-1].kind == "failed"
    bad = dict(data, grasps=[{"hand": "left"}])
    with pytest.raises(MessageError):
        ExecutionReport.from_dict(bad)


def test_video_of_an_execution(world: SimWorld, tmp_path: object) -> None:
    traj = Script(world).move("left", _pose(TOP, np.array([0.75, 0.3, 1.15])), 1.0).build()
    recorder = VideoRecorder(world, VideoConfig(width=160, height=120, every=10, fps=10.0))
    execute(world, traj, ExecutionConfig(settle_s=0.0), on_frame=recorder)
    recorder.close()
    assert len(recorder.frames) >= 9 and recorder.frames[0].shape == (120, 160, 3)
    assert np.abs(recorder.frames[0].astype(int) - recorder.frames[-1].astype(int)).mean() > 0.5  # it moved
    path = recorder.save(tmp_path / "exec.mp4")  # type: ignore[operator]
    assert path.suffix == (".mp4" if mp4_available() else ".gif") and path.stat().st_size > 1000
    assert len(imageio.mimread(path)) == len(recorder.frames)
    with pytest.raises(ConfigError, match="offscreen"):
        VideoRecorder(world, VideoConfig(width=2000, height=2000))


def test_after_a_release_the_fingers_open_to_the_trajectory_and_follow_it(world: SimWorld) -> None:
    """Pre-shaped fingers (5 cm from the mid-plane, :mod:`hsi_retarget.finger_room`): after the release they
    open to the trajectory's 5 cm, not to the full stroke, and then follow it (to 6 cm at the end)."""
    traj = _pick_script(world, "can1", PLACE).build()
    cols = [world.robot.q_index(j) for j in world.robot.gripper_joints["left"]]
    q = np.array(traj.q)
    q[:, cols] = 0.05
    q[-1, cols] = 0.06
    traj = JointTrajectory(traj.robot, traj.t, q, traj.joint_names, traj.events)
    fingers = np.flatnonzero(np.isin(np.asarray(world.map.ctrl_q), world.finger_q["left"]))
    act = np.asarray(world.map.ctrl_adr)[fingers]
    log: list[tuple[float, float]] = []
    report = execute(
        world,
        traj,
        goal=TaskGoal("can1", PLACE),
        on_frame=lambda w: log.append((w.time, float(w.data.ctrl[act].max()))),
    )
    grasp, release = report.grasps[0], report.grasps[1]
    t, ctrl = np.array(log).T
    t -= t[0]
    assert np.allclose(ctrl[t < traj.events[0].time - 0.02], 0.05)  # approaching pre-shaped
    assert ctrl[(t > grasp.time_s) & (t < release.time_s)].max() < 0.045  # closed on the can
    after = t > release.time_s
    assert ctrl[after].max() <= 0.06 + 1e-9  # never opened to the 7 cm stroke
    assert ctrl[(t > release.time_s + 0.3) & (t < release.time_s + 0.45)] == pytest.approx(0.05, abs=1e-6)
    assert ctrl[-1] == pytest.approx(0.06, abs=1e-6)
    assert report.success
