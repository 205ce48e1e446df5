"""Timed 6D wrist trajectories: the common output of every planner and the human-reach model."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import PlanningError

Hand = Literal["left", "right"]
Action = Literal["grasp", "place"]
Segment = Literal["approach", "leave"]

HANDS: tuple[Hand, ...] = ("left", "right")
ACTIONS: tuple[Action, ...] = ("grasp", "place")
SEGMENTS: tuple[Segment, ...] = ("approach", "leave")


def _check_choice(name: str, value: str, valid: tuple[str, ...]) -> None:
    if value not in valid:
        raise PlanningError(f"{name}={value!r} is not valid; choose one of {list(valid)}")


@dataclass(frozen=True)
class WristTrajectory:
    """One timed 6D wrist path segment.

    Attributes:
        t: (T,) [s] strictly increasing sample times, starting at 0.
        position: (T, 3) [m] wrist position in the world frame.
        quaternion: (T, 4) unit quaternions [x y z w], world frame orientation of the wrist.
        hand: which hand moves.
        action: what the contact at the end (approach) or start (leave) does.
        segment: ``approach`` ends at the contact pose, ``leave`` starts there.
        contact_index: index of the contact sample (last for approach, first for leave).
        planner: name of the planner that produced it.
        object_name: the object (label name) the contact is with.
    """

    t: NDArray[np.float64]
    position: NDArray[np.float64]
    quaternion: NDArray[np.float64]
    hand: Hand = "right"
    action: Action = "grasp"
    segment: Segment = "approach"
    contact_index: int = -1
    planner: str = ""
    object_name: str = ""
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.array(self.t, dtype=np.float64, copy=True).reshape(-1)
        pos = np.array(self.position, dtype=np.float64, copy=True)
        quat = np.array(self.quaternion, dtype=np.float64, copy=True)
        n = t.shape[0]
        if n < 2:
            raise PlanningError(f"a trajectory needs at least 2 samples, got {n}")
        if pos.shape != (n, 3) or quat.shape != (n, 4):
            raise PlanningError(
                f"shapes must be t (T,), position (T, 3), quaternion (T, 4); "
                f"got {t.shape}, {pos.shape}, {quat.shape}"
            )
        if not (np.isfinite(t).all() and np.isfinite(pos).all() and np.isfinite(quat).all()):
            raise PlanningError("trajectory contains NaN or infinite values")
        if np.any(np.diff(t) <= 0.0):
            raise PlanningError("trajectory times must be strictly increasing")
        norms = np.linalg.norm(quat, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-3):
            worst = float(np.abs(norms - 1.0).max())
            raise PlanningError(f"quaternions must be unit length (max ||q|-1| = {worst:.3g})")
        _check_choice("hand", self.hand, HANDS)
        _check_choice("action", self.action, ACTIONS)
        _check_choice("segment", self.segment, SEGMENTS)
        ci = self.contact_index if self.contact_index >= 0 else n + self.contact_index
        if not 0 <= ci < n:
            raise PlanningError(f"contact_index {self.contact_index} outside 0..{n - 1}")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "quaternion", quat / norms[:, None])
        object.__setattr__(self, "contact_index", int(ci))
        object.__setattr__(self, "meta", dict(self.meta))

    @property
    def duration(self) -> float:
        """Total duration [s]."""
        return float(self.t[-1] - self.t[0])

    def velocity(self) -> NDArray[np.float64]:
        """(T, 3) [m/s] finite-difference wrist velocity."""
        return np.gradient(self.position, self.t, axis=0)

    def speed(self) -> NDArray[np.float64]:
        """(T,) [m/s] wrist speed."""
        return np.asarray(np.linalg.norm(self.velocity(), axis=1))

    def path_length(self) -> float:
        """Length of the wrist path [m]."""
        return float(np.linalg.norm(np.diff(self.position, axis=0), axis=1).sum())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: ``t`` [s], ``position`` [m], ``quaternion`` [x y z w], contact index, labels."""
        return {
            "hand": self.hand,
            "action": self.action,
            "segment": self.segment,
            "planner": self.planner,
            "object_name": self.object_name,
            "contact_index": self.contact_index,
            "t": self.t.tolist(),
            "position": self.position.tolist(),
            "quaternion": self.quaternion.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> WristTrajectory:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                t=np.asarray(data["t"], dtype=np.float64),
                position=np.asarray(data["position"], dtype=np.float64),
                quaternion=np.asarray(data["quaternion"], dtype=np.float64),
                hand=data.get("hand", "right"),
                action=data.get("action", "grasp"),
                segment=data.get("segment", "approach"),
                contact_index=int(data.get("contact_index", -1)),
                planner=str(data.get("planner", "")),
                object_name=str(data.get("object_name", "")),
            )
        except KeyError as exc:
            raise PlanningError(f"trajectory dict lacks key {exc}; needs t, position, quaternion") from exc
