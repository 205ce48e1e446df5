"""Node base class and executor: names, parameters, timers, guarded callbacks, lifecycle."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from hsi_nodes.msgs import msg_class
from hsi_nodes.node import Executor, Node, Timer, resolve_topic_name
from hsi_nodes.nodes.talker_nodes import EchoNode, HeartbeatNode, TopicRelayNode
from hsi_nodes.transport.inproc import InprocTransport
from hsi_planning.errors import ConfigError, TransportError

STRING = "std_msgs/msg/String"
String = msg_class(STRING)


@dataclass(frozen=True)
class _GainConfig:
    #: Gain [-].
    gain: float = 1.0
    #: Topic [-].
    topic: str = "in"

    def __post_init__(self) -> None:
        if self.gain < 0:
            raise ConfigError(f"gain must be >= 0, got {self.gain}")


class _Fragile(Node[_GainConfig]):
    """Raises on messages whose data is 'bad'; records the others."""

    config_class = _GainConfig

    def __init__(self, name: str = "fragile", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.seen: list[str] = []
        self.events: list[str] = []
        self.create_subscription(self.config.topic, STRING, self._on_msg)

    def _on_msg(self, msg: Any) -> None:
        if msg.data == "bad":
            raise RuntimeError("cannot handle 'bad'")
        self.seen.append(msg.data)

    def on_start(self) -> None:
        self.events.append("start")

    def on_shutdown(self) -> None:
        self.events.append("shutdown")
        raise OSError("flush failed")


@pytest.mark.parametrize(
    ("name", "namespace", "remap", "expected"),
    [
        ("chatter", "/", {}, "/chatter"),
        ("chatter", "/robot/left", {}, "/robot/left/chatter"),
        ("/abs/topic", "/robot", {}, "/abs/topic"),
        ("~/state", "/robot", {}, "/robot/talker/state"),
        ("~", "/", {}, "/talker"),
        ("{node}/x", "/ns", {}, "/ns/talker/x"),
        ("chatter", "/ns", {"chatter": "/global"}, "/global"),
        ("chatter", "/ns", {"/ns/chatter": "renamed"}, "/ns/renamed"),
        ("~/state", "/ns", {"~/state": "~/status"}, "/ns/talker/status"),
        ("chatter", "/ns", {"other": "/x"}, "/ns/chatter"),
    ],
)
def test_topic_names_resolve_like_ros2(
    name: str, namespace: str, remap: dict[str, str], expected: str
) -> None:
    got = resolve_topic_name(name, node_name="talker", namespace=namespace, remappings=remap)
    assert got == expected


@pytest.mark.parametrize("bad", ["", "a//b", "1abc", "~x", "a/", "a b", "/a/-b"])
def test_invalid_topic_names_are_rejected(bad: str) -> None:
    with pytest.raises(TransportError, match="invalid topic name"):
        resolve_topic_name(bad, node_name="talker", namespace="/ns")


def test_node_identity_logger_and_name_errors() -> None:
    transport = InprocTransport()
    node = _Fragile("fragile", namespace="robot/left/", transport=transport)
    assert node.fully_qualified_name == "/robot/left/fragile"
    assert node.get_logger().name == "hsi.robot.left.fragile"
    assert transport.topics() == {"/robot/left/in": STRING}
    assert _Fragile("root", transport=transport).get_logger().name == "hsi.root"
    with pytest.raises(ConfigError, match="invalid node name"):
        _Fragile("bad-name", transport=transport)
    with pytest.raises(ConfigError, match="invalid namespace"):
        _Fragile("ok", namespace="/a/1b", transport=transport)
    with pytest.raises(TransportError, match="invalid topic name"):
        _Fragile("ok2", transport=transport, remappings={"in": "/x//y"})


def test_parameters_build_the_typed_config_and_bad_ones_name_the_node() -> None:
    transport = InprocTransport()
    node = _Fragile("f", namespace="/arm", transport=transport, parameters={"gain": 3})
    assert node.config == _GainConfig(gain=3.0)
    assert isinstance(node.config.gain, float)
    with pytest.raises(
        ConfigError, match=r"node /arm/g: unknown parameter\(s\) \['gian'\]; valid: \['gain', 'topic'\]"
    ):
        _Fragile("g", namespace="/arm", transport=transport, parameters={"gian": 2.0})
    with pytest.raises(ConfigError, match=r"node /arm/h\.gain: expected a number"):
        _Fragile("h", namespace="/arm", transport=transport, parameters={"gain": "high"})
    with pytest.raises(ConfigError, match="gain must be >= 0"):
        _Fragile("i", transport=transport, parameters={"gain": -1.0})


def test_parameter_file_merges_wildcard_plain_and_qualified_entries(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    path.write_text(
        "/**:\n  ros__parameters: {gain: 1.5, topic: all}\n"
        "fragile:\n  ros__parameters: {gain: 2.5}\n"
        "/arm/fragile:\n  ros__parameters: {topic: mine}\n"
        "other:\n  ros__parameters: {gain: 9.0}\n",
        encoding="utf-8",
    )
    assert Node.load_parameter_file(path, "fragile") == {"gain": 2.5, "topic": "all"}
    params = Node.load_parameter_file(path, "/arm/fragile")
    assert params == {"gain": 2.5, "topic": "mine"}
    node = _Fragile("fragile", namespace="/arm", transport=InprocTransport(), parameters=params)
    assert node.config == _GainConfig(gain=2.5, topic="mine")

    bad = tmp_path / "bad.yaml"
    bad.write_text("fragile:\n  ros__parameters:\n    gain: 2.0\n    gainn: 3.0\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"unknown parameter\(s\) \['gainn'\]"):
        _Fragile("fragile", transport=InprocTransport(), parameters=Node.load_parameter_file(bad, "fragile"))
    broken = tmp_path / "broken.yaml"
    broken.write_text("fragile:\n  ros__parameters:\n    gain: [1,\n  x: 2\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"broken\.yaml:\d+: invalid YAML"):
        Node.load_parameter_file(broken, "fragile")


def test_callback_exception_is_logged_counted_and_node_keeps_running(
    caplog: pytest.LogCaptureFixture,
) -> None:
    transport = InprocTransport()
    executor = Executor(transport, use_sim_time=True)
    node = _Fragile("fragile", transport=transport)
    executor.add_node(node)
    pub = transport.publisher("/in", STRING)
    with caplog.at_level(logging.ERROR, logger="hsi.fragile"):
        for text in ("a", "bad", "b", "bad", "c"):
            pub.publish(String(data=text))
        executor.spin_once()
    assert node.seen == ["a", "b", "c"]
    assert node.callback_errors == 2
    errors = [r for r in caplog.records if r.name == "hsi.fragile"]
    assert len(errors) == 2
    assert errors[0].exc_info is not None and "cannot handle 'bad'" in str(errors[0].exc_info[1])
    assert "subscription callback on /in" in errors[0].getMessage()

    ticks: list[int] = []

    def flaky_timer() -> None:
        ticks.append(len(ticks))
        if len(ticks) == 2:
            raise ValueError("tick 2 failed")

    node.create_timer(0.1, flaky_timer)
    executor.spin(0.5)
    assert ticks == [0, 1, 2, 3, 4]  # kept firing after the failure
    assert node.callback_errors == 3


def test_timers_fire_the_expected_number_of_times_in_sim_time() -> None:
    transport = InprocTransport()
    executor = Executor(transport, use_sim_time=True)
    node = _Fragile("clock", transport=transport)
    executor.add_node(node)
    calls: list[tuple[str, int]] = []
    fast = node.create_timer(0.1, lambda: calls.append(("fast", node.now_ns())))
    slow = node.create_timer(0.25, lambda: calls.append(("slow", node.now_ns())))
    t0 = time.monotonic()
    executor.spin(duration_s=10.0)
    assert time.monotonic() - t0 < 2.0  # 10 simulated seconds, no sleeping
    assert fast.count == 100 and slow.count == 40
    assert executor.clock.now_ns() == 10_000_000_000
    assert [t for name, t in calls if name == "slow"][:3] == [250_000_000, 500_000_000, 750_000_000]
    times = [t for _, t in calls]
    assert times == sorted(times)  # due order across timers
    assert node.events == ["start"]


def test_timer_skips_missed_periods() -> None:
    timer = Timer(10, lambda: None)
    timer.next_ns = 100
    timer.fire(135)
    assert timer.next_ns == 140 and timer.count == 1
    timer.fire(140)
    assert timer.next_ns == 150


def test_wall_clock_spin_runs_timers_for_the_duration() -> None:
    transport = InprocTransport()
    executor = Executor(transport)
    node = _Fragile("wall", transport=transport)
    executor.add_node(node)
    timer = node.create_timer(0.02, lambda: None)
    t0 = time.monotonic()
    executor.spin(0.2)
    elapsed = time.monotonic() - t0
    assert 0.19 < elapsed < 1.0
    assert 6 <= timer.count <= 10


def test_spin_stops_on_until_request_stop_and_idle() -> None:
    transport = InprocTransport()
    executor = Executor(transport, use_sim_time=True)
    beat = HeartbeatNode("hb", transport=transport, parameters={"rate_hz": 100.0, "count": 7})
    echo = EchoNode("echo", transport=transport)
    executor.add_node(beat)
    executor.add_node(echo)
    executor.spin(until=executor.all_done)
    assert beat.sent == 7 and beat.is_done() and echo.is_done() is None
    executor.spin()  # sim time, nothing periodic left (the heartbeat cancelled its timer): returns
    assert echo.received == 7 and echo.last.data == "heartbeat 7"
    stopper = _Fragile("stopper", transport=transport)
    executor.add_node(stopper)
    stopper.create_timer(1.0, executor.request_stop)
    t_before = executor.clock.now_ns()
    executor.spin()
    assert executor.clock.now_ns() - t_before == 1_000_000_000


def test_relay_republishes_the_same_object_and_rejects_loops() -> None:
    transport = InprocTransport()
    executor = Executor(transport, use_sim_time=True)
    relay = TopicRelayNode("relay", transport=transport, remappings={"input": "/a", "output": "/b"})
    executor.add_node(relay)
    got: list[Any] = []
    transport.subscribe("/b", STRING, got.append)
    msg = String(data="hello")
    transport.publisher("/a", STRING).publish(msg)
    executor.spin_once()
    executor.spin_once()
    assert got == [msg] and got[0] is msg and relay.relayed == 1
    with pytest.raises(ConfigError, match="same topic /x"):
        TopicRelayNode("loop", transport=transport, remappings={"input": "/x", "output": "/x"})


def test_shutdown_runs_hooks_counts_hook_errors_and_closes_endpoints() -> None:
    transport = InprocTransport()
    executor = Executor(transport, use_sim_time=True)
    first, second = _Fragile("first", transport=transport), _Fragile("second", transport=transport)
    for node in (first, second):
        executor.add_node(node)
    transport.publisher("/in", STRING).publish(String(data="late"))
    executor.shutdown()
    for node in (first, second):
        assert node.seen == ["late"]  # drained before shutdown
        assert node.events == ["start", "shutdown"]
        assert node.callback_errors == 1 and node.destroyed
    assert "/in" in transport.topics()  # only the test's publisher is left
    first.destroy()  # idempotent
    with pytest.raises(TransportError, match="another transport"):
        executor.add_node(_Fragile("x", transport=InprocTransport()))
    with pytest.raises(ConfigError, match="period"):
        first.create_timer(0.0, lambda: None)
