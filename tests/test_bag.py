"""rosbag2 MCAP recording (hsi_nodes.bag), checked against the independent mcap + mcap-ros2 readers."""

from __future__ import annotations

import math
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from test_msgs import sample_messages

from hsi_nodes import msgs
from hsi_nodes.bag import BagWriter, bag_paths, bag_topics, read_bag
from hsi_planning.errors import MessageError, TransportError


def _topic(typename: str) -> str:
    return "/" + typename.replace("/msg/", "/").lower()


def _assert_same(ours: Any, theirs: Any, where: str) -> None:
    """Field-by-field comparison of a rosbags message with an mcap_ros2-decoded one."""
    if hasattr(ours, "__msgtype__"):
        for name in msgs.message_fields(ours.__msgtype__):
            assert hasattr(theirs, name), f"{where}: mcap_ros2 message lacks field {name}"
            _assert_same(getattr(ours, name), getattr(theirs, name), f"{where}.{name}")
    elif isinstance(ours, np.ndarray):
        if ours.dtype == np.uint8:
            assert bytes(theirs) == ours.tobytes(), f"{where}: bytes differ"
        else:
            np.testing.assert_array_equal(np.asarray(theirs, dtype=ours.dtype), ours, err_msg=where)
    elif isinstance(ours, list):
        assert len(ours) == len(theirs), f"{where}: length {len(ours)} != {len(theirs)}"
        for i, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            _assert_same(a, b, f"{where}[{i}]")
    elif isinstance(ours, float) and math.isnan(ours):
        assert math.isnan(theirs), where
    else:
        assert ours == theirs, f"{where}: {ours!r} != {theirs!r}"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """A bag holding two messages of every sample type (second one raw bytes), one topic per type."""
    samples = sample_messages()
    out = tmp_path_factory.mktemp("bags") / "run.mcap"
    with BagWriter(out) as bag:
        bag.add_topic("/declared/but/empty", "std_msgs/msg/String")
        for i, (typename, msg) in enumerate(samples.items()):
            bag.write(_topic(typename), typename, msg, 1_000 + 10 * i)
        for i, (typename, msg) in enumerate(samples.items()):
            bag.write(_topic(typename), typename, msgs.serialize(msg), 5_000 + 10 * i)
        assert bag.message_count == 2 * len(samples)
    return out, samples


