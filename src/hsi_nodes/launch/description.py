"""What a parsed launch file describes: declared arguments, their values, and the nodes to start."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hsi_planning.errors import LaunchError

__all__ = ["LaunchArg", "LaunchDescription", "NodeSpec", "parse_overrides"]

_ARG_NAME = re.compile(r"[A-Za-z_][\w\-]*")


@dataclass(frozen=True)
class NodeSpec:
    """One node to start: registry executable, identity, parameters and remappings."""

    #: Name in :data:`hsi_nodes.nodes.NODE_EXECUTABLES`.
    executable: str
    name: str
    #: ``'/'`` or ``'/a/b'``.
    namespace: str = "/"
    #: Parameter overrides of the node's config dataclass (nested mappings for nested configs).
    parameters: Mapping[str, Any] = field(default_factory=dict)
    #: ``(from, to)`` topic remappings in rule order.
    remappings: tuple[tuple[str, str], ...] = ()
    #: ``'screen'``, ``'log'`` or ``'both'`` (every node logs through ``logging`` in this process).
    output: str = "screen"
    #: Where it was declared, ``path:LINE`` (prefix of errors about this node).
    source: str = "<command line>"
    package: str = "hsi"

    @property
    def fully_qualified_name(self) -> str:
        """``'/ns/name'``."""
        return self.namespace.rstrip("/") + "/" + self.name


@dataclass(frozen=True)
class LaunchArg:
    """A declared launch argument (``default`` None = required)."""

    name: str
    default: str | None
    description: str
    #: ``path:LINE`` of the declaration.
    source: str


@dataclass(frozen=True)
class LaunchDescription:
    """A parsed launch file: declared arguments, final argument values, and the nodes in launch order."""

    path: Path
    args: tuple[LaunchArg, ...]
    values: Mapping[str, str]
    nodes: tuple[NodeSpec, ...]


def parse_overrides(items: Sequence[str]) -> dict[str, str]:
    """``['rate:=5', 'ns:=left']`` -> ``{'rate': '5', 'ns': 'left'}``.

    Raises:
        LaunchError: an item is not ``name:=value``.
    """
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition(":=")
        if not sep or not _ARG_NAME.fullmatch(name):
            raise LaunchError(f"launch argument {item!r} must look like name:=value")
        out[name] = value
    return out
