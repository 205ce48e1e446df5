"""Parser of ROS 2 YAML launch files (``*.launch.yaml``) into a flat list of node specs.

Supported schema (a subset of ROS 2's ``launch_yaml``)::

    launch:
    - arg: {name: rate, default: "10.0", description: "beats per second", choices: [...]}
    - let: {name: ns, value: "robot"}
    - node: {pkg: hsi, exec: heartbeat, name: hb, namespace: "$(var ns)", output: screen,
             param: [{name: rate_hz, value: "$(var rate)"}, {from: "$(find-pkg-share hsi)/config/x.yaml"}],
             remap: [{from: heartbeat, to: /beat}], if: "true"}
    - include: {file: "$(dirname)/other.launch.yaml", arg: [{name: rate, value: "5"}]}
    - group: {scoped: true, push-ros-namespace: left, children: [...]}

Substitutions (:mod:`~hsi_nodes.launch.substitutions`) work in any string. A parameter value that
contains a substitution is typed after substitution by YAML rules (``"$(var rate)"`` -> ``10.0``), as
``launch_ros`` does. Relative ``from:`` and ``include`` paths are relative to the launch file's directory.

Every error is a :class:`LaunchError` whose message starts with ``path:LINE:``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from hsi_nodes.launch.description import LaunchArg, LaunchDescription, NodeSpec
from hsi_nodes.launch.substitutions import PACKAGE, substitute
from hsi_nodes.node import Node, normalize_namespace
from hsi_nodes.nodes import NODE_EXECUTABLES
from hsi_planning.errors import ConfigError, LaunchError

__all__ = ["declared_arguments", "parse_launch_file"]

_ENTRIES = ("arg", "let", "node", "include", "group")
_OUTPUTS = ("screen", "log", "both")


def parse_launch_file(path: str | Path, overrides: Mapping[str, str] | None = None) -> LaunchDescription:
    """Parse ``path`` with command-line argument ``overrides`` (``{name: value}``).

    Raises:
        LaunchError: ``path:LINE: ...`` for invalid YAML, unknown keys (valid ones listed), undefined
            arguments (defined ones listed), missing files, unknown packages/executables, bad values;
            an override of an argument the file does not declare.
    """
    parser = _Parser()
    scope = _Scope(values={}, namespace="/")
    args = parser.parse_file(Path(path), scope, dict(overrides or {}), at=None)
    return LaunchDescription(Path(path), tuple(args), dict(scope.values), tuple(parser.nodes))


def declared_arguments(path: str | Path) -> list[LaunchArg]:
    """The top-level ``arg`` entries of a launch file, defaults unsubstituted (for ``--show-args``).

    Raises:
        LaunchError: missing file or invalid YAML/schema (``path:LINE``).
    """
    parser = _Parser()
    root = parser.compose(Path(path), at=None)
    top = parser._fields(root, ("launch",), ("launch",), "launch file")
    out: list[LaunchArg] = []
    for item in parser._seq(top["launch"][1], "'launch'"):
        entry = parser._fields(item, _ENTRIES, (), "launch entry")
        if "arg" in entry:
            parser._line = item.start_mark.line + 1
            f = parser._fields(
                entry["arg"][1], ("name", "default", "description", "choices"), ("name",), "arg"
            )
            raw = {k: _scalar_text(parser._raw(v)) for k, (_, v) in f.items() if k != "choices"}
            out.append(
                LaunchArg(raw["name"], raw.get("default"), raw.get("description", ""), parser._where())
            )
    return out


@dataclass
class _Scope:
    values: dict[str, str]
    namespace: str


def _scalar_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return "" if value is None else str(value)


class _Parser:
    def __init__(self) -> None:
        self.nodes: list[NodeSpec] = []
        self._stack: list[Path] = []
        self._constructor = yaml.SafeLoader("")
        self._file = Path("<launch>")
        self._line = 1

    # ------------------------------------------------------------------------------------- files

    def compose(self, path: Path, at: str | None) -> yaml.Node:
        """The YAML node tree of ``path`` (sets the current file); ``at`` is the including entry."""
        if not path.is_file():
            raise LaunchError(f"{at or path}: launch file {path} not found")
        path = path.resolve()
        if path in self._stack:
            raise LaunchError(f"{at}: {path} includes itself (include cycle)")
        try:
            root = yaml.compose(path.read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            line = mark.line + 1 if mark is not None else 1
            raise LaunchError(f"{path}:{line}: invalid YAML: {exc.problem or exc.context}") from None
        except (yaml.YAMLError, OSError, UnicodeDecodeError) as exc:
            raise LaunchError(f"{path}:1: cannot read launch file: {exc}") from None
        self._file = path
        if root is None:
            raise self._err(1, "empty launch file; expected a top-level 'launch:' list")
        return root

    def parse_file(self, path: Path, scope: _Scope, given: dict[str, str], at: str | None) -> list[LaunchArg]:
        root = self.compose(path, at)
        path = self._file
        self._stack.append(path)
        try:
            top = self._fields(root, ("launch",), ("launch",), "launch file")
            args: list[LaunchArg] = []
            self._entries(top["launch"][1], scope, given, args)
            unknown = sorted(set(given) - {a.name for a in args})
            if unknown:
                declared = [a.name for a in args]
                msg = f"argument(s) {unknown} not declared in {path.name}; declared: {declared}"
                raise LaunchError(f"{at}: {msg}" if at else f"{path}:{root.start_mark.line + 1}: {msg}")
            return args
        finally:
            self._stack.pop()
            if self._stack:
                self._file = self._stack[-1]

    # ----------------------------------------------------------------------------------- helpers

    def _err(self, line: int, msg: str) -> LaunchError:
        return LaunchError(f"{self._file}:{line}: {msg}")

    def _where(self) -> str:
        """``path:LINE`` of the launch entry being parsed."""
        return f"{self._file}:{self._line}"

    def _fields(
        self,
        node: yaml.Node,
        valid: Sequence[str],
        required: Sequence[str],
        what: str,
        line: int | None = None,
    ) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        if not isinstance(node, yaml.MappingNode):
            raise self._err(node.start_mark.line + 1, f"{what} must be a mapping with keys {list(valid)}")
        out: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for key, value in node.value:
            name = key.value if isinstance(key, yaml.ScalarNode) else repr(key)
            if name not in valid:
                raise self._err(
                    key.start_mark.line + 1, f"unknown key {name!r} in {what}; valid: {list(valid)}"
                )
            if name in out:
                raise self._err(key.start_mark.line + 1, f"duplicate key {name!r} in {what}")
            out[name] = (key, value)
        missing = [k for k in required if k not in out]
        if missing:
            raise self._err(line or node.start_mark.line + 1, f"{what} lacks required key(s) {missing}")
        return out

    def _seq(self, node: yaml.Node, what: str) -> list[yaml.Node]:
        if not isinstance(node, yaml.SequenceNode):
            raise self._err(node.start_mark.line + 1, f"{what} must be a list")
        return list(node.value)

    def _raw(self, node: yaml.Node) -> Any:
        return self._constructor.construct_object(node, deep=True)

    def _subst(self, text: str, node: yaml.Node, scope: _Scope) -> str:
        try:
            return substitute(text, scope.values, self._file)
        except LaunchError as exc:
            raise self._err(node.start_mark.line + 1, str(exc)) from None

    def _str(self, node: yaml.Node, scope: _Scope, what: str) -> str:
        if not isinstance(node, yaml.ScalarNode):
            raise self._err(node.start_mark.line + 1, f"{what} must be a string")
        return self._subst(_scalar_text(self._raw(node)), node, scope)

    def _typed(self, node: yaml.Node, scope: _Scope) -> Any:
        """A parameter value: YAML-typed; strings with substitutions are re-typed after substitution."""
        if isinstance(node, yaml.SequenceNode):
            return [self._typed(v, scope) for v in node.value]
        if isinstance(node, yaml.MappingNode):
            return {self._str(k, scope, "key"): self._typed(v, scope) for k, v in node.value}
        value = self._raw(node)
        if not isinstance(value, str) or "$(" not in value:
            return value
        text = self._subst(value, node, scope)
        try:
            return yaml.safe_load(text) if text.strip() else text
        except yaml.YAMLError:
            return text

    def _condition(self, f: dict[str, tuple[yaml.Node, yaml.Node]], scope: _Scope) -> bool:
        for key, want in (("if", True), ("unless", False)):
            if key in f:
                text = self._str(f[key][1], scope, key).strip().lower()
                if text not in ("true", "false", "1", "0"):
                    raise self._err(
                        f[key][1].start_mark.line + 1, f"{key}: expected true/false/1/0, got {text!r}"
                    )
                if (text in ("true", "1")) != want:
                    return False
        return True

    # ----------------------------------------------------------------------------------- entries

    def _entries(self, seq: yaml.Node, scope: _Scope, given: dict[str, str], args: list[LaunchArg]) -> None:
        for item in self._seq(seq, "'launch'/'children'"):
            entry = self._fields(item, _ENTRIES, (), "launch entry")
            if len(entry) != 1:
                raise self._err(
                    item.start_mark.line + 1, f"a launch entry has exactly one of {list(_ENTRIES)}"
                )
            kind, (_, body) = next(iter(entry.items()))
            self._line = item.start_mark.line + 1
            getattr(self, f"_entry_{kind}")(body, scope, given, args)

    def _entry_arg(
        self, body: yaml.Node, scope: _Scope, given: dict[str, str], args: list[LaunchArg]
    ) -> None:
        f = self._fields(body, ("name", "default", "description", "choices"), ("name",), "arg", self._line)
        name = self._str(f["name"][1], scope, "arg name")
        default = self._str(f["default"][1], scope, "arg default") if "default" in f else None
        description = _scalar_text(self._raw(f["description"][1])) if "description" in f else ""
        args.append(LaunchArg(name, default, description, self._where()))
        value = given.get(name, scope.values.get(name, default))
        if value is None:
            raise self._err(self._line, f"launch argument {name!r} is required: pass {name}:=VALUE")
        if "choices" in f:
            choices = [_scalar_text(c) for c in self._raw(f["choices"][1]) or []]
            if value not in choices:
                raise self._err(self._line, f"argument {name}={value!r} is not one of {choices}")
        scope.values[name] = value

    def _entry_let(
        self, body: yaml.Node, scope: _Scope, given: dict[str, str], args: list[LaunchArg]
    ) -> None:
        f = self._fields(body, ("name", "value"), ("name", "value"), "let", self._line)
        scope.values[self._str(f["name"][1], scope, "let name")] = self._str(
            f["value"][1], scope, "let value"
        )

    def _entry_group(
        self, body: yaml.Node, scope: _Scope, given: dict[str, str], args: list[LaunchArg]
    ) -> None:
        keys = ("scoped", "push-ros-namespace", "children", "if", "unless")
        f = self._fields(body, keys, ("children",), "group", self._line)
        if not self._condition(f, scope):
            return
        scoped = self._raw(f["scoped"][1]) if "scoped" in f else True
        if not isinstance(scoped, bool):
            raise self._err(f["scoped"][1].start_mark.line + 1, "group.scoped must be true or false")
        inner = _Scope(dict(scope.values) if scoped else scope.values, scope.namespace)
        if "push-ros-namespace" in f:
            inner.namespace = self._namespace(f["push-ros-namespace"][1], scope, scope.namespace)
        self._entries(f["children"][1], inner, given, args)

    def _entry_include(
        self, body: yaml.Node, scope: _Scope, given: dict[str, str], args: list[LaunchArg]
    ) -> None:
        f = self._fields(body, ("file", "arg", "if", "unless"), ("file",), "include", self._line)
        where = self._where()
        if not self._condition(f, scope):
            return
        target = Path(self._str(f["file"][1], scope, "include file"))
        target = target if target.is_absolute() else self._file.parent / target
        inc_args: dict[str, str] = {}
        for item in self._seq(f["arg"][1], "include.arg") if "arg" in f else []:
            a = self._fields(item, ("name", "value"), ("name", "value"), "include arg")
            inc_args[self._str(a["name"][1], scope, "arg name")] = self._str(
                a["value"][1], scope, "arg value"
            )
        self.parse_file(target, _Scope(dict(scope.values), scope.namespace), inc_args, at=where)

    def _namespace(self, node: yaml.Node, scope: _Scope, base: str) -> str:
        text = self._str(node, scope, "namespace").strip()
        full = text if text.startswith("/") else base.rstrip("/") + "/" + text
        try:
            return normalize_namespace(full)
        except ConfigError as exc:
            raise self._err(node.start_mark.line + 1, str(exc)) from None

    def _entry_node(
        self, body: yaml.Node, scope: _Scope, given: dict[str, str], args: list[LaunchArg]
    ) -> None:
        keys = ("pkg", "exec", "name", "namespace", "param", "remap", "output", "if", "unless")
        f = self._fields(body, keys, ("pkg", "exec"), "node", self._line)
        where = self._where()
        if not self._condition(f, scope):
            return
        pkg = self._str(f["pkg"][1], scope, "pkg")
        if pkg != PACKAGE:
            raise self._err(f["pkg"][1].start_mark.line + 1, f"unknown package {pkg!r}; valid: [{PACKAGE!r}]")
        exe = self._str(f["exec"][1], scope, "exec")
        if exe not in NODE_EXECUTABLES:
            raise self._err(
                f["exec"][1].start_mark.line + 1,
                f"unknown executable {exe!r}; known: {sorted(NODE_EXECUTABLES)}",
            )
        name = self._str(f["name"][1], scope, "name") if "name" in f else exe
        ns = (
            self._namespace(f["namespace"][1], scope, scope.namespace)
            if "namespace" in f
            else scope.namespace
        )
        output = self._str(f["output"][1], scope, "output") if "output" in f else "screen"
        if output not in _OUTPUTS:
            raise self._err(
                f["output"][1].start_mark.line + 1, f"output {output!r} is not one of {list(_OUTPUTS)}"
            )
        fqn = ns.rstrip("/") + "/" + name
        params: dict[str, Any] = {}
        for item in self._seq(f["param"][1], "node.param") if "param" in f else []:
            self._param(item, scope, fqn, params)
        remaps: list[tuple[str, str]] = []
        for item in self._seq(f["remap"][1], "node.remap") if "remap" in f else []:
            r = self._fields(item, ("from", "to"), ("from", "to"), "remap")
            remaps.append(
                (self._str(r["from"][1], scope, "remap from"), self._str(r["to"][1], scope, "remap to"))
            )
        if any(fqn == n.fully_qualified_name for n in self.nodes):
            raise LaunchError(f"{where}: two nodes named {fqn}; give one another name or namespace")
        self.nodes.append(NodeSpec(exe, name, ns, params, tuple(remaps), output, where, pkg))

    def _param(self, item: yaml.Node, scope: _Scope, fqn: str, params: dict[str, Any]) -> None:
        if isinstance(item, yaml.MappingNode) and any(k.value == "from" for k, _ in item.value):
            p = self._fields(item, ("from",), ("from",), "param")
            node = p["from"][1]
            path = Path(self._str(node, scope, "param from"))
            path = path if path.is_absolute() else self._file.parent / path
            if not path.is_file():
                raise self._err(node.start_mark.line + 1, f"parameter file {path} not found")
            try:
                loaded = Node.load_parameter_file(path, fqn)
            except ConfigError as exc:
                raise self._err(node.start_mark.line + 1, f"bad parameter file: {exc}") from None
            for key, value in loaded.items():
                _set_nested(params, key, value)
            return
        p = self._fields(
            item, ("name", "value"), ("name", "value"), "param (use {name, value} or {from: file})"
        )
        _set_nested(params, self._str(p["name"][1], scope, "param name"), self._typed(p["value"][1], scope))


def _set_nested(params: dict[str, Any], dotted: str, value: Any) -> None:
    """``'a.b'`` -> ``params['a']['b']`` (ROS 2 nested parameter names)."""
    *parents, leaf = dotted.split(".")
    target = params
    for key in parents:
        child = target.get(key)
        if not isinstance(child, dict):
            child = target[key] = {}
        target = child
    if isinstance(value, dict) and isinstance(target.get(leaf), dict):
        for k, v in value.items():
            _set_nested(target[leaf], k, v)
    else:
        target[leaf] = value
