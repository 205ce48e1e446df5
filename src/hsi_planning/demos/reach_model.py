"""The calibrated human-reach model: generated, human-like 6D wrist demonstrations in a scene.

:func:`generate_reach` turns a :class:`ReachRequest` (free pose, contact pose, container opening axis,
hand, action, segment) into a timed :class:`~hsi_planning.trajectory.WristTrajectory` that is curved
(max deviation from the chord a few % to ~15 %), bell-shaped in speed with the peak before mid-movement
for grasps, slower where the path bends (speed ∝ curvature^beta), enters containers along their depth
axis slowly, lifts a carried object, varies most mid-reach (seeded) and keeps the wrist sphere clear of
the scene's obstacles. Defaults are calibrated against HDM05 ``grabHighR`` / ``depositFloorR``
(``benchmarks/human_reach.py``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from hsi_planning.demos.obstacles import ObstacleField
from hsi_planning.demos.orientation import (
    interpolate_orientation,
    rotation_phase,
    smooth_rotation_noise,
    unit_quaternion,
)
from hsi_planning.demos.paths import contact_tail, default_bulge_preference
from hsi_planning.demos.profiles import (
    arc_length,
    fitts_duration,
    path_curvature,
    power_law_modulation,
    time_path,
)
from hsi_planning.demos.reach_config import ReachModelConfig
from hsi_planning.demos.sampling import PathSample, sample_collision_free_path
from hsi_planning.errors import PlanningError
from hsi_planning.trajectory import ACTIONS, HANDS, SEGMENTS, Action, Hand, Segment, WristTrajectory

_LOG = logging.getLogger(__name__)

PLANNER_NAME = "human_reach_model"


def _vector(value: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.array(value, dtype=np.float64, copy=True).reshape(-1)
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise PlanningError(f"{name} must be 3 finite numbers [m], got {value!r}")
    return arr


@dataclass(frozen=True)
class ReachRequest:
    """One reach to generate.

    Attributes:
        start_position: (3,) [m] the wrist's free pose away from the contact: the first sample of an
            approach, the last sample of a leave.
        start_quaternion: (4,) [x y z w] wrist orientation at that free pose.
        contact_position: (3,) [m] wrist position at the contact (grasp or release).
        contact_quaternion: (4,) [x y z w] wrist orientation at the contact.
        approach_axis: (3,) unit direction the hand travels in while entering the container (the
            opening's depth axis pointing inward), or None for a free-space target.
        hand, action, segment: see :class:`WristTrajectory`.
        object_name: the object of the contact; its mesh is left out of the obstacles.
        carried_radius: [m] radius of the carried object (approach to place, leave after grasp).
        insertion_depth: [m] straight insertion length; None = the config's ``insertion_length``.
    """

    start_position: NDArray[np.float64]
    start_quaternion: NDArray[np.float64]
    contact_position: NDArray[np.float64]
    contact_quaternion: NDArray[np.float64]
    approach_axis: NDArray[np.float64] | None = None
    hand: Hand = "right"
    action: Action = "grasp"
    segment: Segment = "approach"
    object_name: str = ""
    carried_radius: float = 0.0
    insertion_depth: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "start_position", _vector(self.start_position, "start_position"))
        object.__setattr__(self, "contact_position", _vector(self.contact_position, "contact_position"))
        object.__setattr__(
            self, "start_quaternion", unit_quaternion(self.start_quaternion, "start_quaternion")
        )
        object.__setattr__(
            self, "contact_quaternion", unit_quaternion(self.contact_quaternion, "contact_quaternion")
        )
        if self.approach_axis is not None:
            axis = _vector(self.approach_axis, "approach_axis")
            norm = float(np.linalg.norm(axis))
            if norm < 1e-9:
                raise PlanningError("approach_axis must be a non-zero direction (or None in free space)")
            object.__setattr__(self, "approach_axis", axis / norm)
        for name, value, valid in (
            ("hand", self.hand, HANDS),
            ("action", self.action, ACTIONS),
            ("segment", self.segment, SEGMENTS),
        ):
            if value not in valid:
                raise PlanningError(f"{name}={value!r} is not valid; choose one of {list(valid)}")
        if not (np.isfinite(self.carried_radius) and self.carried_radius >= 0.0):
            raise PlanningError(f"carried_radius must be >= 0 [m], got {self.carried_radius}")
        if self.insertion_depth is not None and not self.insertion_depth >= 0.0:
            raise PlanningError(f"insertion_depth must be >= 0 [m] or None, got {self.insertion_depth}")

    @property
    def carrying(self) -> bool:
        """Whether the hand carries an object on this segment (approach to place, leave after grasp)."""
        return (self.action, self.segment) in (("place", "approach"), ("grasp", "leave"))


def _speed_factor(
    points: NDArray[np.float64], tail_start: int, config: ReachModelConfig
) -> NDArray[np.float64]:
    """(N,) local speed factor along the approach-ordered path: power law times slowing in the tail."""
    kappa = path_curvature(points)
    factor = power_law_modulation(
        kappa,
        config.power_law_exponent,
        config.curvature_offset,
        config.modulation_min,
        config.modulation_max,
    )
    arc = arc_length(points)
    if tail_start < len(points) - 1:
        ramp = np.clip((arc - (arc[tail_start] - config.insertion_blend)) / config.insertion_blend, 0.0, 1.0)
        smooth = ramp**2 * (3.0 - 2.0 * ramp)
        slow = config.insertion_speed_ratio * np.minimum(factor, 1.0)  # no power-law speed-up inside
        factor = (1.0 - smooth) * factor + smooth * slow
    return factor


def _duration(
    request: ReachRequest, path: PathSample, config: ReachModelConfig, rng: np.random.Generator
) -> float:
    distance = float(np.linalg.norm(request.contact_position - request.start_position))
    base = fitts_duration(distance, config.fitts_intercept, config.fitts_slope, config.fitts_target_width)
    arc = arc_length(path.points)
    tail_length = float(arc[-1] - arc[path.tail_start])
    jitter = float(np.exp(rng.normal(0.0, config.duration_jitter)))
    if request.action == "place":
        jitter *= config.duration_factor_place
    return base * jitter + config.insertion_time_per_m * tail_length


def generate_reach(
    request: ReachRequest,
    obstacles: ObstacleField | None,
    config: ReachModelConfig | None = None,
    rng: np.random.Generator | None = None,
) -> WristTrajectory:
    """Generate one human-like timed 6D wrist trajectory for ``request``.

    Args:
        request: free pose, contact pose, opening axis, hand, action, segment.
        obstacles: the scene's obstacle field (the request's ``object_name`` is left out), or None for
            free space.
        config: model parameters (defaults calibrated on HDM05).
        rng: seeded generator; the same seed gives the same trajectory. None = ``default_rng(0)``.

    Returns:
        A :class:`WristTrajectory` sampled at ``config.sample_rate`` [Hz]: an approach runs from the free
        pose to the contact (``contact_index`` last), a leave from the contact to the free pose
        (``contact_index`` 0). Its ``meta`` records the sampled parameters.

    Raises:
        PlanningError: degenerate request, contact/start inside an obstacle, or no collision-free path.
    """
    config = config or ReachModelConfig()
    rng = rng if rng is not None else np.random.default_rng(0)
    start, contact = request.start_position, request.contact_position
    distance = float(np.linalg.norm(contact - start))
    if distance < 0.01:
        raise PlanningError(f"start and contact are {distance:.4f} m apart; a reach needs at least 0.01 m")
    field = (
        obstacles.without([request.object_name])
        if obstacles is not None and request.object_name
        else obstacles
    )
    lift = config.lift_height if request.carrying else 0.0
    insertion = config.insertion_length if request.insertion_depth is None else request.insertion_depth
    insertion = min(insertion, 0.4 * distance) if request.approach_axis is not None else 0.0
    tail = contact_tail(contact, request.approach_axis, insertion, lift, config.path_step)
    end_direction = None
    if len(tail) > 1:
        end_direction = (tail[1] - tail[0]) / np.linalg.norm(tail[1] - tail[0])
    hand_sign = 1.0 if request.hand == "right" else -1.0
    weights = (config.bulge_weight_up, config.bulge_weight_side)
    preference = default_bulge_preference(start, contact, hand_sign, weights)
    clearance = config.hand_radius
    if request.carrying:
        clearance = max(config.hand_radius, request.carried_radius) + config.carry_clearance
    path = sample_collision_free_path(
        start,
        contact,
        tail,
        end_direction=end_direction,
        preference=preference,
        obstacles=field,
        clearance=clearance,
        deviation=config.deviation(request.action),
        config=config,
        rng=rng,
    )
    factor = _speed_factor(path.points, path.tail_start, config)
    points = path.points
    if request.segment == "leave":
        points, factor = points[::-1].copy(), factor[::-1].copy()
    arc = arc_length(points)
    peak = float(
        np.clip(
            config.peak_time(request.action, request.segment) + rng.normal(0.0, config.peak_jitter),
            0.12,
            0.88,
        )
    )
    duration = _duration(request, path, config, rng)
    sharpness = config.bell_sharpness_place if request.action == "place" else config.bell_sharpness
    t, s = time_path(arc, factor, peak=peak, sharpness=sharpness, duration=duration, rate=config.sample_rate)
    keep = np.concatenate([[True], np.diff(arc) > 1e-9])
    position = np.asarray(CubicSpline(arc[keep], points[keep], axis=0)(s), dtype=np.float64)
    tau = t / t[-1]
    if request.segment == "approach":
        position[0], position[-1] = start, contact
        q_from, q_to = request.start_quaternion, request.contact_quaternion
        phase = rotation_phase(tau, 0.0, config.rotation_end)
    else:
        position[0], position[-1] = contact, start
        q_from, q_to = request.contact_quaternion, request.start_quaternion
        phase = rotation_phase(tau, 1.0 - config.rotation_end, 1.0)
    noise = smooth_rotation_noise(tau, config.orientation_noise, rng)
    quaternion = interpolate_orientation(q_from, q_to, phase, noise)
    meta = {
        "distance": distance,
        "duration": float(t[-1]),
        "peak_time_target": peak,
        "deviation_ratio": path.deviation,
        "attempts": path.attempts,
        "min_clearance_margin": path.min_margin,
        "clearance": clearance,
        "carrying": request.carrying,
    }
    _LOG.debug("generated %s %s %s reach: %s", request.hand, request.action, request.segment, meta)
    return WristTrajectory(
        t=t,
        position=position,
        quaternion=quaternion,
        hand=request.hand,
        action=request.action,
        segment=request.segment,
        contact_index=-1 if request.segment == "approach" else 0,
        planner=PLANNER_NAME,
        object_name=request.object_name,
        meta=meta,
    )
