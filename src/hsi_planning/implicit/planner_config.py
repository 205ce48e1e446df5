"""Run-time configuration of :class:`~hsi_planning.implicit.planner.ImplicitPlanner`."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from hsi_planning.errors import ConfigError

REPAIR_MODES: tuple[str, ...] = ("fallback", "always", "never")
TIMING_MODES: tuple[str, ...] = ("prior", "field")


@dataclass(frozen=True)
class ImplicitPlannerConfig:
    """Run-time settings of the implicit planner (defaults: ≤ 300 ms per plan on 2 cores)."""

    fit_steps: int = 2  #: [steps] Adam steps of the latent fit (Eq. 9) from the warm start per segment
    fit_lr: float = 2e-2  #: [1/step] learning rate of the latent fit
    fit_points: int = 512  #: [points] random grid points per fit step
    latent_reg: float = 1e-4  #: [-] λ of λ·||z||² in the fit
    obstacle_anchors: int = 128  #: [points] obstacle nodes used as known D_toa = 0 points (subsampled)
    prior_tail: float = 0.05  #: [m] arc length of τ_prior before the contact used as known D_toa
    refit_leave: bool = False  #: [-] fit z again for the leave (else the approach's scene code is reused)
    field_stride: int = 3  #: [nodes] D_toa is predicted on every stride-th node and refined trilinearly
    palm_offset: float = 0.06  #: [m] wrist distance beyond the target along the approach axis (training's)
    hand_radius: float = 0.04  #: [m] radius of the hand sphere kept clear of the observed obstacles
    clearance_margin: float = 0.01  #: [m] extra clearance planned for (cloud noise, smoothing, interpolation)
    repair_retries: int = 2  #: [-] repaired fields tried with a margin grown by repair_margin_step each
    repair_margin_step: float = 0.01  #: [m] growth of the margin per repair retry
    clearance_relax: float = 0.10  #: [m] arc length before the contact over which clearance relaxes
    check_margin: float = 0.0075  #: [m] extra clearance the final path keeps from the observed points
    #: [m] beyond the contact along the approach axis, an empty hand comes at most this much closer to
    #: the target's points than at the contact (it does not reach past or around the object it grasps
    #: or has just put down)
    target_slack: float = 0.02
    #: [m] when no attempt keeps the full clearance, the closest one is still returned (logged) if it
    #: misses it by at most this much (the hand sphere itself, without ``check_margin``, stays clear)
    relaxed_margin: float = 0.0075
    #: [-] grow a round held object's box to the cylinder fitted through its visible points
    round_completion: bool = True
    carried_padding: float = 0.01  #: [m] growth of the held object's bounding box (points lie inside it)
    carried_margin: float = 0.004  #: [m] clearance the padded box keeps on the final path (half at the lift)
    start_clearance: float = 0.01  #: [m] a start this close to an obstacle point counts as inside it
    descent_step: float = 0.0125  #: [m] step of the gradient descent on φ̂
    max_descent_steps: int = 400  #: [steps] descent gives up after this many steps
    path_step: float = 0.005  #: [m] arc-length spacing of the smoothed path
    path_smoothing: float = 0.02  #: [m] Gaussian smoothing length of the path (arc length)
    speed_smoothing: float = 0.03  #: [m] Gaussian smoothing length of the speed profile (arc length)
    max_speed: float = 2.5  #: [m/s] speed limit of the wrist
    min_speed: float = 0.05  #: [m/s] lowest speed taken from φ̂ (slow, off-corridor regions)
    max_accel: float = 8.0  #: [m/s²] acceleration limit of the rest-to-rest envelope
    sample_rate: float = 120.0  #: [Hz] output sample rate
    blend_fraction: float = (
        0.2  #: [-] share of the path before the contact blended into the prior's orientation
    )
    #: [deg] a matched prior whose contact wrist points farther than this from the approach axis (a
    #: top-down grasp for a cabinet's front opening) is turned onto it over the blend (180: never)
    contact_facing_angle: float = 45.0
    lift_height: float = 0.04  #: [m] least vertical lift (set-down) at a contact where an object is carried
    max_lift: float = 0.3  #: [m] the lift rises above neighbours and container walls up to this height
    #: [m] lift of a held object whose hidden top may reach the ceiling observed above it (a bottle
    #: under a shelf board slides out just off its support)
    hidden_top_lift: float = 0.02
    #: [m] obstacles this far around the held object's footprint are risen above (walls hide what is
    #: behind them)
    lift_pad: float = 0.05
    phi_cap_factor: float = 1.2  #: [-] Eq. 11 candidates need φ̂ ≤ this × the prior's duration
    repair: str = "fallback"  #: [-] fast-marching repair of φ̂: fallback (when needed), always, never
    #: [-] speed along the path: "prior" (the matched demonstration's profile over normalized arc length)
    #: or "field" (1/|∇φ̂| of the descended field)
    timing: str = "prior"
    crop_margin: float = 0.3  #: [m] obstacle points farther than this outside the planning region are ignored
    #: [-] plan the leave in a second thread while the approach is planned (same result; both cores)
    parallel_segments: bool = True
    threads: int = 1  #: [-] torch threads while planning (1: fastest on busy shared cores); 0 = leave as is
    seed: int = 0  #: [-] seed of the fit's point subsampling and the obstacle anchors

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise ConfigError(f"ImplicitPlannerConfig.{f.name} must be finite, got {value}")
        for name in ("fit_steps", "fit_points", "field_stride", "max_descent_steps"):
            if getattr(self, name) < 1:
                raise ConfigError(f"ImplicitPlannerConfig.{name}={getattr(self, name)} must be ≥ 1")
        positive = (
            "fit_lr",
            "prior_tail",
            "hand_radius",
            "clearance_relax",
            "descent_step",
            "path_step",
            "max_speed",
            "min_speed",
            "max_accel",
            "sample_rate",
            "phi_cap_factor",
        )
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"ImplicitPlannerConfig.{name}={getattr(self, name)} must be > 0")
        non_negative = (
            "latent_reg",
            "obstacle_anchors",
            "threads",
            "palm_offset",
            "clearance_margin",
            "repair_retries",
            "repair_margin_step",
            "carried_padding",
            "carried_margin",
            "check_margin",
            "target_slack",
            "relaxed_margin",
            "start_clearance",
            "path_smoothing",
            "speed_smoothing",
            "lift_height",
            "max_lift",
            "hidden_top_lift",
            "lift_pad",
            "crop_margin",
        )
        for name in non_negative:
            if getattr(self, name) < 0:
                raise ConfigError(f"ImplicitPlannerConfig.{name}={getattr(self, name)} must be ≥ 0")
        if self.min_speed >= self.max_speed:
            raise ConfigError(f"min_speed {self.min_speed} must be below max_speed {self.max_speed} [m/s]")
        if not 0.0 <= self.blend_fraction <= 1.0:
            raise ConfigError(f"blend_fraction={self.blend_fraction} must be in [0, 1]")
        if not 0.0 <= self.contact_facing_angle <= 180.0:
            raise ConfigError(f"contact_facing_angle={self.contact_facing_angle} must be in [0, 180] deg")
        if self.timing not in TIMING_MODES:
            raise ConfigError(f"timing={self.timing!r} must be one of {list(TIMING_MODES)}")
        if self.repair not in REPAIR_MODES:
            raise ConfigError(f"repair={self.repair!r} must be one of {list(REPAIR_MODES)}")
