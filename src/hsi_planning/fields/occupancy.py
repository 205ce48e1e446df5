"""Voxelized obstacle and target occupancy of the grid from a labelled point cloud.

A node (cell centre) is **occupied** by a set of points when one of them lies within
``resolution / 2 + dilation_radius`` of it (Euclidean). With the default dilation of half a cell this is
one cell: any surface sampled more densely than about 3 cm leaves no 6-connected gap, so the occupied
shell is a wall that fast marching (6-neighbour stencil) cannot cross. Obstacles are therefore inflated
by up to one cell, which errs on the safe side for the hand.

A point cloud only sees **surfaces**: the inside of thick furniture or of a closed box is not occupied by
points. With ``fill_enclosed`` the cavities fully enclosed by occupied nodes (not connected to the grid
boundary) are filled; an open cabinet's inside stays free, as it should. A body seen from one side only
(an open shell) is not closed and its inside stays free: fast marching then runs through it.

Points outside the grid only matter within the dilation distance of the border nodes (the Euclidean
distance field D_o uses all obstacle points). Where target and obstacle occupancy overlap (an object
standing on a shelf), the node belongs to the target.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from hsi_planning.errors import CloudError, PlanningError
from hsi_planning.fields.distance import point_distance
from hsi_planning.fields.grid import GridSpec

_LOG = logging.getLogger(__name__)

BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class TargetObstaclePoints:
    """The target and obstacle points picked from a labelled cloud.

    Attributes:
        target: (Nt, 3) [m] points whose label is a target label (Nt ≥ 1).
        obstacles: (No, 3) [m] points whose label is an obstacle label (may be empty).
    """

    target: NDArray[np.float64]
    obstacles: NDArray[np.float64]


def split_cloud(
    points: ArrayLike, labels: ArrayLike, target_labels: Sequence[int], obstacle_labels: Sequence[int]
) -> TargetObstaclePoints:
    """Validate a labelled cloud and pick its target and obstacle points (copies).

    Args:
        points: (N, 3) [m] world-frame points.
        labels: (N,) integer label per point.
        target_labels: labels that make up the target object (at least one must be present).
        obstacle_labels: labels treated as obstacles; points with other labels are ignored.

    Raises:
        CloudError: empty cloud, wrong shapes, NaN/inf points, non-integer labels, a label that is both
            target and obstacle, or no point with a target label.
    """
    pts = np.array(points, dtype=np.float64, copy=True)
    lab = np.asarray(labels)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise CloudError(f"points must have shape (N, 3) [m], got {pts.shape}")
    if pts.shape[0] == 0:
        raise CloudError("the point cloud is empty; the fields need target (and obstacle) points")
    if not np.isfinite(pts).all():
        bad = int((~np.isfinite(pts).all(axis=1)).sum())
        raise CloudError(
            f"{bad} of {pts.shape[0]} points are NaN or infinite; drop them before computing fields"
        )
    if lab.shape != (pts.shape[0],):
        raise CloudError(f"labels must have shape ({pts.shape[0]},) (one per point), got {lab.shape}")
    if not np.issubdtype(lab.dtype, np.integer):
        raise CloudError(f"labels must be integers, got dtype {lab.dtype}")
    targets = {int(v) for v in target_labels}
    obstacles = {int(v) for v in obstacle_labels}
    if not targets:
        raise CloudError("target_labels is empty; name at least one label of the target object")
    both = sorted(targets & obstacles)
    if both:
        raise CloudError(f"label(s) {both} are both target and obstacle; each label must be one or the other")
    is_target = np.isin(lab, sorted(targets))
    if not is_target.any():
        present = sorted({int(v) for v in np.unique(lab)})
        raise CloudError(f"no point has a target label {sorted(targets)}; labels in the cloud: {present}")
    is_obstacle = np.isin(lab, sorted(obstacles)) if obstacles else np.zeros(lab.shape, dtype=bool)
    missing = sorted(obstacles - {int(v) for v in np.unique(lab[is_obstacle])})
    if missing:
        _LOG.debug("obstacle label(s) %s not present in the cloud", missing)
    return TargetObstaclePoints(target=pts[is_target], obstacles=pts[is_obstacle])


def occupancy_from_distance(
    distance: NDArray[np.float64], grid: GridSpec, dilation_radius: float, fill_enclosed: bool
) -> BoolArray:
    """(n, n, n) occupancy from node-to-nearest-point distances (n, n, n) [m] (see the module doc)."""
    occ = np.asarray(distance <= 0.5 * grid.resolution + dilation_radius + 1e-9)
    if fill_enclosed and occ.any():
        occ = np.asarray(ndimage.binary_fill_holes(occ))
    return occ


def voxelize(
    grid: GridSpec, points: ArrayLike, dilation_radius: float = 0.0125, fill_enclosed: bool = True
) -> BoolArray:
    """(n, n, n) occupancy of ``grid`` by ``points`` (N, 3) [m] (see the module doc)."""
    return occupancy_from_distance(point_distance(grid, points), grid, dilation_radius, fill_enclosed)


def free_reachable(obstacle: BoolArray, target: BoolArray) -> BoolArray:
    """(n, n, n) free nodes (neither obstacle nor target) 6-connected to the grid boundary."""
    free = ~obstacle & ~target
    labels, count = ndimage.label(free)
    if count == 0:
        return np.zeros_like(free)
    border = np.concatenate(
        [
            labels[0].ravel(),
            labels[-1].ravel(),
            labels[:, 0].ravel(),
            labels[:, -1].ravel(),
            labels[:, :, 0].ravel(),
            labels[:, :, -1].ravel(),
        ]
    )
    outside = np.unique(border[border > 0])
    return np.asarray(np.isin(labels, outside))


def check_target_accessible(obstacle: BoolArray, target: BoolArray) -> None:
    """Raise unless a free node next to the target is reachable from the grid boundary.

    Raises:
        PlanningError: the target occupies no node, or it is fully enclosed by obstacles (e.g. inside a
            closed cabinet), so no hand can reach it from outside the grid.
    """
    if not target.any():
        raise PlanningError("the target occupies no grid node; is the grid centred on the target?")
    rim = ndimage.binary_dilation(target) & ~target & ~obstacle
    if not rim.any():
        raise PlanningError("the target is fully enclosed by obstacles: no free node touches it")
    if not (rim & free_reachable(obstacle, target)).any():
        raise PlanningError(
            "the target is fully enclosed: no free node next to it is connected to the grid boundary "
            "(open the container first, or lower dilation_radius if a gap is being closed by inflation)"
        )
