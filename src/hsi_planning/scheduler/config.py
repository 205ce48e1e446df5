"""The scheduler's configuration: the component configs it is made of and the timing of unplanned moves."""

from __future__ import annotations

from dataclasses import dataclass, field

from hsi_planning.errors import ConfigError
from hsi_planning.scheduler.auxiliary import AuxiliaryConfig
from hsi_planning.scheduler.body import BodyConfig
from hsi_planning.scheduler.goals import GoalConfig
from hsi_planning.scheduler.hands import HandConfig
from hsi_planning.scheduler.navigation import NavigationConfig
from hsi_planning.scheduler.stance import StanceConfig


@dataclass(frozen=True)
class SchedulerConfig:
    """Every setting of the scheduler (nested component configs) and the timing of unplanned moves."""

    body: BodyConfig = field(default_factory=BodyConfig)  #: body dimensions, postures, reach [m]
    navigation: NavigationConfig = field(default_factory=NavigationConfig)  #: floor map and Eq. 23
    stance: StanceConfig = field(default_factory=StanceConfig)  #: standing pose search
    auxiliary: AuxiliaryConfig = field(default_factory=AuxiliaryConfig)  #: blockers and free spots
    hands: HandConfig = field(default_factory=HandConfig)  #: one/two hands and Eq. 24's w
    goals: GoalConfig = field(default_factory=GoalConfig)  #: click resolution
    hand_speed: float = 0.6  #: [m/s] speed of unplanned wrist moves (to a handle, back to the body)
    door_speed: float = 0.35  #: [m/s] handle speed while opening or closing
    posture_speed: float = 0.5  #: [m/s] speed of hip height changes (crouching, standing up)
    min_move_time: float = 0.3  #: [s] shortest unplanned move
    grasp_time: float = 0.3  #: [s] closing the fingers on an object
    release_time: float = 0.2  #: [s] opening the fingers
    door_steps: int = 5  #: [-] keyframes along a door's arc
    retreat_clearance: float = 0.12  #: [m] how far beyond the opening a take-out ends
    lift_height: float = 0.05  #: [m] lift of a two-handed take-out
    restore_blockers: bool = False  #: [-] put moved blockers back after the take-out (needs a free hand)
    walls_behind: bool = True  #: [-] furniture (except tables) stands against a wall: no walking behind it
    start_xy: tuple[float, float] = (0.0, 0.0)  #: [m] where the person stands at the start
    start_yaw: float = 0.0  #: [deg] the person's heading at the start (0 = facing +x)

    def __post_init__(self) -> None:
        for name in (
            "hand_speed",
            "door_speed",
            "posture_speed",
            "min_move_time",
            "grasp_time",
            "release_time",
        ):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"SchedulerConfig.{name} must be > 0, got {getattr(self, name)}")
        if self.door_steps < 1:
            raise ConfigError(f"SchedulerConfig.door_steps must be >= 1, got {self.door_steps}")
        if self.retreat_clearance < 0.0 or self.lift_height < 0.0:
            raise ConfigError("SchedulerConfig: retreat_clearance and lift_height must be >= 0 m")
