"""Node base class (typed parameters, ROS 2 name resolution, guarded callbacks) and timers.

A node owns publishers, subscriptions and timers on a shared :class:`~hsi_nodes.transport.Transport`.
Its parameters become ``self.config``, an instance of the class attribute :attr:`Node.config_class`
(a frozen config dataclass). Topic names resolve like ROS 2: ``/abs`` stays, ``rel`` gets the namespace,
``~/x`` is node-private (``/ns/node/x``); then remappings ``{from: to}`` apply (both sides resolved).

An exception raised by a subscription or timer callback is logged with its traceback, counted in
:attr:`Node.callback_errors`, and the node keeps running. The :class:`Executor` runs every callback in
one thread (see :mod:`hsi_nodes.executor`; ``Executor`` is re-exported here).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Generic, TypeVar

from hsi_nodes.transport.base import MessageCallback, Publisher, QoS, Subscription, Transport
from hsi_nodes.transport.base import validate_topic_name as _validate_topic
from hsi_planning.config import from_mapping, load_yaml, ros_parameters
from hsi_planning.errors import ConfigError, TransportError

__all__ = ["Executor", "NoParameters", "Node", "Timer", "normalize_namespace", "resolve_topic_name"]

ConfigT = TypeVar("ConfigT")

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_NS_PER_S = 1_000_000_000


def normalize_namespace(namespace: str) -> str:
    """``''`` -> ``'/'``, ``'a/b/'`` -> ``'/a/b'``; raises :class:`ConfigError` for invalid tokens."""
    tokens = [t for t in namespace.strip("/").split("/") if t] if namespace else []
    if any(not _NAME.match(t) for t in tokens) or "//" in namespace:
        raise ConfigError(f"invalid namespace {namespace!r}: tokens must match [A-Za-z_][A-Za-z0-9_]*")
    return "/" + "/".join(tokens)


def _expand(name: str, node_name: str, namespace: str) -> str:
    fqn = namespace.rstrip("/") + "/" + node_name
    name = name.replace("{node}", node_name).replace("{ns}", namespace).replace("{namespace}", namespace)
    if name == "~":
        full = fqn
    elif name.startswith("~/"):
        full = fqn + name[1:]
    elif name.startswith("/"):
        full = name
    else:
        full = namespace.rstrip("/") + "/" + name
    try:
        return _validate_topic(full)
    except TransportError:
        raise TransportError(
            f"invalid topic name {name!r} (node {fqn}): use '/absolute', 'relative' or '~/private' names "
            "with tokens [A-Za-z_][A-Za-z0-9_]*"
        ) from None


def resolve_topic_name(
    name: str, *, node_name: str, namespace: str = "/", remappings: Mapping[str, str] | None = None
) -> str:
    """Fully qualified topic name of ``name`` for node ``node_name`` in ``namespace``, after remapping.

    Raises:
        TransportError: ``name`` or a remapping side is not a valid ROS 2 topic name.
    """
    resolved = _expand(name, node_name, namespace)
    for src, dst in (remappings or {}).items():
        if _expand(src, node_name, namespace) == resolved:
            return _expand(dst, node_name, namespace)
    return resolved


@dataclass(frozen=True)
class NoParameters:
    """Config of a node that takes no parameters."""


class Timer:
    """Calls ``callback()`` every ``period_ns`` [ns] of the transport clock, starting one period after the
    executor first sees it; missed periods are skipped (no burst of catch-up calls)."""

    def __init__(self, period_ns: int, callback: Callable[[], None]) -> None:
        self.period_ns = period_ns
        self.callback = callback
        #: Next due time [ns]; None until the executor starts the timer.
        self.next_ns: int | None = None
        #: Calls so far.
        self.count = 0
        self.cancelled = False

    def cancel(self) -> None:
        """Stop calling the callback (idempotent)."""
        self.cancelled = True

    def fire(self, now_ns: int) -> None:
        """Run the callback and schedule the next call after ``now_ns`` [ns]."""
        assert self.next_ns is not None
        missed = (now_ns - self.next_ns) // self.period_ns + 1
        self.next_ns += missed * self.period_ns
        self.count += 1
        self.callback()


class Node(Generic[ConfigT]):
    """Base class of every node; subclasses set :attr:`config_class` and build endpoints in ``__init__``.

    Args:
        name: node name, ``[A-Za-z_][A-Za-z0-9_]*``.
        namespace: ``''``/``'/'`` or ``'/a/b'`` (a leading slash is added).
        transport: the transport every endpoint of the node uses (and whose clock it reads).
        parameters: overrides of :attr:`config_class` defaults (unknown key or wrong type -> ConfigError).
        remappings: topic remappings ``{from: to}``, applied after name resolution.
    """

    #: Frozen config dataclass built from the node's parameters.
    config_class: ClassVar[type[Any]] = NoParameters

    def __init__(
        self,
        name: str,
        *,
        namespace: str = "",
        transport: Transport,
        parameters: Mapping[str, Any] | None = None,
        remappings: Mapping[str, str] | None = None,
    ) -> None:
        if not isinstance(name, str) or not _NAME.match(name):
            raise ConfigError(f"invalid node name {name!r}: must match [A-Za-z_][A-Za-z0-9_]*")
        self._name = name
        self._namespace = normalize_namespace(namespace)
        self.transport = transport
        self._remappings = dict(remappings or {})
        for src, dst in self._remappings.items():  # fail at construction on bad remap names
            _expand(src, name, self._namespace)
            _expand(dst, name, self._namespace)
        tokens = [t for t in self._namespace.split("/") if t]
        self._logger = logging.getLogger(".".join(["hsi", *tokens, name]))
        self.config: ConfigT = from_mapping(
            self.config_class, parameters, where=f"node {self.fully_qualified_name}"
        )
        self._publishers: list[Publisher] = []
        self._subscriptions: list[Subscription] = []
        self.timers: list[Timer] = []
        #: Exceptions raised (and logged) by this node's callbacks.
        self.callback_errors = 0
        self.destroyed = False

    # ------------------------------------------------------------------------------------ identity

    @property
    def name(self) -> str:
        return self._name

    @property
    def namespace(self) -> str:
        return self._namespace

    @property
    def fully_qualified_name(self) -> str:
        """``'/ns/name'``."""
        return self._namespace.rstrip("/") + "/" + self._name

    def get_logger(self) -> logging.Logger:
        """The logger ``hsi.<namespace tokens>.<name>``."""
        return self._logger

    def now_ns(self) -> int:
        """Current transport clock time [ns]."""
        return self.transport.clock.now_ns()

    def now(self) -> float:
        """Current transport clock time [s]."""
        return self.transport.clock.now()

    @staticmethod
    def load_parameter_file(path: str | Path, node_name: str) -> dict[str, Any]:
        """Parameters of ``node_name`` (plain or fully qualified) from a ROS 2 parameter YAML file.

        Entries are merged in the order ``/**``, the plain name, then the fully qualified name.

        Raises:
            ConfigError: missing file, invalid YAML (file:line), or a malformed parameter document.
        """
        doc = load_yaml(path)
        plain = node_name.rstrip("/").rsplit("/", 1)[-1]
        params = ros_parameters(doc, plain, source=str(path))
        nested = node_name.startswith("/") and node_name.count("/") > 1
        if nested and isinstance(doc, Mapping) and node_name in doc:
            params.update(ros_parameters({node_name: doc[node_name]}, node_name, source=str(path)))
        return params

    # ----------------------------------------------------------------------------------- endpoints

    def resolve(self, topic: str) -> str:
        """Fully qualified name of ``topic`` for this node, after remapping."""
        return resolve_topic_name(
            topic, node_name=self._name, namespace=self._namespace, remappings=self._remappings
        )

    @staticmethod
    def _qos(qos: QoS | int | None) -> QoS:
        return qos if isinstance(qos, QoS) else QoS(depth=10 if qos is None else qos)

    def create_publisher(self, topic: str, typename: str, qos: QoS | int | None = None) -> Publisher:
        """A publisher on the resolved ``topic``; ``qos`` may be a :class:`QoS` or a queue depth."""
        pub = self.transport.publisher(self.resolve(topic), typename, self._qos(qos))
        self._publishers.append(pub)
        return pub

    def create_subscription(
        self, topic: str, typename: str, callback: MessageCallback, qos: QoS | int | None = None
    ) -> Subscription:
        """Subscribe ``callback`` (guarded: exceptions are logged and counted) to the resolved ``topic``."""
        resolved = self.resolve(topic)
        guarded = self._guard(f"subscription callback on {resolved}", callback)
        sub = self.transport.subscribe(resolved, typename, guarded, self._qos(qos))
        self._subscriptions.append(sub)
        return sub

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> Timer:
        """Call ``callback()`` (guarded) every ``period_s`` [s] of the transport clock."""
        if not isinstance(period_s, (int, float)) or not period_s > 0:
            raise ConfigError(f"{self.fully_qualified_name}: timer period must be > 0 [s], got {period_s!r}")
        timer = Timer(max(1, round(period_s * _NS_PER_S)), self._guard("timer callback", callback))
        self.timers.append(timer)
        return timer

    def _guard(self, what: str, fn: Callable[..., None]) -> Callable[..., None]:
        def guarded(*args: Any) -> None:
            try:
                fn(*args)
            except Exception:
                self.callback_errors += 1
                self._logger.exception(
                    "%s raised (error %d in this node); the node keeps running", what, self.callback_errors
                )

        return guarded

    # ----------------------------------------------------------------------------------- lifecycle

    def on_start(self) -> None:
        """Hook: called once by the executor before it first runs callbacks (exceptions propagate)."""

    def on_shutdown(self) -> None:
        """Hook: called once at shutdown before the endpoints close (exceptions are logged and counted)."""

    def is_done(self) -> bool | None:
        """``None``: runs until stopped; ``False``/``True``: a finite task that is not yet / is finished."""
        return None

    def shutdown(self) -> None:
        """Run :meth:`on_shutdown` (guarded), then :meth:`destroy`."""
        if not self.destroyed:
            self._guard("on_shutdown", self.on_shutdown)()
        self.destroy()

    def destroy(self) -> None:
        """Close every endpoint and cancel the timers (idempotent)."""
        for timer in self.timers:
            timer.cancel()
        for sub in self._subscriptions:
            sub.close()
        for pub in self._publishers:
            pub.close()
        self._subscriptions.clear()
        self._publishers.clear()
        self.destroyed = True


# Re-exported for compatibility: the executor lives in :mod:`hsi_nodes.executor`.
from hsi_nodes.executor import Executor  # noqa: E402
