"""One segment (approach or leave) of the minimum-jerk baseline: fields, spheres, warm start, solve, sampling.

:func:`plan_segment` turns a :class:`SegmentSpec` (end poses, duration, obstacle points, the held
object's bounding sphere when carrying) into a timed 6D :class:`~hsi_planning.trajectory.WristTrajectory`:

1. the truncated distance grid of the obstacle points around the segment (:mod:`.sdf`);
2. the hand sphere (offset 0) and, while carrying, the held object's bounding sphere whose offset from
   the wrist turns with the wrist orientation (:mod:`.clearance`);
3. the warm start: the caller's initial path, else the straight minimum-jerk line when it is clear,
   else a fast-marching corridor (:mod:`.warm_start`); when IPOPT fails from one guess, the other is tried;
4. the IPOPT solve (:mod:`.optimizer`), sampled at ``sample_rate``; the orientation is SLERPed between
   the end orientations with the minimum-jerk phase ``10τ³ − 15τ⁴ + 6τ⁵`` (as a robot planner would).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.demos.orientation import interpolate_orientation, rotation_phase
from hsi_planning.demos.profiles import fitts_duration
from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.minjerk.clearance import ClearanceSphere
from hsi_planning.minjerk.optimizer import MinJerkConfig, MinJerkSolution, solve_min_jerk
from hsi_planning.minjerk.sdf import DistanceGrid, distance_grid
from hsi_planning.minjerk.warm_start import corridor_path, path_is_clear, straight_is_clear
from hsi_planning.trajectory import Action, Hand, Segment, WristTrajectory

_LOG = logging.getLogger(__name__)

F64 = NDArray[np.float64]
#: Samples of the held object's offset track over the segment's normalized time.
_OFFSET_SAMPLES = 21
#: [m] a given warm start deeper than this in an obstacle is tried after the corridor (resampling and
#: smoothing a collision-free reference moves it by a few mm).
_GIVEN_TOLERANCE = 0.01


@dataclass(frozen=True)
class SegmentSettings:
    """How a segment is set up: its distance grid, spheres, warm start, default duration and sampling."""

    resolution: float = 0.02  #: [m] grid node spacing
    padding: float = 0.25  #: [m] grid box = segment ends (and initial path) grown by this
    cap: float = 0.2  #: [m] truncation of the distance (must exceed every sphere's radius + margin)
    max_nodes: int = 400_000  #: [-] most grid nodes (the resolution is coarsened beyond)
    hand_radius: float = 0.04  #: [m] radius of the hand sphere
    margin: float = 0.02  #: [m] clearance of the hand sphere beyond its radius
    held_margin: float = 0.01  #: [m] clearance of the held object's bounding sphere beyond its radius
    sample_rate: float = 120.0  #: [Hz] output sample rate
    fitts_intercept: float = 0.5  #: [s] default duration: Fitts-law intercept (the human-reach model's)
    fitts_slope: float = 0.15  #: [s/bit] default duration: Fitts-law slope
    fitts_width: float = 0.05  #: [m] default duration: effective target width
    speed_fraction: float = (
        0.8  #: [-] default duration keeps the min-jerk peak speed/accel below this share of the bounds
    )

    def __post_init__(self) -> None:
        positive = (
            "resolution",
            "padding",
            "cap",
            "hand_radius",
            "sample_rate",
            "fitts_width",
            "speed_fraction",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"{name} must be a finite number > 0, got {value}")
        for name in ("margin", "held_margin", "fitts_intercept", "fitts_slope"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"{name} must be a finite number >= 0, got {value}")
        if self.max_nodes < 1000:
            raise ConfigError(f"max_nodes must be >= 1000, got {self.max_nodes}")
        if self.speed_fraction > 1.0:
            raise ConfigError(f"speed_fraction must be <= 1, got {self.speed_fraction}")
        if self.hand_radius + self.margin >= self.cap:
            raise ConfigError(f"cap ({self.cap} m) must exceed hand_radius + margin")

    def default_duration(self, distance: float, path_length: float, config: MinJerkConfig) -> float:
        """[s] human-like duration for a reach over ``distance`` [m] (Fitts' law, as the human-reach
        model), lengthened so that the min-jerk profile along ``path_length`` [m] peaks below
        ``speed_fraction`` of the speed (1.875 L/T) and acceleration (5.77 L/T²) bounds."""
        fitts = fitts_duration(distance, self.fitts_intercept, self.fitts_slope, self.fitts_width)
        by_speed = 1.875 * path_length / (self.speed_fraction * config.max_speed)
        by_acc = math.sqrt(5.774 * path_length / (self.speed_fraction * config.max_acceleration))
        return max(fitts, by_speed, by_acc)


@dataclass(frozen=True, eq=False)
class SegmentSpec:
    """What one segment must do (arrays are (3,) [m] positions and (4,) [x y z w] quaternions).

    Attributes:
        start, goal: wrist positions at the segment's first and last sample.
        q_start, q_goal: wrist orientations there.
        duration: [s] fixed duration; None = :meth:`SegmentSettings.default_duration` of the warm start.
        grid: the distance grid of the points the spheres must keep clear of (:func:`build_fields`).
        held_centre: (3,) [m] world centre of the held object's bounding sphere at the contact, or None.
        held_radius: [m] its radius.
        contact: (3,) [m] the wrist at the contact (where ``held_centre`` was measured).
        q_contact: (4,) the wrist orientation at the contact.
        initial: (M, 3) [m] warm-start path uniform in time, or None.
        hand, action, segment, object_name: labels of the output trajectory.
    """

    start: F64
    goal: F64
    q_start: F64
    q_goal: F64
    duration: float | None
    grid: DistanceGrid
    contact: F64
    q_contact: F64
    hand: Hand
    action: Action
    segment: Segment
    object_name: str = ""
    held_centre: F64 | None = None
    held_radius: float = 0.0
    initial: F64 | None = None
    meta: dict[str, Any] = field(default_factory=dict)


def _phase(tau: F64) -> F64:
    return rotation_phase(tau, 0.0, 1.0)


def _held_offsets(spec: SegmentSpec) -> F64:
    """(S, 3) [m] held-sphere centre minus wrist at S uniform normalized times (turning with the wrist)."""
    assert spec.held_centre is not None
    tau = np.linspace(0.0, 1.0, _OFFSET_SAMPLES)
    quats = interpolate_orientation(spec.q_start, spec.q_goal, _phase(tau))
    local = Rotation.from_quat(spec.q_contact).inv().apply(spec.held_centre - spec.contact)
    return np.asarray(Rotation.from_quat(quats).apply(local), dtype=np.float64)


def build_fields(
    obstacles: F64, target: F64, cover: F64, settings: SegmentSettings, *, reach: float, held_radius: float
) -> tuple[DistanceGrid, DistanceGrid]:
    """Distance grids without and with the target's points, on one box: ``cover`` (N, 3) [m] (segment
    ends, initial paths) grown by ``settings.padding + reach`` [m] (``reach``: distance of the held
    object's centre from the wrist). The expensive query over the obstacles runs once for both
    segments; the target (few points) is added by a node-wise minimum. The cap covers the held
    object's requirement (``held_radius`` [m] + margin).

    Args:
        obstacles: (N, 3) [m] every point but the target's; target: (M, 3) [m] the target's points.
    """
    pad = settings.padding + reach
    lower, upper = cover.min(axis=0) - pad, cover.max(axis=0) + pad
    cap = max(settings.cap, held_radius + settings.held_margin + 0.05)
    grids = [
        distance_grid(
            pts, lower, upper, resolution=settings.resolution, cap=cap, max_nodes=settings.max_nodes
        )
        for pts in (obstacles, target)
    ]
    return grids[0], grids[0].minimum(grids[1])


def build_spheres(spec: SegmentSpec, settings: SegmentSettings) -> tuple[ClearanceSphere, ...]:
    """The hand sphere and (carrying) the held object's sphere on the segment's distance grid."""
    grid = spec.grid
    spheres = [ClearanceSphere(grid, settings.hand_radius, settings.margin, np.zeros(3), "hand")]
    if spec.held_centre is not None:
        offsets = _held_offsets(spec)
        spheres.append(ClearanceSphere(grid, spec.held_radius, settings.held_margin, offsets, "held object"))
    return tuple(spheres)


def _guesses(
    spec: SegmentSpec, spheres: tuple[ClearanceSphere, ...], config: MinJerkConfig, settings: SegmentSettings
) -> Iterator[tuple[str, F64 | None]]:
    """Warm starts to try, best first: the collision-free ones (given, straight), the corridor, then the
    colliding ones (IPOPT started inside an obstacle, e.g. a reference path that drags the held object
    through its support, mostly stalls: ``Error_In_Step_Computation``, iteration or time limits)."""
    duration = spec.duration or 1.0
    given = spec.initial is not None and path_is_clear(
        spec.initial,
        spec.start,
        spec.goal,
        duration,
        spheres,
        config=config,
        tolerance=_GIVEN_TOLERANCE,
    )
    if given:
        yield ("given", spec.initial)
    clear = straight_is_clear(spec.start, spec.goal, duration, spheres, config)
    if clear:
        yield ("straight", None)
    corridor = corridor_path(spec.start, spec.goal, spheres, config)
    if corridor is not None:
        yield ("corridor", corridor)
    if spec.initial is not None and not given:
        yield ("given", spec.initial)
    if not clear:
        yield ("straight", None)


def plan_segment(
    spec: SegmentSpec, config: MinJerkConfig, settings: SegmentSettings, planner_name: str = "minjerk"
) -> tuple[WristTrajectory, MinJerkSolution, dict[str, float]]:
    """Optimize one segment; returns the trajectory, the solution and timings [s]: ``spheres`` (their
    set-up), ``solve`` (warm starts + NLP builds + IPOPT, all attempts), ``ipopt`` and ``nlp_build`` (the
    successful attempt's IPOPT call and NLP construction).

    Raises:
        PlanningError: every warm start failed (the message of the first failure, naming the IPOPT
            status, plus the attempts), or bad inputs.
    """
    t0 = time.perf_counter()
    spheres = build_spheres(spec, settings)
    t1 = time.perf_counter()
    errors: list[str] = []
    solution: MinJerkSolution | None = None
    distance = float(np.linalg.norm(spec.goal - spec.start))
    for label, guess in _guesses(spec, spheres, config, settings):
        duration = spec.duration
        if duration is None:
            path = guess if guess is not None else np.vstack([spec.start, spec.goal])
            length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
            duration = settings.default_duration(distance, length, config)
        try:
            solution = solve_min_jerk(
                spec.start, spec.goal, duration, spheres, config, initial=guess, warm_start=label
            )
            break
        except PlanningError as exc:
            errors.append(f"[{label}] {exc}")
            if "IPOPT" not in str(exc):
                break  # input errors do not depend on the warm start
    t2 = time.perf_counter()
    if solution is None:
        raise PlanningError(f"{spec.segment} of {spec.object_name or 'the target'}: " + " | ".join(errors))
    duration = solution.spline.duration
    n = max(2, round(duration * settings.sample_rate) + 1)
    t = np.linspace(0.0, duration, n)
    position = solution.spline.evaluate(t)
    position[0], position[-1] = spec.start, spec.goal
    quaternion = interpolate_orientation(spec.q_start, spec.q_goal, _phase(t / duration))
    meta = {
        **spec.meta,
        "status": solution.status,
        "iterations": solution.iterations,
        "warm_start": solution.warm_start,
        "attempts": len(errors) + 1,
        "jerk_cost": solution.jerk_cost,
        "min_margin": solution.min_margin,
        "duration": duration,
        "grid_shape": list(spheres[0].field.shape),
        "held_radius": spec.held_radius if spec.held_centre is not None else 0.0,
    }
    traj = WristTrajectory(
        t=t,
        position=position,
        quaternion=quaternion,
        hand=spec.hand,
        action=spec.action,
        segment=spec.segment,
        contact_index=-1 if spec.segment == "approach" else 0,
        planner=planner_name,
        object_name=spec.object_name,
        meta=meta,
    )
    _LOG.debug("%s: %s after %d attempt(s), %.3f s", spec.segment, solution.status, len(errors) + 1, t2 - t1)
    times = {
        "spheres": t1 - t0,
        "solve": t2 - t1,
        "ipopt": solution.solve_time,
        "nlp_build": solution.build_time,
    }
    return traj, solution, times
