"""Play a :class:`~hsi_retarget.joint_trajectory.JointTrajectory` in MuJoCo and measure how well the TCPs
follow it (the ``hsi retarget --sim`` check; the full task check with grasps and collisions is
:mod:`hsi_retarget.sim_check`).

The robot's position actuators track ``trajectory.sample(t)`` every physics step (fingers held open). A
floating robot's pelvis is held on the trajectory's root pose by its ``pelvis_anchor`` mocap weld (no
walking controller; the legs track their joint targets). Errors are measured at the TCP sites: against the
commanded configuration's TCPs (pinocchio FK: tracking error) and, when the trajectory carries the mapped
goals in ``meta`` (``goal_position``), against those goals (retargeting + tracking error).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError, RetargetError
from hsi_retarget.joint_trajectory import JointTrajectory
from hsi_retarget.robots import RobotModel, attach_robot

F64 = NDArray[np.float64]
_ANCHOR_WELD = "pelvis_anchor_weld"


@dataclass(frozen=True)
class PlaybackConfig:
    """Simulation settings of :func:`play`."""

    sample_period: float = 0.02  #: [s] how often errors are recorded
    settle: float = 0.5  #: [s] hold the last configuration this long at the end
    warmup: float = 0.2  #: [s] hold the first configuration before starting (errors not recorded)

    def __post_init__(self) -> None:
        if not self.sample_period > 0.0 or self.settle < 0.0 or self.warmup < 0.0:
            raise ConfigError("PlaybackConfig: sample_period > 0 s, settle and warmup >= 0 s")


@dataclass(frozen=True)
class PlaybackReport:
    """Errors [m] per side (max / RMS), simulated and wall time [s], and the real-time factor [-]."""

    tracking_max: dict[str, float]
    tracking_rms: dict[str, float]
    goal_max: dict[str, float]
    goal_rms: dict[str, float]
    sim_time: float
    wall_time: float

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("inf")

    def to_dict(self) -> dict[str, Any]:
        """Plain dict."""
        return {
            "tracking_max_m": self.tracking_max,
            "tracking_rms_m": self.tracking_rms,
            "goal_max_m": self.goal_max,
            "goal_rms_m": self.goal_rms,
            "sim_time_s": self.sim_time,
            "wall_time_s": self.wall_time,
            "real_time_factor": self.real_time_factor,
        }


def _model(robot: RobotModel, scene: Any) -> mujoco.MjModel:
    if scene is None:
        return robot.load_mujoco()
    from hsi_planning.scene import build_mjcf

    return mujoco.MjModel.from_xml_string(attach_robot(build_mjcf(scene), robot.name))


def _goals(traj: JointTrajectory) -> dict[str, F64]:
    goals = traj.meta.get("goal_position", {})
    out = {}
    for side, values in goals.items():
        arr = np.asarray(values, dtype=np.float64)
        if arr.shape == (traj.t.shape[0], 3):
            out[str(side)] = arr
    return out


def play(
    traj: JointTrajectory,
    robot: RobotModel | None = None,
    scene: Any = None,
    config: PlaybackConfig | None = None,
) -> PlaybackReport:
    """Simulate ``traj`` on its robot, alone (``scene`` None) or attached at the origin of a scene spec."""
    cfg = config or PlaybackConfig()
    model = robot or RobotModel(traj.robot)
    if model.name != traj.robot or traj.q.shape[1] != model.nq:
        raise RetargetError(
            f"trajectory of {traj.robot} ({traj.q.shape[1]} q) does not fit robot {model.name}"
        )
    mj = _model(model, scene)
    data = mujoco.MjData(mj)
    mapping = model.mujoco_map(mj)
    sites = {s: mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_SITE, f) for s, f in model.tcp_frames.items()}
    weld = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_EQUALITY, _ANCHOR_WELD)
    anchor = int(mj.body_mocapid[mj.eq_obj1id[weld]]) if model.floating and weld >= 0 else -1
    if anchor >= 0:
        data.eq_active[weld] = 1

    def command(q: F64) -> None:
        data.ctrl[:] = mapping.q_to_ctrl(q, data.ctrl)
        if anchor >= 0:
            data.mocap_pos[anchor] = q[:3]
            data.mocap_quat[anchor] = [q[6], q[3], q[4], q[5]]

    q0 = traj.sample(0.0)
    data.qpos[:] = mapping.q_to_qpos(q0, data.qpos)
    command(q0)
    mujoco.mj_forward(mj, data)
    dt = float(mj.opt.timestep)
    for _ in range(int(cfg.warmup / dt)):
        mujoco.mj_step(mj, data)
    goals = _goals(traj)
    tracking: dict[str, list[float]] = {s: [] for s in sites}
    goal_err: dict[str, list[float]] = {s: [] for s in goals}
    every = max(1, round(cfg.sample_period / dt))
    total = traj.duration + cfg.settle
    steps = math.ceil(total / dt)
    wall = time.perf_counter()
    for k in range(steps):
        t = k * dt
        q = traj.sample(t)
        command(q)
        mujoco.mj_step(mj, data)
        if k % every or t > traj.duration:
            continue
        fk = model.fk(traj.sample(t + dt), tuple(model.tcp_frames.values()))
        for side, sid in sites.items():
            actual = np.array(data.site_xpos[sid])
            tracking[side].append(float(np.linalg.norm(actual - fk[model.tcp_frames[side]][:3, 3])))
            if side in goals:
                goal = np.array([np.interp(t + dt, traj.t, goals[side][:, i]) for i in range(3)])
                goal_err[side].append(float(np.linalg.norm(actual - goal)))
    wall = time.perf_counter() - wall

    def stats(values: dict[str, list[float]]) -> tuple[dict[str, float], dict[str, float]]:
        arrays = {s: np.asarray(v) for s, v in values.items() if v}
        return (
            {s: float(a.max()) for s, a in arrays.items()},
            {s: float(np.sqrt(np.mean(a**2))) for s, a in arrays.items()},
        )

    t_max, t_rms = stats(tracking)
    g_max, g_rms = stats(goal_err)
    return PlaybackReport(t_max, t_rms, g_max, g_rms, steps * dt, wall)
