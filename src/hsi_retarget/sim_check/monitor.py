"""Safety monitors of the execution check: robot collisions and joint limit violations.

A *collision* is a contact between a robot geom and a furniture geom (floor, furniture, doors, drawers) or
between geoms of the two arms, penetrating deeper than ``depth_m``. Allowed: a hand touching the body it
approaches to grasp, closes on, holds, or has just released (see :meth:`GraspController.allowed`), and
support geoms
(humanoid soles) on the floor. Contacts with free objects are never collisions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hsi_retarget.sim_check.world import KIND_FURNITURE, KIND_ROBOT, SimWorld


@dataclass(frozen=True)
class CollisionRecord:
    """One colliding geom pair, aggregated over the execution."""

    robot_geom: str  #: robot geom name
    other_geom: str  #: furniture (or other arm) geom name
    other_kind: str  #: ``furniture`` or ``robot`` (arm-arm)
    first_time_s: float  #: first simulated time of penetration [s]
    max_depth_m: float  #: deepest penetration [m]
    steps: int  #: physics steps in collision [-]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dict(self.__dict__)


@dataclass(frozen=True)
class LimitViolation:
    """A joint outside its limits, aggregated per (joint, quantity, source)."""

    joint: str  #: joint name
    quantity: str  #: ``position`` [rad or m] or ``velocity`` [rad/s or m/s]
    source: str  #: ``command`` (the trajectory) or ``state`` (the simulated robot)
    first_time_s: float  #: [s]
    worst_value: float  #: most violating value [rad, m, rad/s or m/s]
    lower: float  #: limit [same unit]
    upper: float  #: limit [same unit]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dict(self.__dict__)


class ContactMonitor:
    """Scans MuJoCo contacts for robot collisions (call :meth:`check` after every physics step)."""

    def __init__(self, world: SimWorld, depth_m: float) -> None:
        self.world = world
        self.depth_m = float(depth_m)
        self._pairs: dict[tuple[int, int], list[Any]] = {}
        m = world.model
        self._floor = {g for g in range(m.ngeom) if m.geom(g).name == "floor"}
        self._support = set(world.support_geoms.tolist())

    def check(self, time: float, allowed: list[set[str]]) -> None:
        """Record penetrating robot contacts at ``time`` [s]; ``allowed[h]``: bodies hand h may touch."""
        d = self.world.data
        n = d.ncon
        if n == 0:
            return
        dist = np.asarray(d.contact.dist[:n])
        deep = np.flatnonzero(dist < -self.depth_m)
        if deep.size == 0:
            return
        pairs = np.asarray(d.contact.geom[:n])[deep]
        kind = self.world.geom_kind
        for (a, b), depth in zip(pairs.tolist(), (-dist[deep]).tolist(), strict=True):
            g1, g2 = (a, b) if kind[a] == KIND_ROBOT else (b, a)
            if kind[g1] != KIND_ROBOT or kind[g2] not in (KIND_ROBOT, KIND_FURNITURE):
                continue
            if self._allowed(g1, g2, allowed):
                continue
            rec = self._pairs.get((g1, g2))
            if rec is None:
                self._pairs[(g1, g2)] = [time, depth, 1]
            else:
                rec[1], rec[2] = max(rec[1], depth), rec[2] + 1

    def _allowed(self, robot_geom: int, other: int, allowed: list[set[str]]) -> bool:
        if robot_geom in self._support and other in self._floor:
            return True
        hand = int(self.world.geom_hand[robot_geom])
        owner = str(self.world.geom_owner[other])
        return hand >= 0 and bool(owner) and owner in allowed[hand]

    def records(self) -> list[CollisionRecord]:
        """Colliding pairs, in order of first contact."""
        m = self.world.model
        out = [
            CollisionRecord(
                m.geom(g1).name,
                m.geom(g2).name,
                "robot" if self.world.geom_kind[g2] == KIND_ROBOT else "furniture",
                float(t),
                float(depth),
                int(steps),
            )
            for (g1, g2), (t, depth, steps) in self._pairs.items()
        ]
        return sorted(out, key=lambda r: r.first_time_s)


class LimitMonitor:
    """Position limits of the robot's actuated joints, commanded and simulated."""

    def __init__(self, world: SimWorld, tolerance: float) -> None:
        robot = world.robot
        self.q_idx = np.array(world.map.ctrl_q, dtype=np.int64)
        by_index = {robot.q_index(n): n for n in robot.joint_names}
        self.names = [by_index[int(i)] for i in self.q_idx]
        self.lower, self.upper = robot.q_lower[self.q_idx], robot.q_upper[self.q_idx]
        self.tolerance = float(tolerance)
        self._worst: dict[tuple[str, str, str], list[Any]] = {}

    def check(self, time: float, q: NDArray[np.float64], source: str) -> None:
        """Record joints of ``q`` (nq,) outside their limits (+/- tolerance) at ``time`` [s]."""
        values = np.asarray(q)[self.q_idx]
        bad = np.flatnonzero((values < self.lower - self.tolerance) | (values > self.upper + self.tolerance))
        for i in bad.tolist():
            bounds = (float(self.lower[i]), float(self.upper[i]))
            self.add((self.names[i], "position", source), time, float(values[i]), bounds)

    def add(self, key: tuple[str, str, str], time: float, value: float, bounds: tuple[float, float]) -> None:
        """Record a violation: ``key`` = (joint, ``position``|``velocity``, ``command``|``state``), ``value``
        outside ``bounds`` (lower, upper) [rad, m, rad/s or m/s] at ``time`` [s]; keeps the first time and the
        worst value."""
        lower, upper = bounds
        excess = max(lower - value, value - upper)
        rec = self._worst.get(key)
        if rec is None:
            self._worst[key] = [time, value, lower, upper, excess]
        elif excess > rec[4]:
            rec[1], rec[4] = value, excess

    def records(self) -> list[LimitViolation]:
        """Violations, in order of first occurrence."""
        out = [
            LimitViolation(j, qty, src, float(r[0]), float(r[1]), float(r[2]), float(r[3]))
            for (j, qty, src), r in self._worst.items()
        ]
        return sorted(out, key=lambda r: r.first_time_s)
