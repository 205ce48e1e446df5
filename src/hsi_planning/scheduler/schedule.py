"""The scheduler's output: timed keyframes of the key joints, the planned wrist segments, and JSON I/O.

A :class:`Schedule` holds snapshots: at every event time each key joint (``left_wrist``, ``right_wrist``,
``hip``, ``root``) gets one :class:`Keyframe`, so any wrist keyframe has the hip pose it is reached from at
the same time. Times are non-decreasing over the list and strictly increasing per key joint. The wrist
motion between two keyframes of a grasp or place is a :class:`PlannedSegment` (the planner's trajectory,
shifted to start at the keyframe time; its duration equals the keyframe time difference).
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import PlanningError
from hsi_planning.trajectory import WristTrajectory

KeyJoint = Literal["left_wrist", "right_wrist", "hip", "root"]
KEY_JOINTS: tuple[str, ...] = get_args(KeyJoint)
ContactEvent = Literal["", "grasp", "release", "push", "pull"]
CONTACT_EVENTS: tuple[str, ...] = get_args(ContactEvent)
#: Tolerance on keyframe times [s] when matching segments to keyframes.
TIME_TOLERANCE = 1e-6


def _vec(value: ArrayLike, n: int, what: str) -> NDArray[np.float64]:
    arr = np.array(value, dtype=np.float64, copy=True).reshape(-1)
    if arr.shape != (n,) or not np.isfinite(arr).all():
        raise PlanningError(f"{what} must be {n} finite numbers, got {np.asarray(value).tolist()!r}")
    return arr


@dataclass(frozen=True, eq=False)
class Keyframe:
    """Where one key joint must be at ``time``.

    Attributes:
        time: [s] from the start of the schedule.
        key_joint: ``left_wrist``, ``right_wrist``, ``hip`` or ``root`` (hip projected on the floor).
        position: (3,) [m] world frame.
        quaternion: (4,) [x y z w] world-frame orientation (unit).
        action: the step this keyframe belongs to (``navigate``, ``open``, ``reach``, ``grasp``,
            ``take_out``, ``close``, ``place``, ``release``, ``hold``, ``carry``, ``idle``, ...).
        contact_event: what happens at this keyframe (``grasp``, ``release``, ``pull``, ``push`` or '').
        hand: ``left``, ``right``, ``both`` or '' (hip/root).
        object_name: the object or furniture part acted on ('' = none).
    """

    time: float
    key_joint: KeyJoint
    position: NDArray[np.float64]
    quaternion: NDArray[np.float64]
    action: str
    contact_event: ContactEvent = ""
    hand: str = ""
    object_name: str = ""

    def __post_init__(self) -> None:
        if not math.isfinite(self.time) or self.time < 0.0:
            raise PlanningError(f"keyframe time must be a finite number >= 0 [s], got {self.time!r}")
        if self.key_joint not in KEY_JOINTS:
            raise PlanningError(
                f"key_joint={self.key_joint!r} is not valid; choose one of {list(KEY_JOINTS)}"
            )
        if self.contact_event not in CONTACT_EVENTS:
            raise PlanningError(
                f"contact_event={self.contact_event!r} is not valid; choose one of {list(CONTACT_EVENTS)}"
            )
        if self.hand not in ("left", "right", "both", ""):
            raise PlanningError(f"hand={self.hand!r} is not valid; choose left, right, both or ''")
        quat = _vec(self.quaternion, 4, "keyframe quaternion")
        norm = float(np.linalg.norm(quat))
        if norm < 1e-9:
            raise PlanningError("keyframe quaternion must be non-zero [x y z w]")
        object.__setattr__(self, "time", float(self.time))
        object.__setattr__(self, "position", _vec(self.position, 3, "keyframe position"))
        object.__setattr__(self, "quaternion", quat / norm)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: time [s], key joint, position [m], quaternion [x y z w], labels."""
        return {
            "time": self.time,
            "key_joint": self.key_joint,
            "position": [float(v) for v in self.position],
            "quaternion": [float(v) for v in self.quaternion],
            "hand": self.hand,
            "action": self.action,
            "contact_event": self.contact_event,
            "object": self.object_name,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Keyframe:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                time=float(data["time"]),
                key_joint=data["key_joint"],
                position=np.asarray(data["position"], dtype=np.float64),
                quaternion=np.asarray(data["quaternion"], dtype=np.float64),
                action=str(data["action"]),
                contact_event=data.get("contact_event", ""),
                hand=str(data.get("hand", "")),
                object_name=str(data.get("object", "")),
            )
        except KeyError as exc:
            raise PlanningError(
                f"keyframe dict lacks key {exc}; needs time, key_joint, position, ..."
            ) from exc


