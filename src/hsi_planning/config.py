"""Typed configuration: dataclasses with defaults, overridden (never replaced) by YAML mappings.

Every component has one ``@dataclass(frozen=True)`` config whose fields carry a unit in their ``#:``
comment and whose ``__post_init__`` validates values. :func:`from_mapping` applies overrides from a
mapping (a parsed YAML document or the ``ros__parameters`` block of a ROS 2 parameter file) and rejects
unknown keys and wrongly typed values with a message that lists what is valid.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

from hsi_planning.errors import ConfigError

T = TypeVar("T")


def _coerce(value: Any, annotation: Any, where: str) -> Any:
    """Check ``value`` against a (resolved) type annotation; convert lists to tuples where declared."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if annotation is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        errors = []
        for arg in args:
            if arg is type(None) and value is None:
                return None
            try:
                return _coerce(value, arg, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(f"{where}: {value!r} matches none of {annotation}")
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where}: {value!r} is not one of {list(args)}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {type(value).__name__} {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}: {value!r}")
        return tuple(_coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True)))
    if origin in (list, dict) or annotation in (list, dict):
        base = origin or annotation
        if not isinstance(value, base):
            raise ConfigError(f"{where}: expected a {base.__name__}, got {type(value).__name__}")
        return value
    if dataclasses.is_dataclass(annotation) and isinstance(annotation, type):
        if isinstance(value, annotation):
            return value
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a mapping for {annotation.__name__}")
        return from_mapping(annotation, value, where=where)
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {type(value).__name__} {value!r}")
        return float(value)
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {type(value).__name__} {value!r}")
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {type(value).__name__} {value!r}")
        return value
    if annotation is Path:
        if not isinstance(value, (str, Path)):
            raise ConfigError(f"{where}: expected a path string, got {value!r}")
        return Path(value)
    return value


def from_mapping(cls: type[T], overrides: Mapping[str, Any] | None, where: str | None = None) -> T:
    """Build config ``cls`` from its defaults with ``overrides`` applied.

    Raises:
        ConfigError: unknown key (the message lists the valid ones), wrong type, or a value that the
            dataclass's ``__post_init__`` rejects.
    """
    if not (dataclasses.is_dataclass(cls) and isinstance(cls, type)):
        raise TypeError(f"{cls!r} is not a dataclass type")
    where = where or cls.__name__
    overrides = dict(overrides or {})
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(overrides) - set(fields))
    if unknown:
        raise ConfigError(f"{where}: unknown parameter(s) {unknown}; valid: {sorted(fields)}")
    kwargs = {k: _coerce(v, hints[k], f"{where}.{k}") for k, v in overrides.items()}
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from exc


def load_yaml(path: str | Path) -> Any:
    """Parse a YAML file; a syntax error becomes a :class:`ConfigError` naming file and line."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    try:
        with path.open(encoding="utf-8") as fh:
            return yaml.safe_load(fh)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        line = f":{mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}{line}: invalid YAML: {exc.problem}") from exc
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {exc}") from exc


def ros_parameters(document: Any, node_name: str, source: str = "<parameters>") -> dict[str, Any]:
    """Extract ``node_name``'s parameters from a ROS 2 parameter document.

    The document has the form ``{<node_name>: {ros__parameters: {...}}}``; the wildcard key ``/**``
    applies to every node and is overridden by the node's own entry. A missing node gives ``{}``.
    """
    if document is None:
        return {}
    if not isinstance(document, Mapping):
        raise ConfigError(f"{source}: a parameter file must map node names to {{ros__parameters: ...}}")
    params: dict[str, Any] = {}
    for key in ("/**", node_name, "/" + node_name.lstrip("/")):
        entry = document.get(key)
        if entry is None:
            continue
        if not isinstance(entry, Mapping) or "ros__parameters" not in entry:
            raise ConfigError(f"{source}: entry {key!r} must contain 'ros__parameters'")
        block = entry["ros__parameters"] or {}
        if not isinstance(block, Mapping):
            raise ConfigError(f"{source}: {key}.ros__parameters must be a mapping")
        params.update(block)
    return params
