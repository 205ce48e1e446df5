"""Sampling a collision-free geometric reach path: random bulge and via-point noise, bent out of collision.

Each attempt draws a target deviation ratio, a bulge direction (the preferred one rotated about the
chord by a random angle, spreading wider on later attempts) and mid-reach noise, scales the bulge so the
path's max deviation from the chord matches the target, then checks the wrist sphere against the
obstacles and bends the free part away from the worst violation (a Gaussian bump along the push
direction) a few times. After ``max_attempts`` failed attempts it raises :class:`PlanningError`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hsi_planning.demos.obstacles import ObstacleField
from hsi_planning.demos.paths import FreePart, bend_bump, free_part, max_deviation_ratio, rotate_about
from hsi_planning.demos.profiles import arc_length
from hsi_planning.demos.reach_config import ReachModelConfig
from hsi_planning.errors import PlanningError

_LOG = logging.getLogger(__name__)
_TOLERANCE = 1e-3  #: [m] slack on the clearance relaxed to what the contact/start pose has


@dataclass(frozen=True)
class PathSample:
    """A collision-free geometric path (approach direction: free pose -> contact).

    Attributes:
        points: (N, 3) [m] dense path samples, first = free pose, last = contact.
        tail_start: index of the pre-contact waypoint (N - 1 when there is no tail).
        deviation: max deviation from the chord / chord length [-].
        attempts: attempts used (1 = first sample was free).
        min_margin: [m] min over samples of (signed distance - required clearance); inf in free space.
    """

    points: NDArray[np.float64]
    tail_start: int
    deviation: float
    attempts: int
    min_margin: float


def _join(free: NDArray[np.float64], tail: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.vstack([free, tail[1:]]) if len(tail) > 1 else free


def required_clearance(
    arc: NDArray[np.float64],
    tail_start: int,
    *,
    full: float,
    start_clear: float,
    end_clear: float,
    relax: float,
) -> NDArray[np.float64]:
    """(N,) [m] clearance required at each path sample with arc length ``arc`` (N,) [m].

    ``full`` [m] away from the ends; inside the tail (from ``tail_start`` on) no more than the contact
    pose has (``end_clear``), relaxing linearly over ``relax`` [m] before it; the same at the start.
    """
    s_tail = arc[tail_start]
    end_c = min(full, max(0.0, end_clear - _TOLERANCE))
    start_c = min(full, max(0.0, start_clear - _TOLERANCE))
    near_end = end_c + (full - end_c) * np.clip((s_tail - arc) / relax, 0.0, 1.0)
    near_start = start_c + (full - start_c) * np.clip(arc / relax, 0.0, 1.0)
    return np.asarray(np.minimum(near_end, near_start), dtype=np.float64)


def _solve_amplitude(part: FreePart, tail: NDArray[np.float64], target: float, distance: float) -> float:
    """Bulge amplitude [m] that makes the whole path's max deviation ratio equal ``target``."""
    zero = np.zeros_like(part.base)

    def dev(amp: float) -> float:
        return max_deviation_ratio(_join(part.points(amp, zero), tail))

    if dev(0.0) >= target:
        return 0.0
    grid = np.linspace(0.0, 0.8 * distance, 17)
    values = [dev(float(a)) for a in grid]
    above = [i for i, v in enumerate(values) if v >= target]
    if not above:
        return float(grid[-1])
    lo, hi = float(grid[above[0] - 1]), float(grid[above[0]])
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if dev(mid) < target else (lo, mid)
    return 0.5 * (lo + hi)


