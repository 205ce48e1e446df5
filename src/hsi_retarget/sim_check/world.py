"""The MuJoCo world of the execution check: a scene with a robot attached, grasp welds and name maps.

:func:`build_world` merges the robot into the scene MJCF (:func:`hsi_retarget.robots.attach_robot`) and
adds TCP probes and inactive grasp welds (:mod:`hsi_retarget.sim_check.mjcf`). :class:`SimWorld` holds
the compiled model and data and classifies every geom (robot, hand, free object, furniture) so the
executor can tell collisions from grasp contacts.

Frames: configurations are pinocchio ``q`` of the robot. A fixed-base robot's ``q`` is relative to its
``base_pose`` in the scene; a floating robot's root pose in ``q`` is in the world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError, SceneError
from hsi_planning.scene import SceneSpec, articulated_parts, build_mjcf, object_names
from hsi_planning.scene_paths import load_scene
from hsi_retarget.robots import RobotModel, attach_robot
from hsi_retarget.robots.mujoco_map import MujocoMap
from hsi_retarget.sim_check.handle_grip import bar_axes
from hsi_retarget.sim_check.mjcf import HANDS, add_probes_and_welds, pivot_name, weld_name

_EQ = mujoco.mjtObj.mjOBJ_EQUALITY
ANCHOR_WELD = "pelvis_anchor_weld"  #: mocap weld of floating robots (see :mod:`hsi_retarget.robots`)

#: Geom kinds in :attr:`SimWorld.geom_kind`.
KIND_ROBOT, KIND_OBJECT, KIND_FURNITURE = 1, 2, 3


@dataclass(frozen=True)
class WorldConfig:
    """Scene and robot of an execution check."""

    scene: str = "kitchen"  #: built-in scene name or spec YAML path [-]
    robot: str = "dual_ur5e"  #: robot name (``dual_ur5e``/``dual_arm`` or ``humanoid``) [-]
    base_pose: tuple[float, float, float] = (
        0.0,
        0.0,
        0.0,
    )  #: robot frame on the floor: x [m], y [m], yaw [rad]
    pelvis_anchor: bool = True  #: floating robots: hold the pelvis on the mocap anchor weld [-]
    timestep: float = 0.0  #: physics step; 0 keeps the model's (2 ms) [s]
    grasp_solref: tuple[float, float] = (0.01, 1.0)  #: grasp weld time constant [s] and damping ratio [-]
    #: floating robots: the pelvis anchor weld's time constant [s] and damping ratio [-] (MuJoCo solref; a
    #: time constant below two physics steps is raised to that by MuJoCo). 4 ms instead of the model's 20 ms
    #: cut the humanoid's static hand error from 12-20 mm to about 5 mm (the soft weld let the root tilt)
    anchor_solref: tuple[float, float] = (0.004, 1.0)
    #: a held door's or drawer's handle bar may turn about its own axis in the gripper (two connect
    #: constraints, :mod:`hsi_retarget.sim_check.handle_grip`) instead of being welded to it [-]. ``None``:
    #: on for a floating robot (the humanoid, whose compliant arms and trunk shook under the weld's strain),
    #: off for a fixed one (the dual arm's stiff arms: with it, 2 of its 100 benchmark episodes lost, none
    #: gained)
    handle_pivot: bool | None = None

    def __post_init__(self) -> None:
        if not self.scene or not self.robot:
            raise ConfigError("WorldConfig.scene and .robot must be non-empty (e.g. 'kitchen', 'dual_ur5e')")
        if len(self.base_pose) != 3 or not all(math.isfinite(v) for v in self.base_pose):
            raise ConfigError(
                f"WorldConfig.base_pose must be finite (x [m], y [m], yaw [rad]), got {self.base_pose}"
            )
        if not (self.timestep >= 0.0 and math.isfinite(self.timestep)):
            raise ConfigError(
                f"WorldConfig.timestep must be >= 0 [s] (0 = model default), got {self.timestep}"
            )
        if len(self.grasp_solref) != 2 or not (self.grasp_solref[0] > 0.0 and self.grasp_solref[1] > 0.0):
            raise ConfigError(
                f"WorldConfig.grasp_solref must be two positive numbers, got {self.grasp_solref}"
            )
        if len(self.anchor_solref) != 2 or not (self.anchor_solref[0] > 0.0 and self.anchor_solref[1] > 0.0):
            raise ConfigError(
                f"WorldConfig.anchor_solref must be two positive numbers (time constant [s], damping ratio "
                f"[-]), got {self.anchor_solref}"
            )


class SimWorld:
    """A compiled scene + robot model with its data and name maps. Not thread-safe.

    Attributes:
        config: the :class:`WorldConfig` used.
        spec: the scene spec.
        robot: the robot's kinematic model (pinocchio).
        model, data: MuJoCo model and data.
        map: pinocchio q/v <-> MuJoCo qpos/qvel/ctrl index map.
        base: (4, 4) world pose of a fixed-base robot's frame (identity for a floating robot, whose root is
            in world coordinates).
        objects: free object names; parts: door and drawer names (their body and joint names).
        geom_kind: (ngeom,) ``KIND_*`` of every geom; geom_hand: (ngeom,) 0/1 for left/right hand geoms,
            -1 otherwise; geom_owner: (ngeom,) body name of the free object or part a geom belongs to
            (``""`` for other geoms).
    """

    def __init__(self, config: WorldConfig, spec: SceneSpec | None = None) -> None:
        self.config = config
        self.spec = spec if spec is not None else load_scene(config.scene)
        self.robot = RobotModel(config.robot)
        self.objects: tuple[str, ...] = tuple(object_names(self.spec))
        self.parts: tuple[str, ...] = tuple(articulated_parts(self.spec))
        merged = attach_robot(build_mjcf(self.spec), self.robot.name, config.base_pose)
        pivot = config.handle_pivot if config.handle_pivot is not None else self.robot.floating
        pivots = self.parts if pivot else ()
        self._pivot_parts: tuple[str, ...] = pivots
        self.xml = add_probes_and_welds(
            merged, self.robot, [*self.objects, *self.parts], config.grasp_solref, pivots
        )
        try:
            self.model = mujoco.MjModel.from_xml_string(self.xml)
        except ValueError as exc:
            raise SceneError(
                f"scene {self.spec.name} + robot {self.robot.name} does not compile: {exc}"
            ) from exc
        if config.timestep > 0.0:
            self.model.opt.timestep = config.timestep
        self.data = mujoco.MjData(self.model)
        self.map: MujocoMap = self.robot.mujoco_map(self.model)
        x, y, yaw = config.base_pose
        self.base = np.eye(4)
        if not self.robot.floating:
            self.base[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
            self.base[:2, 3] = (x, y)
        self._classify()
        self.reset()

    # ----------------------------------------------------------------------------------------- setup
    def _id(self, kind: mujoco.mjtObj, name: str) -> int:
        idx = int(mujoco.mj_name2id(self.model, kind, name))
        if idx < 0:
            raise SceneError(f"world model has no {kind.name[6:].lower()} {name!r}")
        return idx

    def _classify(self) -> None:
        m = self.model
        robot_bodies = {
            self._id(mujoco.mjtObj.mjOBJ_BODY, link.name) for link in self.robot.description.links
        }
        hand_bodies: dict[int, int] = {}
        frame_links = {f.name: f.link for f in self.robot.description.frames}
        self.gripper_body: dict[str, int] = {}
        self.finger_geoms: dict[str, tuple[NDArray[np.int64], NDArray[np.int64]]] = {}
        for h, hand in enumerate(HANDS):
            gripper = self._id(mujoco.mjtObj.mjOBJ_BODY, frame_links[self.robot.tcp_frames[hand]])
            self.gripper_body[hand] = gripper
            hand_bodies[gripper] = h
            fingers = [
                int(m.jnt_bodyid[self._id(mujoco.mjtObj.mjOBJ_JOINT, j)])
                for j in self.robot.gripper_joints[hand]
            ]
            for b in fingers:
                hand_bodies[b] = h
            geoms = [
                np.flatnonzero((m.geom_bodyid == b) & ((m.geom_contype | m.geom_conaffinity) > 0))
                for b in fingers
            ]
            self.finger_geoms[hand] = (geoms[0].astype(np.int64), geoms[1].astype(np.int64))
        owners = {self._id(mujoco.mjtObj.mjOBJ_BODY, n): n for n in (*self.objects, *self.parts)}
        objects = {self._id(mujoco.mjtObj.mjOBJ_BODY, n) for n in self.objects}
        self.geom_kind = np.full(m.ngeom, KIND_FURNITURE, dtype=np.int64)
        self.geom_hand = np.full(m.ngeom, -1, dtype=np.int64)
        self.geom_owner = np.array([""] * m.ngeom, dtype=object)
        for g in range(m.ngeom):
            body = int(m.geom_bodyid[g])
            if body in robot_bodies:
                self.geom_kind[g] = KIND_ROBOT
                self.geom_hand[g] = hand_bodies.get(body, -1)
            elif body in objects:
                self.geom_kind[g] = KIND_OBJECT
            owner = body
            while owner not in owners and owner != 0:  # part geoms may sit on child bodies
                owner = int(m.body_parentid[owner])
            self.geom_owner[g] = owners.get(owner, "")
        self.support_geoms = np.array(
            [g for g in range(m.ngeom) if self.geom_kind[g] == KIND_ROBOT and ":sole" in m.geom(g).name],
            dtype=np.int64,
        )
        self.tcp_site = {
            hand: self._id(mujoco.mjtObj.mjOBJ_SITE, self.robot.tcp_frames[hand]) for hand in HANDS
        }
        self.tcp_probe = {hand: self._id(mujoco.mjtObj.mjOBJ_GEOM, f"{hand}_tcp_probe") for hand in HANDS}
        self.body_ids = {n: self._id(mujoco.mjtObj.mjOBJ_BODY, n) for n in (*self.objects, *self.parts)}
        self.welds = {
            (hand, n): self._id(mujoco.mjtObj.mjOBJ_EQUALITY, weld_name(hand, n))
            for hand in HANDS
            for n in (*self.objects, *self.parts)
        }
        #: (hand, part) -> its two handle pivot constraints; part held that way -> its bar axis (body frame)
        self.pivots = {
            (hand, n): (self._id(_EQ, pivot_name(hand, n, 0)), self._id(_EQ, pivot_name(hand, n, 1)))
            for hand in HANDS
            for n in self._pivot_parts
        }
        self.bar_axes = bar_axes(m, self.spec, {n: self.body_ids[n] for n in self._pivot_parts})
        self.part_joint: dict[str, tuple[int, bool]] = {}
        for part in self.parts:
            j = self._id(mujoco.mjtObj.mjOBJ_JOINT, part)
            self.part_joint[part] = (
                int(m.jnt_qposadr[j]),
                bool(m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE),
            )
        self.object_qpos = {n: int(m.jnt_qposadr[m.body_jntadr[self.body_ids[n]]]) for n in self.objects}
        self.object_dof = {n: int(m.jnt_dofadr[m.body_jntadr[self.body_ids[n]]]) for n in self.objects}
        anchor = int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, ANCHOR_WELD))
        self.anchor_weld = anchor if anchor >= 0 else -1
        self.anchor_mocap = int(m.body_mocapid[m.eq_obj1id[anchor]]) if anchor >= 0 else -1
        if anchor >= 0:
            m.eq_solref[anchor] = self.config.anchor_solref
        self.robot_bodies = np.array(sorted(robot_bodies), dtype=np.int64)
        # actuated 1-DoF joints of the robot (pinocchio q indices), fingers excluded
        fingers_q = {self.robot.q_index(j) for hand in HANDS for j in self.robot.gripper_joints[hand]}
        self.finger_q = {
            hand: np.array([self.robot.q_index(j) for j in self.robot.gripper_joints[hand]]) for hand in HANDS
        }
        self.body_q = np.array([i for i in self.map.ctrl_q if int(i) not in fingers_q], dtype=np.int64)

    # --------------------------------------------------------------------------------------- state
    def reset(self) -> None:
        """Home keyframe (scene at rest, robot at home), grasp welds off, the pelvis anchor per config."""
        m, d = self.model, self.data
        mujoco.mj_resetDataKeyframe(m, d, 0)
        d.eq_active[:] = m.eq_active0
        for eq in [*self.welds.values(), *(e for pair in self.pivots.values() for e in pair)]:
            d.eq_active[eq] = 0
        if self.anchor_weld >= 0:
            d.eq_active[self.anchor_weld] = int(self.config.pelvis_anchor)
        mujoco.mj_forward(m, d)

    @property
    def time(self) -> float:
        """[s] simulated time."""
        return float(self.data.time)

    def robot_q(self) -> NDArray[np.float64]:
        """Current robot configuration (nq,) (pinocchio order)."""
        return self.map.qpos_to_q(self.data.qpos)

    def set_robot_q(self, q: NDArray[np.float64]) -> None:
        """Put the robot at ``q`` (nq,): positions and position targets, zero velocity, kinematics updated."""
        d = self.data
        d.qpos[:] = self.map.q_to_qpos(q, d.qpos)
        d.qvel[self.map.dof_adr] = 0.0
        d.ctrl[:] = self.map.q_to_ctrl(q, d.ctrl)
        if self.anchor_mocap >= 0:
            self.set_anchor(q)
        mujoco.mj_forward(self.model, d)

    def set_anchor(self, q: NDArray[np.float64]) -> None:
        """Move the pelvis anchor mocap body to the root pose of ``q`` (floating robots only)."""
        if self.anchor_mocap < 0:
            return
        root = np.asarray(q, dtype=float)[self.map.free_q : self.map.free_q + 7]
        self.data.mocap_pos[self.anchor_mocap] = root[:3]
        self.data.mocap_quat[self.anchor_mocap] = (root[6], root[3], root[4], root[5])

    def tcp_position(self, hand: str) -> NDArray[np.float64]:
        """Measured world position (3,) [m] of ``hand``'s TCP."""
        return np.array(self.data.site_xpos[self.tcp_site[hand]])

    def commanded_tcp(self, q: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
        """World positions (3,) [m] of both TCPs at configuration ``q`` (nq,) (pinocchio FK)."""
        poses = self.robot.fk(q, tuple(self.robot.tcp_frames[h] for h in HANDS))
        return {h: (self.base @ poses[self.robot.tcp_frames[h]])[:3, 3] for h in HANDS}

    def object_pose(self, name: str) -> NDArray[np.float64]:
        """Pose (7,) of free object ``name``: position [m] and quaternion (w, x, y, z) of its body."""
        if name not in self.object_qpos:
            raise SceneError(f"no free object {name!r}; objects: {list(self.objects)}")
        a = self.object_qpos[name]
        return np.array(self.data.qpos[a : a + 7])

    def move_object(self, name: str, offset: NDArray[np.float64]) -> None:
        """Shift free object ``name`` by ``offset`` (3,) [m] and stop it."""
        a, v = self.object_qpos.get(name, -1), self.object_dof.get(name, -1)
        if a < 0:
            raise SceneError(f"no free object {name!r}; objects: {list(self.objects)}")
        self.data.qpos[a : a + 3] += np.asarray(offset, dtype=float).reshape(3)
        self.data.qvel[v : v + 6] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def opening(self, part: str) -> float:
        """Opening of door [rad] or drawer [m] ``part`` (0 = closed)."""
        if part not in self.part_joint:
            raise SceneError(f"no door or drawer {part!r}; parts: {list(self.parts)}")
        return float(self.data.qpos[self.part_joint[part][0]])

    def is_door(self, part: str) -> bool:
        """Whether ``part`` is hinged (a door) rather than sliding (a drawer)."""
        self.opening(part)
        return self.part_joint[part][1]

    def target_kind(self, name: str) -> str:
        """``object`` or ``part`` for a graspable body name (SceneError otherwise)."""
        if name in self.object_qpos:
            return "object"
        if name in self.part_joint:
            return "part"
        raise SceneError(f"{name!r} is no free object or door/drawer; valid: {[*self.objects, *self.parts]}")


def build_world(config: WorldConfig | None = None, spec: SceneSpec | None = None) -> SimWorld:
    """A :class:`SimWorld` for ``config`` (default: dual UR5e in kitchen); ``spec`` replaces the scene."""
    return SimWorld(config if config is not None else WorldConfig(), spec)
