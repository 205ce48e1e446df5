"""``recorder_node``: records every topic of the transport (or a chosen list) into a rosbag2 MCAP bag.

It taps the transport (:meth:`~hsi_nodes.transport.Transport.subscribe_all`), so it also records topics
that appear after it started, and, like ``ros2 bag record``, the messages latched publishers kept.
Each message is stamped with its publish time on the transport clock. The bag is opened when the
executor starts the node and finished at shutdown (see :class:`hsi_nodes.bag.BagWriter` for the layout).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hsi_nodes.bag import BagWriter
from hsi_nodes.node import Node
from hsi_nodes.transport.base import QoS
from hsi_planning.errors import ConfigError

__all__ = ["RecorderConfig", "RecorderNode"]


@dataclass(frozen=True)
class RecorderConfig:
    """Parameters of :class:`RecorderNode`."""

    #: Bag path, e.g. ``out/run.mcap`` (-> directory ``out/run/`` with ``run.mcap`` + metadata) [path].
    out: str = ""
    #: Topics to record; empty = every topic (relative names get the node namespace) [-].
    topics: tuple[str, ...] = ()
    #: Tap queue depth; messages beyond it between two executor passes are dropped [messages].
    queue_depth: int = 10000
    #: zstd-compress the MCAP chunks [bool].
    compress: bool = False

    def __post_init__(self) -> None:
        if not self.out:
            raise ConfigError("RecorderConfig.out: set the bag path, e.g. out:=run.mcap")
        if self.queue_depth < 1:
            raise ConfigError(f"RecorderConfig.queue_depth must be >= 1 [messages], got {self.queue_depth}")


class RecorderNode(Node[RecorderConfig]):
    """Writes the transport's traffic to an MCAP bag; :attr:`counts` has messages per topic."""

    config_class = RecorderConfig

    def __init__(self, name: str = "recorder", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.writer = BagWriter(self.config.out, compress=self.config.compress)
        topics = [self.resolve(t) for t in self.config.topics] or None
        #: Messages written per topic [messages].
        self.counts: dict[str, int] = {}
        self._tap = self.transport.subscribe_all(
            self._record, QoS(depth=self.config.queue_depth, latched=True), topics
        )
        self._subscriptions.append(self._tap)

    @property
    def dropped(self) -> int:
        """Messages lost because the tap queue overflowed [messages]."""
        return self._tap.dropped

    def on_start(self) -> None:
        self.writer.open()

    def _record(self, topic: str, typename: str, msg: Any, t_ns: int) -> None:
        self.writer.write(topic, typename, msg, t_ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def on_shutdown(self) -> None:
        self.writer.close()
        if self.dropped:
            self.get_logger().warning("dropped %d messages (raise queue_depth)", self.dropped)
        self.get_logger().info(
            "recorded %d messages on %d topics to %s",
            sum(self.counts.values()),
            len(self.counts),
            self.writer.mcap_path,
        )