@dataclass(frozen=True, eq=False)
class PlannedSegment:
    """A planner trajectory placed in the schedule: it runs from ``start_time`` for its duration [s]."""

    start_time: float  #: [s] schedule time of the trajectory's first sample
    trajectory: WristTrajectory  #: the planned wrist segment (its own times start at 0)
    step: str = ""  #: the step it belongs to (e.g. ``reach``, ``take_out``, ``place``, ``withdraw``)

    @property
    def end_time(self) -> float:
        """[s] schedule time of the last sample."""
        return self.start_time + self.trajectory.duration

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the trajectory as :meth:`WristTrajectory.to_dict`)."""
        return {"start_time": self.start_time, "step": self.step, "trajectory": self.trajectory.to_dict()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PlannedSegment:
        """Inverse of :meth:`to_dict`."""
        return cls(
            float(data["start_time"]), WristTrajectory.from_dict(dict(data["trajectory"])), str(data["step"])
        )


@dataclass(frozen=True, eq=False)
class Schedule:
    """A task's keyframes (time-sorted), planned segments, one summary line per step, and the root path.

    Attributes:
        task_id: id of the goal this schedule serves.
        keyframes: sorted by time; every event time has one keyframe per key joint.
        segments: planned wrist segments, in time order.
        steps: human-readable summary, one line per step.
        root_path: (N, 2) [m] the floor path of the root over the whole task (navigation included).
        info: plain diagnostics (assignment, costs, blockers, opened parts, planner name).
    """

    task_id: str
    keyframes: tuple[Keyframe, ...]
    segments: tuple[PlannedSegment, ...] = ()
    steps: tuple[str, ...] = ()
    root_path: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2)))
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        frames = tuple(self.keyframes)
        times = [k.time for k in frames]
        if any(b < a - TIME_TOLERANCE for a, b in itertools.pairwise(times)):
            raise PlanningError("schedule keyframes must be sorted by time")
        for joint in KEY_JOINTS:
            own = [k.time for k in frames if k.key_joint == joint]
            if any(b <= a for a, b in itertools.pairwise(own)):
                raise PlanningError(f"keyframe times of {joint} must be strictly increasing")
        path = np.array(self.root_path, dtype=np.float64, copy=True).reshape(-1, 2)
        object.__setattr__(self, "keyframes", frames)
        object.__setattr__(self, "segments", tuple(self.segments))
        object.__setattr__(self, "steps", tuple(str(s) for s in self.steps))
        object.__setattr__(self, "root_path", path)
        object.__setattr__(self, "info", dict(self.info))

    @property
    def duration(self) -> float:
        """[s] time of the last keyframe (0 for an empty schedule)."""
        return self.keyframes[-1].time if self.keyframes else 0.0

    def of(self, key_joint: str) -> list[Keyframe]:
        """The keyframes of one key joint, in time order."""
        if key_joint not in KEY_JOINTS:
            raise PlanningError(f"key_joint={key_joint!r} is not valid; choose one of {list(KEY_JOINTS)}")
        return [k for k in self.keyframes if k.key_joint == key_joint]

    def at(self, key_joint: str, time: float) -> Keyframe:
        """The keyframe of ``key_joint`` at ``time`` [s] (within :data:`TIME_TOLERANCE`)."""
        for k in self.of(key_joint):
            if abs(k.time - time) <= TIME_TOLERANCE:
                return k
        raise PlanningError(f"no {key_joint} keyframe at t = {time:.6f} s")

    def events(self) -> list[Keyframe]:
        """Wrist keyframes with a contact event (grasp, release, pull, push), in time order."""
        return [k for k in self.keyframes if k.contact_event and k.key_joint.endswith("wrist")]

    def to_dict(self, segments: bool = True) -> dict[str, Any]:
        """JSON-ready dict; ``segments=False`` leaves the (large) planned trajectories out."""
        out: dict[str, Any] = {
            "task_id": self.task_id,
            "duration": self.duration,
            "steps": list(self.steps),
            "keyframes": [k.to_dict() for k in self.keyframes],
            "root_path": self.root_path.tolist(),
            "info": _plain(self.info),
        }
        if segments:
            out["segments"] = [s.to_dict() for s in self.segments]
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Schedule:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                task_id=str(data["task_id"]),
                keyframes=tuple(Keyframe.from_dict(k) for k in data["keyframes"]),
                segments=tuple(PlannedSegment.from_dict(s) for s in data.get("segments", [])),
                steps=tuple(data.get("steps", [])),
                root_path=np.asarray(data.get("root_path", []), dtype=np.float64).reshape(-1, 2),
                info=dict(data.get("info", {})),
            )
        except KeyError as exc:
            raise PlanningError(f"schedule dict lacks key {exc}; needs task_id and keyframes") from exc

    def write_json(self, path: str | Path, segments: bool = True) -> Path:
        """Write :meth:`to_dict` as indented JSON; returns the path."""
        out = Path(path)
        out.write_text(json.dumps(self.to_dict(segments), indent=1) + "\n", encoding="utf-8")
        return out

    @classmethod
    def read_json(cls, path: str | Path) -> Schedule:
        """Read a schedule written by :meth:`write_json`."""
        try:
            return cls.from_dict(json.loads(Path(path).read_text(encoding="utf-8")))
        except (OSError, json.JSONDecodeError) as exc:
            raise PlanningError(f"{path}: cannot read a schedule JSON file: {exc}") from exc


def _plain(value: Any) -> Any:
    """JSON-safe copy of diagnostics (numpy arrays and scalars become lists and floats)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Sequence) and not isinstance(value, str):
        return [_plain(v) for v in value]
    return value
