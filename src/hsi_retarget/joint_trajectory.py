"""Timed joint trajectories: the output of retargeting and the input of the MuJoCo check and backends."""

from __future__ import annotations

from dataclasses import dataclass, field
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
        object.__setattr__(self, "meta", dict(self.meta))

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
        return np.asarray((1.0 - a) * self.q[i] + a * self.q[i + 1])

    def velocities(self) -> NDArray[np.float64]:
        """(T, nq) [unit/s] finite-difference rates of ``q`` (for limit checks of actuated joints)."""
        if self.t.shape[0] < 2:
            return np.zeros_like(self.q)
        return np.asarray(np.gradient(self.q, self.t, axis=0))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {
            "robot": self.robot,
            "joint_names": list(self.joint_names),
            "t": self.t.tolist(),
            "q": self.q.tolist(),
            "events": [e.__dict__ for e in self.events],
        }

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
            )
        except (KeyError, TypeError) as exc:
            msg = f"joint trajectory dict is malformed ({exc}); needs robot, t, q, joint_names"
            raise RetargetError(msg) from exc
