"""Index maps between pinocchio's (q, v) order and a MuJoCo model's (qpos, qvel, ctrl) order.

Built by joint name, so they hold for the robot's own MJCF and for any scene the robot was attached to
(with the attach ``prefix``). The free joint differs in two ways: the quaternion is (x, y, z, w) in
pinocchio and (w, x, y, z) in MuJoCo (a permutation of addresses), and pinocchio's linear velocity is in
the root frame while MuJoCo's is in the world frame (converted in :meth:`MujocoMap.v_to_qvel`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError, RetargetError

IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class MujocoMap:
    """Addresses such that ``qpos[qpos_adr[i]] == q[i]``, ``qvel[dof_adr[k]] == v[k]`` (up to the free-joint
    velocity frame) and ``ctrl[ctrl_adr[m]] == q[ctrl_q[m]]`` for the robot's position actuators."""

    nq: int  #: pinocchio configuration size [-]
    nv: int  #: pinocchio velocity size [-]
    qpos_adr: IntArray  #: (nq,) MuJoCo qpos address of each pinocchio q entry
    dof_adr: IntArray  #: (nv,) MuJoCo dof address of each pinocchio v entry
    ctrl_adr: IntArray  #: (n_act,) actuator ids of the robot's position actuators
    ctrl_q: IntArray  #: (n_act,) pinocchio q index each actuator drives
    free_q: int  #: q index of the free flyer (its position), -1 if none

    @staticmethod
    def build(model: pin.Model, mj_model: mujoco.MjModel, prefix: str = "") -> MujocoMap:
        """Match every pinocchio joint (and its position actuator) by name ``prefix + name``.

        Raises:
            ConfigError: a joint or actuator is missing in ``mj_model`` or has another type.
        """
        qpos_adr = np.zeros(model.nq, dtype=np.int64)
        dof_adr = np.zeros(model.nv, dtype=np.int64)
        ctrl_adr: list[int] = []
        ctrl_q: list[int] = []
        free_q = -1
        for jid in range(1, model.njoints):
            name, joint = model.names[jid], model.joints[jid]
            mj_id = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, prefix + name)
            if mj_id < 0:
                raise ConfigError(f"MuJoCo model has no joint {prefix + name!r} (pinocchio joint {name})")
            qa, da = int(mj_model.jnt_qposadr[mj_id]), int(mj_model.jnt_dofadr[mj_id])
            free = mj_model.jnt_type[mj_id] == mujoco.mjtJoint.mjJNT_FREE
            if free != (joint.nq == 7) or (not free and joint.nq != 1):
                raise ConfigError(
                    f"joint {name}: pinocchio nq {joint.nq} does not match the MuJoCo joint type"
                )
            if free:
                free_q = joint.idx_q
                qpos_adr[joint.idx_q : joint.idx_q + 7] = [qa, qa + 1, qa + 2, qa + 4, qa + 5, qa + 6, qa + 3]
                dof_adr[joint.idx_v : joint.idx_v + 6] = np.arange(da, da + 6)
                continue
            qpos_adr[joint.idx_q], dof_adr[joint.idx_v] = qa, da
            act = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_ACTUATOR, prefix + name)
            if act < 0:
                raise ConfigError(f"MuJoCo model has no actuator {prefix + name!r} for joint {name}")
            ctrl_adr.append(act)
            ctrl_q.append(joint.idx_q)
        return MujocoMap(
            model.nq,
            model.nv,
            qpos_adr,
            dof_adr,
            np.array(ctrl_adr, dtype=np.int64),
            np.array(ctrl_q, dtype=np.int64),
            free_q,
        )

    def _check(self, vec: NDArray[np.float64], size: int, what: str) -> NDArray[np.float64]:
        arr = np.asarray(vec, dtype=float)
        if arr.shape != (size,):
            raise RetargetError(f"{what} must have shape ({size},), got {arr.shape}")
        return arr

    def q_to_qpos(self, q: NDArray[np.float64], qpos: NDArray[np.float64]) -> NDArray[np.float64]:
        """A copy of ``qpos`` (MuJoCo, (mj nq,)) with the robot's entries set from ``q`` (nq,)."""
        out = np.array(qpos, dtype=float)
        out[self.qpos_adr] = self._check(q, self.nq, "q")
        return out

    def qpos_to_q(self, qpos: NDArray[np.float64]) -> NDArray[np.float64]:
        """The robot configuration q (nq,) in pinocchio order from a MuJoCo qpos."""
        return np.array(np.asarray(qpos, dtype=float)[self.qpos_adr])

    def v_to_qvel(
        self, q: NDArray[np.float64], v: NDArray[np.float64], qvel: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """A copy of ``qvel`` with the robot's entries set from pinocchio velocity ``v`` (nv,) at ``q``."""
        v = np.array(self._check(v, self.nv, "v"))
        if self.free_q >= 0:
            quat = np.asarray(q, dtype=float)[self.free_q + 3 : self.free_q + 7]
            v[0:3] = Rotation.from_quat(quat).as_matrix() @ v[0:3]
        out = np.array(qvel, dtype=float)
        out[self.dof_adr] = v
        return out

    def qvel_to_v(self, qpos: NDArray[np.float64], qvel: NDArray[np.float64]) -> NDArray[np.float64]:
        """Pinocchio velocity v (nv,) from a MuJoCo (qpos, qvel)."""
        v = np.array(np.asarray(qvel, dtype=float)[self.dof_adr])
        if self.free_q >= 0:
            quat = self.qpos_to_q(qpos)[self.free_q + 3 : self.free_q + 7]
            v[0:3] = Rotation.from_quat(quat).as_matrix().T @ v[0:3]
        return v

    def q_to_ctrl(self, q: NDArray[np.float64], ctrl: NDArray[np.float64]) -> NDArray[np.float64]:
        """A copy of ``ctrl`` (mj nu,) with the robot's position targets set from ``q`` (nq,)."""
        out = np.array(ctrl, dtype=float)
        out[self.ctrl_adr] = self._check(q, self.nq, "q")[self.ctrl_q]
        return out
