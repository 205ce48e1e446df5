"""Trajectory plots of one demo task (matplotlib, Agg): wrist paths and speed profiles.

One PNG per task with three panels:

1. top view (x-y) of the planned human wrist paths, the robot's commanded TCP paths and the root path,
   with the target and its placement marked;
2. speed profiles [m/s] over time of the robot's commanded TCPs (retargeted, time-scaled) and of the
   planned wrists (schedule time);
3. the TCP tracking error [m] measured in MuJoCo.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from hsi_nodes.demo.pipeline import TaskOutcome

__all__ = ["plot_task", "tcp_paths"]

F64 = NDArray[np.float64]
_COLORS = {"left": "tab:blue", "right": "tab:red"}


def tcp_paths(outcome: TaskOutcome, step: int = 2) -> tuple[F64, dict[str, F64]]:
    """(times (K,) [s], side -> (K, 3) [m]) of the robot's commanded TCPs (FK of every ``step``-th sample
    of the joint trajectory; world frame for a floating robot and for the dual arm, whose base joints are
    in the world frame)."""
    from hsi_retarget.robots import RobotModel

    traj = outcome.trajectory
    if traj is None:
        return np.zeros(0), {}
    robot = RobotModel(traj.robot)
    frames = tuple(robot.tcp_frames[s] for s in ("left", "right"))
    idx = np.arange(0, traj.t.shape[0], max(1, step))
    out = {s: np.zeros((idx.size, 3)) for s in ("left", "right")}
    for row, i in enumerate(idx):
        poses = robot.fk(traj.q[i], frames)
        for side, rows in out.items():
            rows[row] = poses[robot.tcp_frames[side]][:3, 3]
    return np.asarray(traj.t[idx], dtype=np.float64), out


def _speed(t: F64, p: F64) -> F64:
    if t.shape[0] < 2:
        return np.zeros(t.shape[0])
    v = np.gradient(p, t, axis=0)
    return np.asarray(np.linalg.norm(v, axis=1), dtype=np.float64)


def plot_task(outcome: TaskOutcome, path: Path) -> Path | None:
    """Write the task's plot to ``path`` (PNG); None when nothing was planned (nothing to plot)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hsi_retarget.sources import human_motion_from_schedule

    if outcome.schedule is None:
        return None
    human = human_motion_from_schedule(outcome.schedule, 30.0)
    t_robot, robot = tcp_paths(outcome)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    top, speed, track = axes
    for side, pos in human.wrist_position.items():
        top.plot(pos[:, 0], pos[:, 1], "--", color=_COLORS[side], lw=1, label=f"{side} wrist (plan)")
        speed.plot(human.t, _speed(human.t, pos), "--", color=_COLORS[side], lw=1, label=f"{side} plan")
    for side, pos in robot.items():
        top.plot(pos[:, 0], pos[:, 1], color=_COLORS[side], lw=1.5, label=f"{side} TCP (robot)")
        speed.plot(t_robot, _speed(t_robot, pos), color=_COLORS[side], lw=1.5, label=f"{side} robot")
    root = outcome.schedule.root_path
    if root.shape[0]:
        top.plot(root[:, 0], root[:, 1], color="0.4", lw=2, label="root path")
    if outcome.placement is not None:
        top.plot(*outcome.placement[:2], "k*", ms=12, label="placement")
    top.set(xlabel="x [m]", ylabel="y [m]", title=f"{outcome.task.name}: top view")
    top.set_aspect("equal", adjustable="datalim")
    top.legend(fontsize=7, loc="best")
    speed.set(xlabel="time [s]", ylabel="speed [m/s]", title="wrist / TCP speed")
    speed.legend(fontsize=7)
    trace = outcome.report.trace
    if trace is not None and trace.t.size:
        for i, side in enumerate(("left", "right")):
            track.plot(trace.t, trace.tcp_error[:, i], color=_COLORS[side], label=side)
        track.legend(fontsize=7)
    verdict = "success" if outcome.report.success else f"failure ({outcome.stage})"
    track.set(xlabel="time [s]", ylabel="TCP error [m]", title=f"MuJoCo tracking — {verdict}")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
