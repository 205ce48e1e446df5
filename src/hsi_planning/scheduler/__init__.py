"""The bimanual scheduler and navigation (CHOICE §6): goals from clicks, auxiliary objects (doors,
drawers, blockers), hand assignment (Eq. 24), root navigation (2D fast marching, Eq. 23), standing poses
from reach limits, and the state machine that emits timed keyframes for both wrists, the hip and the root.
"""

from hsi_planning.scheduler.auxiliary import AuxiliaryConfig, enclosing_part, find_blockers, free_spots
from hsi_planning.scheduler.body import BodyConfig, HipPose
from hsi_planning.scheduler.config import SchedulerConfig
from hsi_planning.scheduler.goals import (
    Goal,
    GoalConfig,
    PickGoal,
    PlaceGoal,
    camera_ray,
    check_place_free,
    ray_hit,
    resolve_click,
)
from hsi_planning.scheduler.hands import (
    Assignment,
    HandConfig,
    HandState,
    candidate_assignments,
    deviation_cost,
    hand_crossing,
)
from hsi_planning.scheduler.linear_planner import LinearPlanner
from hsi_planning.scheduler.navigation import FloorMap, NavigationConfig, approach_cost, plan_root_path
from hsi_planning.scheduler.reach_planner import CloudObstacles, ReachModelPlanner, ReachPlannerConfig
from hsi_planning.scheduler.schedule import KEY_JOINTS, Keyframe, PlannedSegment, Schedule
from hsi_planning.scheduler.stance import StanceConfig, StanceTarget, choose_stance
from hsi_planning.scheduler.state_machine import Scheduler, Task
from hsi_planning.scheduler.world import SceneWorld, WorldState

__all__ = [
    "KEY_JOINTS",
    "Assignment",
    "AuxiliaryConfig",
    "BodyConfig",
    "CloudObstacles",
    "FloorMap",
    "Goal",
    "GoalConfig",
    "HandConfig",
    "HandState",
    "HipPose",
    "Keyframe",
    "LinearPlanner",
    "NavigationConfig",
    "PickGoal",
    "PlaceGoal",
    "PlannedSegment",
    "ReachModelPlanner",
    "ReachPlannerConfig",
    "SceneWorld",
    "Schedule",
    "Scheduler",
    "SchedulerConfig",
    "StanceConfig",
    "StanceTarget",
    "Task",
    "WorldState",
    "approach_cost",
    "camera_ray",
    "candidate_assignments",
    "check_place_free",
    "choose_stance",
    "deviation_cost",
    "enclosing_part",
    "find_blockers",
    "free_spots",
    "hand_crossing",
    "plan_root_path",
    "ray_hit",
    "resolve_click",
]
