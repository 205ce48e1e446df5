"""Perturbations of an execution: pushes on robot links and the target object moved after planning.

A :class:`Push` applies a constant world-frame force (``xfrc_applied``, at the link's centre of mass) for a
short time: an impulse of ``force * duration``. A :class:`TargetMove` shifts a free object by up to 5 cm
(horizontally by default) before the robot grasps it. Every event is passed to the caller's re-plan hook
``on_perturbation(world, event) -> JointTrajectory | None``; a returned trajectory replaces the rest of the
current one from that moment (its time 0 = now). :func:`random_perturbations` draws seeded events; a target
move is drawn again (up to :data:`MOVE_DRAWS` times) while it would push the object into a neighbour or off
its support: a scene no one could set up (MuJoCo would shove the neighbour aside, and a re-plan from the
moved scene would be refused as invalid).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hsi_planning.errors import ConfigError, SceneError
from hsi_planning.scene import moved_object
from hsi_planning.scene.validate import validate_scene
from hsi_retarget.joint_trajectory import JointTrajectory
from hsi_retarget.sim_check.mjcf import HANDS
from hsi_retarget.sim_check.world import SimWorld

MAX_TARGET_SHIFT_M = 0.05  #: the largest target move the check models [m]
MOVE_DRAWS = 32  #: target moves drawn before the move is left out [-]
_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class Push:
    """A force on robot body ``body`` from ``time_s`` for ``duration_s``."""

    time_s: float  #: start, from the execution start [s]
    body: str  #: robot link (MuJoCo body) name
    force: tuple[float, float, float]  #: world-frame force at the link's centre of mass [N]
    duration_s: float  #: [s]

    @property
    def magnitude(self) -> float:
        """[N] force magnitude."""
        return float(np.linalg.norm(self.force))


@dataclass(frozen=True)
class TargetMove:
    """Free object ``object_name`` shifted by ``offset`` at ``time_s`` (after planning, before the grasp)."""

    time_s: float  #: [s] from the execution start
    object_name: str  #: free object name
    offset: tuple[float, float, float]  #: [m]

    def __post_init__(self) -> None:
        if float(np.linalg.norm(self.offset)) > MAX_TARGET_SHIFT_M + 1e-9:
            raise ConfigError(f"TargetMove.offset {self.offset} is longer than {MAX_TARGET_SHIFT_M} m")

    @property
    def magnitude(self) -> float:
        """[m] shift distance."""
        return float(np.linalg.norm(self.offset))


PerturbationEvent = Push | TargetMove
#: ``on_perturbation(world, event)``: return a new trajectory to re-plan, or None to go on.
RePlanHook = Callable[[SimWorld, PerturbationEvent], JointTrajectory | None]


@dataclass(frozen=True)
class PerturbationConfig:
    """Random perturbations of one execution."""

    seed: int = 0  #: RNG seed [-]
    pushes: int = 2  #: number of pushes [-]
    push_force_n: tuple[float, float] = (40.0, 120.0)  #: push magnitude range [N]
    push_duration_s: float = 0.1  #: push length [s]
    push_window: tuple[float, float] = (0.15, 0.85)  #: push start times as fractions of the duration [-]
    push_bodies: tuple[str, ...] = ()  #: robot links to push; empty: every arm link [-]
    target_shift_m: float = 0.05  #: largest target move; 0 = none [m]
    target_shift_at: float = 0.3  #: target move time as a fraction of the time to its first grasp [-]

    def __post_init__(self) -> None:
        lo, hi = self.push_force_n
        if self.pushes < 0 or not (0.0 <= lo <= hi and math.isfinite(hi)):
            raise ConfigError(
                f"PerturbationConfig: need pushes >= 0 and 0 <= push_force_n[0] <= push_force_n[1] [N], "
                f"got {self.pushes}, {self.push_force_n}"
            )
        if not (0.0 < self.push_duration_s < 5.0):
            raise ConfigError(
                f"PerturbationConfig.push_duration_s must be in (0, 5) [s], got {self.push_duration_s}"
            )
        a, b = self.push_window
        if not (0.0 <= a <= b <= 1.0) or not (0.0 <= self.target_shift_at <= 1.0):
            raise ConfigError("PerturbationConfig.push_window and target_shift_at are fractions in [0, 1]")
        if not (0.0 <= self.target_shift_m <= MAX_TARGET_SHIFT_M):
            raise ConfigError(
                f"PerturbationConfig.target_shift_m must be in [0, {MAX_TARGET_SHIFT_M}] [m], "
                f"got {self.target_shift_m}"
            )


def arm_links(world: SimWorld) -> tuple[str, ...]:
    """Names of the bodies moved by the arm joints of both arms (the default push targets)."""
    m = world.model
    out = []
    for hand in HANDS:
        for joint in world.robot.arm_joints[hand]:
            out.append(m.body(int(m.jnt_bodyid[m.joint(joint).id])).name)
    return tuple(out)


def random_perturbations(
    world: SimWorld, trajectory: JointTrajectory, config: PerturbationConfig, target: str = ""
) -> tuple[PerturbationEvent, ...]:
    """Seeded pushes over the trajectory and, with ``target`` (a free object), one horizontal target move.

    The move happens at ``target_shift_at`` of the time to the first grasp of a free object (``target``, or a
    blocker moved out of its way first: the re-plan starts with empty hands; at 0 s without a grasp), over a
    distance uniform in [0.5, 1] x ``target_shift_m``, in a direction that keeps it clear of its neighbours.
    """
    rng = np.random.default_rng(config.seed)
    bodies = config.push_bodies or arm_links(world)
    for b in bodies:
        if b not in {world.model.body(int(i)).name for i in world.robot_bodies}:
            raise ConfigError(f"push body {b!r} is not a robot link; links: {list(arm_links(world))}")
    events: list[PerturbationEvent] = []
    t0, t1 = (f * trajectory.duration for f in config.push_window)
    for _ in range(config.pushes):
        direction = rng.normal(size=3)
        force = direction / np.linalg.norm(direction) * rng.uniform(*config.push_force_n)
        events.append(
            Push(
                float(rng.uniform(t0, t1)),
                str(rng.choice(list(bodies))),
                _triple(force),
                config.push_duration_s,
            )
        )
    if target and config.target_shift_m > 0.0:
        world.target_kind(target)
        grasps = [
            e.time
            for e in trajectory.events
            if e.kind == "grasp" and e.object_name in world.objects  # free objects, not doors/drawers
        ]
        when = config.target_shift_at * min(grasps, default=0.0)
        for _ in range(MOVE_DRAWS):
            angle = rng.uniform(0.0, 2.0 * math.pi)
            dist = rng.uniform(0.5, 1.0) * config.target_shift_m
            offset = (dist * math.cos(angle), dist * math.sin(angle), 0.0)
            if _fits(world, target, offset):
                events.append(TargetMove(float(when), target, offset))
                break
        else:
            _LOG.warning("no move of %r by %.3f m keeps it clear of its neighbours: left out", target, dist)
    return tuple(sorted(events, key=lambda e: e.time_s))


def _fits(world: SimWorld, target: str, offset: tuple[float, float, float]) -> bool:
    """Whether free object ``target`` moved by ``offset`` [m] still stands on its support, clear of every
    other object (the world's scene spec validates)."""
    try:
        validate_scene(moved_object(world.spec, target, offset))
    except SceneError:
        return False
    return True


def event_dict(event: PerturbationEvent) -> dict[str, Any]:
    """A JSON-ready description of an event."""
    if isinstance(event, Push):
        return {
            "kind": "push",
            "time_s": event.time_s,
            "body": event.body,
            "force_n": list(event.force),
            "duration_s": event.duration_s,
        }
    return {
        "kind": "target_move",
        "time_s": event.time_s,
        "object": event.object_name,
        "offset_m": list(event.offset),
    }


def _triple(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))
