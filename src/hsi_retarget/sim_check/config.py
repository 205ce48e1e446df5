"""What an execution check must achieve (:class:`TaskGoal`) and how it runs (:class:`ExecutionConfig`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from hsi_planning.errors import ConfigError
from hsi_retarget.sim_check.grasp import GraspConfig
from hsi_retarget.sim_check.place_feedback import PlaceFeedbackConfig


@dataclass(frozen=True)
class TaskGoal:
    """What the execution must achieve; an empty goal only asks for no collisions."""

    object_name: str = ""  #: free object to place ("" none) [-]
    placement: tuple[float, float, float] | None = None  #: world position of the object's body origin [m]
    open_part: str = ""  #: door or drawer that must end open ("" none) [-]
    planner: str = ""  #: planner label for the report [-]

    def __post_init__(self) -> None:
        if self.placement is not None and (
            len(self.placement) != 3 or not all(math.isfinite(v) for v in self.placement)
        ):
            raise ConfigError(f"TaskGoal.placement must be a finite (x, y, z) [m], got {self.placement}")
        if self.placement is not None and not self.object_name:
            raise ConfigError("TaskGoal.placement needs object_name (the object to place)")


@dataclass(frozen=True)
class ExecutionConfig:
    """Control and judgement parameters of :func:`hsi_retarget.sim_check.execute`."""

    control_rate_hz: float = 100.0  #: actuator target update rate [Hz]
    settle_s: float = 0.5  #: hold time after the trajectory ends [s]
    feedforward: bool = True  #: compensate servo damping and gravity in the position targets [-]
    snap_to_start: bool = True  #: put the robot at the trajectory's first configuration first [-]
    collision_depth_m: float = 5e-5  #: penetration above which a robot contact is a collision [m]
    limit_tolerance: float = 0.01  #: slack on joint position limits [rad or m]
    velocity_tolerance: float = 0.05  #: relative slack on commanded velocity limits [-]
    placement_tolerance_m: float = 0.02  #: object-to-placement distance for success [m]
    door_open_rad: float = math.radians(60.0)  #: required door opening [rad]
    drawer_open_m: float = 0.20  #: required drawer opening [m]
    recovery_error_m: float = 0.01  #: TCP error under which a perturbation counts as recovered [m]
    recovery_window_s: float = 1.5  #: time after a perturbation to recover [s]
    fall_drop_m: float = 0.3  #: floating robots: pelvis drop that counts as a fall [m]
    grasp: GraspConfig = field(default_factory=GraspConfig)  #: grasp detection
    #: the carry of the task's object corrected from its pose in the hand
    #: (:mod:`hsi_retarget.sim_check.place_feedback`)
    place_feedback: PlaceFeedbackConfig = field(default_factory=PlaceFeedbackConfig)

    def __post_init__(self) -> None:
        positive = ("control_rate_hz", "placement_tolerance_m", "door_open_rad", "drawer_open_m")
        nonneg = (
            "settle_s",
            "collision_depth_m",
            "limit_tolerance",
            "velocity_tolerance",
            "recovery_error_m",
            "recovery_window_s",
            "fall_drop_m",
        )
        for name in (*positive, *nonneg):
            value = getattr(self, name)
            if not (math.isfinite(value) and (value > 0.0 if name in positive else value >= 0.0)):
                bound = "> 0" if name in positive else ">= 0"
                raise ConfigError(f"ExecutionConfig.{name} must be finite and {bound}, got {value}")
