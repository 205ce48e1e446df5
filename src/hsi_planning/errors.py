"""The one exception family of the stack.

Every error says what was wrong and what would have been valid. Catch :class:`HsiError` to handle
anything the stack raises on purpose.
"""

from __future__ import annotations


class HsiError(Exception):
    """Base class of every error the HSI stack raises on purpose."""


class ConfigError(HsiError, ValueError):
    """A configuration value, parameter file or YAML document is invalid."""


class SceneError(HsiError, ValueError):
    """A scene spec is malformed, or a scene cannot be built or simulated."""


class CloudError(HsiError, ValueError):
    """A point cloud is empty, malformed or inconsistent."""


class MessageError(HsiError, ValueError):
    """A message type is unknown or a message cannot be (de)serialized."""


class TransportError(HsiError):
    """Publishing, subscribing or recording failed."""


class LaunchError(HsiError):
    """A launch file is invalid; the message names the file and line."""


class PlanningError(HsiError):
    """A planner could not produce a trajectory for the request."""


class MotionDataError(HsiError, ValueError):
    """A motion-capture file is malformed or lacks what was asked for."""


class RetargetError(HsiError):
    """A goal cannot be mapped onto the robot (out of reach, limits)."""


class HardwareError(HsiError):
    """A robot backend failed: connection, timeout, safety stop."""
