"""The collision-free minimum-jerk baseline (DESIGN "Minimum-jerk baseline"): CasADi + IPOPT.

- :mod:`.sdf`: truncated obstacle distance grid from a point cloud, a cubic spline in NumPy and CasADi
  (:mod:`.field_callback`: the CasADi callback with exact sparse derivatives).
- :mod:`.quintic`: the piecewise quintic Hermite parameterization, its exact jerk integral, warm-start fit.
- :mod:`.clearance`: hand / held-object spheres against the field, relaxed near tight ends.
- :mod:`.optimizer`: :func:`solve_min_jerk`, the IPOPT problem.
- :mod:`.warm_start`: straight line or fast-marching corridor initial guesses.
- :mod:`.segment`: one approach or leave segment, end to end.
- :mod:`.planner`: :class:`MinJerkPlanner`, same requests/results as the implicit planner.
"""

from hsi_planning.minjerk.clearance import ClearanceSphere
from hsi_planning.minjerk.optimizer import MinJerkConfig, MinJerkSolution, min_duration, solve_min_jerk
from hsi_planning.minjerk.planner import (
    PLANNER_NAME,
    MinJerkPlanner,
    MinJerkPlannerConfig,
    contact_orientation,
)
from hsi_planning.minjerk.quintic import QuinticSpline, rest_to_rest
from hsi_planning.minjerk.sdf import DistanceGrid, distance_grid, nearest_distance
from hsi_planning.minjerk.segment import SegmentSettings, SegmentSpec, build_fields, plan_segment
from hsi_planning.minjerk.warm_start import corridor_path, straight_is_clear

__all__ = [
    "PLANNER_NAME",
    "ClearanceSphere",
    "DistanceGrid",
    "MinJerkConfig",
    "MinJerkPlanner",
    "MinJerkPlannerConfig",
    "MinJerkSolution",
    "QuinticSpline",
    "SegmentSettings",
    "SegmentSpec",
    "build_fields",
    "contact_orientation",
    "corridor_path",
    "distance_grid",
    "min_duration",
    "nearest_distance",
    "plan_segment",
    "rest_to_rest",
    "solve_min_jerk",
    "straight_is_clear",
]
