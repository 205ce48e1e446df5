"""Message transports behind one interface: ``inproc`` (one process, zero copy) now, ``dds`` later.

Use :func:`make_transport` to build one by name (what launch files and the CLI do).
"""

from __future__ import annotations

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

__all__ = [
    "TRANSPORTS",
    "Clock",
    "MessageCallback",
    "Publisher",
    "QoS",
    "Subscription",
    "TapCallback",
    "Transport",
    "make_transport",
    "validate_topic_name",
]

#: Transport names accepted by :func:`make_transport`.
TRANSPORTS = ("inproc", "dds")


def make_transport(kind: str = "inproc", clock: Clock | None = None) -> Transport:
    """Build the transport called ``kind`` (``'inproc'`` or ``'dds'``) with an optional shared ``clock``.

    Raises:
        TransportError: unknown kind, or a backend that is not available yet (``dds``).
    """
    if kind == "inproc":
        from hsi_nodes.transport.inproc import InprocTransport

        return InprocTransport(clock)
    if kind == "dds":
        raise TransportError(
            "the 'dds' transport (Cyclone DDS) is not available yet; use 'inproc' (all nodes in one process)"
        )
    raise TransportError(f"unknown transport {kind!r}; valid: {list(TRANSPORTS)}")
