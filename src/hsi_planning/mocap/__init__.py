"""Motion capture: ASF/AMC and BVH loaders, forward kinematics, wrist trajectories and reach segmentation.

World frame of every result: z up, x forward, y left (metres); see :mod:`hsi_planning.mocap.skeleton`.
"""

from hsi_planning.mocap.amc import load_amc
from hsi_planning.mocap.asf import load_asf
from hsi_planning.mocap.bvh import load_bvh, save_bvh
from hsi_planning.mocap.hdm05 import hdm05_clips, hdm05_reach_stats, median_stats, reach_metrics
from hsi_planning.mocap.reach import (
    ReachConfig,
    ReachSegment,
    hand_joint_name,
    hip_trajectory,
    lowpass,
    segment_reaches,
    wrist_rotations,
    wrist_trajectory,
)
from hsi_planning.mocap.skeleton import (
    Z_UP_FROM_Y_UP,
    Joint,
    JointTrajectories,
    Motion,
    Skeleton,
    forward_kinematics,
)

__all__ = [
    "Z_UP_FROM_Y_UP",
    "Joint",
    "JointTrajectories",
    "Motion",
    "ReachConfig",
    "ReachSegment",
    "Skeleton",
    "forward_kinematics",
    "hand_joint_name",
    "hdm05_clips",
    "hdm05_reach_stats",
    "hip_trajectory",
    "load_amc",
    "load_asf",
    "load_bvh",
    "lowpass",
    "median_stats",
    "reach_metrics",
    "save_bvh",
    "segment_reaches",
    "wrist_rotations",
    "wrist_trajectory",
]
