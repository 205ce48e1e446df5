"""Generated human demonstrations: the calibrated human-reach model and its obstacle field."""

from hsi_planning.demos.obstacles import ObstacleField, box_mesh
from hsi_planning.demos.reach_config import ReachModelConfig
from hsi_planning.demos.reach_model import PLANNER_NAME, ReachRequest, generate_reach

__all__ = ["PLANNER_NAME", "ObstacleField", "ReachModelConfig", "ReachRequest", "box_mesh", "generate_reach"]
