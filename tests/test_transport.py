"""In-process transport: delivery, queues, latching, type checks, taps, threads."""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

from hsi_nodes.msgs import make_header, msg_class
from hsi_nodes.node import Executor
from hsi_nodes.transport import QoS, make_transport
from hsi_nodes.transport.inproc import InprocTransport
from hsi_planning.errors import ConfigError, MessageError, TransportError

STRING = "std_msgs/msg/String"
String = msg_class(STRING)


def _spin_all(transport: InprocTransport) -> int:
    """Dispatch everything queued (what an executor pass does)."""
    return sum(s.dispatch(s.pending()) for s in transport.subscriptions())


def test_delivery_is_zero_copy_and_waits_for_dispatch() -> None:
    transport = InprocTransport()
    got: list[Any] = []
    transport.subscribe("/chatter", STRING, got.append)
    pub = transport.publisher("/chatter", STRING)
    msgs = [String(data=f"m{i}") for i in range(3)]
    for m in msgs:
        pub.publish(m)
    assert got == []  # pull-based: nothing runs before an executor dispatches
    assert _spin_all(transport) == 3
    assert [id(m) for m in got] == [id(m) for m in msgs]  # the same objects: zero copy
    assert pub.count == 3
    assert transport.message_counts() == {"/chatter": 3}


def test_every_subscription_gets_every_message() -> None:
    transport = InprocTransport()
    a: list[str] = []
    b: list[str] = []
    transport.subscribe("/t", STRING, lambda m: a.append(m.data))
    transport.subscribe("/t", STRING, lambda m: b.append(m.data))
    transport.subscribe("/other", STRING, lambda m: a.append("wrong topic"))
    transport.publisher("/t", STRING).publish(String(data="x"))
    _spin_all(transport)
    assert a == ["x"] and b == ["x"]


def test_full_queue_drops_oldest_and_counts() -> None:
    transport = InprocTransport()
    got: list[str] = []
    sub = transport.subscribe("/q", STRING, lambda m: got.append(m.data), QoS(depth=3))
    pub = transport.publisher("/q", STRING)
    for i in range(7):
        pub.publish(String(data=str(i)))
    assert sub.pending() == 3
    _spin_all(transport)
    assert got == ["4", "5", "6"]
    assert sub.dropped == 4 and sub.delivered == 3


def test_latched_publisher_serves_late_latched_subscribers_only() -> None:
    transport = InprocTransport()
    pub = transport.publisher("/map", STRING, QoS(depth=2, latched=True))
    for name in ("a", "b", "c"):
        pub.publish(String(data=name))
    late: list[str] = []
    volatile: list[str] = []
    transport.subscribe("/map", STRING, lambda m: late.append(m.data), QoS(depth=5, latched=True))
    transport.subscribe("/map", STRING, lambda m: volatile.append(m.data))
    _spin_all(transport)
    assert late == ["b", "c"]  # last `depth` messages of the publisher
    assert volatile == []
    pub.publish(String(data="d"))
    _spin_all(transport)
    assert late == ["b", "c", "d"] and volatile == ["d"]
    pub.close()  # a closed publisher keeps nothing
    later: list[str] = []
    transport.subscribe("/map", STRING, lambda m: later.append(m.data), QoS(latched=True))
    _spin_all(transport)
    assert later == []


def test_latched_history_of_two_publishers_is_merged_in_publish_order() -> None:
    transport = InprocTransport()
    p1 = transport.publisher("/s", STRING, QoS(depth=3, latched=True))
    p2 = transport.publisher("/s", STRING, QoS(depth=3, latched=True))
    for i, pub in enumerate((p1, p2, p1, p2)):
        pub.publish(String(data=str(i)))
    got: list[str] = []
    transport.subscribe("/s", STRING, lambda m: got.append(m.data), QoS(depth=10, latched=True))
    _spin_all(transport)
    assert got == ["0", "1", "2", "3"]


