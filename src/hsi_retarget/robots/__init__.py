"""Robot models written from published kinematics: ``dual_ur5e`` (two UR5e on a holonomic base with a torso
lift) and ``humanoid`` (adult proportions, floating base). One Python description per robot generates the
committed URDF (``urdf/``, kinematics with pinocchio) and MJCF (``sim/robots/``, MuJoCo with position
actuators and a ``home`` keyframe); :func:`attach_robot` merges a robot into a scene MJCF.
"""

from hsi_retarget.robots.catalog import ALIASES, DESCRIPTIONS, description, robot_name
from hsi_retarget.robots.compose import attach_robot
from hsi_retarget.robots.description import Frame, Geom, Inertial, Joint, Link, RobotDescription
from hsi_retarget.robots.model import ROOT_JOINT, RobotModel, q_to_pose, robot_files
from hsi_retarget.robots.mujoco_map import MujocoMap
from hsi_retarget.robots.ur5e import dh_transform, ur5e_fk

__all__ = [
    "ALIASES",
    "DESCRIPTIONS",
    "ROOT_JOINT",
    "Frame",
    "Geom",
    "Inertial",
    "Joint",
    "Link",
    "MujocoMap",
    "RobotDescription",
    "RobotModel",
    "attach_robot",
    "description",
    "dh_transform",
    "q_to_pose",
    "robot_files",
    "robot_name",
    "ur5e_fk",
]
