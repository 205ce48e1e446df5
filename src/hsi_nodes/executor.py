"""The single-threaded, deterministic executor that runs the callbacks of nodes on one transport.

Order per pass: due timers first (by due time), then queued messages (subscriptions in creation order).
With ``use_sim_time`` it jumps the clock to the next timer when idle, so tests run a simulated minute in
milliseconds.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from hsi_nodes.transport.base import Transport
from hsi_planning.errors import TransportError

if TYPE_CHECKING:
    from hsi_nodes.node import Node, Timer

__all__ = ["Executor"]

_NS_PER_S = 1_000_000_000


class Executor:
    """Single-threaded, deterministic executor of the nodes on one transport (see the module docstring).

    It serves every subscription of the transport and the timers of the nodes added to it.
    """

    def __init__(self, transport: Transport, *, use_sim_time: bool = False, sim_start_s: float = 0.0) -> None:
        self.transport = transport
        self.clock = transport.clock
        if use_sim_time:
            self.clock.use_sim_time(round(sim_start_s * _NS_PER_S))
        self._nodes: list[Node[Any]] = []
        self._started: set[int] = set()
        self._stop = False

    @property
    def nodes(self) -> list[Node[Any]]:
        return list(self._nodes)

    def add_node(self, node: Node[Any]) -> None:
        """Serve ``node``'s timers; its :meth:`Node.on_start` runs at the next spin."""
        if node.transport is not self.transport:
            raise TransportError(
                f"node {node.fully_qualified_name} uses another transport than this executor"
            )
        if node not in self._nodes:
            self._nodes.append(node)

    def remove_node(self, node: Node[Any]) -> None:
        if node in self._nodes:
            self._nodes.remove(node)

    def request_stop(self) -> None:
        """Make a running :meth:`spin` return after the current callback (callable from callbacks)."""
        self._stop = True

    def all_done(self) -> bool:
        """True when at least one node has a finite task and every such node reports done."""
        states = [s for s in (n.is_done() for n in self._nodes) if s is not None]
        return bool(states) and all(states)

    def _timers(self) -> list[Timer]:
        return [t for n in self._nodes if not n.destroyed for t in n.timers if not t.cancelled]

    def _run_ready(self) -> int:
        for node in self._nodes:
            if id(node) not in self._started:
                self._started.add(id(node))
                node.on_start()
        now = self.clock.now_ns()
        ran = 0
        timers = self._timers()
        for timer in timers:
            if timer.next_ns is None:
                timer.next_ns = now + timer.period_ns
        for timer in sorted((t for t in timers if t.next_ns is not None and t.next_ns <= now), key=_due):
            if not timer.cancelled:
                timer.fire(now)
                ran += 1
        for sub in self.transport.subscriptions():
            waiting = sub.pending()
            if waiting:
                ran += sub.dispatch(waiting)
        return ran

    def spin_once(self, timeout_s: float | None = 0.0) -> int:
        """Run the ready callbacks; if none, wait up to ``timeout_s`` [s] (``None``: until the next timer)
        for work and run it. In simulated time the wait advances the clock instead. Returns callbacks run."""
        return self._spin_once_ns(None if timeout_s is None else max(0, round(timeout_s * _NS_PER_S)))

    def _spin_once_ns(self, timeout_ns: int | None) -> int:
        ran = self._run_ready()
        if ran:
            return ran
        now = self.clock.now_ns()
        dues = [t.next_ns for t in self._timers() if t.next_ns is not None]
        limits = [*dues, *([] if timeout_ns is None else [now + timeout_ns])]
        target = min(limits) if limits else None
        if self.clock.simulated:
            if target is None or target <= now:
                return 0
            self.clock.advance_to(target)
        else:
            wait_s = 0.1 if target is None else (target - now) / _NS_PER_S
            self.transport.wait(wait_s)
        return self._run_ready()

    def spin(self, duration_s: float | None = None, until: Callable[[], bool] | None = None) -> None:
        """Run callbacks for ``duration_s`` [s] of clock time (``None``: until stopped), or until
        ``until()`` is true, :meth:`request_stop` is called, or (simulated time) nothing is left to do."""
        self._stop = False
        deadline = None if duration_s is None else self.clock.now_ns() + round(duration_s * _NS_PER_S)
        while not self._stop:
            if until is not None and until():
                return
            if deadline is None:
                if self._spin_once_ns(None) == 0 and self.clock.simulated:
                    return
                continue
            remaining = deadline - self.clock.now_ns()
            if self._spin_once_ns(max(0, remaining)) == 0 and remaining <= 0:
                return

    def shutdown(self, drain_rounds: int = 100) -> None:
        """Deliver queued messages (up to ``drain_rounds`` passes), then shut every node down."""
        for _ in range(drain_rounds):
            if self._run_ready() == 0:
                break
        for node in self._nodes:
            node.shutdown()
        self._nodes.clear()


def _due(timer: Timer) -> int:
    return timer.next_ns if timer.next_ns is not None else 0
