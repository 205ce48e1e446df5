"""The report panel of the web UI: a task outcome as markdown and its speed profiles as an image."""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from hsi_nodes.demo.pipeline import TaskOutcome

__all__ = ["SUCCESS_TEXT", "report_markdown", "speed_image"]

F64 = NDArray[np.float64]
#: First line of the report of a successful task.
SUCCESS_TEXT = "Task succeeded"


def report_markdown(outcome: TaskOutcome) -> str:
    """The report panel's markdown of one task outcome."""
    rep = outcome.report
    head = f"**{SUCCESS_TEXT}**" if rep.success else f"**Task failed** (stage `{outcome.stage}`)"
    lines = [head, "", f"- object: `{rep.object}`, robot `{rep.robot}`, planner `{rep.planner}`"]
    if rep.placement_error_m is not None:
        lines.append(f"- placement error: {rep.placement_error_m * 100:.1f} cm")
    lines.append(f"- duration: {rep.duration_s:.2f} s, collisions: {rep.collisions}")
    if np.isfinite(rep.max_tracking_error_m):
        lines.append(f"- TCP tracking error: max {rep.max_tracking_error_m * 1000:.1f} mm")
    lines.append("- wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in outcome.timings.items()))
    lines += [f"- failure: {f}" for f in rep.failures[:4]]
    if outcome.schedule is not None:
        lines += ["", "Steps:", *[f"- {s}" for s in outcome.schedule.steps[:12]]]
    return "\n".join(lines)


def speed_image(outcome: TaskOutcome, tcp_t: F64, tcp: dict[str, F64]) -> NDArray[np.uint8] | None:
    """(H, W, 3) uint8 plot of the planned wrist and robot TCP speeds [m/s] over time [s]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    from hsi_retarget.sources import human_motion_from_schedule

    if outcome.schedule is None:
        return None
    human = human_motion_from_schedule(outcome.schedule, 30.0)
    fig, ax = plt.subplots(figsize=(4.2, 2.6), dpi=80)
    colors = {"left": "tab:blue", "right": "tab:red"}
    for side, pos in human.wrist_position.items():
        if pos.shape[0] > 1:
            speed = np.linalg.norm(np.gradient(pos, human.t, axis=0), axis=1)
            ax.plot(human.t, speed, "--", color=colors[side], lw=1, label=f"{side} plan")
    for side, pos in tcp.items():
        if pos.shape[0] > 1:
            speed = np.linalg.norm(np.gradient(pos, tcp_t, axis=0), axis=1)
            ax.plot(tcp_t, speed, color=colors[side], lw=1.4, label=f"{side} robot")
    ax.set(xlabel="time [s]", ylabel="speed [m/s]", title="wrist / TCP speed")
    ax.legend(fontsize=6)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    buf.seek(0)
    return np.asarray(Image.open(buf).convert("RGB"), dtype=np.uint8)
