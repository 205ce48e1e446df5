"""Runs a parsed launch description: builds the transport, starts the nodes, spins, shuts down cleanly.

All nodes live in this process on one transport (``inproc``) and one :class:`~hsi_nodes.executor.Executor`.
A run ends after ``duration_s`` of clock time, when every node with a finite task reports done, when
simulated time has nothing left to do, or on Ctrl-C; then queued messages are delivered, every node's
``on_shutdown`` runs (recorders finish their bags) and the transport closes.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Self

from hsi_nodes.executor import Executor
from hsi_nodes.launch.description import LaunchDescription, NodeSpec
from hsi_nodes.node import Node
from hsi_nodes.nodes import load_executable
from hsi_nodes.transport import Transport, make_transport
from hsi_planning.errors import HsiError, LaunchError

__all__ = ["LaunchRunner", "LaunchSummary", "run_launch"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LaunchSummary:
    """What a run did."""

    #: ``'/ns/name (exec)'`` of every node, in launch order.
    nodes: tuple[str, ...]
    #: Topics that existed at the end of the run: name -> message type.
    topics: dict[str, str]
    #: Messages published per topic [messages].
    message_counts: dict[str, int]
    #: Messages dropped by full subscription queues, per topic (``'*'`` = taps) [messages].
    dropped: dict[str, int]
    #: Callback exceptions per node (nodes without errors omitted).
    callback_errors: dict[str, int]
    #: Clock time the run lasted [s] (simulated time with ``use_sim_time``).
    duration_s: float
    #: Wall time the run lasted [s].
    wall_s: float
    #: ``'duration'``, ``'done'``, ``'idle'`` or ``'interrupted'``.
    stop_reason: str

    @property
    def total_errors(self) -> int:
        return sum(self.callback_errors.values())

    def format(self) -> str:
        """Human-readable multi-line summary."""
        lines = [
            f"{len(self.nodes)} nodes ran for {self.duration_s:.3f} s clock / {self.wall_s:.3f} s wall; "
            f"stopped: {self.stop_reason}",
            *(f"  node  {n}" for n in self.nodes),
        ]
        names = sorted(set(self.topics) | set(self.message_counts))
        width = max((len(t) for t in names), default=5)
        for topic in names:
            typename = self.topics.get(topic, "-")
            drops = f"  ({self.dropped[topic]} dropped)" if self.dropped.get(topic) else ""
            lines.append(
                f"  topic {topic:<{width}}  {typename:<32} {self.message_counts.get(topic, 0):>7}{drops}"
            )
        if self.dropped.get("*"):
            lines.append(f"  taps dropped {self.dropped['*']} messages")
        errors = ", ".join(f"{n}: {c}" for n, c in self.callback_errors.items()) or "none"
        lines.append(f"  callback errors: {errors}")
        return "\n".join(lines)


class LaunchRunner:
    """Builds and runs the nodes of ``description`` (plus ``extra_nodes``) in this process.

    Use as a context manager or call :meth:`start`, :meth:`spin`, :meth:`shutdown`.

    Args:
        description: parsed launch file.
        transport: ``'inproc'`` (``'dds'`` raises "not available yet").
        use_sim_time: simulated clock advanced as fast as possible (tests, offline runs).
        extra_nodes: nodes added after the launch file's, e.g. the recorder of ``hsi record``.
    """

    def __init__(
        self,
        description: LaunchDescription,
        *,
        transport: str = "inproc",
        use_sim_time: bool = False,
        extra_nodes: Sequence[NodeSpec] = (),
    ) -> None:
        self.specs = (*description.nodes, *extra_nodes)
        names = [s.fully_qualified_name for s in self.specs]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise LaunchError(f"{description.path}: node name(s) {dupes} used twice")
        self._transport_kind = transport
        self._use_sim_time = use_sim_time
        self.transport: Transport | None = None
        self.executor: Executor | None = None
        self.nodes: list[Node[Any]] = []
        self._t0_ns = 0
        self._t0_wall = 0.0
        self._summary: LaunchSummary | None = None
        #: Why the last :meth:`spin` returned.
        self.stop_reason = "not started"

    def start(self) -> None:
        """Create the transport and every node (a node that fails to build names its launch file line).

        Raises:
            LaunchError: ``path:LINE: ...`` for a node whose class or parameters are invalid.
            TransportError: unavailable transport.
        """
        self.transport = make_transport(self._transport_kind)
        self.executor = Executor(self.transport, use_sim_time=self._use_sim_time)
        self._t0_ns, self._t0_wall = self.transport.clock.now_ns(), time.monotonic()
        for spec in self.specs:
            try:
                cls = load_executable(spec.executable)
                node = cls(
                    spec.name,
                    namespace=spec.namespace,
                    transport=self.transport,
                    parameters=spec.parameters,
                    remappings=dict(spec.remappings),
                )
            except HsiError as exc:
                self._abort()
                raise LaunchError(
                    f"{spec.source}: cannot start node {spec.fully_qualified_name}: {exc}"
                ) from exc
            except BaseException:  # a bug in a node class: still release what was built, then re-raise
                self._abort()
                raise
            self.nodes.append(node)
            self.executor.add_node(node)
            _log.info("started %s (%s)", node.fully_qualified_name, spec.executable)

    def _abort(self) -> None:
        for node in self.nodes:
            node.destroy()
        if self.transport is not None:
            self.transport.close()

    def spin(self, duration_s: float | None = None, *, stop_when_done: bool = True) -> str:
        """Spin until ``duration_s`` [s] of clock time pass (``None``: no limit) or all finite nodes are done;
        returns the stop reason (``'duration'``, ``'done'``, ``'idle'``). Ctrl-C propagates."""
        if self.executor is None:
            raise LaunchError("call start() before spin()")
        executor = self.executor
        t_end = None if duration_s is None else executor.clock.now_ns() + round(duration_s * 1e9)
        executor.spin(duration_s, until=executor.all_done if stop_when_done else None)
        if stop_when_done and executor.all_done():
            self.stop_reason = "done"
        elif t_end is not None and executor.clock.now_ns() >= t_end:
            self.stop_reason = "duration"
        else:
            self.stop_reason = "idle"
        return self.stop_reason

    def shutdown(self, stop_reason: str | None = None) -> LaunchSummary:
        """Deliver queued messages, shut every node down, close the transport; returns the summary.

        ``stop_reason`` defaults to what :meth:`spin` returned."""
        if self._summary is not None:
            return self._summary
        if self.transport is None or self.executor is None:
            raise LaunchError("call start() before shutdown()")
        transport, executor = self.transport, self.executor
        subscriptions = transport.subscriptions()
        topics = transport.topics()
        executor.shutdown()  # drains queues first, so counts below include the last messages
        dropped: dict[str, int] = {}
        for sub in subscriptions:
            if sub.dropped:
                dropped[sub.topic] = dropped.get(sub.topic, 0) + sub.dropped
        self._summary = LaunchSummary(
            nodes=tuple(
                f"{n.fully_qualified_name} ({s.executable})"
                for s, n in zip(self.specs, self.nodes, strict=True)
            ),
            topics=topics,
            message_counts=transport.message_counts(),
            dropped=dropped,
            callback_errors={
                n.fully_qualified_name: n.callback_errors for n in self.nodes if n.callback_errors
            },
            duration_s=(transport.clock.now_ns() - self._t0_ns) * 1e-9,
            wall_s=time.monotonic() - self._t0_wall,
            stop_reason=stop_reason or self.stop_reason,
        )
        transport.close()
        return self._summary

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self.executor is not None:
            self.shutdown("interrupted" if exc_type is KeyboardInterrupt else "error" if exc_type else None)


def run_launch(
    description: LaunchDescription,
    *,
    duration_s: float | None = None,
    transport: str = "inproc",
    use_sim_time: bool = False,
    extra_nodes: Sequence[NodeSpec] = (),
) -> LaunchSummary:
    """Run ``description`` until ``duration_s`` [s], all finite nodes are done, idle (sim time) or Ctrl-C.

    Ctrl-C ends the run cleanly (stop reason ``'interrupted'``); other errors propagate after shutdown.
    """
    runner = LaunchRunner(
        description, transport=transport, use_sim_time=use_sim_time, extra_nodes=extra_nodes
    )
    runner.start()
    reason = "error"
    try:
        reason = runner.spin(duration_s)
    except KeyboardInterrupt:
        reason = "interrupted"
        _log.info("interrupted; shutting down")
    finally:
        summary = runner.shutdown(reason)
    return summary
