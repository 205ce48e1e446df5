"""Timed joint trajectories: the output of retargeting and the input of the MuJoCo check and backends."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import RetargetError


@dataclass(frozen=True)
class ContactEvent:
    """A gripper event on the trajectory.

    Attributes:
        time: [s] from the trajectory start.
        hand: ``left`` or ``right``.
        kind: ``grasp`` (close on ``object_name``) or ``release`` (open).
        object_name: scene label of the object (or door/drawer handle part).
    """

    time: float
    hand: str
    kind: str
    object_name: str = ""


@dataclass(frozen=True)
class JointTrajectory:
    """A time-parameterized configuration trajectory of one robot.

    Attributes:
        robot: robot name (``dual_ur5e`` or ``humanoid``, see :mod:`hsi_retarget.robots`).
        t: (T,) [s] strictly increasing sample times from 0.
        q: (T, nq) pinocchio configurations (a floating base first: xyz [m] + quaternion xyzw).
        joint_names: names of the pinocchio joints in ``q`` order (excluding the universe joint).
        events: gripper grasp/release events, sorted by time.
        meta: plain diagnostics (reach violations, IK residuals [m], ...).
    """

    robot: str
    t: NDArray[np.float64]
    q: NDArray[np.float64]
    joint_names: tuple[str, ...]
    events: tuple[ContactEvent, ...] = ()
    meta: dict[str, Any] = field(default_factory=dict)
    #: q index of a floating base (x y z qx qy qz qw), -1 if none; ``sample`` re-normalizes its quaternion.
    #: ``None``: 0 when q has 7 more columns than ``joint_names`` (the root is not among them), else -1.
    floating_index: int | None = None

    def __post_init__(self) -> None:
        t = np.array(self.t, dtype=np.float64, copy=True).reshape(-1)
        q = np.array(self.q, dtype=np.float64, copy=True)
        if t.shape[0] < 1 or q.ndim != 2 or q.shape[0] != t.shape[0]:
            raise RetargetError(f"need t (T,) and q (T, nq) with T >= 1; got {t.shape} and {q.shape}")
        if not (np.isfinite(t).all() and np.isfinite(q).all()):
            raise RetargetError("joint trajectory contains NaN or infinite values")
        if t.shape[0] > 1 and np.any(np.diff(t) <= 0.0):
            raise RetargetError("joint trajectory times must be strictly increasing")
        events = tuple(sorted(self.events, key=lambda e: e.time))
        for e in events:
            if e.hand not in ("left", "right") or e.kind not in ("grasp", "release"):
                raise RetargetError(f"bad contact event {e}: hand left|right, kind grasp|release")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        object.__setattr__(self, "events", events)
        floating = self.floating_index
        if floating is None:
            floating = 0 if q.shape[1] == len(tuple(self.joint_names)) + 7 else -1
        object.__setattr__(self, "floating_index", int(floating))
        if floating >= 0 and floating + 7 > q.shape[1]:
            raise RetargetError(
                f"floating_index {self.floating_index} needs 7 entries in q of width {q.shape[1]}"
            )
        object.__setattr__(self, "meta", dict(self.meta))

    @property
    def root_index(self) -> int:
        """q index of the floating base, -1 if none."""
        return -1 if self.floating_index is None else int(self.floating_index)

    @property
    def duration(self) -> float:
        """[s] total duration."""
        return float(self.t[-1] - self.t[0])

    def sample(self, time: float) -> NDArray[np.float64]:
        """(nq,) configuration at ``time`` [s] by linear interpolation (clamped at the ends).

        A floating-base quaternion is re-normalized after interpolation.
        """
        if time <= self.t[0]:
            return np.array(self.q[0], dtype=np.float64)
        if time >= self.t[-1]:
            return np.array(self.q[-1], dtype=np.float64)
        i = int(np.searchsorted(self.t, time)) - 1
        a = (time - self.t[i]) / (self.t[i + 1] - self.t[i])
        q0, q1 = self.q[i], np.array(self.q[i + 1])
        k = self.root_index
        if k >= 0 and float(q0[k + 3 : k + 7] @ q1[k + 3 : k + 7]) < 0.0:
            q1[k + 3 : k + 7] *= -1.0  # same hemisphere: interpolate along the short arc
        out = np.asarray((1.0 - a) * q0 + a * q1, dtype=np.float64)
        if k >= 0:
            quat = out[k + 3 : k + 7]
            out[k + 3 : k + 7] = quat / np.linalg.norm(quat)
        return out

    def velocities(self) -> NDArray[np.float64]:
        """(T, nq) [unit/s] finite-difference rates of ``q`` (for limit checks of actuated joints)."""
        if self.t.shape[0] < 2:
            return np.zeros_like(self.q)
        return np.asarray(np.gradient(self.q, self.t, axis=0))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (``meta`` made JSON-safe: arrays become lists)."""
        return {
            "robot": self.robot,
            "joint_names": list(self.joint_names),
            "floating_index": self.floating_index,
            "t": self.t.tolist(),
            "q": self.q.tolist(),
            "events": [dict(e.__dict__) for e in self.events],
            "meta": plain(self.meta),
        }

    def write_json(self, path: str | Path) -> Path:
        """Write :meth:`to_dict` as JSON; returns the path."""
        out = Path(path)
        out.write_text(json.dumps(self.to_dict()) + "\n", encoding="utf-8")
        return out

    @classmethod
    def read_json(cls, path: str | Path) -> JointTrajectory:
        """Read a file written by :meth:`write_json`."""
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise RetargetError(f"{path}: cannot read a joint trajectory JSON file: {exc}") from exc
        if not isinstance(data, dict):
            raise RetargetError(
                f"{path}: a joint trajectory JSON file holds an object, got {type(data).__name__}"
            )
        return cls.from_dict(data)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> JointTrajectory:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                robot=str(data["robot"]),
                t=np.asarray(data["t"], dtype=np.float64),
                q=np.asarray(data["q"], dtype=np.float64),
                joint_names=tuple(data["joint_names"]),
                events=tuple(ContactEvent(**e) for e in data.get("events", [])),
                meta=dict(data.get("meta", {})),
                floating_index=data.get("floating_index"),
            )
        except (KeyError, TypeError, ValueError) as exc:
            msg = f"joint trajectory dict is malformed ({exc}); needs robot, t, q, joint_names"
            raise RetargetError(msg) from exc


def plain(value: Any) -> Any:
    """JSON-safe copy of diagnostics: numpy arrays and scalars become lists and Python numbers, non-finite
    floats become ``None``."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return plain(value.item())
    if isinstance(value, float):
        return value if np.isfinite(value) else None
    if isinstance(value, Sequence) and not isinstance(value, str):
        return [plain(v) for v in value]
    return value
