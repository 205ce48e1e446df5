"""Launch files: parsing (substitutions, includes, groups, params), running, recording, CLI, errors."""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any

import pytest

from hsi_nodes.bag import read_bag
from hsi_nodes.cli import launch as launch_cli
from hsi_nodes.cli import record as record_cli
from hsi_nodes.launch import (
    LaunchRunner,
    NodeSpec,
    declared_arguments,
    package_share,
    parse_launch_file,
    parse_overrides,
    run_launch,
)
from hsi_nodes.node import Node, NoParameters
from hsi_nodes.nodes import NODE_EXECUTABLES, load_executable
from hsi_planning.errors import LaunchError, TransportError

DATA = Path(__file__).parent / "data" / "launch"
DEMO = DATA / "heartbeat_relay.launch.yaml"


def _marked_line(path: Path) -> int:
    """1-based line of the line marked ``# error here`` in a bad fixture."""
    lines = path.read_text(encoding="utf-8").splitlines()
    marked = [i + 1 for i, line in enumerate(lines) if line.rstrip().endswith("# error here")]
    assert len(marked) == 1, path
    return marked[0]


def _cli(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="hsi")
    sub = parser.add_subparsers(dest="command")
    launch_cli.register(sub)
    record_cli.register(sub)
    return parser.parse_args(argv)


def test_parse_resolves_args_includes_groups_and_parameters(repo_root: Path) -> None:
    desc = parse_launch_file(DEMO, {"rate": "20"})
    assert [a.name for a in desc.args] == ["rate", "count", "with_echo"]
    assert desc.values["rate"] == "20" and desc.values["beat_topic"] == "/beat"
    assert [n.fully_qualified_name for n in desc.nodes] == ["/hb", "/relay/topic_relay", "/monitor/echo"]
    hb, relay, echo = desc.nodes
    # params.yaml ('/**' text, hb rate/count) first, then the listed values override, typed by YAML rules
    assert hb.parameters == {"text": "tick", "rate_hz": 20, "count": 4}
    assert hb.remappings == (("heartbeat", "/beat"),)
    assert hb.source == f"{DEMO.resolve()}:7"
    assert relay.parameters == {"output_topic": "out"} and relay.remappings == (("input", "/beat"),)
    assert relay.source.endswith("relay.launch.yaml:7")
    assert echo.parameters == {"topic": "/relay/out"}
    no_echo = parse_launch_file(DEMO, {"with_echo": "false"})
    assert [n.name for n in no_echo.nodes] == ["hb", "topic_relay"]
    assert package_share("hsi") == repo_root


def test_substitutions_env_find_pkg_share_and_typing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HSI_TEST_RATE", "12.5")
    monkeypatch.delenv("HSI_TEST_UNSET", raising=False)
    path = tmp_path / "s.launch.yaml"
    path.write_text(
        "launch:\n"
        "- arg: {name: n, default: 3}\n"
        "- let: {name: share, value: $(find-pkg-share hsi)}\n"
        "- node:\n"
        "    {pkg: hsi, exec: heartbeat, name: hb_$(var n), namespace: $(optenv HSI_TEST_UNSET ns1),\n"
        "     param: [{name: rate_hz, value: $(env HSI_TEST_RATE)}, {name: count, value: $(var n)},\n"
        "             {name: text, value: '$(var n) of $(env HSI_TEST_UNSET none)'}]}\n",
        encoding="utf-8",
    )
    desc = parse_launch_file(path)
    (node,) = desc.nodes
    assert node.fully_qualified_name == "/ns1/hb_3"
    assert node.parameters == {"rate_hz": 12.5, "count": 3, "text": "3 of none"}
    assert Path(desc.values["share"]) == package_share()
    path.write_text("launch:\n- let: {name: x, value: $(find-pkg-share rclcpp)}\n", encoding="utf-8")
    with pytest.raises(LaunchError, match=r":2: unknown package 'rclcpp'; only 'hsi'"):
        parse_launch_file(path)
    path.write_text("launch:\n- let: {name: x, value: $(env HSI_TEST_UNSET)}\n", encoding="utf-8")
    with pytest.raises(LaunchError, match=r":2: environment variable 'HSI_TEST_UNSET' is not set"):
        parse_launch_file(path)
    path.write_text("launch:\n- let: {name: x, value: $(anon y)}\n", encoding="utf-8")
    with pytest.raises(
        LaunchError, match=r":2: unsupported substitution \$\(anon y\); supported: \$\(var NAME\)"
    ):
        parse_launch_file(path)


