"""Launch-file substitutions: ``$(var NAME)``, ``$(env NAME [DEFAULT])``, ``$(optenv NAME [DEFAULT])``,
``$(find-pkg-share hsi)``, ``$(dirname)``, ``$(filename)``.

``$(find-pkg-share hsi)`` is the source checkout holding ``package.xml`` when running from source, else
``<prefix>/share/hsi`` (an installed package); other packages do not exist without a ROS install.
Nested substitutions resolve innermost first (``$(var $(var which))``).
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Mapping
from pathlib import Path

from hsi_planning.errors import LaunchError

__all__ = ["PACKAGE", "SUPPORTED", "package_share", "substitute"]

#: The one ROS 2 package that exists here (package.xml ``<name>``).
PACKAGE = "hsi"
#: Human-readable list of the supported substitutions (used in error messages).
SUPPORTED = (
    "$(var NAME), $(env NAME [DEFAULT]), $(optenv NAME [DEFAULT]), $(find-pkg-share hsi), $(dirname), "
    "$(filename)"
)
_SUBST = re.compile(r"\$\(([^()]*)\)")
_MAX_NESTING = 32


def package_share(package: str = PACKAGE) -> Path:
    """Share directory of ``package`` (only ``hsi``): the source checkout root, else ``<prefix>/share/hsi``.

    Raises:
        LaunchError: another package, or no share directory found.
    """
    if package != PACKAGE:
        raise LaunchError(f"unknown package {package!r}; only {PACKAGE!r} is available (no ROS install)")
    source_root = Path(__file__).resolve().parents[3]
    for cand in (source_root, Path(sys.prefix) / "share" / PACKAGE):
        if (cand / "package.xml").is_file():
            return cand
    raise LaunchError(f"cannot find the share directory of {PACKAGE!r} (looked in {source_root})")


def _one(body: str, values: Mapping[str, str], current_file: Path) -> str:
    parts = body.split()
    cmd, rest = (parts[0], parts[1:]) if parts else ("", [])
    if cmd == "var" and len(rest) == 1:
        if rest[0] not in values:
            raise LaunchError(f"undefined launch argument {rest[0]!r}; defined: {sorted(values)}")
        return values[rest[0]]
    if cmd in ("env", "optenv") and len(rest) in (1, 2):
        value = os.environ.get(rest[0], rest[1] if len(rest) == 2 else None)
        if value is None and cmd == "env":
            raise LaunchError(f"environment variable {rest[0]!r} is not set and has no default")
        return value or ""
    if cmd == "find-pkg-share" and len(rest) == 1:
        return str(package_share(rest[0]))
    if cmd in ("dirname", "filename") and not rest:
        return str(current_file.parent if cmd == "dirname" else current_file)
    raise LaunchError(f"unsupported substitution $({body}); supported: {SUPPORTED}")


def substitute(text: str, values: Mapping[str, str], current_file: Path) -> str:
    """``text`` with every substitution evaluated (``values``: launch arguments; ``current_file``: the
    launch file being read).

    Raises:
        LaunchError: undefined argument (defined ones listed), unset environment variable, unknown package,
            unsupported or unterminated substitution. The message has no location; callers add ``path:LINE``.
    """
    for _ in range(_MAX_NESTING):
        text, n = _SUBST.subn(lambda m: _one(m.group(1), values, current_file), text)
        if n == 0:
            break
    if "$(" in text:
        raise LaunchError(f"unterminated or unsupported substitution in {text!r}")
    return text
