"""The wrist planners the scheduler can use, by name (the node's and the CLI's ``planner`` parameter)."""

from __future__ import annotations

from pathlib import Path

from hsi_planning.errors import ConfigError
from hsi_planning.planning import PLANNER_NAMES, Planner, make_planner
from hsi_planning.scheduler.linear_planner import LinearPlanner
from hsi_planning.scheduler.reach_planner import ReachModelPlanner

#: Names accepted by :func:`scheduler_planner`: the human-reach model, the straight stand-in, and
#: every planner of :func:`hsi_planning.planning.make_planner`.
SCHEDULER_PLANNERS: tuple[str, ...] = ("reach_model", "linear", *PLANNER_NAMES)


def scheduler_planner(name: str, checkpoint: str | Path | None = None) -> Planner:
    """A planner by name (``reach_model``, ``linear``, ``implicit``, ...).

    Raises:
        ConfigError: unknown name (the valid ones are listed).
        PlanningError: the implicit planner's checkpoint cannot be read.
    """
    if name == "reach_model":
        return ReachModelPlanner()
    if name == "linear":
        return LinearPlanner()
    if name in PLANNER_NAMES:
        return make_planner(name, checkpoint)
    raise ConfigError(f"unknown planner {name!r}; available: {list(SCHEDULER_PLANNERS)}")
