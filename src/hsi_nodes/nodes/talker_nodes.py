"""Small utility nodes: ``heartbeat`` (periodic liveness message), ``echo`` (log a topic, like
``ros2 topic echo``) and ``topic_relay`` (republish a topic under another name, like topic_tools relay).

They are used by the tests and as launch-file examples; remap their relative topic names to wire them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from hsi_nodes.msgs import msg_class
from hsi_nodes.node import Node
from hsi_nodes.transport.base import QoS
from hsi_planning.errors import ConfigError

__all__ = [
    "EchoConfig",
    "EchoNode",
    "HeartbeatConfig",
    "HeartbeatNode",
    "TopicRelayConfig",
    "TopicRelayNode",
]

_TYPENAME = re.compile(r"^[A-Za-z_]\w*/msg/[A-Za-z_]\w*$")
_STRING = "std_msgs/msg/String"


def _check_typename(owner: str, typename: str) -> None:
    if not _TYPENAME.match(typename):
        raise ConfigError(f"{owner}.typename must look like 'pkg/msg/Type', got {typename!r}")


def _check_depth(owner: str, depth: int) -> None:
    if depth < 1:
        raise ConfigError(f"{owner}.queue_depth must be >= 1 [messages], got {depth}")


@dataclass(frozen=True)
class HeartbeatConfig:
    """Parameters of :class:`HeartbeatNode`."""

    #: Publishing rate [Hz].
    rate_hz: float = 10.0
    #: Messages to send before reporting done; 0 = run forever [messages].
    count: int = 0
    #: Text of each message, followed by the sequence number [-].
    text: str = "heartbeat"
    #: Topic the beats go to (relative names get the node namespace) [-].
    topic: str = "heartbeat"

    def __post_init__(self) -> None:
        if not self.rate_hz > 0:
            raise ConfigError(f"HeartbeatConfig.rate_hz must be > 0 [Hz], got {self.rate_hz}")
        if self.count < 0:
            raise ConfigError(f"HeartbeatConfig.count must be >= 0 (0 = forever), got {self.count}")


class HeartbeatNode(Node[HeartbeatConfig]):
    """Publishes ``std_msgs/String`` ``'<text> <seq>'`` (seq from 1) at ``rate_hz`` on ``topic``."""

    config_class = HeartbeatConfig

    def __init__(self, name: str = "heartbeat", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self._msg = msg_class(_STRING)
        self.publisher = self.create_publisher(self.config.topic, _STRING)
        self.sent = 0
        self.timer = self.create_timer(1.0 / self.config.rate_hz, self._beat)

    def _beat(self) -> None:
        if self.is_done():
            self.timer.cancel()
            return
        self.sent += 1
        self.publisher.publish(self._msg(data=f"{self.config.text} {self.sent}"))

    def is_done(self) -> bool | None:
        return None if self.config.count == 0 else self.sent >= self.config.count


@dataclass(frozen=True)
class EchoConfig:
    """Parameters of :class:`EchoNode`."""

    #: Topic to print (relative names get the node namespace) [-].
    topic: str = "heartbeat"
    #: Message type of ``topic``, e.g. ``sensor_msgs/msg/JointState`` [-].
    typename: str = _STRING
    #: Messages to receive before reporting done; 0 = run forever [messages].
    max_messages: int = 0
    #: Subscription queue depth [messages].
    queue_depth: int = 10
    #: Longest printed message text; longer texts are cut [characters].
    max_chars: int = 300

    def __post_init__(self) -> None:
        _check_typename("EchoConfig", self.typename)
        _check_depth("EchoConfig", self.queue_depth)
        if self.max_messages < 0 or self.max_chars < 10:
            raise ConfigError("EchoConfig: max_messages must be >= 0 and max_chars >= 10")


class EchoNode(Node[EchoConfig]):
    """Logs every message of ``topic`` at INFO level (shared message: read only) and keeps the last one."""

    config_class = EchoConfig

    def __init__(self, name: str = "echo", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.received = 0
        self.last: Any = None
        self.subscription = self.create_subscription(
            self.config.topic, self.config.typename, self._on_message, self.config.queue_depth
        )

    def _on_message(self, msg: Any) -> None:
        self.received += 1
        self.last = msg
        text = repr(msg)
        if len(text) > self.config.max_chars:
            text = text[: self.config.max_chars - 3] + "..."
        self.get_logger().info("%s #%d: %s", self.subscription.topic, self.received, text)

    def is_done(self) -> bool | None:
        return None if self.config.max_messages == 0 else self.received >= self.config.max_messages


@dataclass(frozen=True)
class TopicRelayConfig:
    """Parameters of :class:`TopicRelayNode`."""

    #: Topic to read (relative names get the node namespace) [-].
    input_topic: str = "input"
    #: Topic to republish on [-].
    output_topic: str = "output"
    #: Message type of both topics [-].
    typename: str = _STRING
    #: Queue depth of the subscription and the publisher [messages].
    queue_depth: int = 10
    #: Republish latched (transient local), e.g. for maps and scene descriptions [bool].
    latched: bool = False

    def __post_init__(self) -> None:
        _check_typename("TopicRelayConfig", self.typename)
        _check_depth("TopicRelayConfig", self.queue_depth)


class TopicRelayNode(Node[TopicRelayConfig]):
    """Republishes every message of ``input_topic`` on ``output_topic`` (the same object, zero copy)."""

    config_class = TopicRelayConfig

    def __init__(self, name: str = "topic_relay", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        cfg = self.config
        if self.resolve(cfg.input_topic) == self.resolve(cfg.output_topic):
            raise ConfigError(
                f"{self.fully_qualified_name}: input and output resolve to the same topic "
                f"{self.resolve(cfg.input_topic)}; remap one of them"
            )
        qos = QoS(depth=cfg.queue_depth, latched=cfg.latched)
        self.relayed = 0
        self.publisher = self.create_publisher(cfg.output_topic, cfg.typename, qos)
        self.subscription = self.create_subscription(cfg.input_topic, cfg.typename, self._relay, qos)

    def _relay(self, msg: Any) -> None:
        self.publisher.publish(msg)
        self.relayed += 1
