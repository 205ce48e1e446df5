"""The robots known to the stack: name -> description factory, aliases, and the committed file paths."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from hsi_planning.errors import ConfigError
from hsi_retarget.robots.description import RobotDescription
from hsi_retarget.robots.dual_ur5e import dual_ur5e_description
from hsi_retarget.robots.humanoid import humanoid_description

#: Robot name -> description factory.
DESCRIPTIONS: dict[str, Callable[[], RobotDescription]] = {
    "dual_ur5e": dual_ur5e_description,
    "humanoid": humanoid_description,
}
#: Accepted aliases of the robot names (e.g. the CLI's ``dual_arm``).
ALIASES = {"dual_arm": "dual_ur5e", "dual_ur5": "dual_ur5e"}


def robot_name(name: str) -> str:
    """The canonical robot name for ``name`` (an alias or a name)."""
    canonical = ALIASES.get(name, name)
    if canonical not in DESCRIPTIONS:
        raise ConfigError(
            f"unknown robot {name!r}; known: {sorted(DESCRIPTIONS)} (aliases {sorted(ALIASES)})"
        )
    return canonical


def description(name: str) -> RobotDescription:
    """The :class:`RobotDescription` of robot ``name`` (built fresh)."""
    return DESCRIPTIONS[robot_name(name)]()


def relative_paths(name: str) -> tuple[Path, Path]:
    """(URDF path, MJCF path) of robot ``name`` relative to the repository root."""
    canonical = robot_name(name)
    return Path("urdf") / f"{canonical}.urdf", Path("sim") / "robots" / f"{canonical}.xml"
