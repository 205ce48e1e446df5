"""Trajectory metrics: kinematics and human-likeness (timing, path shape, curvature, smoothness, DTW)."""

from hsi_planning.metrics.dtw import dtw_distance, normalized_trajectory
from hsi_planning.metrics.kinematics import (
    chord_length,
    curvature,
    integrated_squared_jerk,
    max_path_deviation_ratio,
    mean_acceleration,
    normalized_peak_speed_time,
    path_length,
    rms_curvature,
    speed_curvature_exponent,
    speed_profile,
)
from hsi_planning.metrics.smoothness import dimensionless_jerk, log_dimensionless_jerk, sparc

__all__ = [
    "chord_length",
    "curvature",
    "dimensionless_jerk",
    "dtw_distance",
    "integrated_squared_jerk",
    "log_dimensionless_jerk",
    "max_path_deviation_ratio",
    "mean_acceleration",
    "normalized_peak_speed_time",
    "normalized_trajectory",
    "path_length",
    "rms_curvature",
    "sparc",
    "speed_curvature_exponent",
    "speed_profile",
]
