"""Execute a :class:`JointTrajectory` in a :class:`SimWorld` (the MuJoCo check).

Control: at ``control_rate_hz`` the robot's position actuators get ``trajectory.sample(t)``; with
``feedforward`` the target is offset by ``(kv * qdot_ref + bias) / kp``, cancelling the servo's damping lag
and gravity sag (an ideal joint controller with gravity compensation). Fingers follow the trajectory until
a gripper event, then the grasp controller (:mod:`hsi_retarget.sim_check.grasp`) at the gripper's speed
limit. A floating robot's pelvis anchor (mocap) follows the trajectory's root. After the trajectory the
robot holds its last configuration for ``settle_s``. Perturbations (:mod:`hsi_retarget.sim_check.perturb`)
are applied on time; a re-plan hook may replace the trajectory. The outcome is judged by
:func:`hsi_retarget.sim_check.judge.judge`.
"""

from __future__ import annotations

import time as wallclock
from collections.abc import Callable, Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import RetargetError
from hsi_retarget.joint_trajectory import JointTrajectory
from hsi_retarget.sim_check.config import ExecutionConfig, TaskGoal
from hsi_retarget.sim_check.grasp import GraspController
from hsi_retarget.sim_check.judge import RunLog, judge
from hsi_retarget.sim_check.mjcf import HANDS
from hsi_retarget.sim_check.monitor import ContactMonitor, LimitMonitor
from hsi_retarget.sim_check.perturb import PerturbationEvent, Push, RePlanHook, TargetMove
from hsi_retarget.sim_check.place_feedback import PlaceFeedback
from hsi_retarget.sim_check.report import ExecutionReport, ExecutionTrace
from hsi_retarget.sim_check.world import SimWorld


class _Servo:
    """Position targets for the robot's actuators (with optional feedforward)."""

    def __init__(self, world: SimWorld, feedforward: bool) -> None:
        m, mp = world.model, world.map
        self.world, self.feedforward = world, feedforward
        self.act = np.asarray(mp.ctrl_adr)
        self.q_idx = np.asarray(mp.ctrl_q)
        self.dof = m.jnt_dofadr[m.actuator_trnid[self.act, 0]]
        self.kp = m.actuator_gainprm[self.act, 0]
        self.kv = -m.actuator_biasprm[self.act, 2]
        self.fingers = {h: np.flatnonzero(np.isin(self.q_idx, world.finger_q[h])) for h in HANDS}
        self.is_finger = np.isin(self.q_idx, np.concatenate([world.finger_q[h] for h in HANDS]))

    def apply(
        self, q_ref: NDArray[np.float64], qd_ref: NDArray[np.float64], fingers: dict[str, float | None]
    ) -> None:
        d = self.world.data
        target = q_ref[self.q_idx].copy()
        if self.feedforward:
            ff = (self.kv * qd_ref[self.q_idx] + d.qfrc_bias[self.dof]) / self.kp
            target += np.where(self.is_finger, 0.0, ff)
        for hand, value in fingers.items():
            if value is not None:
                target[self.fingers[hand]] = value
        d.ctrl[self.act] = target
        self.world.set_anchor(q_ref)


def check_trajectory(world: SimWorld, traj: JointTrajectory) -> None:
    """Raise RetargetError unless ``traj`` is for ``world``'s robot (same joints in the same order)."""
    if traj.q.shape[1] != world.robot.nq or tuple(traj.joint_names) != world.robot.joint_names:
        raise RetargetError(
            f"trajectory for {traj.robot} ({traj.q.shape[1]} q) does not match the world's robot "
            f"{world.robot.name} ({world.robot.nq} q, joints {list(world.robot.joint_names)[:3]}...)"
        )


