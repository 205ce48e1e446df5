"""Registry of node executables: the ``exec:`` names a launch file may use with ``pkg: hsi``.

To add a node, add one line to :data:`NODE_EXECUTABLES`: ``"exec_name": "module.path:ClassName"``.
The module is imported only when a launch file starts that node.
"""

from __future__ import annotations

import importlib
from typing import Any

from hsi_nodes.node import Node
from hsi_planning.errors import LaunchError

__all__ = ["NODE_EXECUTABLES", "load_executable"]

#: exec name -> ``"module:Class"`` of a :class:`~hsi_nodes.node.Node` subclass.
NODE_EXECUTABLES: dict[str, str] = {
    "heartbeat": "hsi_nodes.nodes.talker_nodes:HeartbeatNode",
    "echo": "hsi_nodes.nodes.talker_nodes:EchoNode",
    "topic_relay": "hsi_nodes.nodes.talker_nodes:TopicRelayNode",
    "recorder_node": "hsi_nodes.nodes.recorder_node:RecorderNode",
    "sim_node": "hsi_nodes.nodes.sim_node:SimNode",
    "scene_cloud_node": "hsi_nodes.nodes.scene_cloud_node:SceneCloudNode",
    "scheduler_node": "hsi_nodes.nodes.scheduler_node:SchedulerNode",
    "planner_node": "hsi_nodes.nodes.planner_node:PlannerNode",
    "retarget_node": "hsi_nodes.nodes.retarget_node:RetargetNode",
    "sim_check_node": "hsi_nodes.nodes.sim_check_node:SimCheckNode",
    "click_player": "hsi_nodes.nodes.click_player_node:ClickPlayerNode",
}


def load_executable(name: str) -> type[Node[Any]]:
    """Import and return the node class registered as ``name``.

    Raises:
        LaunchError: unknown name (the message lists the known ones), or the entry does not name a Node.
    """
    target = NODE_EXECUTABLES.get(name)
    if target is None:
        raise LaunchError(f"unknown executable {name!r}; known: {sorted(NODE_EXECUTABLES)}")
    module_name, _, attr = target.partition(":")
    cls = getattr(importlib.import_module(module_name), attr, None)
    if not (isinstance(cls, type) and issubclass(cls, Node)):
        raise LaunchError(f"executable {name!r} -> {target} is not a Node subclass")
    return cls
