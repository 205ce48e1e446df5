"""In-process transport: every node in one Python process, messages passed by reference (zero copy).

A published message object is *shared* by every subscriber (no serialization, no copy): callbacks and
recorders must treat received messages as read-only, and a publisher must not modify a message after
publishing it (build a new one each time). Each subscription has a bounded keep-last queue: when it is
full the oldest message is dropped and counted in :attr:`Subscription.dropped`.

Publishing is thread safe (a driver thread may publish); callbacks run only when an executor dispatches
them, in the executor's thread.
"""

from __future__ import annotations

import itertools
import logging
import threading
from collections import deque
from collections.abc import Callable, Collection
from typing import Any

from hsi_nodes.msgs import msg_class, normalize_typename
from hsi_nodes.transport.base import (
    Clock,
    MessageCallback,
    Publisher,
    QoS,
    Subscription,
    TapCallback,
    Transport,
    validate_topic_name,
)
from hsi_planning.errors import TransportError

__all__ = ["InprocTransport"]

_log = logging.getLogger(__name__)

#: Queued or latched entry: (sequence number, publish time [ns], topic, typename, message).
_Entry = tuple[int, int, str, str, Any]


class _Topic:
    def __init__(self, typename: str) -> None:
        self.typename = typename
        self.publishers: list[_InprocPublisher] = []
        self.subscriptions: list[_InprocSubscription] = []


class _InprocPublisher(Publisher):
    def __init__(self, owner: InprocTransport, topic: str, typename: str, qos: QoS) -> None:
        super().__init__(topic, typename, qos)
        self._owner = owner
        self.history: deque[_Entry] = deque(maxlen=qos.depth)
        self.closed = False

    def publish(self, msg: Any) -> None:
        self._owner._publish(self, msg)

    def close(self) -> None:
        self._owner._remove_publisher(self)


class _InprocSubscription(Subscription):
    def __init__(
        self,
        owner: InprocTransport,
        topic: str,
        typename: str,
        qos: QoS,
        call: Callable[[_Entry], None],
        *,
        topics: frozenset[str] | None = None,
    ) -> None:
        super().__init__(topic, typename, qos)
        self._owner = owner
        self._call = call
        self.topic_filter = topics
        self.queue: deque[_Entry] = deque()
        self.closed = False

    def accepts(self, topic: str) -> bool:
        return self.topic_filter is None or topic in self.topic_filter

    def enqueue(self, entry: _Entry) -> None:
        """Append under the transport lock; drop the oldest entry when full."""
        if len(self.queue) >= self.qos.depth:
            self.queue.popleft()
            self.dropped += 1
        self.queue.append(entry)

    def pending(self) -> int:
        return len(self.queue)

    def dispatch(self, max_messages: int) -> int:
        done = 0
        while done < max_messages:
            with self._owner._cond:
                if self.closed or not self.queue:
                    break
                entry = self.queue.popleft()
            done += 1
            self.delivered += 1
            self._call(entry)
        return done

    def close(self) -> None:
        self._owner._remove_subscription(self)


