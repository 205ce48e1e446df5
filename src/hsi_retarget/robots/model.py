"""``RobotModel``: a robot's URDF loaded with pinocchio, plus its semantics, limits, home pose and MJCF.

Frames: every link of the description and every named frame (``left_tcp``, ``right_tcp``,
``{side}_shoulder``, ``{side}_tool0`` ...) is a pinocchio BODY frame and, in the MJCF, a body or a site of
the same name. Configurations ``q`` are in pinocchio order (a floating root first: x y z qx qy qz qw);
use :meth:`RobotModel.mujoco_map` to convert to and from MuJoCo's qpos/ctrl.
"""

from __future__ import annotations

import sys
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError, RetargetError
from hsi_retarget.robots.catalog import description, relative_paths, robot_name
from hsi_retarget.robots.description import RobotDescription
from hsi_retarget.robots.mujoco_map import MujocoMap

ROOT_JOINT = "root_joint"  #: name of the free-flyer joint of floating robots (pinocchio and MuJoCo)


def robot_files(name: str) -> tuple[Path, Path]:
    """(URDF path, MJCF path) of robot ``name``: source checkout first, then ``<prefix>/share/hsi``.

    Raises:
        ConfigError: unknown robot, or its files are in neither place.
    """
    urdf_rel, mjcf_rel = relative_paths(name)
    roots = [Path(__file__).resolve().parents[3], Path(sys.prefix) / "share" / "hsi"]
    for root in roots:
        if (root / urdf_rel).is_file() and (root / mjcf_rel).is_file():
            return root / urdf_rel, root / mjcf_rel
    raise ConfigError(f"robot files {urdf_rel} and {mjcf_rel} not found under {[str(r) for r in roots]}")


