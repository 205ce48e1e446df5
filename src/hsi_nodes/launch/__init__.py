"""ROS 2 YAML launch files: :mod:`~hsi_nodes.launch.parser` reads them, :mod:`~hsi_nodes.launch.runner`
runs the nodes they list in this process."""

from __future__ import annotations

from hsi_nodes.launch.description import LaunchArg, LaunchDescription, NodeSpec, parse_overrides
from hsi_nodes.launch.parser import declared_arguments, parse_launch_file
from hsi_nodes.launch.runner import LaunchRunner, LaunchSummary, run_launch
from hsi_nodes.launch.substitutions import package_share

__all__ = [
    "LaunchArg",
    "LaunchDescription",
    "LaunchRunner",
    "LaunchSummary",
    "NodeSpec",
    "declared_arguments",
    "package_share",
    "parse_launch_file",
    "parse_overrides",
    "run_launch",
]
