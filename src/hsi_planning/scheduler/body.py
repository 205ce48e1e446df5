"""The scheduler's body model: a hip pose (root on the floor, height, heading, trunk pitch), the
shoulders it implies, the arm's reach limit, and the wrist's ready and carry poses relative to the hip.

Hip frame: x forward (heading ``yaw`` about world z), y to the left, z up; the trunk leans forward by
``pitch`` about the hip's y axis. A shoulder sits at ``(0, ±shoulder_lateral, shoulder_height)`` in the
trunk frame (+ left, - right), so leaning moves it forward and down. A wrist at ``p`` is reachable when
``min_reach <= |p - shoulder| <= arm_reach``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError
from hsi_planning.trajectory import Hand

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class BodyConfig:
    """Dimensions and postures of an adult for reach and stance decisions."""

    arm_reach: float = 0.75  #: [m] largest wrist distance from its shoulder
    reach_margin: float = 0.03  #: [m] kept below ``arm_reach`` when a stance is chosen
    min_reach: float = 0.12  #: [m] smallest wrist distance from its shoulder
    shoulder_lateral: float = 0.18  #: [m] shoulder offset to the side of the hip (left +, right -)
    shoulder_height: float = 0.45  #: [m] shoulder height above the hip along the trunk
    body_radius: float = 0.25  #: [m] radius of the body's footprint (root clearance)
    standing_height: float = 0.95  #: [m] hip height standing upright
    #: (hip height [m], forward trunk pitch [deg]) of the stances tried, most upright first
    postures: tuple[tuple[float, float], ...] = (
        (0.95, 0.0),
        (0.92, 10.0),
        (0.88, 20.0),
        (0.82, 30.0),
        (0.74, 40.0),
        (0.64, 45.0),
        (0.54, 50.0),
        (0.44, 55.0),
    )
    ready_offset: tuple[float, float, float] = (
        0.25,
        0.2,
        0.1,
    )  #: [m] free wrist, hip frame (left; y mirrored)
    carry_offset: tuple[float, float, float] = (0.3, 0.1, 0.25)  #: [m] wrist carrying an object, hip frame
    torso_clearance: float = 0.08  #: [m] free space required around the shoulders and the neck

    def __post_init__(self) -> None:
        if not 0.3 <= self.arm_reach <= 1.2:
            raise ConfigError(f"BodyConfig.arm_reach must be in [0.3, 1.2] m, got {self.arm_reach}")
        if not 0.0 <= self.reach_margin < 0.5 * self.arm_reach:
            raise ConfigError(
                f"BodyConfig.reach_margin must be in [0, arm_reach/2) m, got {self.reach_margin}"
            )
        if not 0.0 <= self.min_reach < self.arm_reach - self.reach_margin:
            raise ConfigError("BodyConfig needs 0 <= min_reach < arm_reach - reach_margin [m]")
        for name in ("shoulder_lateral", "shoulder_height", "body_radius", "standing_height"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"BodyConfig.{name} must be > 0 m, got {getattr(self, name)}")
        if not self.postures:
            raise ConfigError("BodyConfig.postures must list at least one (hip height [m], pitch [deg])")
        for height, pitch in self.postures:
            if not (0.2 <= height <= 1.2 and 0.0 <= pitch <= 80.0):
                raise ConfigError(
                    f"BodyConfig.postures entry ({height}, {pitch}): hip height in [0.2, 1.2] m, "
                    "pitch in [0, 80] deg"
                )
        if self.torso_clearance < 0.0:
            raise ConfigError(f"BodyConfig.torso_clearance must be >= 0 m, got {self.torso_clearance}")

    @property
    def reach_limit(self) -> float:
        """[m] the reach used when choosing stances (``arm_reach - reach_margin``)."""
        return self.arm_reach - self.reach_margin


def hand_sign(hand: Hand) -> float:
    """+1 for the left hand, -1 for the right (the sign of its lateral hip-frame offset)."""
    return 1.0 if hand == "left" else -1.0


@dataclass(frozen=True, eq=False)
class HipPose:
    """A hip pose: ``position`` (3,) [m] (x, y on the floor plan, z = hip height), ``yaw`` [rad] heading
    about world z, ``pitch`` [rad] forward trunk lean."""

    position: F64
    yaw: float
    pitch: float = 0.0

    def __post_init__(self) -> None:
        pos = np.array(self.position, dtype=np.float64, copy=True).reshape(3)
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "yaw", float(self.yaw))
        object.__setattr__(self, "pitch", float(self.pitch))

    @classmethod
    def standing(cls, xy: ArrayLike, yaw: float, config: BodyConfig) -> HipPose:
        """Upright at ``xy`` (2,) [m] facing ``yaw`` [rad]."""
        x, y = (float(v) for v in np.asarray(xy, dtype=np.float64).reshape(2))
        return cls(np.array([x, y, config.standing_height]), yaw, 0.0)

    @property
    def xy(self) -> F64:
        """(2,) [m] root position on the floor."""
        return np.array(self.position[:2], copy=True)

    @property
    def heading(self) -> F64:
        """(2,) unit facing direction on the floor."""
        return np.array([math.cos(self.yaw), math.sin(self.yaw)])

    def rotation(self) -> Rotation:
        """Trunk orientation: yaw about world z, then pitch about the hip's y axis (leaning forward)."""
        return Rotation.from_euler("ZY", [self.yaw, self.pitch])

    def quaternion(self) -> F64:
        """(4,) [x y z w] trunk orientation (hip keyframe)."""
        return np.asarray(self.rotation().as_quat(), dtype=np.float64)

    def root_quaternion(self) -> F64:
        """(4,) [x y z w] heading only (root keyframe)."""
        return np.asarray(Rotation.from_euler("z", self.yaw).as_quat(), dtype=np.float64)

    def root_position(self) -> F64:
        """(3,) [m] the hip projected on the floor (z = 0)."""
        return np.array([self.position[0], self.position[1], 0.0])

    def shoulder(self, hand: Hand, config: BodyConfig) -> F64:
        """(3,) [m] world position of ``hand``'s shoulder."""
        local = np.array([0.0, hand_sign(hand) * config.shoulder_lateral, config.shoulder_height])
        return np.asarray(self.position + self.rotation().apply(local), dtype=np.float64)

    def neck(self, config: BodyConfig) -> F64:
        """(3,) [m] world position of the base of the neck (between the shoulders)."""
        return np.asarray(self.position + self.rotation().apply([0.0, 0.0, config.shoulder_height]))

    def wrist_offset(self, hand: Hand, offset: tuple[float, float, float]) -> F64:
        """(3,) [m] world position of a hip-frame wrist offset (left-hand values; y mirrored for the right).

        Uses the heading only (the wrist stays in front of the body when the trunk leans)."""
        local = np.array([offset[0], hand_sign(hand) * offset[1], offset[2]])
        return np.asarray(self.position + Rotation.from_euler("z", self.yaw).apply(local), dtype=np.float64)

    def reach_distance(self, hand: Hand, point: ArrayLike, config: BodyConfig) -> float:
        """[m] distance from ``hand``'s shoulder to ``point`` (3,)."""
        return float(np.linalg.norm(np.asarray(point, dtype=np.float64) - self.shoulder(hand, config)))

    def reachable(self, hand: Hand, point: ArrayLike, config: BodyConfig, tolerance: float = 1e-6) -> bool:
        """Whether ``point`` (3,) [m] is within ``[min_reach, arm_reach]`` of ``hand``'s shoulder."""
        d = self.reach_distance(hand, point, config)
        return config.min_reach - tolerance <= d <= config.arm_reach + tolerance

    def to_dict(self) -> dict[str, float | list[float]]:
        """Plain dict: position [m], yaw and pitch [deg]."""
        return {
            "position": [float(v) for v in self.position],
            "yaw_deg": math.degrees(self.yaw),
            "pitch_deg": math.degrees(self.pitch),
        }


def wrist_quaternion(direction: ArrayLike) -> F64:
    """(4,) [x y z w] wrist orientation whose x axis points along ``direction`` (3,) (into the target),
    z axis as close to world up as possible (world +x when ``direction`` is vertical)."""
    x = np.asarray(direction, dtype=np.float64).reshape(3)
    x = x / np.linalg.norm(x)
    hint = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.95 else np.array([1.0, 0.0, 0.0])
    z = hint - (hint @ x) * x
    z /= np.linalg.norm(z)
    rot = np.column_stack([x, np.cross(z, x), z])
    return np.asarray(Rotation.from_matrix(rot).as_quat(), dtype=np.float64)
