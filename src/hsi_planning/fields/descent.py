"""Gradient descent on a time-of-arrival field: the path a hand takes to the goal, and its timing.

From a start point the hand steps against ∇φ (normalised, fixed step) until it is within ``stop_radius``
of the goal. Timing comes from φ itself: φ(x) is the remaining time, so the time stamp of step k is
φ(x₀) − φ(x_k) (made non-decreasing). Obstacle and unreachable nodes hold a large φ; before taking the
gradient they get the value of their nearest reachable node, so the descent follows the free-space
gradient next to walls instead of being kicked away by the jump.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.fields.field_set import FieldSet
from hsi_planning.fields.grid import GridSpec

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DescentConfig:
    """Parameters of :func:`descend`."""

    step: float = 0.0125  #: [m] step length (half a default cell)
    stop_radius: float = 0.0125  #: [m] stop when this close to the goal
    max_steps: int = 1000  #: [-] give up after this many steps
    patience: int = 20  #: [-] give up after this many steps without a new lowest φ

    def __post_init__(self) -> None:
        if not (self.step > 0.0 and self.stop_radius > 0.0):
            raise ConfigError(f"step ({self.step} m) and stop_radius ({self.stop_radius} m) must be > 0")
        if self.max_steps < 1 or self.patience < 1:
            raise ConfigError(f"max_steps ({self.max_steps}) and patience ({self.patience}) must be ≥ 1")


@dataclass(frozen=True, eq=False)
class Descent:
    """Result of :func:`descend`.

    Attributes:
        positions: (K, 3) [m] visited points, ``positions[0]`` is the start.
        times: (K,) [s] time stamps from 0, non-decreasing (φ(start) − φ(x_k)).
        remaining: (K,) [s] φ at each point (interpolated remaining time); ``remaining[-1]`` is the time
            still to go from the last point to the goal (a cell's worth of a slow final approach, which
            trilinear interpolation cannot resolve: add it when joining the goal / the prior's last frames).
        reached: whether the last point is within ``stop_radius`` of the goal.
    """

    positions: FloatArray
    times: FloatArray
    remaining: FloatArray
    reached: bool


def descent_potential(phi: ArrayLike, blocked_value: float) -> FloatArray:
    """(n, n, n) [s] φ with every node at or above ``blocked_value`` replaced by its nearest other node."""
    arr = np.asarray(phi, dtype=np.float64)
    blocked = ~np.isfinite(arr) | (arr >= blocked_value)
    if blocked.all():
        raise PlanningError("the time-of-arrival field has no reachable node")
    if not blocked.any():
        return np.array(arr, copy=True)
    _, idx = ndimage.distance_transform_edt(blocked, return_indices=True)
    return np.asarray(arr[tuple(idx)], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class DescentField:
    """A time field made ready for descent (:func:`prepare_descent`), to reuse for several descents.

    Attributes:
        phi: (n, n, n) [s] the field itself (not copied: it must not change afterwards).
        potential: (n, n, n) [s] :func:`descent_potential` of ``phi``.
        gradient: (n, n, n, 3) [s/m] the potential's gradient.
    """

    phi: FloatArray
    potential: FloatArray
    gradient: FloatArray


def prepare_descent(grid: GridSpec, phi: ArrayLike, blocked_value: float) -> DescentField:
    """The :class:`DescentField` of ``phi`` (n, n, n) [s]: potential and gradient, computed once."""
    arr = np.asarray(phi, dtype=np.float64)
    potential = descent_potential(arr, blocked_value)
    return DescentField(phi=arr, potential=potential, gradient=grid.gradient(potential))


def descend_field(
    grid: GridSpec,
    phi: ArrayLike,
    start: ArrayLike,
    goal: ArrayLike,
    *,
    blocked_value: float,
    config: DescentConfig | None = None,
    prepared: DescentField | None = None,
) -> Descent:
    """Descend the time-of-arrival field ``phi`` (n, n, n) [s] from ``start`` (3,) [m] towards ``goal`` (3,).

    Nodes with φ ≥ ``blocked_value`` (obstacles, unreachable) are treated as described in the module doc.
    ``prepared``: ``phi``'s :class:`DescentField` when already computed (the same answer, faster).

    Raises:
        PlanningError: start outside the grid, or a field without reachable nodes.
    """
    cfg = config or DescentConfig()
    x = np.asarray(start, dtype=np.float64).reshape(3)
    g = np.asarray(goal, dtype=np.float64).reshape(3)
    if not (np.isfinite(x).all() and np.isfinite(g).all()):
        raise PlanningError("start and goal must be finite 3-vectors [m]")
    if not grid.contains(x)[0]:
        raise PlanningError(f"start {x.round(3).tolist()} [m] lies outside the grid around {grid.centre}")
    if prepared is None:
        prepared = prepare_descent(grid, phi, blocked_value)
    potential, gradient = prepared.potential, prepared.gradient
    positions = [x.copy()]
    values = [float(grid.interpolate(potential, x)[0])]
    best, since_best = values[0], 0
    reached = bool(np.linalg.norm(x - g) <= cfg.stop_radius)
    for _ in range(cfg.max_steps):
        if reached or since_best >= cfg.patience:
            break
        grad = grid.interpolate_gradient(gradient, x)[0]
        norm = float(np.linalg.norm(grad))
        if norm < 1e-12:
            break
        x = x - min(cfg.step, float(np.linalg.norm(x - g))) * grad / norm
        positions.append(x.copy())
        values.append(float(grid.interpolate(potential, x)[0]))
        if values[-1] < best:
            best, since_best = values[-1], 0
        else:
            since_best += 1
        reached = bool(np.linalg.norm(x - g) <= cfg.stop_radius)
    remaining = np.asarray(values)
    times = np.maximum.accumulate(np.maximum(remaining[0] - remaining, 0.0))
    return Descent(positions=np.asarray(positions), times=times, remaining=remaining, reached=reached)


def descend(field_set: FieldSet, start: ArrayLike, config: DescentConfig | None = None) -> Descent:
    """Descend the time-of-arrival field of ``field_set`` from ``start`` (3,) [m] to its goal.

    Raises:
        PlanningError: the field set was computed without a demonstration (no φ), or bad start.
    """
    if field_set.phi is None or field_set.goal is None:
        raise PlanningError("this FieldSet has no time-of-arrival field; compute it with a demonstration")
    return descend_field(
        field_set.grid,
        field_set.phi,
        start,
        field_set.goal,
        blocked_value=field_set.config.unreachable_time,
        config=config,
    )
