"""The result of one execution check and its JSON / Markdown forms.

:class:`ExecutionReport` carries the fields of the demo's ``report.json`` entries (``object``,
``robot``, ``planner``, ``success``, ``placement_error_m``, ``duration_s``, ``collisions``,
``max_tracking_error_m``) plus
door/drawer opening, limit violations, perturbations, grasps, final object poses and timing.
:func:`reports_markdown` renders several reports as one table; :func:`write_reports` writes both files.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hsi_retarget.sim_check.grasp import GraspRecord
from hsi_retarget.sim_check.monitor import CollisionRecord, LimitViolation


@dataclass(frozen=True)
class PerturbationRecord:
    """What a perturbation did to the execution."""

    event: dict[str, Any]  #: the event (see :func:`hsi_retarget.sim_check.perturb.event_dict`)
    peak_error_m: float  #: largest TCP tracking error from the event to the end of its recovery window [m]
    baseline_error_m: float  #: largest TCP tracking error in the 0.2 s before the event [m]
    recovered: bool  #: the error fell back under the recovery threshold within the window
    recovery_time_s: float | None  #: from the end of the push to recovery [s]; None if not recovered
    replanned: bool  #: the re-plan hook returned a new trajectory

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {**self.__dict__, "event": dict(self.event)}


@dataclass(frozen=True)
class ExecutionTrace:
    """Time series at the control rate (for plots and recovery analysis)."""

    t: NDArray[np.float64]  #: (K,) [s] since the execution start
    tcp_error: NDArray[np.float64]  #: (K, 2) [m] left/right TCP position error vs commanded FK
    joint_error: NDArray[np.float64]  #: (K,) [rad or m] largest actuated-joint error (fingers excluded)


@dataclass(frozen=True)
class ExecutionReport:
    """Outcome of executing one trajectory in MuJoCo."""

    object: str  #: task object (or the door/drawer for an opening task)
    robot: str
    planner: str
    success: bool
    placement_error_m: float | None  #: object-to-placement distance [m]; None without a placement goal
    duration_s: float  #: simulated time [s]
    collisions: int  #: number of colliding (robot geom, furniture/arm geom) pairs
    max_tracking_error_m: float  #: largest TCP position error [m]
    rms_tracking_error_m: float  #: RMS TCP position error [m]
    max_joint_error: float  #: largest actuated-joint error [rad or m]
    opening_part: str = ""  #: door or drawer required to open ("" none)
    opening: float | None = None  #: its final opening [rad for doors, m for drawers]
    opening_required: float | None = None  #: required opening [same unit]
    collision_details: tuple[CollisionRecord, ...] = ()
    limit_violations: tuple[LimitViolation, ...] = ()
    perturbations: tuple[PerturbationRecord, ...] = ()
    grasps: tuple[GraspRecord, ...] = ()
    object_final_poses: dict[str, list[float]] = field(default_factory=dict)  #: name -> pos [m] + quat wxyz
    failures: tuple[str, ...] = ()  #: why ``success`` is False
    replans: int = 0  #: trajectories taken from the re-plan hook
    #: largest correction of the task object's carry from its pose in the hand [m]
    #: (:mod:`hsi_retarget.sim_check.place_feedback`)
    place_shift_m: float = 0.0
    wall_time_s: float = 0.0  #: [s]
    realtime_factor: float = 0.0  #: simulated seconds per wall-clock second [-]
    trace: ExecutionTrace | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the trace is left out; NaN/inf become None)."""
        out: dict[str, Any] = {}
        for key, value in self.__dict__.items():
            if key == "trace":
                continue
            if isinstance(value, tuple):
                out[key] = [_item(v) for v in value]
            else:
                out[key] = value
        out["limit_violation_count"] = len(self.limit_violations)
        clean: dict[str, Any] = _finite(out)
        return clean

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ExecutionReport:
        """The report of a :meth:`to_dict` dict (e.g. read back from JSON): every field, the collision,
        limit, perturbation and grasp records included (None for a NaN that JSON turned into null; the trace
        is not part of the dict).

        Raises:
            MessageError: a record with missing or unknown fields.
        """
        from hsi_planning.errors import MessageError

        nan = float("nan")

        def num(key: str, default: float = nan) -> float:
            value = data.get(key)
            return default if value is None else float(value)

        def records(key: str, kind: Any) -> tuple[Any, ...]:
            try:
                return tuple(kind(**item) for item in data.get(key) or [])
            except TypeError as exc:
                raise MessageError(f"ExecutionReport.from_dict: bad {key} record: {exc}") from exc

        placement = data.get("placement_error_m")
        opening, required = data.get("opening"), data.get("opening_required")
        return cls(
            object=str(data.get("object", "")),
            robot=str(data.get("robot", "")),
            planner=str(data.get("planner", "")),
            success=bool(data.get("success", False)),
            placement_error_m=None if placement is None else float(placement),
            duration_s=num("duration_s", 0.0),
            collisions=int(data.get("collisions") or 0),
            max_tracking_error_m=num("max_tracking_error_m"),
            rms_tracking_error_m=num("rms_tracking_error_m"),
            max_joint_error=num("max_joint_error"),
            opening_part=str(data.get("opening_part") or ""),
            opening=None if opening is None else float(opening),
            opening_required=None if required is None else float(required),
            collision_details=records("collision_details", CollisionRecord),
            limit_violations=records("limit_violations", LimitViolation),
            perturbations=records("perturbations", PerturbationRecord),
            grasps=records("grasps", GraspRecord),
            object_final_poses={
                str(k): [float(x) for x in v] for k, v in (data.get("object_final_poses") or {}).items()
            },
            failures=tuple(str(f) for f in data.get("failures") or []),
            replans=int(data.get("replans") or 0),
            wall_time_s=num("wall_time_s", 0.0),
            realtime_factor=num("realtime_factor", 0.0),
        )

    def to_json(self, path: str | Path | None = None) -> str:
        """JSON text of :meth:`to_dict`; also written to ``path`` if given."""
        text = json.dumps(self.to_dict(), indent=2)
        if path is not None:
            Path(path).write_text(text + "\n", encoding="utf-8")
        return text

    def to_markdown(self) -> str:
        """A Markdown section: summary table, then collisions, limit violations and perturbations."""
        lines = [
            f"### {self.object or '(no object)'} — {self.robot} / {self.planner or '-'}: "
            + ("**success**" if self.success else "**failure**"),
            "",
            "| quantity | value |",
            "|---|---|",
            f"| placement error [m] | {_num(self.placement_error_m)} |",
            f"| duration [s] | {self.duration_s:.2f} |",
            f"| collisions | {self.collisions} |",
            f"| max / RMS tracking error [m] | {self.max_tracking_error_m:.4f} / "
            f"{self.rms_tracking_error_m:.4f} |",
            f"| max joint error | {self.max_joint_error:.4f} |",
            f"| limit violations | {len(self.limit_violations)} |",
            f"| real-time factor | {self.realtime_factor:.2f} |",
        ]
        if self.opening_part:
            lines.append(
                f"| opening of {self.opening_part} | {_num(self.opening)} "
                f"(required {_num(self.opening_required)}) |"
            )
        if self.failures:
            lines += ["", "Failures: " + "; ".join(self.failures)]
        holds = {"weld": "welded on contact", "pivot": "its bar free to turn in the gripper"}
        for g in self.grasps:
            if g.kind == "grasp":
                how = f" ({holds[g.hold]})" if g.hold in holds else ""
                lines.append(f"- {g.hand} hand grasps {g.target} at {g.time_s:.2f} s{how}")
        for c in self.collision_details:
            lines.append(
                f"- collision {c.robot_geom} ↔ {c.other_geom} at {c.first_time_s:.2f} s, "
                f"{c.max_depth_m * 1000:.2f} mm"
            )
        for v in self.limit_violations:
            lines.append(
                f"- {v.source} {v.quantity} limit of {v.joint}: {v.worst_value:.3f} "
                f"not in [{v.lower:.3f}, {v.upper:.3f}]"
            )
        for p in self.perturbations:
            rec = (
                f"recovered after {p.recovery_time_s:.2f} s"
                if p.recovered and p.recovery_time_s is not None
                else "not recovered"
            )
            lines.append(
                f"- {p.event['kind']} at {p.event['time_s']:.2f} s: peak error {p.peak_error_m:.4f} m, {rec}"
                + (", re-planned" if p.replanned else "")
            )
        return "\n".join(lines) + "\n"