class _Run:
    """State of one execution (trajectory in force, events, logs)."""

    def __init__(
        self,
        world: SimWorld,
        trajectory: JointTrajectory,
        cfg: ExecutionConfig,
        hook: RePlanHook | None,
        goal: TaskGoal,
    ) -> None:
        self.world, self.cfg, self.hook = world, cfg, hook
        m = world.model
        self.n_sub = max(1, round(1.0 / (cfg.control_rate_hz * m.opt.timestep)))
        self.dt = self.n_sub * m.opt.timestep
        self.grasp = GraspController(world, cfg.grasp)
        self.contacts = ContactMonitor(world, cfg.collision_depth_m)
        self.limits = LimitMonitor(world, cfg.limit_tolerance)
        self.servo = _Servo(world, cfg.feedforward)
        self.feedback = PlaceFeedback(world, goal.object_name, goal.placement, cfg.place_feedback)
        self.pushes: list[tuple[Push, int]] = []
        self.replanned: list[bool] = []
        self.log: tuple[list[float], list[list[float]], list[float]] = ([], [], [])
        self.fell = False
        self.root_z0 = float(world.robot_q()[world.map.free_q + 2]) if world.map.free_q >= 0 else 0.0
        self._switch(trajectory, 0.0)

    def _switch(self, trajectory: JointTrajectory, t: float) -> None:
        check_trajectory(self.world, trajectory)
        self.active, self.t_active, self.events = trajectory, t, list(trajectory.events)
        self.grasp.expect(trajectory.events, t)
        self.feedback.switch(trajectory)
        vel = trajectory.velocities()
        robot = self.world.robot
        for name, iq in zip(self.limits.names, self.limits.q_idx.tolist(), strict=True):
            vmax = float(robot.v_max[robot.v_index(name)])
            k = int(np.argmax(np.abs(vel[:, iq])))
            if abs(vel[k, iq]) > vmax * (1.0 + self.cfg.velocity_tolerance):
                key = (name, "velocity", "command")
                self.limits.add(key, t + float(trajectory.t[k]), float(vel[k, iq]), (-vmax, vmax))

    @property
    def end(self) -> float:
        """[s] execution end (trajectory in force + settling)."""
        return self.t_active + self.active.duration + self.cfg.settle_s

    def perturb(self, t: float, pending: list[PerturbationEvent]) -> None:
        """Start due perturbations (and call the hook), stop finished pushes."""
        w = self.world
        while pending and pending[0].time_s <= t + 1e-9:
            event = pending.pop(0)
            if isinstance(event, Push):
                body = w.model.body(event.body).id
                w.data.xfrc_applied[body, :3] = event.force
                self.pushes.append((event, body))
            elif isinstance(event, TargetMove):
                w.move_object(event.object_name, np.asarray(event.offset))
            new = self.hook(w, event) if self.hook is not None else None
            self.replanned.append(new is not None)
            if new is not None:
                self._switch(new, t)
        for push, body in list(self.pushes):
            if t >= push.time_s + push.duration_s - 1e-9:
                w.data.xfrc_applied[body, :3] = 0.0
                self.pushes.remove((push, body))

    def control(self, t: float) -> None:
        """Apply due gripper events, set actuator targets, record tracking and limits at ``t`` [s]."""
        w, tau = self.world, t - self.t_active
        while self.events and self.events[0].time <= tau + 1e-9:
            self.grasp.command(self.events.pop(0), t)
        q_ref = self.feedback.command(self.active.sample(tau), tau, t, self.grasp.held, self.dt)
        qd_ref = (self.active.sample(tau + self.dt / 2) - self.active.sample(tau - self.dt / 2)) / self.dt
        reference = {h: float(np.mean(q_ref[w.finger_q[h]])) for h in HANDS}
        self.servo.apply(q_ref, qd_ref, self.grasp.finger_targets(self.dt, reference))
        self.limits.check(t, q_ref, "command")
        mujoco.mj_kinematics(w.model, w.data)
        q_now = w.robot_q()
        self.limits.check(t, q_now, "state")
        cmd = w.commanded_tcp(q_ref)
        self.log[0].append(t)
        self.log[1].append([float(np.linalg.norm(w.tcp_position(h) - cmd[h])) for h in HANDS])
        err = np.abs(q_now[w.body_q] - q_ref[w.body_q])
        self.log[2].append(float(err.max()) if err.size else 0.0)
        if w.map.free_q >= 0 and q_now[w.map.free_q + 2] < self.root_z0 - self.cfg.fall_drop_m:
            self.fell = True

    def step(self, t: float, start: float) -> float:
        """Physics steps of one control period with collision checks; returns the new time [s]."""
        w = self.world
        allowed = [self.grasp.allowed(0, t), self.grasp.allowed(1, t)]
        for _ in range(self.n_sub):
            mujoco.mj_step(w.model, w.data)
            self.contacts.check(w.time - start, allowed)
        t = w.time - start
        self.grasp.update(t)
        return t

    def trace(self) -> ExecutionTrace:
        t, tcp, joint = self.log
        return ExecutionTrace(np.array(t), np.array(tcp).reshape(-1, 2), np.array(joint))


def execute(
    world: SimWorld,
    trajectory: JointTrajectory,
    config: ExecutionConfig | None = None,
    *,
    goal: TaskGoal | None = None,
    perturbations: Sequence[PerturbationEvent] = (),
    on_perturbation: RePlanHook | None = None,
    on_frame: Callable[[SimWorld], None] | None = None,
) -> ExecutionReport:
    """Run ``trajectory`` on ``world`` (from its current scene state) and report on it.

    Args:
        world: the simulated scene + robot (not reset here; see :meth:`SimWorld.reset`).
        trajectory: robot configurations over time with gripper events (fixed-base robots: relative to
            the world's ``base_pose``; a floating root: in the world frame).
        config: control and judgement parameters.
        goal: placement and/or opening to check; without one, success = no collisions (and no fall).
        perturbations: pushes and target moves (times from the execution start [s]).
        on_perturbation: re-plan hook, called at every perturbation event; a returned trajectory replaces
            the current one from that moment (its time 0 = now).
        on_frame: called after every control step (e.g. a :class:`~hsi_retarget.sim_check.VideoRecorder`).

    Raises:
        RetargetError: the trajectory (or a re-planned one) is for another robot.
    """
    cfg = config if config is not None else ExecutionConfig()
    check_trajectory(world, trajectory)
    if cfg.snap_to_start:
        world.set_robot_q(trajectory.q[0])
    goal = goal if goal is not None else TaskGoal()
    run = _Run(world, trajectory, cfg, on_perturbation, goal)
    pending = sorted(perturbations, key=lambda e: e.time_s)
    start, wall0 = world.time, wallclock.perf_counter()
    t = 0.0
    while t <= run.end + 1e-9:
        run.perturb(t, pending)
        run.control(t)
        t = run.step(t, start)
        if on_frame is not None:
            on_frame(world)
    for _push, body in run.pushes:
        world.data.xfrc_applied[body, :3] = 0.0
    log = RunLog(
        world=world,
        goal=goal,
        config=cfg,
        trace=run.trace(),
        grasp=run.grasp,
        contacts=run.contacts,
        limits=run.limits,
        events=tuple(sorted(perturbations, key=lambda e: e.time_s)),
        replanned=tuple(run.replanned),
        fell=run.fell,
        place_shift_m=run.feedback.largest,
        duration_s=t,
        wall_s=wallclock.perf_counter() - wall0,
    )
    return judge(log)
