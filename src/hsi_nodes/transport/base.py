"""The transport interface: publishers, subscriptions, quality of service and the shared clock.

A transport moves ROS 2 message objects (the ``rosbags`` dataclasses built by :mod:`hsi_nodes.msgs`)
between nodes by fully qualified topic name (``/robot/joint_states``). Each topic has one message type
(``sensor_msgs/msg/JointState``); endpoints that disagree raise :class:`TransportError`.

Delivery is *pull-based*: publishing only queues a message on every matching subscription; an executor
(:class:`hsi_nodes.node.Executor`) later calls :meth:`Subscription.dispatch` to run the callbacks, so all
callbacks run in the executor's thread, one at a time.

The transport also carries the :class:`Clock` shared by every node on it (like ROS 2's ``/clock`` with
``use_sim_time``): wall time, or a simulated time that only the executor advances.
"""

from __future__ import annotations

import re
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

from hsi_planning.errors import ConfigError, TransportError

__all__ = [
    "Clock",
    "MessageCallback",
    "Publisher",
    "QoS",
    "Subscription",
    "TapCallback",
    "Transport",
    "validate_topic_name",
]

#: Callback of a topic subscription: receives the message (shared, do not mutate).
MessageCallback = Callable[[Any], None]
#: Callback of an all-topics tap: ``(topic, typename, message, t_ns)``; ``t_ns`` [ns] is the publish time.
TapCallback = Callable[[str, str, Any, int], None]

_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_ABSOLUTE_TOPIC = re.compile(rf"^(/{_TOKEN})+$")


def validate_topic_name(topic: str) -> str:
    """Check that ``topic`` is a fully qualified ROS 2 topic name (``/a/b_2``) and return it.

    Raises:
        TransportError: the name is relative, empty, has empty tokens, a trailing slash, or tokens that do
            not match ``[A-Za-z_][A-Za-z0-9_]*``.
    """
    if not isinstance(topic, str) or not _ABSOLUTE_TOPIC.match(topic):
        raise TransportError(
            f"invalid topic name {topic!r}: a transport needs a fully qualified name like '/ns/topic' "
            "(tokens [A-Za-z_][A-Za-z0-9_]*, no empty tokens or trailing '/'); nodes resolve relative names"
        )
    return topic


@dataclass(frozen=True)
class QoS:
    """Quality of service of a publisher or subscription (a subset of ROS 2's profile)."""

    #: Queue depth [messages] (history keep-last): a full subscription queue drops its oldest message;
    #: a latched publisher keeps this many messages for late subscribers.
    depth: int = 10
    #: Transient local durability: a latched subscription receives the last ``depth`` messages that latched
    #: publishers kept, even if it subscribes after they were published [bool].
    latched: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.depth, bool) or not isinstance(self.depth, int) or self.depth < 1:
            raise ConfigError(f"QoS.depth must be an integer >= 1 [messages], got {self.depth!r}")
        if not isinstance(self.latched, bool):
            raise ConfigError(f"QoS.latched must be true or false, got {self.latched!r}")


class Clock:
    """The time source of a transport: wall time, or simulated time advanced by the executor.

    Simulated time starts at ``start_ns`` and moves only through :meth:`advance_to`, so timers and
    stamps are deterministic and a simulated minute takes milliseconds.
    """

    def __init__(self, *, simulated: bool = False, start_ns: int = 0) -> None:
        self._simulated = simulated
        self._sim_ns = int(start_ns)
        self._lock = threading.Lock()

    @property
    def simulated(self) -> bool:
        """True when time is simulated (``use_sim_time``)."""
        return self._simulated

    def use_sim_time(self, start_ns: int = 0) -> None:
        """Switch to simulated time starting at ``start_ns`` [ns]."""
        with self._lock:
            self._simulated = True
            self._sim_ns = int(start_ns)

    def now_ns(self) -> int:
        """Current time [ns] (since the Unix epoch for wall time)."""
        if not self._simulated:
            return time.time_ns()
        with self._lock:
            return self._sim_ns

    def now(self) -> float:
        """Current time [s]."""
        return self.now_ns() * 1e-9

    def advance_to(self, t_ns: int) -> None:
        """Set simulated time to ``t_ns`` [ns]; time never moves backwards.

        Raises:
            TransportError: the clock is a wall clock, or ``t_ns`` lies in the past.
        """
        with self._lock:
            if not self._simulated:
                raise TransportError(
                    "cannot advance a wall clock; create the executor with use_sim_time=True"
                )
            if t_ns < self._sim_ns:
                raise TransportError(f"simulated time cannot go back from {self._sim_ns} ns to {t_ns} ns")
            self._sim_ns = int(t_ns)