class RobotModel:
    """Kinematics (pinocchio), semantics and limits of one robot. Not thread-safe (one cached pin.Data)."""

    def __init__(self, name: str) -> None:
        """Load robot ``name`` (``dual_ur5e`` or its alias ``dual_arm``, or ``humanoid``)."""
        self.name = robot_name(name)
        self.description: RobotDescription = description(self.name)
        self.urdf_path, self.mjcf_path = robot_files(self.name)
        desc = self.description
        self.floating = desc.floating
        if self.floating:
            self.model = pin.buildModelFromUrdf(str(self.urdf_path), pin.JointModelFreeFlyer(), ROOT_JOINT)
        else:
            self.model = pin.buildModelFromUrdf(str(self.urdf_path))
        self._data = self.model.createData()
        self.nq, self.nv = int(self.model.nq), int(self.model.nv)
        names = [str(n) for n in self.model.names[1:]]
        self.joint_names: tuple[str, ...] = tuple(n for n in names if n != ROOT_JOINT)
        self.arm_joints = dict(desc.arm_joints)
        self.gripper_joints = dict(desc.gripper_joints)
        self.tcp_frames = dict(desc.tcp_frames)
        self.shoulder_frames = dict(desc.shoulder_frames)
        self.frame_names: tuple[str, ...] = tuple(link.name for link in desc.links) + tuple(
            f.name for f in desc.frames
        )
        self._frame_ids = {n: self.model.getFrameId(n, pin.FrameType.BODY) for n in self.frame_names}
        missing = [n for n, i in self._frame_ids.items() if i >= self.model.nframes]
        if missing:
            raise ConfigError(f"{self.urdf_path}: frames {missing} missing; regenerate with build_models")
        self.q_lower, self.q_upper = np.full(self.nq, -np.inf), np.full(self.nq, np.inf)
        self.v_max, self.a_max, self.effort = (
            np.full(self.nv, np.inf),
            np.full(self.nv, np.inf),
            np.zeros(self.nv),
        )
        self.q_home = np.asarray(pin.neutral(self.model), dtype=float)
        if self.floating:
            self.q_lower[3:7], self.q_upper[3:7] = -1.0, 1.0
            self.q_home[:7] = _pose_to_q(desc.root_home)
        for name_j in self.joint_names:
            j = desc.joint(name_j)
            iq, iv = self.q_index(name_j), self.v_index(name_j)
            self.q_lower[iq], self.q_upper[iq] = j.lower, j.upper
            self.v_max[iv], self.a_max[iv], self.effort[iv] = j.velocity, j.acceleration, j.effort
            self.q_home[iq] = desc.home.get(name_j, 0.0)

    def q_index(self, joint: str) -> int:
        """Index of 1-DoF ``joint`` in q."""
        if joint not in self.joint_names:
            raise ConfigError(f"robot {self.name} has no joint {joint!r}; joints: {list(self.joint_names)}")
        return int(self.model.joints[self.model.getJointId(joint)].idx_q)

    def v_index(self, joint: str) -> int:
        """Index of 1-DoF ``joint`` in v."""
        self.q_index(joint)
        return int(self.model.joints[self.model.getJointId(joint)].idx_v)

    def arm_q_indices(self, side: str) -> NDArray[np.int64]:
        """q indices (n_arm,) of the ``side`` arm's joints, proximal first."""
        if side not in self.arm_joints:
            raise ConfigError(f"side must be one of {sorted(self.arm_joints)}, got {side!r}")
        return np.array([self.q_index(j) for j in self.arm_joints[side]], dtype=np.int64)

    def arm_v_indices(self, side: str) -> NDArray[np.int64]:
        """v indices (n_arm,) of the ``side`` arm's joints, proximal first (Jacobian columns)."""
        self.arm_q_indices(side)
        return np.array([self.v_index(j) for j in self.arm_joints[side]], dtype=np.int64)

    def _checked(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        arr = np.asarray(q, dtype=float)
        if arr.shape != (self.nq,) or not np.all(np.isfinite(arr)):
            raise RetargetError(f"q must be a finite vector of shape ({self.nq},), got shape {arr.shape}")
        return arr

    def _frame_id(self, frame: str) -> int:
        if frame not in self._frame_ids:
            raise ConfigError(f"robot {self.name} has no frame {frame!r}; frames: {list(self.frame_names)}")
        return int(self._frame_ids[frame])

    def fk(
        self, q: NDArray[np.float64], frames: tuple[str, ...] | list[str] | None = None
    ) -> dict[str, NDArray[np.float64]]:
        """World poses (4, 4) [m] of ``frames`` (default: all mapped frames) at configuration ``q`` (nq,)."""
        ids = {f: self._frame_id(f) for f in (self.frame_names if frames is None else frames)}
        pin.framesForwardKinematics(self.model, self._data, self._checked(q))
        return {f: np.array(self._data.oMf[i].homogeneous) for f, i in ids.items()}

    def frame_pose(self, q: NDArray[np.float64], frame: str) -> NDArray[np.float64]:
        """World pose (4, 4) [m] of one frame at ``q`` (nq,)."""
        return self.fk(q, (frame,))[frame]

    def jacobian(self, q: NDArray[np.float64], frame: str) -> NDArray[np.float64]:
        """Frame Jacobian (6, nv), world-aligned at the frame origin: rows (linear [m/s], angular [rad/s])."""
        fid = self._frame_id(frame)
        q = self._checked(q)
        pin.computeJointJacobians(self.model, self._data, q)
        pin.updateFramePlacements(self.model, self._data)
        jac = pin.getFrameJacobian(self.model, self._data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        return np.array(jac)

    def integrate(self, q: NDArray[np.float64], dq: NDArray[np.float64]) -> NDArray[np.float64]:
        """``q (+) dq``: configuration (nq,) moved by a tangent step ``dq`` (nv,) (pinocchio convention)."""
        return np.asarray(
            pin.integrate(self.model, self._checked(q), np.asarray(dq, dtype=float)), dtype=float
        )

    def random_configuration(self, rng: np.random.Generator, root_box: float = 1.0) -> NDArray[np.float64]:
        """A configuration (nq,) uniform within the joint limits; a floating root gets a uniform position
        in ``[-root_box, root_box]^3`` [m] and a uniform random orientation."""
        q = np.array(self.q_home)
        for name_j in self.joint_names:
            i = self.q_index(name_j)
            q[i] = rng.uniform(self.q_lower[i], self.q_upper[i])
        if self.floating:
            q[:3] = rng.uniform(-root_box, root_box, 3)
            quat = rng.normal(size=4)
            q[3:7] = quat / np.linalg.norm(quat)
        return q

    def within_limits(self, q: NDArray[np.float64], tol: float = 1e-9) -> bool:
        """Whether every 1-DoF joint of ``q`` (nq,) is inside its limits (+/- ``tol``)."""
        q = self._checked(q)
        return bool(np.all(q >= self.q_lower - tol) and np.all(q <= self.q_upper + tol))

    def load_mujoco(self) -> mujoco.MjModel:
        """The robot's own MJCF (``sim/robots/<name>.xml``) compiled."""
        return mujoco.MjModel.from_xml_path(str(self.mjcf_path))

    def mujoco_map(self, mj_model: mujoco.MjModel, prefix: str = "") -> MujocoMap:
        """Index map between this model's q/v and ``mj_model``'s qpos/qvel/ctrl (names ``prefix + name``)."""
        return MujocoMap.build(self.model, mj_model, prefix)


def _pose_to_q(pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """A (4, 4) pose as a free-flyer configuration (7,): x y z qx qy qz qw."""
    return np.concatenate([pose[:3, 3], Rotation.from_matrix(pose[:3, :3]).as_quat()])


def q_to_pose(q7: NDArray[np.float64]) -> NDArray[np.float64]:
    """A free-flyer configuration (7,) (x y z qx qy qz qw) as a (4, 4) pose."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(np.asarray(q7[3:7], dtype=float)).as_matrix()
    out[:3, 3] = q7[:3]
    return out
