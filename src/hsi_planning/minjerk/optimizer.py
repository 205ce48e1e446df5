"""Collision-free minimum-jerk trajectory optimization with CasADi + IPOPT (the robotics baseline).

Decision variables: positions, velocities and accelerations at K uniform knots over a **fixed**
duration T (a piecewise quintic Hermite curve, :mod:`.quintic`; scaled to metres as [P; hV; h²A]); the
first and last knot are fixed to the start and goal with zero velocity and acceleration. Objective: the
exact integrated squared jerk ∫|x'''|² dt (quadratic), divided by that of the straight minimum-jerk
line. Constraints at ``checks_per_segment`` points per knot interval (ends excluded, they are fixed):

- speed ``|v| <= max_speed`` and acceleration ``|a| <= max_acceleration`` (squared norms);
- clearance of every :class:`~hsi_planning.minjerk.clearance.ClearanceSphere` (the hand; the held
  object while carrying) on the cubic-spline distance field, relaxed near a tight end;
- knot positions inside the distance grids (where the field is known).

IPOPT runs with the exact Hessian (the field is C²), the adaptive barrier update, quietly
(``print_level 0``, ``sb yes``), bounded by ``max_iterations`` and ``max_wall_time``. A numerical stop
(``Error_In_Step_Computation``, ``Restoration_Failed``) or a budget stop (``Maximum_Iterations_Exceeded``,
``Maximum_WallTime_Exceeded``, ``Maximum_CpuTime_Exceeded``: on a loaded machine the wall-time limit comes
before the iteration limit) on an iterate that satisfies every constraint within ``constraint_tolerance`` is
kept (status ``feasible (...)``: collision-free and within the bounds, its jerk not proven minimal). Any
other status, or a result that still violates a clearance by more than ``constraint_tolerance``, raises
:class:`PlanningError` naming the IPOPT return status.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any, cast

import casadi as ca
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.minjerk.clearance import ClearanceSphere
from hsi_planning.minjerk.quintic import (
    QuinticSpline,
    check_points,
    initial_spline,
    jerk_cost_root,
    value_operator,
)

_LOG = logging.getLogger(__name__)

F64 = NDArray[np.float64]
_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
#: IPOPT stops that can leave a feasible, not yet optimal iterate (kept when every constraint holds).
_KEEP_IF_FEASIBLE = (
    "Error_In_Step_Computation",
    "Restoration_Failed",
    "Maximum_Iterations_Exceeded",
    "Maximum_WallTime_Exceeded",
    "Maximum_CpuTime_Exceeded",
)
#: [m] knots stay this far inside the field box, so the curve between knots stays inside too.
_BOX_INSET = 0.03


@dataclass(frozen=True)
class MinJerkConfig:
    """Parameters of the minimum-jerk optimizer."""

    knots: int = 40  #: [-] knots K (positions, velocities, accelerations are variables at each)
    checks_per_segment: int = 3  #: [-] constraint checks per knot interval (clearance, speed, acceleration)
    max_speed: float = 1.5  #: [m/s] bound on |v|
    max_acceleration: float = 10.0  #: [m/s²] bound on |a|
    relax_slope: float = 0.5  #: [m/m] clearance regained per metre travelled away from a tight end
    relax_slack: float = 0.005  #: [m] tolerance subtracted from an end's own clearance when relaxing
    warm_start_smoothing: float = (
        1000.0  #: [-] weight of staying on the initial path vs its jerk (warm start)
    )
    max_iterations: int = 200  #: [-] IPOPT max_iter (successful solves take ~5–40)
    max_wall_time: float = 3.0  #: [s] IPOPT max_wall_time per attempt
    tolerance: float = 1e-6  #: [-] IPOPT tol (on the scaled problem)
    #: [m] largest accepted clearance violation after the solve: a tenth of the distance grid's 2 cm node
    #: spacing (its trilinear interpolation is no more accurate); at 1 mm, iterates 1.0-1.5 mm inside a
    #: 2 cm margin were refused (humanoid drawer_can/plain/1: no schedule with either hand)
    constraint_tolerance: float = 2e-3

    def __post_init__(self) -> None:
        if not 4 <= self.knots <= 400:
            raise ConfigError(f"knots must be in 4..400, got {self.knots}")
        if not 1 <= self.checks_per_segment <= 20:
            raise ConfigError(f"checks_per_segment must be in 1..20, got {self.checks_per_segment}")
        positive = {
            "max_speed": self.max_speed,
            "max_acceleration": self.max_acceleration,
            "relax_slope": self.relax_slope,
            "warm_start_smoothing": self.warm_start_smoothing,
            "max_wall_time": self.max_wall_time,
            "tolerance": self.tolerance,
            "constraint_tolerance": self.constraint_tolerance,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"{name} must be a finite number > 0, got {value}")
        if not (math.isfinite(self.relax_slack) and self.relax_slack >= 0.0):
            raise ConfigError(f"relax_slack must be >= 0 [m], got {self.relax_slack}")
        if self.relax_slope > 1.0:
            raise ConfigError(
                f"relax_slope must be <= 1 (a distance grows at most 1 m/m), got {self.relax_slope}"
            )
        if self.max_iterations < 1:
            raise ConfigError(f"max_iterations must be >= 1, got {self.max_iterations}")


@dataclass(frozen=True, eq=False)
class MinJerkSolution:
    """An optimized trajectory and how the solve went.

    Attributes:
        spline: the optimal curve (knot positions, velocities, accelerations).
        status: IPOPT's return status (e.g. ``Solve_Succeeded``).
        iterations: IPOPT iterations.
        solve_time: [s] wall time of the IPOPT call; build_time: [s] wall time to build the NLP.
        jerk_cost: [m²/s⁵] ∫|x'''|² dt of the solution.
        min_margin: [m] smallest clearance minus requirement over the checks and spheres (inf: none).
        warm_start: how the initial guess was made (``straight``, ``corridor``, ``given``).
    """

    spline: QuinticSpline
    status: str
    iterations: int
    solve_time: float
    build_time: float
    jerk_cost: float
    min_margin: float
    warm_start: str = ""


def min_duration(distance: float, max_speed: float, max_acceleration: float) -> float:
    """[s] shortest rest-to-rest time over ``distance`` [m] with |v| <= max_speed [m/s] and
    |a| <= max_acceleration [m/s²] (trapezoidal speed; a lower bound for any path and any jerk)."""
    d = max(float(distance), 0.0)
    if d >= max_speed**2 / max_acceleration:
        return d / max_speed + max_speed / max_acceleration
    return 2.0 * math.sqrt(d / max_acceleration)


def _sparse(matrix: F64) -> ca.DM:
    """A CasADi matrix with the structural zeros of ``matrix`` left out (keeps the Jacobians sparse)."""
    return ca.DM(sp.csc_matrix(matrix))


def _check_tau(knots: int, per_segment: int) -> F64:
    seg, sig = check_points(knots, per_segment)
    return np.asarray((seg + sig) / (knots - 1), dtype=np.float64)[1:-1]


def margins(spline: QuinticSpline, spheres: tuple[ClearanceSphere, ...], config: MinJerkConfig) -> F64:
    """(M·S,) [m] clearance minus (relaxed) requirement at the interior check points of every sphere."""
    wrist = value_operator(spline.knots, spline.duration, config.checks_per_segment)[1:-1] @ spline.stacked()
    tau = _check_tau(spline.knots, config.checks_per_segment)
    a, b = spline.position[0], spline.position[-1]
    out = [
        s.margin_at(wrist, tau, s.relaxed_ends(a, b, config.relax_slack), config.relax_slope) for s in spheres
    ]
    return np.concatenate(out) if out else np.zeros(0)


def _box(spheres: tuple[ClearanceSphere, ...]) -> tuple[F64, F64]:
    """Wrist bounds (3,), (3,) [m] keeping every sphere centre inside its field's valid box."""
    lo = np.full(3, -np.inf)
    hi = np.full(3, np.inf)
    for s in spheres:
        lo = np.maximum(lo, s.field.lower - s.offsets.min(axis=0))
        hi = np.minimum(hi, s.field.upper - s.offsets.max(axis=0))
    return lo, hi


def _clearances(
    spheres: tuple[ClearanceSphere, ...], wrist: ca.MX, tau: F64, keep_alive: list[ca.Function]
) -> list[tuple[ClearanceSphere, ca.MX, ca.MX]]:
    """(sphere, centres (3, M), field distance (1, M)) per sphere; one field callback per distinct
    grid evaluates the centres of all spheres on it at once."""
    out: list[tuple[ClearanceSphere, ca.MX, ca.MX]] = []
    m = tau.size
    for field_id in dict.fromkeys(id(s.field) for s in spheres):
        group = [s for s in spheres if id(s.field) == field_id]
        centres = [wrist + ca.DM(s.offset_at(tau).T) for s in group]
        fn = group[0].field.casadi_function(m * len(group), f"distance_{len(keep_alive)}")
        keep_alive.append(fn)
        dist = fn(ca.horzcat(*centres))
        out += [
            (s, c, dist[:, i * m : (i + 1) * m]) for i, (s, c) in enumerate(zip(group, centres, strict=True))
        ]
    return out


def _check_inputs(start: ArrayLike, goal: ArrayLike, duration: float, cfg: MinJerkConfig) -> tuple[F64, F64]:
    a = np.asarray(start, dtype=np.float64).reshape(-1)
    b = np.asarray(goal, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or b.shape != (3,) or not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise PlanningError("start and goal must be 3 finite numbers each [m]")
    if not (math.isfinite(duration) and duration > 0.0):
        raise PlanningError(f"duration must be > 0 [s], got {duration}")
    dist = float(np.linalg.norm(b - a))
    t_min = min_duration(dist, cfg.max_speed, cfg.max_acceleration)
    if duration < t_min:
        raise PlanningError(
            f"duration {duration:.3f} s is too short: moving {dist:.3f} m rest to rest with |v| <= "
            f"{cfg.max_speed} m/s and |a| <= {cfg.max_acceleration} m/s² takes at least {t_min:.3f} s"
        )
    return a, b


def solve_min_jerk(
    start: ArrayLike,
    goal: ArrayLike,
    duration: float,
    spheres: tuple[ClearanceSphere, ...],
    config: MinJerkConfig | None = None,
    *,
    initial: ArrayLike | None = None,
    warm_start: str = "",
) -> MinJerkSolution:
    """Minimize ∫|x'''|² dt from ``start`` to ``goal`` (3,) [m] in ``duration`` [s] (rest to rest).

    Args:
        spheres: clearance constraints (may be empty: then the result is the free-space min-jerk line).
        config: optimizer parameters.
        initial: (N, 3) [m] warm-start path sampled uniformly in time over [0, T] (N >= 2), smoothed by
            :func:`initial_spline`; None = the straight minimum-jerk line.
        warm_start: a label for the initial guess, kept in the solution and error messages.

    Raises:
        PlanningError: bad inputs; a duration shorter than :func:`min_duration` allows; an end outside
            a field grid; IPOPT failing (the message names its return status) or returning a solution
            that violates a clearance.
    """
    cfg = config or MinJerkConfig()
    a, b = _check_inputs(start, goal, duration, cfg)
    lo, hi = _box(spheres)
    for name, p in (("start", a), ("goal", b)):
        if np.any(p < lo - 1e-9) or np.any(p > hi + 1e-9):
            raise PlanningError(
                f"{name} {p.round(3).tolist()} [m] lies outside the distance grid "
                f"{lo.round(3).tolist()}..{hi.round(3).tolist()}"
            )
    k, m = cfg.knots, cfg.checks_per_segment
    h = duration / (k - 1)
    row_scale = np.concatenate([np.ones(k), np.full(k, 1.0 / h), np.full(k, 1.0 / h**2)])  # Z = S Ẑ
    t0 = time.perf_counter()
    z = ca.MX.sym("z", 3 * k * 3)
    Zs = ca.reshape(z, 3 * k, 3)
    scale = 720.0 * max(float(np.linalg.norm(b - a)), 0.05) ** 2 / duration**5  # straight line's jerk
    cost = ca.sumsqr(ca.mtimes(_sparse(jerk_cost_root(k, duration) * row_scale / math.sqrt(scale)), Zs))
    groups: list[ca.MX] = []
    lbg: list[F64] = []
    ubg: list[F64] = []
    for deriv, bound in ((1, cfg.max_speed), (2, cfg.max_acceleration)):
        vals = ca.mtimes(_sparse(value_operator(k, duration, m, deriv)[1:-1] * row_scale / bound), Zs)
        groups.append(ca.sum2(vals * vals))
        lbg.append(np.full(vals.shape[0], -np.inf))
        ubg.append(np.ones(vals.shape[0]))
    wrist = ca.mtimes(_sparse(value_operator(k, duration, m)[1:-1] * row_scale), Zs).T  # (3, M)
    tau = _check_tau(k, m)
    keep_alive: list[ca.Function] = []  # CasADi callbacks must outlive the solver
    for sphere, centres, dist in _clearances(spheres, wrist, tau, keep_alive):
        ends = sphere.relaxed_ends(a, b, cfg.relax_slack)
        groups.append((dist - sphere.requirement_casadi(centres, ends, cfg.relax_slope)).T)
        lbg.append(np.zeros(tau.size))
        ubg.append(np.full(tau.size, np.inf))
    x0 = (
        initial_spline(initial, a, b, duration, knots=k, smoothing=cfg.warm_start_smoothing).stacked()
        / row_scale[:, None]
    )
    inset = np.minimum(_BOX_INSET, 0.25 * (hi - lo))
    lbx = np.full((3 * k, 3), -np.inf)
    ubx = np.full((3 * k, 3), np.inf)
    lbx[:k], ubx[:k] = lo + inset, hi - inset
    for row, value in ((0, a), (k - 1, b)):
        lbx[row] = ubx[row] = value
        for block in (1, 2):
            lbx[block * k + row] = ubx[block * k + row] = 0.0
    x0 = np.clip(x0, lbx, ubx)
    opts = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": cfg.max_iterations,
        "ipopt.max_wall_time": cfg.max_wall_time,
        "ipopt.tol": cfg.tolerance,
        "ipopt.mu_strategy": "adaptive",
    }
    nlp: dict[str, Any] = {"x": z, "f": cost, "g": ca.vertcat(*groups)}
    solver = ca.nlpsol("minjerk", "ipopt", nlp, cast(Any, opts))
    t1 = time.perf_counter()
    result = solver(
        x0=x0.reshape(-1, order="F"),
        lbx=lbx.reshape(-1, order="F"),
        ubx=ubx.reshape(-1, order="F"),
        lbg=np.concatenate(lbg),
        ubg=np.concatenate(ubg),
    )
    t2 = time.perf_counter()
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    iters = int(stats.get("iter_count", -1))
    sol = np.asarray(result["x"], dtype=np.float64).reshape(3 * k, 3, order="F") * row_scale[:, None]
    spline = QuinticSpline(duration, sol[:k], sol[k : 2 * k], sol[2 * k :])
    worst = margins(spline, spheres, cfg)
    min_margin = float(worst.min()) if worst.size else math.inf
    g = np.asarray(result["g"], dtype=np.float64).reshape(-1)
    lo_g, hi_g = np.concatenate(lbg), np.concatenate(ubg)
    violation = float(max(0.0, np.max(lo_g - g, initial=0.0), np.max(g - hi_g, initial=0.0)))
    if status in _KEEP_IF_FEASIBLE and violation <= cfg.constraint_tolerance:
        # IPOPT stalled or ran out of budget on a feasible iterate (bounds, ends and clearance hold): keep it
        _LOG.info("min-jerk: IPOPT %s after %d iterations on a feasible iterate; kept", status, iters)
        status = f"feasible ({status})"
    elif status not in _SUCCESS:
        raise PlanningError(
            f"IPOPT did not find a collision-free minimum-jerk trajectory: return status {status} after "
            f"{iters} iterations ({t2 - t1:.2f} s; worst clearance margin {min_margin:+.3f} m; warm start "
            f"{warm_start or 'straight'}); the goal may be enclosed by obstacles or the duration and "
            "bounds too tight"
        )
    if min_margin < -cfg.constraint_tolerance:  # the check points between the constraint samples
        raise PlanningError(
            f"IPOPT returned {status} but the trajectory violates the clearance by {-min_margin:.4f} m "
            f"(> constraint_tolerance {cfg.constraint_tolerance} m)"
        )
    _LOG.debug("min-jerk: %s in %d iterations, build %.3f s, solve %.3f s", status, iters, t1 - t0, t2 - t1)
    return MinJerkSolution(
        spline=spline,
        status=status,
        iterations=iters,
        solve_time=t2 - t1,
        build_time=t1 - t0,
        jerk_cost=spline.jerk_cost(),
        min_margin=min_margin,
        warm_start=warm_start,
    )
