"""The MuJoCo execution check: run a robot's :class:`~hsi_retarget.joint_trajectory.JointTrajectory` in
a scene with position actuators, grasp by a weld activated on contact, open doors and drawers by their
handles, push the robot and move the target, and report success, tracking error, collisions and limit
violations.

Typical use::

    world = build_world(WorldConfig(scene="kitchen", robot="dual_ur5e", base_pose=(0.2, 0.0, 0.0)))
    report = execute(world, trajectory, ExecutionConfig(), goal=TaskGoal("can1", placement=(0.9, 0.0, 0.9)))
    print(report.to_json())
"""

from hsi_planning.gl import ensure_headless_gl

ensure_headless_gl()  # before mujoco is first imported (rendering backend)

from hsi_retarget.sim_check.config import ExecutionConfig, TaskGoal  # noqa: E402
from hsi_retarget.sim_check.execute import check_trajectory, execute  # noqa: E402
from hsi_retarget.sim_check.grasp import GraspConfig, GraspController, GraspRecord  # noqa: E402
from hsi_retarget.sim_check.mjcf import HANDS, weld_name  # noqa: E402
from hsi_retarget.sim_check.monitor import CollisionRecord, LimitViolation  # noqa: E402
from hsi_retarget.sim_check.perturb import (  # noqa: E402
    MAX_TARGET_SHIFT_M,
    PerturbationConfig,
    PerturbationEvent,
    Push,
    RePlanHook,
    TargetMove,
    arm_links,
    random_perturbations,
)
from hsi_retarget.sim_check.place_feedback import PlaceFeedback, PlaceFeedbackConfig  # noqa: E402
from hsi_retarget.sim_check.report import (  # noqa: E402
    ExecutionReport,
    ExecutionTrace,
    PerturbationRecord,
    reports_markdown,
    write_reports,
)
from hsi_retarget.sim_check.video import VideoConfig, VideoRecorder, mp4_available  # noqa: E402
from hsi_retarget.sim_check.world import SimWorld, WorldConfig, build_world  # noqa: E402

__all__ = [
    "HANDS",
    "MAX_TARGET_SHIFT_M",
    "CollisionRecord",
    "ExecutionConfig",
    "ExecutionReport",
    "ExecutionTrace",
    "GraspConfig",
    "GraspController",
    "GraspRecord",
    "LimitViolation",
    "PerturbationConfig",
    "PerturbationEvent",
    "PerturbationRecord",
    "PlaceFeedback",
    "PlaceFeedbackConfig",
    "Push",
    "RePlanHook",
    "SimWorld",
    "TargetMove",
    "TaskGoal",
    "VideoConfig",
    "VideoRecorder",
    "WorldConfig",
    "arm_links",
    "build_world",
    "check_trajectory",
    "execute",
    "mp4_available",
    "random_perturbations",
    "reports_markdown",
    "weld_name",
    "write_reports",
]
