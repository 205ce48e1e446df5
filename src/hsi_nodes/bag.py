"""Recording and reading rosbag2 MCAP bags (``rosbags`` writer/reader, CDR messages).

Path layout. ``ros2 bag play`` wants a bag *directory* holding ``metadata.yaml`` and the storage file, and
``rosbags`` names that file after the directory. A requested path therefore maps to:

- ``out/run.mcap`` → the bag directory ``out/run/`` containing ``out/run/run.mcap`` + ``metadata.yaml``;
- ``out/run`` (no ``.mcap`` suffix) → the same directory.

The ``.mcap`` file inside is a self-contained MCAP (profile ``ros2``, ``ros2msg`` schemas with all
dependent definitions, ``cdr`` message encoding), readable on its own by Foxglove, the ``mcap`` CLI and
``mcap-ros2-support``; the directory is what ``ros2 bag info/play`` take. :func:`read_bag` accepts the
requested path, the directory or the ``.mcap`` file.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Collection, Iterator
from pathlib import Path
from types import TracebackType
from typing import Any, NamedTuple, Self

from rosbags.interfaces import Connection
from rosbags.rosbag2 import (
    CompressionFormat,
    CompressionMode,
    Reader,
    ReaderError,
    StoragePlugin,
    Writer,
    WriterError,
)

from hsi_nodes.msgs import (
    deserialize,
    message_definition,
    msg_class,
    normalize_typename,
    serialize,
    type_hash,
)
from hsi_planning.errors import TransportError

__all__ = ["BagMessage", "BagWriter", "bag_paths", "bag_topics", "read_bag"]

_log = logging.getLogger(__name__)

_MCAP = ".mcap"


def bag_paths(path: str | Path) -> tuple[Path, Path]:
    """``(bag directory, .mcap file)`` that a requested bag ``path`` maps to (see the module docstring)."""
    p = Path(path)
    if p.suffix == _MCAP:
        bag_dir = p.with_suffix("")
        return bag_dir, bag_dir / p.name
    return p, p / f"{p.name}{_MCAP}"


class BagWriter:
    """Write a rosbag2 MCAP bag; use as a context manager (the bag is complete once closed).

    ``write`` is thread-safe, so transport callbacks may record from several threads.

    Args:
        path: requested bag path (``F.mcap`` → directory ``F/`` with ``F/F.mcap``, see module docstring).
        compress: zstd-compress the MCAP chunks (readable by ros2 bag, Foxglove and the mcap readers).

    Raises:
        TransportError: the bag directory exists already (bags are never overwritten).
    """

    def __init__(self, path: str | Path, *, compress: bool = False) -> None:
        self.bag_dir, self.mcap_path = bag_paths(path)
        if self.bag_dir.exists():
            raise TransportError(
                f"bag directory {self.bag_dir} exists already; choose a new path or delete it"
            )
        self._writer = Writer(self.bag_dir, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
        if compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._connections: dict[str, tuple[str, Connection]] = {}
        self._lock = threading.Lock()
        self._open = False
        self._closed = False
        self.message_count = 0

    def open(self) -> None:
        """Create the bag directory and start the MCAP file (done by ``__enter__``)."""
        with self._lock:
            if self._open or self._closed:
                raise TransportError(f"bag {self.bag_dir} was already opened")
            try:
                self.bag_dir.parent.mkdir(parents=True, exist_ok=True)
                self._writer.open()
            except (WriterError, OSError) as exc:
                raise TransportError(f"cannot create bag {self.bag_dir}: {exc}") from exc
            self._open = True
        _log.info("recording to %s", self.mcap_path)

    def close(self) -> None:
        """Finish the MCAP file and write ``metadata.yaml`` (idempotent)."""
        with self._lock:
            if not self._open:
                return
            self._open = False
            self._closed = True
            try:
                self._writer.close()
            except (WriterError, OSError) as exc:
                raise TransportError(f"cannot finish bag {self.bag_dir}: {exc}") from exc
        _log.info(
            "wrote %d messages on %d topics to %s", self.message_count, len(self._connections), self.mcap_path
        )

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    @property
    def topics(self) -> dict[str, str]:
        """``topic -> typename`` of every topic added so far."""
        return {topic: typename for topic, (typename, _) in self._connections.items()}

    def add_topic(self, topic: str, typename: str) -> None:
        """Declare ``topic`` with message type ``typename`` (repeating the same pair is a no-op).

        Raises:
            TransportError: bag not open, or ``topic`` was added with another type.
            MessageError: unknown ``typename``.
        """
        with self._lock:
            self._add_topic_locked(topic, typename)

    def _add_topic_locked(self, topic: str, typename: str) -> Connection:
        name = normalize_typename(typename)
        if not self._open:
            raise TransportError(f"bag {self.bag_dir} is not open; use 'with BagWriter(path) as bag:'")
        if not topic.startswith("/"):
            raise TransportError(f"topic {topic!r} must be absolute (start with '/')")
        have = self._connections.get(topic)
        if have is not None:
            if have[0] != name:
                raise TransportError(f"topic {topic} is recorded as {have[0]}, cannot also record {name}")
            return have[1]
        msg_class(name)
        conn = self._writer.add_connection(
            topic, name, msgdef=message_definition(name), rihs01=type_hash(name)
        )
        self._connections[topic] = (name, conn)
        return conn

    def write(self, topic: str, typename: str, msg: object, t_ns: int) -> None:
        """Record ``msg`` (a message or its CDR bytes) on ``topic`` at receive time ``t_ns`` [ns].

        The topic is added on first use.

        Raises:
            TransportError: bag not open, topic type clash, or negative ``t_ns``.
            MessageError: ``msg`` is not a ``typename`` message.
        """
        if t_ns < 0:
            raise TransportError(f"bag timestamps must be >= 0 ns, got {t_ns}")
        data = bytes(msg) if isinstance(msg, bytes | bytearray | memoryview) else serialize(msg, typename)
        with self._lock:
            conn = self._add_topic_locked(topic, typename)
            try:
                self._writer.write(conn, int(t_ns), data)
            except (WriterError, OSError) as exc:
                raise TransportError(f"cannot write to bag {self.bag_dir}: {exc}") from exc
            self.message_count += 1


class BagMessage(NamedTuple):
    """One recorded message: ``msg`` is the decoded message, or CDR bytes when read with ``raw=True``."""

    topic: str
    typename: str
    t_ns: int  #: [ns] receive (log) time
    msg: Any


def _reader_path(path: str | Path) -> Path:
    p = Path(path)
    if p.exists():
        return p
    bag_dir, mcap_file = bag_paths(p)
    for cand in (bag_dir, mcap_file):
        if cand.exists():
            return cand
    raise TransportError(f"no bag at {p} (also looked for {bag_dir}/ and {mcap_file})")


def read_bag(
    path: str | Path, *, topics: Collection[str] | None = None, raw: bool = False
) -> Iterator[BagMessage]:
    """Messages of a rosbag2 bag (directory or ``.mcap``/``.db3`` file), in time order.

    Args:
        path: the path given to :class:`BagWriter`, the bag directory, or a storage file.
        topics: only these topics (None = all).
        raw: yield CDR bytes instead of decoded messages (no type store lookup).

    Raises:
        TransportError: no bag at ``path`` or it cannot be read.
        MessageError: a message type is unknown to the type store (use ``raw=True`` to read it anyway).
    """
    rpath = _reader_path(path)
    try:
        with Reader(rpath) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            if not conns:
                return
            for conn, t_ns, data in reader.messages(connections=conns):
                msg = bytes(data) if raw else deserialize(data, conn.msgtype)
                yield BagMessage(conn.topic, conn.msgtype, int(t_ns), msg)
    except (ReaderError, OSError) as exc:
        raise TransportError(f"cannot read bag {rpath}: {exc}") from exc


def bag_topics(path: str | Path) -> dict[str, tuple[str, int]]:
    """``topic -> (typename, message count)`` of a bag (see :func:`read_bag` for ``path``)."""
    rpath = _reader_path(path)
    out: dict[str, tuple[str, int]] = {}
    try:
        with Reader(rpath) as reader:
            for c in reader.connections:
                typename, count = out.get(c.topic, (c.msgtype, 0))
                out[c.topic] = (typename, count + int(c.msgcount))
    except (ReaderError, OSError) as exc:
        raise TransportError(f"cannot read bag {rpath}: {exc}") from exc
    return out