@pytest.mark.parametrize(
    ("fixture", "pattern"),
    [
        ("bad_unknown_key.launch.yaml", r"unknown key 'exe' in node; valid: \['pkg', 'exec', 'name'"),
        ("bad_missing_include.launch.yaml", r"launch file .*no_such\.launch\.yaml not found"),
        ("bad_missing_param_file.launch.yaml", r"parameter file .*no_such_params\.yaml not found"),
        ("bad_undefined_arg.launch.yaml", r"undefined launch argument 'cuont'; defined: \['count', 'rate'\]"),
        ("bad_unknown_exec.launch.yaml", r"unknown executable 'no_such_node'; known: \[.*'heartbeat'.*\]"),
        ("bad_yaml.launch.yaml", r"invalid YAML: mapping values are not allowed here"),
    ],
)
def test_bad_launch_files_name_file_and_line(fixture: str, pattern: str) -> None:
    path = DATA / fixture
    with pytest.raises(LaunchError) as info:
        parse_launch_file(path)
    message = str(info.value)
    assert message.startswith(f"{path.resolve()}:{_marked_line(path)}: "), message
    assert re.search(pattern, message), message


def test_error_inside_an_included_file_names_that_file() -> None:
    child = DATA / "bad_unknown_key.launch.yaml"
    with pytest.raises(
        LaunchError, match=rf"^{re.escape(str(child.resolve()))}:{_marked_line(child)}: unknown key"
    ):
        parse_launch_file(DATA / "bad_include_child.launch.yaml")


def test_argument_errors(tmp_path: Path) -> None:
    with pytest.raises(
        LaunchError, match=r"argument\(s\) \['rat'\] not declared in heartbeat_relay\.launch\.yaml"
    ):
        parse_launch_file(DEMO, {"rat": "5"})
    with pytest.raises(LaunchError, match=r"relay\.launch\.yaml:2: launch argument 'input' is required"):
        parse_launch_file(DATA / "relay.launch.yaml")
    assert parse_overrides(["a:=1", "b_c:=x:=y", "d:="]) == {"a": "1", "b_c": "x:=y", "d": ""}
    with pytest.raises(LaunchError, match="name:=value"):
        parse_overrides(["rate=5"])
    path = tmp_path / "x.launch.yaml"
    for text, pattern in [
        ("nodes: []\n", r":1: unknown key 'nodes' in launch file; valid: \['launch'\]"),
        ("launch:\n- node: {pkg: rclpy, exec: talker}\n", r":2: unknown package 'rclpy'; valid: \['hsi'\]"),
        ("launch:\n- arg: {name: m, default: a, choices: [a, b]}\n", None),
        ("launch:\n- arg: {name: m, default: c, choices: [a, b]}\n", r":2: argument m='c' is not one of"),
        ("launch:\n- node: {pkg: hsi}\n", r":2: node lacks required key\(s\) \['exec'\]"),
        (
            "launch:\n- node: {pkg: hsi, exec: echo}\n- node: {pkg: hsi, exec: echo}\n",
            r":3: two nodes named /echo",
        ),
        ("launch:\n- node: {pkg: hsi, exec: echo, output: loud}\n", r":2: output 'loud' is not one of"),
        ("launch:\n- group: {if: maybe, children: []}\n", r":2: if: expected true/false"),
        ("", r":1: empty launch file"),
        (f"launch:\n- include: {{file: {path.name}}}\n", r"includes itself"),
    ]:
        path.write_text(text, encoding="utf-8")
        if pattern is None:
            assert parse_launch_file(path).values == {"m": "a"}
        else:
            with pytest.raises(LaunchError, match=pattern):
                parse_launch_file(path)


def test_run_records_a_bag_that_reads_back(tmp_path: Path) -> None:
    desc = parse_launch_file(DEMO, {"rate": "10", "count": "4"})
    out = tmp_path / "run.mcap"
    recorder = NodeSpec("recorder_node", "rec", "/", {"out": str(out)}, source="test")
    summary = run_launch(desc, use_sim_time=True, extra_nodes=(recorder,))
    assert summary.stop_reason == "done"
    assert summary.duration_s == pytest.approx(0.4)
    assert summary.message_counts == {"/beat": 4, "/relay/out": 4}
    assert summary.topics["/beat"] == "std_msgs/msg/String"
    assert summary.total_errors == 0 and summary.dropped == {}
    assert "/monitor/echo (echo)" in summary.nodes and "/beat" in summary.format()
    got = [(m.topic, m.msg.data, m.t_ns) for m in read_bag(out)]
    beats = [(t, d) for topic, d, t in got if topic == "/beat"]
    assert beats == [(k * 100_000_000, f"tick {k}") for k in range(1, 5)]  # 'text' from params.yaml
    assert sorted(d for topic, d, _ in got if topic == "/relay/out") == [f"tick {k}" for k in range(1, 5)]


def test_runner_reports_node_errors_with_the_launch_line(tmp_path: Path) -> None:
    bad = DATA / "bad_param_value.launch.yaml"
    runner = LaunchRunner(parse_launch_file(bad), use_sim_time=True)
    with pytest.raises(
        LaunchError, match=rf"{bad.name}:{_marked_line(bad)}: cannot start node /heartbeat: .*rate_hz"
    ):
        runner.start()
    with pytest.raises(TransportError, match="not available yet"):
        LaunchRunner(parse_launch_file(DEMO), transport="dds").start()
    with LaunchRunner(parse_launch_file(DEMO, {"count": "2"}), use_sim_time=True) as runner:
        assert runner.spin(duration_s=0.05) == "duration"
        assert runner.spin() == "done"
    summary = runner.shutdown()
    assert summary.message_counts["/beat"] == 2 and summary.stop_reason == "done"


