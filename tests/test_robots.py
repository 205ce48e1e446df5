"""Robot models: generated files, URDF (pinocchio) vs MJCF (MuJoCo) kinematics, UR5e DH, limits,
dynamics sanity, actuator tracking, the standing humanoid, and robots attached to the kitchen scene."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from hsi_planning.errors import ConfigError, RetargetError, SceneError
from hsi_planning.scene import SceneSpec, build_mjcf
from hsi_planning.scene_paths import load_scene
from hsi_retarget.robots import RobotModel, attach_robot, description, ur5e_fk
from hsi_retarget.robots.build_models import generated_files
from hsi_retarget.robots.description import Inertial, Joint
from hsi_retarget.robots.ur5e import UR5E_A, UR5E_ALPHA, UR5E_D, UR5E_MASS

ROBOTS = ("dual_ur5e", "humanoid")
ROBOT_BODY_PREFIXES = ("left_", "right_", "base_", "torso", "pelvis", "head")


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request: pytest.FixtureRequest) -> RobotModel:
    return RobotModel(request.param)


@pytest.fixture(scope="module")
def kitchen_xml() -> str:
    return build_mjcf(load_scene("kitchen"))


def _mj_pose(m: mujoco.MjModel, d: mujoco.MjData, name: str) -> np.ndarray:
    out = np.eye(4)
    bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
    if bid >= 0:
        out[:3, :3], out[:3, 3] = d.xmat[bid].reshape(3, 3), d.xpos[bid]
        return out
    sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
    assert sid >= 0, f"{name} is neither a body nor a site in the MJCF"
    out[:3, :3], out[:3, 3] = d.site_xmat[sid].reshape(3, 3), d.site_xpos[sid]
    return out


def _step(m: mujoco.MjModel, d: mujoco.MjData, seconds: float) -> None:
    for _ in range(round(seconds / m.opt.timestep)):
        mujoco.mj_step(m, d)
    assert np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))
    warnings = {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(d.warning) if w.number}
    assert not warnings, f"MuJoCo warnings: {warnings}"


def test_committed_files_equal_generator_output(repo_root: Path) -> None:
    for rel, text in generated_files().items():
        path = repo_root / rel
        assert path.is_file(), f"{rel} missing: run python -m hsi_retarget.robots.build_models"
        assert path.read_text(encoding="utf-8") == text, f"{rel} is stale: rerun build_models"


def test_models_load_with_expected_structure(robot: RobotModel) -> None:
    m = robot.load_mujoco()
    assert m.nkey >= 1 and m.key(0).name == "home"
    n_joints = len(robot.joint_names)
    assert m.nu == n_joints and robot.nv == n_joints + (6 if robot.floating else 0)
    for side in ("left", "right"):
        assert len(robot.arm_joints[side]) == (6 if robot.name == "dual_ur5e" else 7)
        assert f"{side}_tcp" in robot.frame_names and robot.shoulder_frames[side] in robot.frame_names
    collision = pin.buildGeomFromUrdf(robot.model, str(robot.urdf_path), pin.GeometryType.COLLISION)
    assert collision.ngeoms > 40  # capsules become a cylinder + 2 spheres in URDF
    if robot.name == "humanoid":
        assert robot.nq == 7 + n_joints and m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
        legs = [
            j
            for j in robot.joint_names
            if j.startswith("left_") and ("hip" in j or "knee" in j or "ankle" in j)
        ]
        assert len(legs) == 6 and sum(j.startswith("waist") for j in robot.joint_names) == 3


def test_home_keyframe_is_the_home_pose(robot: RobotModel) -> None:
    m = robot.load_mujoco()
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mp = robot.mujoco_map(m)
    np.testing.assert_allclose(mp.qpos_to_q(d.qpos), robot.q_home, atol=1e-12)
    np.testing.assert_allclose(mp.q_to_ctrl(robot.q_home, np.zeros(m.nu)), d.ctrl, atol=1e-12)
    assert robot.within_limits(robot.q_home)


def test_pinocchio_and_mujoco_fk_agree_on_1000_configurations(robot: RobotModel) -> None:
    m = robot.load_mujoco()
    d = mujoco.MjData(m)
    mp = robot.mujoco_map(m)
    rng = np.random.default_rng(7)
    pos_err = rot_err = 0.0
    for _ in range(1000):
        q = robot.random_configuration(rng)
        d.qpos[:] = mp.q_to_qpos(q, d.qpos)
        mujoco.mj_kinematics(m, d)
        for name, pose in robot.fk(q).items():
            mj = _mj_pose(m, d, name)
            pos_err = max(pos_err, float(np.linalg.norm(mj[:3, 3] - pose[:3, 3])))
            rot_err = max(rot_err, float(np.linalg.norm(pin.log3(mj[:3, :3].T @ pose[:3, :3]))))
    assert len(robot.frame_names) >= 25
    assert pos_err < 1e-6, f"max position disagreement {pos_err} m (limit 1 mm; expected ~1e-15)"
    assert rot_err < 1e-6, f"max orientation disagreement {rot_err} rad"


@pytest.mark.parametrize("side", ["left", "right"])
def test_ur5e_arm_chain_equals_dh_formula(side: str) -> None:
    robot = RobotModel("dual_ur5e")
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = robot.random_configuration(rng)
        poses = robot.fk(q, [f"{side}_ur_base_link", f"{side}_tool0"])
        chain = np.linalg.inv(poses[f"{side}_ur_base_link"]) @ poses[f"{side}_tool0"]
        np.testing.assert_allclose(chain, ur5e_fk(q[robot.arm_q_indices(side)]), atol=1e-12)
    # hand-checked UR5e zero pose: flange at x = a2 + a3, y = -(d4 + d6), z = d1 - d5 in the DH base
    np.testing.assert_allclose(ur5e_fk(np.zeros(6))[:3, 3], [-0.8172, -0.2329, 0.0628], atol=1e-12)


def test_ur5e_uses_published_parameters() -> None:
    assert UR5E_D == (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
    assert UR5E_A == (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(UR5E_ALPHA, [math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0], atol=0)
    robot = RobotModel("dual_ur5e")
    masses = [robot.model.inertias[robot.model.getJointId(j)].mass for j in robot.arm_joints["left"]]
    np.testing.assert_allclose(masses[:5], UR5E_MASS[:5], atol=1e-12)
    assert masses[5] == pytest.approx(UR5E_MASS[5] + 0.95, abs=1e-9)  # wrist 3 carries the gripper palm
    for side in ("left", "right"):
        for j in robot.arm_joints[side]:
            i, v = robot.q_index(j), robot.v_index(j)
            limit = math.pi if "elbow" in j else 2 * math.pi
            assert (robot.q_lower[i], robot.q_upper[i]) == (-limit, limit)
            assert robot.v_max[v] == pytest.approx(math.pi)
        fingers = [robot.q_upper[robot.q_index(j)] for j in robot.gripper_joints[side]]
        assert sum(fingers) == pytest.approx(0.14)  # a 2F-140-like gripper


def test_jacobian_matches_finite_differences(robot: RobotModel) -> None:
    rng = np.random.default_rng(11)
    eps = 1e-6
    for _ in range(5):
        q = robot.random_configuration(rng)
        for frame in (robot.tcp_frames["left"], robot.tcp_frames["right"], robot.shoulder_frames["left"]):
            jac = robot.jacobian(q, frame)
            assert jac.shape == (6, robot.nv)
            if frame == robot.tcp_frames["left"] and not robot.floating:
                assert np.abs(jac[:, robot.arm_v_indices("right")]).max() == 0.0  # other arm: no effect
            fd = np.zeros((6, robot.nv))
            for k in range(robot.nv):
                dq = np.zeros(robot.nv)
                dq[k] = eps
                plus = robot.frame_pose(robot.integrate(q, dq), frame)
                minus = robot.frame_pose(robot.integrate(q, -dq), frame)
                fd[:3, k] = (plus[:3, 3] - minus[:3, 3]) / (2 * eps)
                fd[3:, k] = pin.log3(plus[:3, :3] @ minus[:3, :3].T) / (2 * eps)
            np.testing.assert_allclose(jac, fd, atol=1e-6)


def test_urdf_limits_match_mjcf(robot: RobotModel) -> None:
    m = robot.load_mujoco()
    for name in robot.joint_names:
        jid, aid = m.joint(name).id, m.actuator(name).id
        i, v = robot.q_index(name), robot.v_index(name)
        urdf_range = (robot.model.lowerPositionLimit[i], robot.model.upperPositionLimit[i])
        np.testing.assert_allclose(m.jnt_range[jid], urdf_range, atol=1e-12)
        np.testing.assert_allclose(m.actuator_ctrlrange[aid], urdf_range, atol=1e-12)
        assert robot.model.velocityLimit[v] == pytest.approx(robot.v_max[v])
        effort = robot.model.effortLimit[v]
        np.testing.assert_allclose(m.actuator_forcerange[aid], (-effort, effort), atol=1e-9)
        assert m.jnt_limited[jid] and m.actuator_forcelimited[aid] and robot.a_max[v] > 0


def test_inertias_are_physical(robot: RobotModel) -> None:
    m = robot.load_mujoco()
    total = float(m.body_subtreemass[0])
    assert total == pytest.approx(160.58 if robot.name == "dual_ur5e" else 70.04, abs=0.01)
    for inertia in robot.model.inertias[1:]:
        assert inertia.mass >= 0.0
        if inertia.mass > 0:
            eig = np.linalg.eigvalsh(inertia.inertia)
            assert eig[0] > 0 and eig[0] + eig[1] >= eig[2] * (1 - 1e-9)
            # radius of gyration between 1 cm and 1 m: plausible for these segments
            assert 1e-2 < math.sqrt(eig[2] / inertia.mass) < 1.0
    with pytest.raises(ConfigError, match="triangle"):
        Inertial(1.0, (0.0, 0.0, 0.0), (1.0, 1.0, 3.0, 0.0, 0.0, 0.0))


def test_robot_alone_steps_one_second(robot: RobotModel) -> None:
    m = robot.load_mujoco()
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    if robot.floating:
        d.eq_active[m.equality("pelvis_anchor_weld").id] = 1  # no floor in the robot file: hold the pelvis
    _step(m, d, 1.0)
    dev = np.abs(robot.mujoco_map(m).qpos_to_q(d.qpos) - robot.q_home)
    assert dev.max() < 0.02, f"joints drifted {dev.max()} from home under gravity"


@pytest.mark.parametrize("joint", ["left_shoulder_lift_joint", "right_elbow_joint", "left_wrist_1_joint"])
def test_position_actuators_track_a_step_under_gravity(joint: str) -> None:
    robot = RobotModel("dual_ur5e")
    m = robot.load_mujoco()
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    assert np.linalg.norm(m.opt.gravity) == pytest.approx(9.81)
    adr = m.jnt_qposadr[m.joint(joint).id]
    target = d.qpos[adr] + 0.2
    d.ctrl[m.actuator(joint).id] = target
    _step(m, d, 1.0)
    assert abs(d.qpos[adr] - target) < 0.02


def test_humanoid_proportions_and_standing() -> None:
    robot = RobotModel("humanoid")
    poses = robot.fk(robot.q_home)
    assert poses["pelvis"][2, 3] == pytest.approx(0.95, abs=0.02)
    assert poses["left_sole"][2, 3] == pytest.approx(0.0, abs=1e-9)
    head_top = poses["head"][2, 3] + 0.14 + 0.1  # skull centre + radius
    assert head_top == pytest.approx(1.75, abs=0.03)
    shoulders = poses["left_shoulder"][:3, 3] - poses["right_shoulder"][:3, 3]
    assert shoulders[1] == pytest.approx(0.38, abs=0.02) and poses["left_shoulder"][2, 3] == pytest.approx(
        1.43, abs=0.02
    )
    scene = build_mjcf(SceneSpec(name="floor_only", furniture=()))
    m = mujoco.MjModel.from_xml_string(attach_robot(scene, "humanoid"))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    assert d.eq_active[m.equality("pelvis_anchor_weld").id] == 0  # stands on its own actuators
    _step(m, d, 1.5)
    q = robot.mujoco_map(m).qpos_to_q(d.qpos)
    assert abs(q[2] - robot.q_home[2]) < 0.01
    tilt = np.linalg.norm(pin.log3(pin.XYZQUATToSE3(q[:7]).rotation))
    assert tilt < 0.02 and np.abs(q[7:] - robot.q_home[7:]).max() < 0.02


def test_dual_ur5e_layout() -> None:
    robot = RobotModel("dual_ur5e")
    poses = robot.fk(robot.q_home)
    left, right = poses["left_shoulder"][:3, 3], poses["right_shoulder"][:3, 3]
    assert np.linalg.norm(left - right) == pytest.approx(0.4, abs=1e-9)
    assert 1.3 <= left[2] <= 1.5 and robot.q_home[robot.q_index("torso_lift_joint")] == pytest.approx(0.225)
    lift = robot.q_index("torso_lift_joint")
    assert 0.3 <= robot.q_upper[lift] - robot.q_lower[lift] <= 0.5
    for side, y in (("left", 0.25), ("right", -0.25)):
        tcp = poses[f"{side}_tcp"]
        np.testing.assert_allclose(tcp[:3, 3], [0.45, y, 1.0], atol=1e-3)  # in front of the robot
        np.testing.assert_allclose(tcp[:3, 2], [1.0, 0.0, 0.0], atol=1e-3)  # approach forward
        pad_a, pad_b = poses[f"{side}_finger_a"][:3, 3], poses[f"{side}_finger_b"][:3, 3]
        np.testing.assert_allclose(
            (pad_a + pad_b) / 2, poses[f"{side}_gripper_link"][:3, 3] + tcp[:3, 2] * 0.09
        )


@pytest.mark.parametrize("name", ROBOTS)
def test_robot_attached_to_kitchen(name: str, kitchen_xml: str) -> None:
    robot = RobotModel(name)
    m = mujoco.MjModel.from_xml_string(attach_robot(kitchen_xml, name, (0.0, 0.0, 0.0)))
    scene = mujoco.MjModel.from_xml_string(kitchen_xml)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mp = robot.mujoco_map(m)
    np.testing.assert_allclose(mp.qpos_to_q(d.qpos), robot.q_home, atol=1e-12)
    for j in range(scene.njnt):  # scene joints keep their rest state (objects at their spec poses)
        src, dst = scene.jnt_qposadr[j], m.jnt_qposadr[m.joint(scene.joint(j).name).id]
        width = 7 if scene.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE else 1
        np.testing.assert_allclose(d.qpos[dst : dst + width], scene.qpos0[src : src + width], atol=1e-12)
    mujoco.mj_forward(m, d)
    for c in d.contact[: d.ncon]:
        names = (m.geom(c.geom1).name, m.geom(c.geom2).name)
        robot_geoms = [n for n in names if n.startswith(ROBOT_BODY_PREFIXES)]
        if robot_geoms:
            other = [n for n in names if n not in robot_geoms]
            ok = other == ["floor"] and ":sole" in robot_geoms[0]
            assert ok, f"initial robot contact {names} ({c.dist} m)"
    _step(m, d, 1.0)
    dev = np.abs(mp.qpos_to_q(d.qpos) - robot.q_home)
    assert dev.max() < 0.02


@pytest.mark.parametrize("name", ROBOTS)
def test_attach_with_prefix_and_pose_keeps_kinematics(name: str, kitchen_xml: str) -> None:
    robot = RobotModel(name)
    pose = (0.3, -0.4, 0.7)
    m = mujoco.MjModel.from_xml_string(attach_robot(kitchen_xml, name, pose, prefix="robot/"))
    d = mujoco.MjData(m)
    mp = robot.mujoco_map(m, prefix="robot/")
    base = np.eye(4)
    base[:3, :3] = pin.rpy.rpyToMatrix(0.0, 0.0, pose[2])
    base[:2, 3] = pose[:2]
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = robot.random_configuration(rng)
        if robot.floating:  # the free joint lives in the world frame: express the root pose there
            q[:7] = pin.SE3ToXYZQUAT(pin.SE3(base) * pin.XYZQUATToSE3(q[:7]))
            base_used = np.eye(4)
        else:
            base_used = base
        d.qpos[:] = mp.q_to_qpos(q, d.qpos)
        mujoco.mj_kinematics(m, d)
        for frame in (robot.tcp_frames["left"], robot.tcp_frames["right"]):
            np.testing.assert_allclose(
                _mj_pose(m, d, "robot/" + frame), base_used @ robot.frame_pose(q, frame), atol=1e-9
            )
    mujoco.mj_resetDataKeyframe(m, d, 0)
    home = robot.q_home.copy()
    if robot.floating:
        home[:7] = pin.SE3ToXYZQUAT(pin.SE3(base) * pin.XYZQUATToSE3(home[:7]))
        np.testing.assert_allclose(d.mocap_pos[0], home[:3], atol=1e-12)
    np.testing.assert_allclose(mp.qpos_to_q(d.qpos), home, atol=1e-12)


def test_mujoco_map_velocity_convention() -> None:
    robot = RobotModel("humanoid")
    m = robot.load_mujoco()
    mp = robot.mujoco_map(m)
    rng = np.random.default_rng(2)
    q, v, dt = robot.random_configuration(rng), rng.normal(size=robot.nv), 1e-5
    qpos = mp.q_to_qpos(q, np.zeros(m.nq))
    qvel = mp.v_to_qvel(q, v, np.zeros(m.nv))
    np.testing.assert_allclose(mp.qvel_to_v(qpos, qvel), v, atol=1e-12)
    moved = qpos.copy()
    mujoco.mj_integratePos(m, moved, qvel, dt)
    np.testing.assert_allclose(mp.qpos_to_q(moved), robot.integrate(q, v * dt), atol=1e-8)


def test_errors_name_what_is_valid(kitchen_xml: str) -> None:
    with pytest.raises(ConfigError, match="known"):
        RobotModel("ur10")
    robot = RobotModel("dual_arm")
    assert robot.name == "dual_ur5e"
    with pytest.raises(RetargetError, match="shape"):
        robot.fk(np.zeros(3))
    with pytest.raises(ConfigError, match="frames"):
        robot.frame_pose(robot.q_home, "nose")
    with pytest.raises(SceneError, match="base_pose"):
        attach_robot(kitchen_xml, "dual_ur5e", (0.0, 0.0))
    twice = attach_robot(kitchen_xml, "dual_ur5e")
    with pytest.raises(SceneError, match="prefix"):
        attach_robot(twice, "dual_ur5e")
    with pytest.raises(SceneError, match="unknown robot"):
        attach_robot(kitchen_xml, "ur10")
    with pytest.raises(ConfigError, match="outside"):
        desc = description("dual_ur5e")
        type(desc)(**{**desc.__dict__, "home": {**desc.home, "left_elbow_joint": 4.0}})
    with pytest.raises(ConfigError, match="lower limit"):
        Joint("j", "revolute", (0.0, 0.0, 1.0), 1.0, -1.0, 1.0, 1.0, 1.0, 1.0, 0.0)
