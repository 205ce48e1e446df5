"""Configuration of the object-centric field computation (grid, occupancy, distances, time of arrival)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from hsi_planning.errors import ConfigError


@dataclass(frozen=True)
class FieldConfig:
    """Parameters of :func:`hsi_planning.fields.compute_fields`.

    The inverse fields are bounded: D_t, D_o ≤ 1/epsilon (40 1/m) and D_toa ≤ 1/epsilon_time (40 1/s).
    """

    size: float = 0.80  #: [m] edge of the node cube (outermost node planes)
    resolution: float = 0.025  #: [m] node spacing = cell edge
    approach_shift: float = 0.0  #: [m] grid centre moved from the target centre towards the approach side
    dilation_radius: float = 0.0125  #: [m] a node is occupied if a point lies within resolution/2 + this
    fill_enclosed: bool = True  #: [-] mark cavities enclosed by occupied nodes as occupied (closed shells)
    surface_offset: float = 0.0125  #: [m] nodes this close to a target point seed fast marching (level 0)
    epsilon: float = 0.025  #: [m] distance floor of D_t = 1/max(d, ε) and D_o
    epsilon_time: float = 0.025  #: [s] time floor of D_toa = 1/max(φ, ε_t)
    sigma: float = 0.05  #: [m] width of the Gaussian speed corridor around the demonstration
    corridor_plateau: float = 0.0125  #: [m] distance from the path still counted as on it (sub-cell)
    floor_speed: float = 0.05  #: [m/s] lowest front speed anywhere (keeps φ finite off the corridor)
    goal_radius: float = 0.05  #: [m] φ inside this sphere around the goal is the demo's own time
    path_spacing: float = 0.005  #: [m] arc-length resampling step of the demonstration path
    unreachable_distance: float = 100.0  #: [m] distance stored for obstacle / unreachable nodes (D_t = 0)
    unreachable_time: float = 100.0  #: [s] φ stored for obstacle / unreachable nodes (D_toa = 0)
    fmm_order: int = 2  #: [-] finite-difference order of fast marching (1 or 2)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise ConfigError(f"FieldConfig.{f.name} must be finite, got {value}")
        positive = (
            "size",
            "resolution",
            "surface_offset",
            "epsilon",
            "epsilon_time",
            "sigma",
            "floor_speed",
            "path_spacing",
            "goal_radius",
        )
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise ConfigError(f"FieldConfig.{name} must be > 0, got {getattr(self, name)}")
        if self.corridor_plateau < 0.0:
            raise ConfigError(f"FieldConfig.corridor_plateau must be ≥ 0 [m], got {self.corridor_plateau}")
        if self.dilation_radius < 0.0:
            raise ConfigError(f"FieldConfig.dilation_radius must be ≥ 0 [m], got {self.dilation_radius}")
        ratio = self.size / self.resolution
        if abs(ratio - round(ratio)) > 1e-6 * ratio or round(ratio) < 2:
            raise ConfigError(
                f"FieldConfig.size ({self.size} m) must be an integer multiple (≥ 2) of resolution "
                f"({self.resolution} m)"
            )
        diagonal = math.sqrt(3.0) * self.size
        if self.unreachable_distance <= diagonal:
            raise ConfigError(
                f"FieldConfig.unreachable_distance ({self.unreachable_distance} m) must exceed the grid "
                f"diagonal {diagonal:.3f} m"
            )
        if self.unreachable_time <= 0.0:
            raise ConfigError(f"FieldConfig.unreachable_time must be > 0 [s], got {self.unreachable_time}")
        if self.fmm_order not in (1, 2):
            raise ConfigError(f"FieldConfig.fmm_order must be 1 or 2, got {self.fmm_order}")