def sample_collision_free_path(
    start: NDArray[np.float64],
    contact: NDArray[np.float64],
    tail: NDArray[np.float64],
    *,
    end_direction: NDArray[np.float64] | None,
    preference: NDArray[np.float64],
    obstacles: ObstacleField | None,
    clearance: float,
    deviation: float,
    config: ReachModelConfig,
    rng: np.random.Generator,
) -> PathSample:
    """Sample a path from ``start`` to ``contact`` (3,) [m] ending with ``tail`` (K, 3) [m].

    ``end_direction``: unit tangent where the free part meets the tail (None: chord);
    ``preference``: unit (3,) preferred bulge direction; ``clearance`` [m] required wrist clearance;
    ``deviation``: median of the sampled max deviation ratio [-] (lognormal, ``config.deviation_spread``).

    Raises:
        PlanningError: the contact or start lies inside an obstacle, the tail collides, or no
            collision-free sample was found in ``config.max_attempts`` attempts.
    """
    distance = float(np.linalg.norm(contact - start))
    axis = (contact - start) / distance
    use_field = obstacles is not None and len(obstacles.names) > 0
    start_clear = end_clear = math.inf
    if use_field:
        assert obstacles is not None
        start_clear, end_clear = (float(v) for v in obstacles.distance(np.vstack([start, contact])))
        for label, value, point in (("contact", end_clear, contact), ("start", start_clear, start)):
            if value < 0.0:
                name = obstacles.nearest_name(point[None, :])[0]
                raise PlanningError(
                    f"the {label} position {np.round(point, 3).tolist()} [m] lies inside obstacle {name!r} "
                    f"(signed distance {value:.3f} m); move it into free space"
                )
    best_margin, best_name = -math.inf, ""
    for attempt in range(config.max_attempts):
        target = float(
            np.clip(
                deviation * np.exp(rng.normal(0.0, config.deviation_spread)),
                config.deviation_min,
                config.deviation_max,
            )
        )
        angle = rng.normal(0.0, math.radians(config.bulge_angle_std) * (1.0 + 0.5 * attempt))
        if attempt >= 2 and rng.random() < 0.3:
            angle += math.pi
        direction = rotate_about(preference, axis, float(angle))
        exponent = config.bulge_exponent + config.bulge_exponent_jitter * rng.uniform(-1.0, 1.0)
        part = free_part(
            start,
            tail[0],
            end_direction=end_direction,
            bulge_direction=direction,
            bulge_exponent=exponent,
            noise_std=config.noise_ratio * distance,
            rng=rng,
            step=config.path_step,
        )
        amplitude = _solve_amplitude(part, tail, target, distance)
        bend = np.zeros_like(part.base)
        n_free = len(part.u)
        for _ in range(config.bend_iterations + 1):
            points = _join(part.points(amplitude, bend), tail)
            points[0], points[-1] = start, contact
            if not use_field:
                return PathSample(points, n_free - 1, max_deviation_ratio(points), attempt + 1, math.inf)
            assert obstacles is not None
            arc = arc_length(points)
            need = required_clearance(
                arc,
                n_free - 1,
                full=clearance,
                start_clear=start_clear,
                end_clear=end_clear,
                relax=config.clearance_relax_length,
            )
            margin = obstacles.distance(points) - need
            worst = int(np.argmin(margin))
            if margin[worst] >= 0.0:
                _LOG.debug("reach path found on attempt %d (min margin %.3f m)", attempt + 1, margin[worst])
                return PathSample(
                    points, n_free - 1, max_deviation_ratio(points), attempt + 1, float(margin[worst])
                )
            if margin[worst] > best_margin:
                best_margin = float(margin[worst])
                best_name = obstacles.nearest_name(points[worst : worst + 1])[0]
            if worst >= n_free - 1:
                raise PlanningError(
                    f"the straight insertion/lift near the contact passes {-margin[worst]:.3f} m too close "
                    f"to obstacle {obstacles.nearest_name(points[worst : worst + 1])[0]!r}; check "
                    "approach_axis (inward depth axis of the opening) and insertion_depth"
                )
            push = obstacles.push_direction(points[worst : worst + 1])[0]
            gain = -float(margin[worst]) + 0.01
            bend = bend + gain * bend_bump(part.u, float(part.u[worst]), 0.12)[:, None] * push[None, :]
    raise PlanningError(
        f"no collision-free reach found in {config.max_attempts} attempts: the best sample still comes "
        f"{-best_margin:.3f} m closer to {best_name!r} than the wrist clearance of {clearance:.3f} m allows; "
        "free the way (open the door, move the blocking object) or raise max_attempts / bend_iterations"
    )
