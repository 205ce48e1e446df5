"""The web UI as a node on the transport: it publishes what the person clicks and the goals they start.

``/clicked_point`` (``geometry_msgs/PointStamped``, what RViz's Publish Point sends) for every click in
the 3D view that lands on the scene, and ``/hsi/goal`` (``hsi/msg/PickPlaceGoal``) when a task starts.
Publishing is thread safe, so the viser callbacks and the task worker publish directly.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from hsi_nodes.msgs import Point, make_header, make_pose, msg_class
from hsi_nodes.node import Node
from hsi_nodes.transport.base import Transport
from hsi_planning.errors import ConfigError, MessageError

__all__ = ["CLICK_TYPE", "GOAL_TYPE", "UiNode", "UiNodeConfig"]

CLICK_TYPE = "geometry_msgs/msg/PointStamped"
GOAL_TYPE = "hsi/msg/PickPlaceGoal"


@dataclass(frozen=True)
class UiNodeConfig:
    """Topics and frame of the UI node."""

    click_topic: str = "/clicked_point"  #: clicked points [topic name]
    goal_topic: str = "/hsi/goal"  #: pick-and-place goals [topic name]
    frame_id: str = "world"  #: frame of the published points and poses [-]

    def __post_init__(self) -> None:
        if not (self.click_topic and self.goal_topic and self.frame_id):
            raise ConfigError("UiNodeConfig: click_topic, goal_topic and frame_id must be non-empty")


def _finite(point: ArrayLike, what: str) -> tuple[float, float, float]:
    values = tuple(float(v) for v in np.asarray(point, dtype=np.float64).reshape(-1))
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise MessageError(f"{what} must be 3 finite numbers [m], got {point!r}")
    return values[0], values[1], values[2]


class UiNode(Node[UiNodeConfig]):
    """Publisher of the UI's clicks and goals (see the module docstring)."""

    config_class = UiNodeConfig

    def __init__(
        self,
        transport: Transport,
        *,
        name: str = "hsi_ui",
        parameters: Mapping[str, Any] | None = None,
        remappings: Mapping[str, str] | None = None,
    ) -> None:
        super().__init__(name, transport=transport, parameters=parameters, remappings=remappings)
        self._click = self.create_publisher(self.config.click_topic, CLICK_TYPE)
        self._goal = self.create_publisher(self.config.goal_topic, GOAL_TYPE)
        #: Messages published so far per kind (``click``, ``goal``).
        self.published = {"click": 0, "goal": 0}

    def publish_click(self, point: ArrayLike) -> Any:
        """Publish a ``PointStamped`` at ``point`` (3,) [m]; returns the message."""
        x, y, z = _finite(point, "clicked point")
        msg = msg_class(CLICK_TYPE)(
            header=make_header(self.now(), self.config.frame_id), point=Point(x, y, z)
        )
        self._click.publish(msg)
        self.published["click"] += 1
        return msg

    def publish_goal(
        self,
        task_id: str,
        object_name: str,
        pick_point: ArrayLike,
        place: ArrayLike | None,
        *,
        planner: str = "",
        hand: str = "",
    ) -> Any:
        """Publish a ``PickPlaceGoal``: pick ``object_name`` (clicked at ``pick_point`` (3,) [m]) and put
        its bottom centre at ``place`` (3,) [m] (None: pick and hold); returns the message."""
        px, py, pz = _finite(pick_point, "pick point")
        place_xyz = _finite(place, "place point") if place is not None else (0.0, 0.0, 0.0)
        msg = msg_class(GOAL_TYPE)(
            header=make_header(self.now(), self.config.frame_id),
            task_id=task_id,
            object_name=object_name,
            pick_point=Point(px, py, pz),
            has_place=place is not None,
            place_pose=make_pose(place_xyz),
            hand=hand,
            planner=planner,
        )
        self._goal.publish(msg)
        self.published["goal"] += 1
        return msg