def test_type_mismatch_and_bad_names_raise() -> None:
    transport = InprocTransport()
    transport.publisher("/x", STRING)
    with pytest.raises(TransportError, match=r"carries std_msgs/msg/String.*sensor_msgs/msg/JointState"):
        transport.subscribe("/x", "sensor_msgs/msg/JointState", print)
    with pytest.raises(TransportError, match="carries"):
        transport.publisher("/x", "std_msgs/msg/Header")
    pub = transport.publisher("/x", "std_msgs/String")  # short form normalizes to the same type
    assert pub.typename == STRING
    with pytest.raises(TransportError, match="sends std_msgs/msg/String, got a std_msgs/msg/Header"):
        pub.publish(make_header(0.0, "map"))
    with pytest.raises(TransportError, match="got a dict"):
        pub.publish({"data": "x"})
    with pytest.raises(MessageError, match="did you mean"):
        transport.publisher("/y", "std_msgs/msg/Strin")
    for bad in ("relative", "/a//b", "/a/", "/1a", "", "/a b"):
        with pytest.raises(TransportError, match="invalid topic name"):
            transport.publisher(bad, STRING)


def test_topics_follow_endpoints() -> None:
    transport = InprocTransport()
    pub = transport.publisher("/b", STRING)
    sub = transport.subscribe("/a", "sensor_msgs/msg/JointState", print)
    assert transport.topics() == {"/a": "sensor_msgs/msg/JointState", "/b": STRING}
    sub.close()
    pub.close()
    assert transport.topics() == {}
    transport.subscribe("/a", STRING, print)  # the name is free again: another type is fine
    assert transport.topics() == {"/a": STRING}


def test_tap_sees_all_or_selected_topics_with_publish_time() -> None:
    transport = make_transport("inproc")
    executor = Executor(transport, use_sim_time=True, sim_start_s=2.5)
    everything: list[tuple[str, str, str, int]] = []
    chosen: list[str] = []
    latched_pub = transport.publisher("/scene", STRING, QoS(latched=True))
    latched_pub.publish(String(data="kept"))
    transport.subscribe_all(lambda t, ty, m, ns: everything.append((t, ty, m.data, ns)), QoS(latched=True))
    transport.subscribe_all(lambda t, ty, m, ns: chosen.append(m.data), topics=["/b"])
    transport.publisher("/a", STRING).publish(String(data="1"))
    executor.clock.advance_to(3_000_000_000)
    transport.publisher("/b", STRING).publish(String(data="2"))
    assert executor.spin_once() == 3 + 1
    assert everything == [
        ("/scene", STRING, "kept", 2_500_000_000),
        ("/a", STRING, "1", 2_500_000_000),
        ("/b", STRING, "2", 3_000_000_000),
    ]
    assert chosen == ["2"]
    assert "*" not in transport.topics()


def test_closed_endpoints_and_transport_refuse_use() -> None:
    transport = InprocTransport()
    pub = transport.publisher("/c", STRING)
    got: list[str] = []
    sub = transport.subscribe("/c", STRING, lambda m: got.append(m.data))
    pub.publish(String(data="queued"))
    sub.close()
    assert _spin_all(transport) == 0 and got == []  # close drops queued messages
    transport.close()
    assert transport.closed
    with pytest.raises(TransportError, match="closed"):
        pub.publish(String(data="late"))
    with pytest.raises(TransportError, match="closed"):
        transport.publisher("/c", STRING)
    transport.close()  # idempotent


def test_publishing_from_a_thread_wakes_a_wall_clock_executor() -> None:
    transport = InprocTransport()
    executor = Executor(transport)
    got: list[str] = []
    transport.subscribe("/hw", STRING, lambda m: got.append(m.data))
    pub = transport.publisher("/hw", STRING)
    thread = threading.Timer(0.05, lambda: pub.publish(String(data="from thread")))
    t0 = time.monotonic()
    thread.start()
    ran = executor.spin_once(timeout_s=5.0)
    elapsed = time.monotonic() - t0
    thread.join()
    assert ran == 1 and got == ["from thread"]
    assert 0.03 < elapsed < 2.0  # woke on the publish, not at the 5 s timeout


def test_qos_and_transport_choice_validation() -> None:
    with pytest.raises(ConfigError, match="depth"):
        QoS(depth=0)
    with pytest.raises(ConfigError, match="latched"):
        QoS(latched="yes")  # type: ignore[arg-type]
    with pytest.raises(TransportError, match="not available yet"):
        make_transport("dds")
    with pytest.raises(TransportError, match=r"valid: \['inproc', 'dds'\]"):
        make_transport("zmq")
