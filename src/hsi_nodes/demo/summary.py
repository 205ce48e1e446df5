"""The demo's reports: ``report.json`` (one entry per task), ``report.md`` and the printed summary.

Each ``report.json`` entry is the task's :class:`~hsi_retarget.sim_check.ExecutionReport` as a dict
(``object``, ``robot``, ``planner``, ``success``, ``placement_error_m``, ``duration_s``, ``collisions``,
``max_tracking_error_m``, and the details: failures, grasps, collisions, limit violations) plus the task
(``task``, ``scene``, ``description``), the ``stage`` it reached, the ``error`` that stopped it, the
schedule and retargeting summaries and the wall time per stage (:meth:`TaskOutcome.entry`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from hsi_nodes.demo.pipeline import TaskOutcome
from hsi_retarget.sim_check.report import REPORT_KEYS

__all__ = ["REQUIRED_KEYS", "format_summary", "write_summary"]

#: Keys every ``report.json`` entry has (the issue's list).
REQUIRED_KEYS: tuple[str, ...] = REPORT_KEYS


def _num(value: Any, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def _rows(outcomes: Sequence[TaskOutcome]) -> list[list[str]]:
    rows = []
    for o in outcomes:
        e = o.entry()
        rows.append(
            [
                o.task.name,
                str(e["object"]),
                "yes" if e["success"] else "no",
                o.stage,
                _num(e["placement_error_m"]),
                _num(e["duration_s"], 1),
                str(e["collisions"]),
                _num(e["max_tracking_error_m"]),
                _num(o.timings.get("total"), 1),
            ]
        )
    return rows


_HEADER = [
    "task",
    "object",
    "success",
    "stage",
    "placement err [m]",
    "duration [s]",
    "collisions",
    "max track err [m]",
    "wall [s]",
]


def format_summary(outcomes: Sequence[TaskOutcome], info: Mapping[str, Any]) -> str:
    """A plain-text table of the tasks with one line per failure reason."""
    rows = [_HEADER, *_rows(outcomes)]
    widths = [max(len(r[i]) for r in rows) for i in range(len(_HEADER))]
    lines = [
        f"pick-and-place demo: robot {info.get('robot')}, planner {info.get('planner')}, "
        f"{sum(o.report.success for o in outcomes)}/{len(outcomes)} tasks succeeded",
    ]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    for o in outcomes:
        for reason in (*o.report.failures, *o.diagnosis()):
            lines.append(f"  {o.task.name}: {reason[:300]}")
    return "\n".join(lines)


def _markdown(outcomes: Sequence[TaskOutcome], info: Mapping[str, Any]) -> str:
    from hsi_retarget.sim_check import reports_markdown

    lines = [
        "# Simulated pick-and-place demo",
        "",
        f"Robot `{info.get('robot')}`, planner `{info.get('planner')}`, "
        f"{sum(o.report.success for o in outcomes)}/{len(outcomes)} tasks succeeded, "
        f"demo wall time {_num(info.get('wall_s'), 1)} s. Each task runs from the scene at rest (a fresh "
        "MuJoCo world); success = the object within 2 cm of its placement, no robot collisions.",
        "",
        "| " + " | ".join(_HEADER) + " |",
        "|" + "---|" * len(_HEADER),
    ]
    lines += ["| " + " | ".join(r) + " |" for r in _rows(outcomes)]
    lines.append("")
    for o in outcomes:
        lines.append(f"- **{o.task.name}** ({o.task.scene}): {o.task.description}")
        if o.schedule is not None:
            lines += [f"    - `{s.strip()}`" for s in o.schedule.steps]
        if o.error:
            lines.append(f"    - stopped in stage `{o.stage}`: {o.error}")
        lines += [f"    - {d}" for d in o.diagnosis()]
    lines.append("")
    executed = [o.report for o in outcomes if o.stage == "done"]
    if executed:
        lines.append(reports_markdown(executed, title="MuJoCo execution details"))
    files = info.get("files", {})
    if files:
        lines += ["## Files", ""] + [f"- {k}: `{v}`" for k, v in files.items()]
    return "\n".join(lines) + "\n"


def write_summary(outcomes: Sequence[TaskOutcome], out: Path, info: Mapping[str, Any]) -> tuple[Path, Path]:
    """Write ``report.json`` (a list of :meth:`TaskOutcome.entry`) and ``report.md`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    json_path, md_path = out / "report.json", out / "report.md"
    entries = [o.entry() for o in outcomes]
    json_path.write_text(json.dumps(entries, indent=2) + "\n", encoding="utf-8")
    md_path.write_text(_markdown(outcomes, info), encoding="utf-8")
    return json_path, md_path
