"""Typed config: defaults overridden by mappings, unknown keys and bad types rejected with clear errors."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import pytest

from hsi_planning.config import from_mapping, load_yaml, ros_parameters
from hsi_planning.errors import ConfigError


@dataclass(frozen=True)
class _Inner:
    gain: float = 1.0  #: [1] gain


@dataclass(frozen=True)
class _Cfg:
    rate: float = 10.0  #: [Hz] rate
    count: int = 3  #: [1] count
    name: str = "a"  #: name
    mode: Literal["fast", "slow"] = "fast"  #: mode
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: [m] a point
    many: tuple[str, ...] = ()  #: names
    inner: _Inner = _Inner()  #: nested
    maybe: float | None = None  #: [s] optional

    def __post_init__(self) -> None:
        if self.rate <= 0:
            raise ConfigError(f"rate must be > 0 Hz, got {self.rate}")


def test_defaults_and_overrides() -> None:
    cfg = from_mapping(_Cfg, {"rate": 5, "xyz": [1, 2, 3], "many": ["x", "y"], "inner": {"gain": 2}})
    assert cfg.rate == 5.0 and isinstance(cfg.rate, float)
    assert cfg.xyz == (1.0, 2.0, 3.0)
    assert cfg.many == ("x", "y")
    assert cfg.inner.gain == 2.0
    assert cfg.count == 3 and cfg.maybe is None
    assert from_mapping(_Cfg, {"maybe": 0.5}).maybe == 0.5


@pytest.mark.parametrize(
    ("overrides", "fragment"),
    [
        ({"bogus": 1}, "valid:"),
        ({"rate": "fast"}, "expected a number"),
        ({"count": 1.5}, "expected an integer"),
        ({"count": True}, "expected an integer"),
        ({"mode": "medium"}, "not one of"),
        ({"xyz": [1, 2]}, "expected 3 values"),
        ({"rate": -1.0}, "rate must be > 0"),
        ({"inner": {"gian": 1.0}}, "unknown parameter"),
    ],
)
def test_bad_values_are_rejected(overrides: dict[str, object], fragment: str) -> None:
    with pytest.raises(ConfigError, match=fragment):
        from_mapping(_Cfg, overrides)


def test_load_yaml_names_file_and_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: 1\nb: [1, 2\nc: 3\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml:\d+"):
        load_yaml(bad)
    with pytest.raises(ConfigError, match="no such file"):
        load_yaml(tmp_path / "missing.yaml")


def test_ros_parameters_merge_wildcard_and_node() -> None:
    doc = {"/**": {"ros__parameters": {"rate": 1.0, "count": 2}}, "n": {"ros__parameters": {"rate": 3.0}}}
    assert ros_parameters(doc, "n") == {"rate": 3.0, "count": 2}
    assert ros_parameters(doc, "other") == {"rate": 1.0, "count": 2}
    with pytest.raises(ConfigError, match="ros__parameters"):
        ros_parameters({"n": {"rate": 1}}, "n")