def test_registry_is_lazy_and_checked() -> None:
    assert {"heartbeat", "echo", "topic_relay", "recorder_node"} <= set(NODE_EXECUTABLES)
    assert load_executable("topic_relay").__name__ == "TopicRelayNode"
    with pytest.raises(LaunchError, match=r"unknown executable 'nope'; known: \["):
        load_executable("nope")


def test_cli_launch_and_record(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = _cli(["launch", str(DEMO), "--sim-time", "count:=2"])  # override after an option
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "stopped: done" in out and re.search(r"/beat\s+std_msgs/msg/String\s+2", out)

    args = _cli(["launch", str(DEMO), "--show-args"])
    assert args.func(args) == 0
    assert "rate (default: '10.0')  heartbeat rate [Hz]" in capsys.readouterr().out

    bag = tmp_path / "rec.mcap"
    argv = ["record", "--out", str(bag), "--launch", str(DEMO), "--sim-time", "--topics", "/beat", "count:=3"]
    args = _cli(argv)
    assert args.func(args) == 0
    assert "bag: " in capsys.readouterr().out
    assert [m.msg.data for m in read_bag(bag)] == ["tick 1", "tick 2", "tick 3"]  # only /beat
    with pytest.raises(TransportError, match="exists already"):
        args.func(args)
    args = _cli(["launch", str(DEMO), "--duration", "-1"])
    with pytest.raises(LaunchError, match="--duration must be > 0"):
        args.func(args)


def test_declared_arguments_lists_top_level_args() -> None:
    args = declared_arguments(DATA / "relay.launch.yaml")
    assert [(a.name, a.default) for a in args] == [("input", None), ("ns", "relay")]
    assert args[0].description == "topic to relay" and args[0].source.endswith("relay.launch.yaml:2")


class _Interrupter(Node[NoParameters]):
    """Raises KeyboardInterrupt (what Ctrl-C does) from a timer after 0.25 s."""

    def __init__(self, name: str = "interrupter", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.create_timer(0.25, self._interrupt)

    def _interrupt(self) -> None:
        raise KeyboardInterrupt


def test_ctrl_c_shuts_down_cleanly_and_finishes_the_bag(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(NODE_EXECUTABLES, "interrupter", f"{__name__}:_Interrupter")  # one-line registration
    path = tmp_path / "i.launch.yaml"
    path.write_text(
        "launch:\n- node: {pkg: hsi, exec: heartbeat}\n- node: {pkg: hsi, exec: interrupter}\n",
        encoding="utf-8",
    )
    out = tmp_path / "i.mcap"
    recorder = NodeSpec("recorder_node", "rec", "/", {"out": str(out)})
    summary = run_launch(parse_launch_file(path), use_sim_time=True, extra_nodes=(recorder,))
    assert summary.stop_reason == "interrupted"
    assert summary.duration_s == pytest.approx(0.25)
    assert [m.msg.data for m in read_bag(out)] == ["heartbeat 1", "heartbeat 2"]


def test_unscoped_group_shares_arguments_and_namespaces_nest(tmp_path: Path) -> None:
    path = tmp_path / "g.launch.yaml"
    path.write_text(
        "launch:\n"
        "- group:\n"
        "    scoped: false\n"
        "    push-ros-namespace: outer\n"
        "    children:\n"
        "    - let: {name: leaked, value: yes_it_did}\n"
        "    - group:\n"
        "        push-ros-namespace: inner\n"
        "        children:\n"
        "        - node: {pkg: hsi, exec: echo, namespace: sub}\n"
        "        - node: {pkg: hsi, exec: echo, name: abs, namespace: /top}\n"
        "- group: {children: [{let: {name: hidden, value: x}}]}\n"
        "- node: {pkg: hsi, exec: echo, name: e2, unless: 'false',\n"
        "         param: [{name: topic, value: $(var leaked)}]}\n",
        encoding="utf-8",
    )
    desc = parse_launch_file(path)
    assert [n.fully_qualified_name for n in desc.nodes] == ["/outer/inner/sub/echo", "/top/abs", "/e2"]
    assert desc.values == {"leaked": "yes_it_did"}  # the scoped group's 'hidden' did not leak
    assert desc.nodes[2].parameters == {"topic": "yes_it_did"}


def test_wall_clock_run_stops_after_the_duration() -> None:
    desc = parse_launch_file(DEMO, {"rate": "50", "count": "1000"})
    summary = run_launch(desc, duration_s=0.2)
    assert summary.stop_reason == "duration"
    assert 0.19 < summary.wall_s < 1.5
    assert 5 <= summary.message_counts["/beat"] <= 11
    assert summary.message_counts["/relay/out"] == summary.message_counts["/beat"]  # drained at shutdown
