"""All fields of one scene and demonstration on one object-centric grid, and how to compute them."""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from hsi_planning.errors import PlanningError
from hsi_planning.fields.config import FieldConfig
from hsi_planning.fields.distance import inverse_field, point_distance, target_distance
from hsi_planning.fields.grid import GridSpec
from hsi_planning.fields.occupancy import check_target_accessible, occupancy_from_distance, split_cloud
from hsi_planning.fields.toa import time_of_arrival
from hsi_planning.trajectory import WristTrajectory

_LOG = logging.getLogger(__name__)

F32 = NDArray[np.float32]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class FieldSet:
    """The fields of one scene (and optionally one demonstration), each (n, n, n) on ``grid``.

    Attributes:
        grid: the object-centric grid.
        config: the configuration the fields were computed with.
        d_t: [1/m] 1 / max(geodesic distance to the target, ε); 0 on obstacle / unreachable nodes.
        d_o: [1/m] 1 / max(Euclidean distance to the nearest obstacle point, ε); 0 without obstacles.
        d_toa: [1/s] 1 / max(φ, ε_t); 0 on obstacle / unreachable nodes; None without a demonstration.
        dist_t: [m] geodesic distance to the target (``config.unreachable_distance`` where blocked).
        dist_o: [m] Euclidean distance to the nearest obstacle point (``unreachable_distance`` if none).
        phi: [s] time of arrival (``config.unreachable_time`` where blocked); None without a demonstration.
        obstacle_mask: obstacle occupancy (excludes target nodes).
        target_mask: target occupancy.
        goal: (3,) [m] the demonstration's contact point; None without a demonstration.
    """

    grid: GridSpec
    config: FieldConfig
    d_t: F32
    d_o: F32
    d_toa: F32 | None
    dist_t: F32
    dist_o: F32
    phi: F32 | None
    obstacle_mask: BoolArray
    target_mask: BoolArray
    goal: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        shape = self.grid.shape
        for name in ("d_t", "d_o", "d_toa", "dist_t", "dist_o", "phi", "obstacle_mask", "target_mask"):
            value = getattr(self, name)
            if value is None:
                if name not in ("d_toa", "phi"):
                    raise PlanningError(f"FieldSet.{name} is required")
                continue
            dtype = bool if name.endswith("_mask") else np.float32
            arr = np.array(value, dtype=dtype, copy=True)
            if arr.shape != shape:
                raise PlanningError(f"FieldSet.{name} has shape {arr.shape}, the grid needs {shape}")
            object.__setattr__(self, name, arr)
        if (self.d_toa is None) != (self.phi is None) or (self.phi is None) != (self.goal is None):
            raise PlanningError("FieldSet: d_toa, phi and goal must be all given or all None")
        if self.goal is not None:
            object.__setattr__(self, "goal", np.array(self.goal, dtype=np.float64, copy=True).reshape(3))

    @property
    def has_toa(self) -> bool:
        """Whether a time-of-arrival field (from a demonstration) is present."""
        return self.phi is not None


def _approach_direction(
    demo: WristTrajectory | None, direction: ArrayLike | None
) -> NDArray[np.float64] | None:
    if direction is not None:
        return np.asarray(direction, dtype=np.float64).reshape(3)
    if demo is None:
        return None
    ci = demo.contact_index
    other = demo.position[0] if demo.segment == "approach" else demo.position[-1]
    return np.asarray(other - demo.position[ci])


def compute_fields(
    points: ArrayLike,
    labels: ArrayLike,
    target_labels: Sequence[int],
    obstacle_labels: Sequence[int],
    demo: WristTrajectory | None = None,
    *,
    config: FieldConfig | None = None,
    grid: GridSpec | None = None,
    approach_direction: ArrayLike | None = None,
) -> FieldSet:
    """Compute D_t, D_o (and D_toa with a demonstration) from a labelled point cloud.

    Args:
        points: (N, 3) [m] world-frame cloud.
        labels: (N,) integer label per point.
        target_labels: labels of the target object.
        obstacle_labels: labels of obstacles; other labels are ignored.
        demo: a demonstration ending (approach) or starting (leave) at the contact with the target.
        config: field parameters (defaults: 0.80 m cube, 0.025 m cells).
        grid: use this grid instead of one centred on the target.
        approach_direction: (3,) direction the hand comes from, for ``config.approach_shift``;
            default: from the contact point towards the other end of ``demo``.

    Raises:
        CloudError: empty cloud, NaN points, bad labels, target label absent.
        PlanningError: the target is fully enclosed, or the demonstration's goal is outside the grid or
            inside an obstacle.
    """
    cfg = config or FieldConfig()
    t0 = time.perf_counter()
    cloud = split_cloud(points, labels, target_labels, obstacle_labels)
    if grid is None:
        grid = GridSpec.around(
            cloud.target,
            cfg.size,
            cfg.resolution,
            cfg.approach_shift,
            _approach_direction(demo, approach_direction),
        )
    e_target = point_distance(grid, cloud.target)
    e_obstacle = point_distance(grid, cloud.obstacles)
    target_shell = occupancy_from_distance(e_target, grid, cfg.dilation_radius, fill_enclosed=False)
    target = occupancy_from_distance(e_target, grid, cfg.dilation_radius, cfg.fill_enclosed)
    # Fill obstacle cavities with the target counted as solid, so a closed box holding the target fills.
    solid = occupancy_from_distance(e_obstacle, grid, cfg.dilation_radius, fill_enclosed=False) | target
    if cfg.fill_enclosed:
        solid = np.asarray(ndimage.binary_fill_holes(solid))
    obstacle = solid & ~target
    check_target_accessible(obstacle, target)
    far = cfg.unreachable_distance
    dist_t = target_distance(
        grid,
        e_target,
        target & ~target_shell,
        obstacle,
        surface_offset=cfg.surface_offset,
        unreachable_distance=far,
        order=cfg.fmm_order,
    )
    dist_o = np.minimum(e_obstacle, far)
    d_toa: F32 | None = None
    phi: NDArray[np.float64] | None = None
    goal: NDArray[np.float64] | None = None
    if demo is not None:
        phi, goal = time_of_arrival(grid, demo, obstacle, cfg)
        d_toa = inverse_field(phi, cfg.epsilon_time, cfg.unreachable_time)
    fields = FieldSet(
        grid=grid,
        config=cfg,
        d_t=inverse_field(dist_t, cfg.epsilon, far),
        d_o=inverse_field(dist_o, cfg.epsilon, far),
        d_toa=d_toa,
        dist_t=dist_t.astype(np.float32),
        dist_o=dist_o.astype(np.float32),
        phi=None if phi is None else phi.astype(np.float32),
        obstacle_mask=obstacle,
        target_mask=target,
        goal=goal,
    )
    _LOG.debug("fields on a %d³ grid in %.3f s", grid.n, time.perf_counter() - t0)
    return fields
