"""Configuration of the human-reach model: one frozen dataclass, every field with its unit."""

from __future__ import annotations

from dataclasses import dataclass

from hsi_planning.errors import ConfigError
from hsi_planning.trajectory import Action, Segment


@dataclass(frozen=True)
class ReachModelConfig:
    """Parameters of the human-reach model (defaults calibrated on HDM05: ``benchmarks/human_reach.py``)."""

    sample_rate: float = 120.0  #: [Hz] output sample rate
    path_step: float = 0.005  #: [m] spacing of the dense geometric path
    fitts_intercept: float = 0.45  #: [s] Fitts-law intercept of the movement time
    fitts_slope: float = 0.15  #: [s/bit] Fitts-law slope
    fitts_target_width: float = 0.05  #: [m] effective target width in the Fitts index of difficulty
    duration_jitter: float = 0.08  #: [-] std of the log movement-time factor (lognormal)
    insertion_time_per_m: float = 2.5  #: [s/m] extra time per metre of straight insertion / lift tail
    #: [-] normalized time of the bell's peak, approach to grasp (the power-law modulation then moves the
    #: measured peak earlier: on HDM05 poses 0.32 gives ≈ 0.24, 0.6 for place ≈ 0.32)
    peak_grasp_approach: float = 0.32
    peak_place_approach: float = 0.6  #: [-] same, approach to place
    peak_grasp_leave: float = 0.5  #: [-] same, carrying the grasped object out
    peak_place_leave: float = 0.45  #: [-] same, withdrawing the empty hand after placing
    peak_jitter: float = 0.03  #: [-] std of the peak time
    #: [-] a + b of the bell tau^a (1-tau)^b (4 = min-jerk width; widened so that a, b >= 1.5)
    bell_sharpness: float = 4.7
    bell_sharpness_place: float = 3.75  #: [-] same for place reaches (flatter: carrying, placing)
    deviation_grasp: float = 0.095  #: [-] median max path deviation / chord length, grasp reaches
    deviation_place: float = 0.30  #: [-] same for place reaches (HDM05 depositFloorR bends the trunk)
    deviation_spread: float = 0.25  #: [-] std of the log deviation (lognormal around the median)
    deviation_min: float = 0.03  #: [-] lower clip of the sampled deviation
    deviation_max: float = 0.40  #: [-] upper clip of the sampled deviation
    duration_factor_place: float = 1.25  #: [-] movement-time factor of place reaches (slower than grasps)
    bulge_exponent: float = 3.7  #: [-] k of the bulge profile u - u^(k+1) (1 = symmetric, larger = later)
    bulge_exponent_jitter: float = 0.5  #: [-] half-width of the uniform jitter of k
    bulge_angle_std: float = 20.0  #: [deg] std of the bulge direction about the chord
    bulge_weight_up: float = 1.0  #: [-] weight of "upward" in the preferred bulge direction
    bulge_weight_side: float = 0.7  #: [-] weight of the hand's side (elbow out)
    noise_ratio: float = 0.03  #: [-] std of the mid-reach via-point perturbation / chord length
    #: [-] beta of the local modulation speed ∝ curvature^beta (with the bell: measured β ≈ -0.38)
    power_law_exponent: float = -0.5
    curvature_offset: float = 0.5  #: [1/m] kappa_0 added to the curvature before the power law
    modulation_min: float = 0.4  #: [-] lower clip of the power-law speed factor
    modulation_max: float = 1.2  #: [-] upper clip of the power-law speed factor
    insertion_length: float = 0.12  #: [m] straight insertion along the opening's depth axis
    insertion_speed_ratio: float = 0.5  #: [-] speed factor inside the container (tail)
    insertion_blend: float = 0.06  #: [m] path length over which the speed drops to that factor
    lift_height: float = 0.04  #: [m] lift of a carried object above its support
    carry_clearance: float = 0.02  #: [m] extra clearance while carrying an object
    hand_radius: float = 0.04  #: [m] radius of the wrist/hand sphere checked against obstacles
    clearance_relax_length: float = 0.10  #: [m] path length over which clearance relaxes near contact
    max_attempts: int = 20  #: [-] path samples tried before giving up
    bend_iterations: int = 12  #: [-] collision bends per sample
    rotation_end: float = 0.9  #: [-] normalized time by which the wrist rotation is done (approach)
    orientation_noise: float = 0.04  #: [rad] std of the mid-reach orientation perturbation

    def __post_init__(self) -> None:
        positive = (
            "sample_rate",
            "path_step",
            "fitts_target_width",
            "fitts_slope",
            "bell_sharpness",
            "bell_sharpness_place",
            "hand_radius",
            "insertion_blend",
            "clearance_relax_length",
            "curvature_offset",
        )
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"ReachModelConfig.{name} must be > 0, got {getattr(self, name)}")
        nonneg = (
            "fitts_intercept",
            "duration_jitter",
            "insertion_time_per_m",
            "peak_jitter",
            "deviation_spread",
            "noise_ratio",
            "bulge_angle_std",
            "insertion_length",
            "lift_height",
            "carry_clearance",
            "orientation_noise",
            "bulge_weight_up",
            "bulge_weight_side",
            "bulge_exponent_jitter",
        )
        for name in nonneg:
            if not getattr(self, name) >= 0.0:
                raise ConfigError(f"ReachModelConfig.{name} must be >= 0, got {getattr(self, name)}")
        for name in ("peak_grasp_approach", "peak_place_approach", "peak_grasp_leave", "peak_place_leave"):
            if not 0.1 <= getattr(self, name) <= 0.9:
                raise ConfigError(f"ReachModelConfig.{name} must be in [0.1, 0.9], got {getattr(self, name)}")
        for name in ("deviation_grasp", "deviation_place"):
            if not 0.0 <= self.deviation_min <= getattr(self, name) <= self.deviation_max <= 0.5:
                raise ConfigError(
                    f"ReachModelConfig needs 0 <= deviation_min <= {name} <= deviation_max <= 0.5"
                )
        if not self.duration_factor_place > 0.0:
            raise ConfigError(
                f"ReachModelConfig.duration_factor_place must be > 0, got {self.duration_factor_place}"
            )
        if self.bulge_exponent - self.bulge_exponent_jitter < 1.0:
            raise ConfigError(
                f"ReachModelConfig needs bulge_exponent - bulge_exponent_jitter >= 1, got "
                f"{self.bulge_exponent} - {self.bulge_exponent_jitter}"
            )
        if not -1.0 <= self.power_law_exponent <= 0.0:
            raise ConfigError(
                f"ReachModelConfig.power_law_exponent must be in [-1, 0], got {self.power_law_exponent}"
            )
        if not 0.0 < self.modulation_min <= 1.0 <= self.modulation_max:
            raise ConfigError("ReachModelConfig needs 0 < modulation_min <= 1 <= modulation_max")
        if not 0.0 < self.insertion_speed_ratio <= 1.0:
            raise ConfigError(
                f"ReachModelConfig.insertion_speed_ratio must be in (0, 1], got {self.insertion_speed_ratio}"
            )
        if self.max_attempts < 1 or self.bend_iterations < 0:
            raise ConfigError("ReachModelConfig needs max_attempts >= 1 and bend_iterations >= 0")
        if not 0.3 <= self.rotation_end <= 1.0:
            raise ConfigError(f"ReachModelConfig.rotation_end must be in [0.3, 1], got {self.rotation_end}")

    def deviation(self, action: Action) -> float:
        """Median max path deviation ratio [-] of an action's reaches."""
        return float(getattr(self, f"deviation_{action}"))

    def peak_time(self, action: Action, segment: Segment) -> float:
        """Normalized time of the bell's peak for an action and segment."""
        return float(getattr(self, f"peak_{action}_{segment}"))