class InprocTransport(Transport):
    """Zero-copy in-process transport; see the module docstring for the sharing rules."""

    def __init__(self, clock: Clock | None = None) -> None:
        super().__init__(clock)
        self._cond = threading.Condition(threading.RLock())
        self._topics: dict[str, _Topic] = {}
        self._taps: list[_InprocSubscription] = []
        self._subs: list[_InprocSubscription] = []
        self._counts: dict[str, int] = {}
        self._seq = itertools.count()
        self._closed = False

    # ------------------------------------------------------------------------------------ endpoints

    def _check_open(self) -> None:
        if self._closed:
            raise TransportError("the transport is closed")

    def _topic_for(self, topic: str, typename: str) -> tuple[str, _Topic]:
        """Validate names and return the (created if needed) topic entry; call under the lock."""
        self._check_open()
        validate_topic_name(topic)
        name = normalize_typename(typename)
        msg_class(name)  # unknown type -> MessageError with close matches
        entry = self._topics.get(topic)
        if entry is None:
            entry = self._topics[topic] = _Topic(name)
        elif entry.typename != name:
            raise TransportError(
                f"topic {topic!r} carries {entry.typename}; cannot use it with {name} "
                "(one message type per topic: rename or remap one of the endpoints)"
            )
        return name, entry

    def publisher(self, topic: str, typename: str, qos: QoS | None = None) -> Publisher:
        with self._cond:
            name, entry = self._topic_for(topic, typename)
            pub = _InprocPublisher(self, topic, name, qos or QoS())
            entry.publishers.append(pub)
            return pub

    def subscribe(
        self, topic: str, typename: str, callback: MessageCallback, qos: QoS | None = None
    ) -> Subscription:
        with self._cond:
            name, entry = self._topic_for(topic, typename)
            sub = _InprocSubscription(self, topic, name, qos or QoS(), lambda e: callback(e[4]))
            if sub.qos.latched:
                self._replay_latched(sub, entry.publishers)
            entry.subscriptions.append(sub)
            self._subs.append(sub)
            return sub

    def subscribe_all(
        self, callback: TapCallback, qos: QoS | None = None, topics: Collection[str] | None = None
    ) -> Subscription:
        with self._cond:
            self._check_open()
            wanted = None if topics is None else frozenset(validate_topic_name(t) for t in topics)
            tap = _InprocSubscription(
                self, "*", "*", qos or QoS(), lambda e: callback(e[2], e[3], e[4], e[1]), topics=wanted
            )
            if tap.qos.latched:
                pubs = [p for name, t in self._topics.items() if tap.accepts(name) for p in t.publishers]
                self._replay_latched(tap, pubs)
            self._taps.append(tap)
            self._subs.append(tap)
            return tap

    @staticmethod
    def _replay_latched(sub: _InprocSubscription, publishers: list[_InprocPublisher]) -> None:
        """Queue the kept messages of latched publishers on a new latched subscription, oldest first."""
        kept = sorted(e for p in publishers if p.qos.latched for e in p.history)
        for e in kept:
            sub.enqueue(e)

    def _remove_publisher(self, pub: _InprocPublisher) -> None:
        with self._cond:
            pub.closed = True
            pub.history.clear()
            entry = self._topics.get(pub.topic)
            if entry is not None and pub in entry.publishers:
                entry.publishers.remove(pub)
                self._drop_if_unused(pub.topic, entry)

    def _remove_subscription(self, sub: _InprocSubscription) -> None:
        with self._cond:
            sub.closed = True
            sub.queue.clear()
            if sub in self._subs:
                self._subs.remove(sub)
            if sub in self._taps:
                self._taps.remove(sub)
            entry = self._topics.get(sub.topic)
            if entry is not None and sub in entry.subscriptions:
                entry.subscriptions.remove(sub)
                self._drop_if_unused(sub.topic, entry)

    def _drop_if_unused(self, topic: str, entry: _Topic) -> None:
        if not entry.publishers and not entry.subscriptions:
            del self._topics[topic]

    # -------------------------------------------------------------------------------------- traffic

    def _publish(self, pub: _InprocPublisher, msg: Any) -> None:
        actual = getattr(msg, "__msgtype__", None)
        if actual != pub.typename:
            got = actual or type(msg).__name__
            raise TransportError(f"publisher on {pub.topic!r} sends {pub.typename}, got a {got}")
        with self._cond:
            if pub.closed or self._closed:
                raise TransportError(f"publisher on {pub.topic!r} is closed")
            entry: _Entry = (next(self._seq), self.clock.now_ns(), pub.topic, pub.typename, msg)
            if pub.qos.latched:
                pub.history.append(entry)
            pub.count += 1
            self._counts[pub.topic] = self._counts.get(pub.topic, 0) + 1
            for sub in self._topics[pub.topic].subscriptions:
                sub.enqueue(entry)
            for tap in self._taps:
                if tap.accepts(pub.topic):
                    tap.enqueue(entry)
            self._cond.notify_all()

    def topics(self) -> dict[str, str]:
        with self._cond:
            return {name: self._topics[name].typename for name in sorted(self._topics)}

    def message_counts(self) -> dict[str, int]:
        with self._cond:
            return dict(sorted(self._counts.items()))

    def subscriptions(self) -> list[Subscription]:
        with self._cond:
            return list(self._subs)

    def wait(self, timeout_s: float) -> None:
        with self._cond:
            if timeout_s <= 0 or any(s.queue for s in self._subs):
                return
            self._cond.wait(timeout_s)

    def close(self) -> None:
        with self._cond:
            if self._closed:
                return
            for sub in list(self._subs):
                self._remove_subscription(sub)
            for entry in list(self._topics.values()):
                for pub in list(entry.publishers):
                    self._remove_publisher(pub)
            self._topics.clear()
            self._closed = True
            self._cond.notify_all()
            _log.debug("inproc transport closed")

    @property
    def closed(self) -> bool:
        return self._closed
