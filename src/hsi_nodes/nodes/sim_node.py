"""``sim_node``: steps the MuJoCo model of a scene and publishes its state.

Topics (all stamped with the transport clock):

- ``/robot/joint_states`` (``sensor_msgs/JointState``): joints that belong to no scene part or object, i.e.
  the robot's. The scene models have no robot yet, so the message has no names (it still ticks).
- ``/scene/joint_states`` (``sensor_msgs/JointState``): door hinges [rad] and drawer slides [m], with
  velocities [rad/s] / [m/s].
- ``/tf`` (``tf2_msgs/TFMessage``): one transform ``world`` → object per free object (the body pose).

Each timer tick (``publish_rate``) runs as many ``mj_step`` calls as needed for physics time to reach the
clock: with a simulated clock physics time equals clock time since start; with the wall clock it advances
``realtime_factor`` times as fast. MuJoCo warnings are logged once per kind; a NaN/inf state resets the
simulation (logged, counted in :attr:`SimNode.resets`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hsi_nodes.msgs import msg_class, ns_to_time
from hsi_nodes.node import Node
from hsi_planning.errors import ConfigError
from hsi_planning.gl import ensure_headless_gl

ensure_headless_gl()  # before mujoco is first imported: it picks its OpenGL backend at import
import mujoco  # noqa: E402

__all__ = ["SimConfig", "SimNode", "joint_addresses", "object_transforms"]

_JOINT_STATE = "sensor_msgs/msg/JointState"
_TF = "tf2_msgs/msg/TFMessage"
#: A tick runs at most this many times its nominal number of steps (catch-up limit) [-].
_MAX_CATCH_UP = 4


@dataclass(frozen=True)
class SimConfig:
    """Parameters of :class:`SimNode`."""

    #: Scene: built-in name (``kitchen``) or path of a spec YAML [-].
    scene: str = "kitchen"
    #: Physics time step; 0 = the model's own (2 ms for the scene models) [s].
    timestep: float = 0.0
    #: State publishing rate (physics steps run in between) [Hz].
    publish_rate: float = 50.0
    #: Physics time per wall-clock time with a wall clock; ignored with a simulated clock [-].
    realtime_factor: float = 1.0
    #: Physics time after which the node reports done and stops stepping; 0 = run forever [s].
    duration_s: float = 0.0
    #: Parent frame of the object transforms [-].
    frame_id: str = "world"

    def __post_init__(self) -> None:
        if not self.scene:
            raise ConfigError("SimConfig.scene: give a built-in scene name (e.g. kitchen) or a spec path")
        if not (self.timestep >= 0.0 and math.isfinite(self.timestep)):
            raise ConfigError(f"SimConfig.timestep must be >= 0 [s] (0 = model default), got {self.timestep}")
        if not (self.publish_rate > 0.0 and math.isfinite(self.publish_rate)):
            raise ConfigError(f"SimConfig.publish_rate must be > 0 [Hz], got {self.publish_rate}")
        if not (self.realtime_factor > 0.0 and math.isfinite(self.realtime_factor)):
            raise ConfigError(f"SimConfig.realtime_factor must be > 0 [-], got {self.realtime_factor}")
        if not (self.duration_s >= 0.0 and math.isfinite(self.duration_s)):
            raise ConfigError(f"SimConfig.duration_s must be >= 0 [s] (0 = forever), got {self.duration_s}")
        if not self.frame_id:
            raise ConfigError("SimConfig.frame_id must not be empty")


def joint_addresses(model: mujoco.MjModel, names: list[str]) -> tuple[list[int], list[int]]:
    """``(qpos addresses, dof addresses)`` of the named joints of ``model`` (KeyError for unknown ones)."""
    qpos, dof = [], []
    for name in names:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise KeyError(name)
        qpos.append(int(model.jnt_qposadr[jid]))
        dof.append(int(model.jnt_dofadr[jid]))
    return qpos, dof


def object_transforms(
    model: mujoco.MjModel, data: mujoco.MjData, bodies: list[str], stamp_ns: int, frame_id: str = "world"
) -> Any:
    """``tf2_msgs/TFMessage`` with the world pose of each body in ``bodies`` (data must be forwarded)."""
    stamped, transform = (
        msg_class("geometry_msgs/msg/TransformStamped"),
        msg_class("geometry_msgs/msg/Transform"),
    )
    vec, quat = msg_class("geometry_msgs/msg/Vector3"), msg_class("geometry_msgs/msg/Quaternion")
    header = msg_class("std_msgs/msg/Header")
    out = []
    for name in bodies:
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        p, q = data.xpos[bid], data.xquat[bid]  # MuJoCo quaternions are (w, x, y, z)
        out.append(
            stamped(
                header=header(stamp=ns_to_time(stamp_ns), frame_id=frame_id),
                child_frame_id=name,
                transform=transform(
                    translation=vec(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                    rotation=quat(x=float(q[1]), y=float(q[2]), z=float(q[3]), w=float(q[0])),
                ),
            )
        )
    return msg_class(_TF)(transforms=out)


class SimNode(Node[SimConfig]):
    """Steps the scene in MuJoCo and publishes joint states and object transforms (module docstring)."""

    config_class = SimConfig

    def __init__(self, name: str = "sim_node", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        from hsi_planning.scene import articulated_parts, build_mjcf, object_names
        from hsi_planning.scene_paths import load_scene

        cfg = self.config
        self.spec = load_scene(cfg.scene)
        #: The MuJoCo model and data (owned by this node; read them only between callbacks).
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(self.spec))
        if cfg.timestep > 0.0:
            self.model.opt.timestep = cfg.timestep
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        #: Free objects (``/tf`` children) and articulated parts (``/scene/joint_states``), spec order.
        self.objects = object_names(self.spec)
        self.parts = articulated_parts(self.spec)
        self.robot_joints = self._robot_joints(set(self.objects) | set(self.parts))
        self._parts_adr = joint_addresses(self.model, self.parts)
        self._robot_adr = joint_addresses(self.model, self.robot_joints)
        self._steps_per_tick = max(1, round(1.0 / (cfg.publish_rate * self.model.opt.timestep)))
        #: Physics steps run, NaN resets, ticks that hit the catch-up limit.
        self.steps = 0
        self.resets = 0
        self.lagging_ticks = 0
        self._warned: set[int] = set()
        self._t0_ns: int | None = None
        self._joint_state = msg_class(_JOINT_STATE)
        self._header = msg_class("std_msgs/msg/Header")
        self.robot_pub = self.create_publisher("/robot/joint_states", _JOINT_STATE)
        self.scene_pub = self.create_publisher("/scene/joint_states", _JOINT_STATE)
        self.tf_pub = self.create_publisher("/tf", _TF, 100)
        self.timer = self.create_timer(1.0 / cfg.publish_rate, self._tick)
        self.get_logger().info(
            "scene %r: %d objects, %d articulated parts, %d robot joints; dt %.4g s, %d steps per tick",
            self.spec.name,
            len(self.objects),
            len(self.parts),
            len(self.robot_joints),
            self.model.opt.timestep,
            self._steps_per_tick,
        )

    def _robot_joints(self, scene_joints: set[str]) -> list[str]:
        names = []
        for j in range(self.model.njnt):
            name = mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_JOINT, j)
            free = self.model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
            if name and name not in scene_joints and not free:
                names.append(name)
        return names

    @property
    def sim_time(self) -> float:
        """Physics time since start [s]."""
        return float(self.data.time)

    def on_start(self) -> None:
        self._t0_ns = self.now_ns()

    def is_done(self) -> bool | None:
        if self.config.duration_s <= 0.0:
            return None
        return self.sim_time >= self.config.duration_s - 0.5 * float(self.model.opt.timestep)

    def _target_time(self) -> float:
        """Physics time [s] the current tick should reach."""
        if self._t0_ns is None:
            self._t0_ns = self.now_ns()
        elapsed = (self.now_ns() - self._t0_ns) * 1e-9
        if not self.transport.clock.simulated:
            elapsed *= self.config.realtime_factor
        if self.config.duration_s > 0.0:
            elapsed = min(elapsed, self.config.duration_s)
        return elapsed

    def _tick(self) -> None:
        if self.is_done():
            self.timer.cancel()
            self.get_logger().info("done: %.3f s simulated in %d steps", self.sim_time, self.steps)
            return
        dt = self.model.opt.timestep
        wanted = math.floor((self._target_time() - self.sim_time) / dt + 0.5)
        limit = _MAX_CATCH_UP * self._steps_per_tick
        if wanted > limit:
            self.lagging_ticks += 1
            if self.lagging_ticks == 1:
                self.get_logger().warning(
                    "physics falls behind the clock (%d steps due, %d run per tick); lower realtime_factor",
                    wanted,
                    limit,
                )
        for _ in range(min(max(wanted, 0), limit)):
            t = self.data.time
            mujoco.mj_step(self.model, self.data)
            self.steps += 1
            if self.data.time < t:  # MuJoCo reset the state itself (bad qpos/qvel/qacc warning)
                self.data.time = t + dt
                self._count_reset(t, "MuJoCo reset the unstable state")
            elif not (np.all(np.isfinite(self.data.qpos)) and np.all(np.isfinite(self.data.qvel))):
                self._reset(t + dt)
        self._log_warnings()
        self._publish()

    def _log_warnings(self) -> None:
        """Log each kind of MuJoCo warning the first time it occurs."""
        for index in range(int(mujoco.mjtWarning.mjNWARNING)):
            info = self.data.warning[index]
            if index not in self._warned and info.number > 0:
                self._warned.add(index)
                self.get_logger().warning(
                    "MuJoCo warning %s (info %d) near t = %.3f s; logged once",
                    mujoco.mjtWarning(index).name,
                    info.lastinfo,
                    self.sim_time,
                )

    def _reset(self, t: float) -> None:
        """Back to the initial state, keeping physics time ``t`` [s] aligned with the clock."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.time = t
        mujoco.mj_forward(self.model, self.data)
        self._count_reset(t, "non-finite MuJoCo state; reset to the initial state")

    def _count_reset(self, t: float, what: str) -> None:
        self.resets += 1
        self.get_logger().error("%s at t = %.3f s (reset %d)", what, t, self.resets)

    def _joint_msg(self, stamp_ns: int, names: list[str], adr: tuple[list[int], list[int]]) -> Any:
        qpos_adr, dof_adr = adr
        return self._joint_state(
            header=self._header(stamp=ns_to_time(stamp_ns), frame_id=""),
            name=list(names),
            position=np.array(self.data.qpos[qpos_adr], dtype=np.float64),
            velocity=np.array(self.data.qvel[dof_adr], dtype=np.float64),
            effort=np.zeros(0, dtype=np.float64),
        )

    def _publish(self) -> None:
        stamp = self.now_ns()
        self.robot_pub.publish(self._joint_msg(stamp, self.robot_joints, self._robot_adr))
        self.scene_pub.publish(self._joint_msg(stamp, self.parts, self._parts_adr))
        self.tf_pub.publish(
            object_transforms(self.model, self.data, self.objects, stamp, self.config.frame_id)
        )