#: Keys every task entry of a report has (the issue's list), in table-column order.
REPORT_KEYS: tuple[str, ...] = (
    "object",
    "robot",
    "planner",
    "success",
    "placement_error_m",
    "duration_s",
    "collisions",
    "max_tracking_error_m",
)


def reports_markdown(reports: list[ExecutionReport], title: str = "Execution in MuJoCo") -> str:
    """One Markdown table of the main fields of ``reports``, then each report's details."""
    lines = [f"## {title}", "", "| " + " | ".join(REPORT_KEYS) + " |", "|" + "---|" * len(REPORT_KEYS)]
    for r in reports:
        row = r.to_dict()
        lines.append("| " + " | ".join(_num(row[c]) for c in REPORT_KEYS) + " |")
    successes = sum(r.success for r in reports)
    lines += ["", f"Success: {successes}/{len(reports)}", ""]
    return "\n".join(lines) + "\n" + "\n".join(r.to_markdown() for r in reports)


def write_reports(reports: list[ExecutionReport], folder: str | Path) -> tuple[Path, Path]:
    """Write ``report.json`` (a list of :meth:`ExecutionReport.to_dict`) and ``report.md`` into ``folder``."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    json_path, md_path = out / "report.json", out / "report.md"
    json_path.write_text(json.dumps([r.to_dict() for r in reports], indent=2) + "\n", encoding="utf-8")
    md_path.write_text(reports_markdown(reports), encoding="utf-8")
    return json_path, md_path


def _item(value: Any) -> Any:
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    return value


def _num(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _finite(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
