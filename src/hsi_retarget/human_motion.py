"""Human goals over time (:class:`HumanMotion`): the common input of the retargeting mapping, built from a
recorded motion, a schedule or planned wrist segments by :mod:`hsi_retarget.sources`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import RetargetError
from hsi_retarget.joint_trajectory import ContactEvent

F64 = NDArray[np.float64]
Side = Literal["left", "right"]
SIDES: tuple[Side, Side] = ("left", "right")


@dataclass(frozen=True, eq=False)
class HumanMotion:
    """Human goals over time, from a recorded motion or a plan (world frame).

    Attributes:
        t: (T,) [s] increasing sample times.
        wrist_position: side -> (T, 3) [m] for the hands that have goals.
        wrist_rotation: side -> (T, 3, 3) wrist orientation (planner convention, see the module docstring).
        active: side -> (T,) bool, samples where that wrist goal is to be tracked.
        hip_position: (T, 3) [m]; ``hip_yaw`` (T,) [rad] heading; ``hip_pitch`` (T,) [rad] forward lean.
        shoulder_position: side -> (T, 3) [m] measured shoulders (mocap); empty: from the hip (adult).
        arm_length: [m] measured shoulder-wrist length; ``None``: the config's.
        standing_hip_height: [m] hip height standing upright; ``None``: the config's.
        standing_shoulder_height: [m] shoulder height standing; ``None``: hip + the config's offset.
        events: grasp/release events of the motion.
        source: description of where it came from.
        contact: side -> (T,) [0..1] closeness to a contact (1 on the straight approach into a grasp or
            release, while the hand holds a door or drawer, on the first retreat); weights the IK's TCP
            task up there (:class:`~hsi_retarget.ik.IKConfig`). Empty: none.
    """

    t: F64
    wrist_position: dict[str, F64]
    wrist_rotation: dict[str, F64]
    active: dict[str, NDArray[np.bool_]]
    hip_position: F64
    hip_yaw: F64
    hip_pitch: F64 | None = None
    shoulder_position: dict[str, F64] = field(default_factory=dict)
    arm_length: float | None = None
    standing_hip_height: float | None = None
    standing_shoulder_height: float | None = None
    events: tuple[ContactEvent, ...] = ()
    source: str = ""
    contact: dict[str, F64] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.array(self.t, dtype=np.float64, copy=True).reshape(-1)
        n = t.shape[0]
        if n < 1 or (n > 1 and np.any(np.diff(t) <= 0.0)) or not np.isfinite(t).all():
            raise RetargetError("HumanMotion.t must be finite and strictly increasing [s]")

        def arr(a: F64, shape: tuple[int, ...], what: str) -> F64:
            out = np.array(a, dtype=np.float64, copy=True)
            if out.shape != shape or not np.isfinite(out).all():
                raise RetargetError(f"HumanMotion.{what} must be finite with shape {shape}, got {out.shape}")
            return out

        sides = set(self.wrist_position)
        if not sides <= set(SIDES) or sides != set(self.wrist_rotation) or sides != set(self.active):
            raise RetargetError("HumanMotion wrist_position/rotation/active need the same sides (left/right)")
        object.__setattr__(self, "t", t)
        object.__setattr__(
            self,
            "wrist_position",
            {s: arr(p, (n, 3), "wrist_position") for s, p in self.wrist_position.items()},
        )
        object.__setattr__(
            self,
            "wrist_rotation",
            {s: arr(r, (n, 3, 3), "wrist_rotation") for s, r in self.wrist_rotation.items()},
        )
        active = {s: np.array(a, dtype=bool, copy=True).reshape(-1) for s, a in self.active.items()}
        if any(a.shape != (n,) for a in active.values()):
            raise RetargetError(f"HumanMotion.active flags must have shape ({n},)")
        object.__setattr__(self, "active", active)
        object.__setattr__(self, "hip_position", arr(self.hip_position, (n, 3), "hip_position"))
        object.__setattr__(self, "hip_yaw", arr(self.hip_yaw, (n,), "hip_yaw"))
        pitch = np.zeros(n) if self.hip_pitch is None else arr(self.hip_pitch, (n,), "hip_pitch")
        object.__setattr__(self, "hip_pitch", pitch)
        object.__setattr__(
            self,
            "shoulder_position",
            {s: arr(p, (n, 3), "shoulder_position") for s, p in self.shoulder_position.items()},
        )
        object.__setattr__(self, "events", tuple(self.events))
        contact = {s: arr(c, (n,), "contact") for s, c in self.contact.items()}
        if not set(contact) <= sides or any(np.any((c < 0.0) | (c > 1.0)) for c in contact.values()):
            raise RetargetError("HumanMotion.contact: sides with wrist goals, values in [0, 1]")
        object.__setattr__(self, "contact", contact)

    @property
    def n_samples(self) -> int:
        """Number of samples T."""
        return int(self.t.shape[0])