class Publisher(ABC):
    """Publishes messages of one type on one topic."""

    def __init__(self, topic: str, typename: str, qos: QoS) -> None:
        self.topic = topic
        self.typename = typename
        self.qos = qos
        #: Messages published so far [messages].
        self.count = 0

    @abstractmethod
    def publish(self, msg: Any) -> None:
        """Send ``msg`` (a message of :attr:`typename`) to every subscription of the topic.

        Raises:
            TransportError: the publisher or transport is closed, or ``msg`` is of another type.
        """

    @abstractmethod
    def close(self) -> None:
        """Stop publishing (idempotent); a latched publisher's kept messages are discarded."""


class Subscription(ABC):
    """A bounded queue of received messages and the callback that the executor runs on them."""

    def __init__(self, topic: str, typename: str, qos: QoS) -> None:
        self.topic = topic
        self.typename = typename
        self.qos = qos
        #: Messages dropped because the queue was full (oldest first) [messages].
        self.dropped = 0
        #: Messages handed to the callback [messages].
        self.delivered = 0

    @abstractmethod
    def pending(self) -> int:
        """Number of queued messages waiting for :meth:`dispatch`."""

    @abstractmethod
    def dispatch(self, max_messages: int) -> int:
        """Run the callback on up to ``max_messages`` queued messages (oldest first); return how many.

        Exceptions raised by the callback propagate to the caller (nodes wrap their callbacks).
        """

    @abstractmethod
    def close(self) -> None:
        """Stop receiving and drop queued messages (idempotent)."""


class Transport(ABC):
    """Moves messages between the nodes of a system; see the module docstring."""

    def __init__(self, clock: Clock | None = None) -> None:
        #: Time source shared by every node on this transport.
        self.clock = clock if clock is not None else Clock()

    @abstractmethod
    def publisher(self, topic: str, typename: str, qos: QoS | None = None) -> Publisher:
        """A publisher of ``typename`` messages on the fully qualified ``topic``.

        Raises:
            TransportError: invalid topic name, or the topic already has another type.
            MessageError: unknown message type.
        """

    @abstractmethod
    def subscribe(
        self, topic: str, typename: str, callback: MessageCallback, qos: QoS | None = None
    ) -> Subscription:
        """Queue every ``typename`` message published on ``topic`` for ``callback``.

        Raises:
            TransportError: invalid topic name, or the topic already has another type.
            MessageError: unknown message type.
        """

    @abstractmethod
    def subscribe_all(
        self, callback: TapCallback, qos: QoS | None = None, topics: Collection[str] | None = None
    ) -> Subscription:
        """A tap on every topic (or only ``topics``), present and future, for recorders and monitors.

        A latched tap also receives the messages latched publishers kept (like ``ros2 bag record``).
        The returned subscription's :attr:`~Subscription.topic` is ``'*'`` and its type ``'*'``.
        """

    @abstractmethod
    def topics(self) -> dict[str, str]:
        """Topics with at least one publisher or subscription: name -> message type, sorted by name."""

    @abstractmethod
    def message_counts(self) -> dict[str, int]:
        """Messages published per topic since the transport was created [messages]."""

    @abstractmethod
    def subscriptions(self) -> list[Subscription]:
        """Open subscriptions (taps included) in creation order; the executor serves these."""

    @abstractmethod
    def wait(self, timeout_s: float) -> None:
        """Block up to ``timeout_s`` [s] of wall time until some subscription has a queued message."""

    @abstractmethod
    def close(self) -> None:
        """Close every endpoint; later use raises :class:`TransportError` (idempotent)."""

    @property
    @abstractmethod
    def closed(self) -> bool:
        """True after :meth:`close`."""
