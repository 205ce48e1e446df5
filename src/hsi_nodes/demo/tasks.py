"""The demo's scripted clicks: which object each task picks and where it puts it, per demo variant.

A :class:`DemoTask` is what a person does in RViz: a click on the object to pick (``click``, resolved by
the scheduler's :func:`~hsi_planning.scheduler.resolve_click` against the labelled cloud) or, for an object
the cameras cannot see (inside a closed cabinet or drawer, hidden behind another), its name as a UI's object
list would give it (``object_name``); then a click on the top of a free surface where it goes
(``place_click``: the bottom centre of the placed object, resolved against the cloud with the object
held). Each task is one pick-and-place goal (``hsi/msg/PickPlaceGoal`` in the node path).

Variants (:data:`VARIANTS`):

- ``kitchen`` (``make demo``): a visible can clicked on the counter and put down 0.5 m to the side; the
  door-cabinet pick-and-place (``bottle2`` behind ``cabinet1``'s closed door onto the open shelf); the
  drawer pick (``mug2`` out of the closed top drawer onto the counter); the narrow-shelf pick with a
  blocker (``can1`` hidden behind ``bottle1`` in scene ``narrow_shelf``, onto the top board: the bottle is
  moved aside first);
- ``test`` (``hsi demo --test``): the smallest task, the counter can alone.

Places are chosen so the approach that grasps an object also suits its placement (front-access shelves
and cabinets for side grasps, counters for top-down grasps): the robot's gripper holds objects rigidly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hsi_planning.errors import ConfigError

__all__ = ["VARIANTS", "DemoTask", "demo_tasks"]

Point = tuple[float, float, float]


@dataclass(frozen=True)
class DemoTask:
    """One scripted pick-and-place."""

    name: str  #: short id (file names, task ids) [-]
    scene: str  #: built-in scene name or spec path [-]
    place_click: Point  #: clicked point on a free surface top: the placed object's bottom centre [m]
    click: Point | None = None  #: clicked point on the object to pick [m]; None: ``object_name``
    object_name: str = ""  #: object picked by name (hidden from the cameras) [-]
    hand: str = ""  #: grasping hand ``left``/``right``/``both``; '' = the scheduler decides [-]
    #: hand that opens the target's door or drawer ``left``/``right``; '' = the scheduler decides [-]
    door_hand: str = ""
    description: str = ""  #: one line for the report [-]

    def __post_init__(self) -> None:
        if not self.name or not self.name.replace("_", "").isalnum():
            raise ConfigError(f"DemoTask.name must be a non-empty identifier, got {self.name!r}")
        if self.hand not in ("", "left", "right", "both"):
            raise ConfigError(f"task {self.name!r}: hand must be '', left, right or both, got {self.hand!r}")
        if self.door_hand not in ("", "left", "right"):
            raise ConfigError(
                f"task {self.name!r}: door_hand must be '', left or right, got {self.door_hand!r}"
            )
        if (self.click is None) == (not self.object_name):
            raise ConfigError(f"task {self.name!r}: give exactly one of click [m] or object_name")
        points = [self.place_click] + ([self.click] if self.click is not None else [])
        for p in points:
            if len(p) != 3 or not all(math.isfinite(v) for v in p):
                raise ConfigError(f"task {self.name!r}: clicks must be 3 finite numbers [m], got {p}")

    @property
    def label(self) -> str:
        """What is picked: the object name, or the click for a clicked object."""
        if self.object_name:
            return self.object_name
        assert self.click is not None
        return "click " + ",".join(f"{v:.2f}" for v in self.click)


_COUNTER_CAN = DemoTask(
    "counter_can",
    "kitchen",
    place_click=(0.75, -0.2, 0.9),
    click=(0.9, 0.3, 1.02),
    description="counter pick-and-place: the clicked can1 put down 0.5 m to the right",
)

_KITCHEN = (
    _COUNTER_CAN,
    DemoTask(
        "cabinet_bottle",
        "kitchen",
        place_click=(0.75, 1.15, 1.25),
        object_name="bottle2",
        description="door-cabinet pick-and-place: bottle2 behind the closed cabinet door onto shelf board 2",
    ),
    DemoTask(
        "drawer_mug",
        "kitchen",
        place_click=(0.75, -0.3, 0.9),
        object_name="mug2",
        description="drawer pick: mug2 out of the closed top drawer onto the counter",
    ),
    DemoTask(
        "narrow_shelf_can",
        "narrow_shelf",
        place_click=(0.75, 0.25, 1.6),
        object_name="can1",
        description="narrow-shelf pick with a blocker: can1 behind bottle1, onto the top board",
    ),
)

#: Demo variant -> its scripted tasks, in order.
VARIANTS: dict[str, tuple[DemoTask, ...]] = {"kitchen": _KITCHEN, "test": (_COUNTER_CAN,)}


def demo_tasks(variant: str, only: tuple[str, ...] = ()) -> tuple[DemoTask, ...]:
    """The tasks of ``variant`` (``kitchen`` or ``test``), restricted to the names in ``only`` if given.

    Raises:
        ConfigError: unknown variant or task name (the valid ones are listed).
    """
    if variant not in VARIANTS:
        raise ConfigError(f"unknown demo variant {variant!r}; available: {sorted(VARIANTS)}")
    tasks = VARIANTS[variant]
    if not only:
        return tasks
    names = {t.name for v in VARIANTS.values() for t in v}
    unknown = sorted(set(only) - names)
    if unknown:
        raise ConfigError(f"unknown demo task(s) {unknown}; available: {sorted(names)}")
    every = {t.name: t for v in VARIANTS.values() for t in v}
    return tuple(every[n] for n in only)
