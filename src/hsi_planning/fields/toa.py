"""Time-of-arrival field φ of a demonstration and its bounded inverse D_toa.

φ solves the Eikonal equation |∇φ| = 1 / F(x) outside obstacles with φ(x_goal) = 0, where the front
speed is

    F(x) = max(|v(x_n)| · exp(−max(d(x, τ) − p, 0)² / (2σ²)), floor_speed),

x_n being the nearest point of the demonstration path τ, d(x, τ) the distance to it and p a sub-cell
plateau (below). On the path F equals the demonstrated hand speed, so φ there is the demonstration's
own remaining time; away from it the front slows down (the Gaussian corridor of width σ), and the floor
speed keeps φ finite everywhere reachable. The goal x_goal is the contact point: the end of an approach
segment, or the start of a leave segment whose time is reversed (φ is then the time since the contact).

Near the goal the front is started by hand: the nodes inside a sphere of radius r₀ = ``goal_radius``
(two cells) around the goal take the demonstration's own remaining time at their distance from the goal,
and fast marching (``skfmm.travel_time``) continues from that sphere, adding the demonstration's time to
cover its last r₀ (obstacle nodes inside the sphere stay blocked, but a thin obstacle between a node
and the goal inside the sphere is not seen). A sphere of one cell or less is resolved by too few
nodes: skfmm's initialisation next to it then overestimates φ by ≈ 0.5 cell / speed, an offset that
carries over to the whole field.

Nodes within ``corridor_plateau`` (half a cell) of the path count as on it (the Gaussian is evaluated at
the distance minus the plateau): the path rarely passes through nodes, and without the plateau the
front would run ≈ 5–9 % slower than the demonstration along it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import skfmm
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from hsi_planning.errors import PlanningError
from hsi_planning.fields.config import FieldConfig
from hsi_planning.fields.grid import GridSpec
from hsi_planning.trajectory import WristTrajectory

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class DemoPath:
    """A demonstration resampled by arc length, ordered from the goal (index 0) outwards.

    Attributes:
        positions: (K, 3) [m] path points, ``positions[0]`` is the goal (contact point).
        arc: (K,) [m] arc length from the goal.
        speed: (K,) [m/s] demonstrated hand speed.
        remaining: (K,) [s] demonstrated time to the goal (time since the contact for a leave segment).
    """

    positions: FloatArray
    arc: FloatArray
    speed: FloatArray
    remaining: FloatArray

    @property
    def goal(self) -> FloatArray:
        """(3,) [m] the contact point."""
        return np.array(self.positions[0], copy=True)

    def time_at_arc(self, s: NDArray[np.floating] | float) -> FloatArray:
        """Demonstrated remaining time [s] at arc length ``s`` [m] from the goal (clamped to the path)."""
        return np.asarray(np.interp(s, self.arc, self.remaining), dtype=np.float64)


def demo_path(demo: WristTrajectory, spacing: float = 0.005) -> DemoPath:
    """Resample the part of ``demo`` that leads to (approach) or from (leave) its contact sample.

    Args:
        demo: the demonstration; ``contact_index`` marks the contact sample.
        spacing: [m] largest arc-length step of the resampled path.

    Raises:
        PlanningError: fewer than two samples on the contact side, or a path that does not move.
    """
    ci = demo.contact_index
    speed = demo.speed()
    if demo.segment == "approach":
        pos, spd = demo.position[: ci + 1][::-1], speed[: ci + 1][::-1]
        rem = (demo.t[ci] - demo.t[: ci + 1])[::-1]
    else:
        pos, spd, rem = demo.position[ci:], speed[ci:], demo.t[ci:] - demo.t[ci]
    if pos.shape[0] < 2:
        raise PlanningError(
            f"the {demo.segment} demonstration has no samples before/after its contact index {ci}; "
            "an approach needs samples before the contact, a leave samples after it"
        )
    step = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    keep = np.concatenate([[True], step > 1e-9])
    pos, spd, rem = pos[keep], spd[keep], rem[keep]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))])
    if arc.shape[0] < 2 or arc[-1] < 1e-6:
        raise PlanningError("the demonstration does not move (path length below 1 µm)")
    k = max(2, math.ceil(arc[-1] / spacing) + 1)
    s = np.linspace(0.0, arc[-1], k)
    new_pos = np.stack([np.interp(s, arc, pos[:, c]) for c in range(3)], axis=1)
    return DemoPath(
        positions=new_pos,
        arc=s,
        speed=np.interp(s, arc, spd),
        remaining=np.interp(s, arc, rem),
    )


def speed_field(
    grid: GridSpec, path: DemoPath, sigma: float, floor_speed: float, plateau: float = 0.0
) -> FloatArray:
    """(n, n, n) [m/s] front speed F(x) of the module doc.

    F = max(|v(x_n)| · exp(−max(d − plateau, 0)² / (2 sigma²)), floor_speed); ``sigma``, ``plateau`` [m].
    """
    d, idx = cKDTree(path.positions).query(grid.points(), k=1)
    d_eff = np.maximum(np.asarray(d) - plateau, 0.0)
    corridor = path.speed[idx] * np.exp(-0.5 * (d_eff / sigma) ** 2)
    return np.asarray(np.maximum(corridor, floor_speed), dtype=np.float64).reshape(grid.shape)


def time_of_arrival(
    grid: GridSpec, demo: WristTrajectory, obstacle: BoolArray, config: FieldConfig
) -> tuple[FloatArray, FloatArray]:
    """Time-of-arrival field of ``demo`` on ``grid`` with ``obstacle`` (n, n, n) nodes impassable.

    Returns:
        phi: (n, n, n) [s] time to reach the goal, 0 at the goal; ``config.unreachable_time`` on
            obstacle nodes and where no free path leads to the goal.
        goal: (3,) [m] the contact point.

    Raises:
        PlanningError: the goal lies outside the grid or inside an obstacle node, or a bad demonstration.
    """
    path = demo_path(demo, config.path_spacing)
    goal = path.goal
    if not grid.contains(goal)[0]:
        raise PlanningError(f"the demonstration's goal {goal.round(3).tolist()} [m] lies outside the grid")
    gi = tuple(int(v) for v in grid.index(goal)[0])
    if obstacle[gi]:
        raise PlanningError(
            f"the demonstration's goal {goal.round(3).tolist()} [m] lies inside an obstacle node "
            f"{list(gi)}; the contact point must be in free space next to the target"
        )
    r = np.linalg.norm(grid.points() - goal, axis=1).reshape(grid.shape)
    r0 = max(config.goal_radius, float(r.min()) * (1.0 + 1e-6) + 1e-9)
    phi0 = r - r0
    speed = speed_field(grid, path, config.sigma, config.floor_speed, config.corridor_plateau)
    masked = np.ma.MaskedArray(phi0, mask=obstacle)
    try:
        tt = skfmm.travel_time(masked, speed, dx=grid.resolution, order=config.fmm_order)
    except ValueError as exc:
        raise PlanningError(f"fast marching of the time of arrival failed: {exc}") from exc
    blocked = np.ma.getmaskarray(tt)
    values = np.asarray(np.ma.filled(tt, 0.0), dtype=np.float64)
    inside = phi0 < 0.0
    phi = np.where(inside, path.time_at_arc(r), values + float(path.time_at_arc(r0)))
    phi = np.minimum(phi, config.unreachable_time)
    phi[(blocked & ~inside) | obstacle] = config.unreachable_time
    return np.asarray(phi), goal