def test_path_layout(recorded: tuple[Path, dict[str, Any]]) -> None:
    out, samples = recorded
    bag_dir, mcap_file = bag_paths(out)
    assert bag_dir == out.with_suffix("") and mcap_file == bag_dir / "run.mcap"
    assert sorted(p.name for p in bag_dir.iterdir()) == ["metadata.yaml", "run.mcap"]
    meta = yaml.safe_load((bag_dir / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap" and meta["relative_file_paths"] == ["run.mcap"]
    assert meta["message_count"] == 2 * len(samples)
    assert bag_paths("x/run") == (Path("x/run"), Path("x/run/run.mcap"))


def test_independent_mcap_reader_sees_identical_content(recorded: tuple[Path, dict[str, Any]]) -> None:
    out, samples = recorded
    _, mcap_file = bag_paths(out)
    seen: dict[str, int] = {}
    with mcap_file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        header = reader.get_header()
        assert header.profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        topics = {ch.topic for ch in summary.channels.values()}
        assert "/declared/but/empty" in topics
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            typename = schema.name
            assert channel.topic == _topic(typename)
            assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
            assert schema.data.decode() == msgs.message_definition(typename)
            assert message.data == msgs.serialize(samples[typename])
            assert message.log_time in (
                1_000 + 10 * list(samples).index(typename),
                5_000 + 10 * list(samples).index(typename),
            )
            _assert_same(samples[typename], decoded, typename)
            seen[typename] = seen.get(typename, 0) + 1
    assert seen == dict.fromkeys(samples, 2)


def test_read_bag_round_trip_any_path_form(recorded: tuple[Path, dict[str, Any]]) -> None:
    out, samples = recorded
    bag_dir, mcap_file = bag_paths(out)
    for path in (out, bag_dir, mcap_file):
        got = list(read_bag(path))
        assert len(got) == 2 * len(samples)
        assert [m.t_ns for m in got] == sorted(m.t_ns for m in got)
        for m in got:
            assert m.topic == _topic(m.typename)
            assert msgs.messages_equal(m.msg, samples[m.typename]), m.typename
    only = list(read_bag(out, topics=["/hsi/schedule"], raw=True))
    assert [m.t_ns for m in only] == [
        1_000 + 10 * list(samples).index("hsi/msg/Schedule"),
        5_000 + 10 * list(samples).index("hsi/msg/Schedule"),
    ]
    assert all(m.msg == msgs.serialize(samples["hsi/msg/Schedule"]) for m in only)
    info = bag_topics(out)
    assert info["/hsi/schedule"] == ("hsi/msg/Schedule", 2)
    assert info["/declared/but/empty"] == ("std_msgs/msg/String", 0)


def test_compressed_bag_readable_by_mcap(tmp_path: Path) -> None:
    cloud = sample_messages()["sensor_msgs/msg/PointCloud2"]
    with BagWriter(tmp_path / "z.mcap", compress=True) as bag:
        for k in range(3):
            bag.write("/scene/points", "sensor_msgs/msg/PointCloud2", cloud, k)
    with (tmp_path / "z" / "z.mcap").open("rb") as f:
        decoded = [
            d for _, _, _, d in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
        ]
    assert len(decoded) == 3
    _assert_same(cloud, decoded[-1], "PointCloud2")
    assert len(list(read_bag(tmp_path / "z.mcap"))) == 3


def test_threaded_writes(tmp_path: Path) -> None:
    string = msgs.msg_class("std_msgs/msg/String")

    def worker(k: int, bag: BagWriter) -> None:
        for i in range(50):
            bag.write(f"/t{k}", "std_msgs/msg/String", string(data=f"{k}:{i}"), k * 1000 + i)

    with BagWriter(tmp_path / "threads") as bag:
        threads = [threading.Thread(target=worker, args=(k, bag)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    got = list(read_bag(tmp_path / "threads"))
    assert len(got) == 200
    assert {m.msg.data for m in got} == {f"{k}:{i}" for k in range(4) for i in range(50)}


def test_writer_errors(tmp_path: Path) -> None:
    string = msgs.msg_class("std_msgs/msg/String")
    unopened = BagWriter(tmp_path / "a.mcap")
    with pytest.raises(TransportError, match="not open"):
        unopened.write("/s", "std_msgs/msg/String", string(data="x"), 0)
    with BagWriter(tmp_path / "b.mcap") as bag:
        bag.write("/s", "std_msgs/msg/String", string(data="x"), 0)
        with pytest.raises(TransportError, match="recorded as std_msgs/msg/String"):
            bag.add_topic("/s", "geometry_msgs/msg/Point")
        with pytest.raises(TransportError, match="absolute"):
            bag.add_topic("relative", "std_msgs/msg/String")
        with pytest.raises(MessageError, match="unknown message type"):
            bag.add_topic("/x", "std_msgs/msg/Strin")
        with pytest.raises(MessageError, match="not the requested"):
            bag.write("/p", "geometry_msgs/msg/Point", string(data="x"), 1)
        with pytest.raises(TransportError, match=">= 0 ns"):
            bag.write("/s", "std_msgs/msg/String", string(data="x"), -1)
    with pytest.raises(TransportError, match="exists already"):
        BagWriter(tmp_path / "b.mcap")
    with pytest.raises(TransportError, match="no bag at"):
        list(read_bag(tmp_path / "missing.mcap"))
    assert [m.msg.data for m in read_bag(tmp_path / "b.mcap")] == ["x"]
