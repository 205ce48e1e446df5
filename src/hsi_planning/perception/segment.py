"""Segmentation of an unlabelled cloud (a real sensor's) into object clusters with open3d.

Pipeline (z is up; furniture surfaces are level or plumb):

1. Optional crop to a region of interest and voxel downsampling.
2. Repeated RANSAC (``segment_plane``). A horizontal/vertical fit is snapped to exactly level/plumb
   at the densest position (RANSAC often returns a slightly tilted plane through a small board), and
   only inliers forming a connected patch with many points and a furniture-sized extent are removed,
   so an object's slice that happens to lie in the counter-top plane, or a box top, survives.
3. A level sweep removes wide horizontal patches too sparse for RANSAC (a board seen edge-on).
4. DBSCAN (``cluster_dbscan``) of the rest; small clusters are dissolved, and loose points join the
   nearest cluster within ``attach_radius`` (sparse grazing samples, thin handles and spouts).

Cluster ids are dense, ordered by decreasing size; ``-1`` = plane, noise or outside the ROI.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import open3d as o3d
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from hsi_planning.errors import CloudError, ConfigError

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class SegmentConfig:
    """Parameters of :func:`segment_unlabelled`."""

    roi_min: tuple[float, float, float] | None = None  #: lower corner of the region of interest [m]
    roi_max: tuple[float, float, float] | None = None  #: upper corner of the region of interest [m]
    voxel_size: float = 0.0  #: pre-downsampling voxel edge [m]; 0 = use the points as given
    plane_distance: float = 0.006  #: RANSAC inlier distance to a plane [m]
    plane_iterations: int = 400  #: RANSAC iterations per plane [-]
    max_planes: int = 24  #: plane fits attempted at most [-]
    plane_min_points: int = 300  #: a removed planar patch has at least this many points [-]
    plane_min_extent: float = 0.2  #: ... and spans at least this much along its longer side [m]
    plane_patch_eps: float = 0.035  #: neighbour distance that connects points of one planar patch [m]
    level_min_extent: float = 0.35  #: level sweep: horizontal patches this wide are removed (0 = off) [m]
    level_min_points: int = 20  #: level sweep: fewest points of a horizontal level [-]
    orientations: Literal["horizontal", "vertical", "both"] = "both"  #: plane normals removed [-]
    max_tilt_deg: float = 10.0  #: tolerance of "horizontal"/"vertical" plane normals [deg]
    dbscan_eps: float = 0.02  #: DBSCAN neighbourhood radius [m]
    dbscan_min_points: int = 3  #: DBSCAN core-point neighbour count [-]
    min_cluster_points: int = 40  #: smaller clusters are dissolved (their points become noise) [-]
    attach_radius: float = 0.04  #: noise points this close to a cluster join it (0 = off) [m]
    seed: int = 0  #: seed of open3d's RANSAC sampler [-]

    def __post_init__(self) -> None:
        if (self.roi_min is None) != (self.roi_max is None):
            raise ConfigError("roi_min and roi_max must be given together (or neither)")
        lo, hi = self.roi_min or (0.0,) * 3, self.roi_max or (1.0,) * 3
        if not all(a < b for a, b in zip(lo, hi, strict=True)):
            raise ConfigError(
                f"roi_min {self.roi_min} must be below roi_max {self.roi_max} on every axis [m]"
            )
        for name in ("plane_distance", "plane_patch_eps", "dbscan_eps"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"{name} must be > 0 m, got {getattr(self, name)}")
        if min(self.voxel_size, self.plane_min_extent, self.attach_radius, self.level_min_extent) < 0.0:
            raise ConfigError("voxel_size, plane_min_extent, level_min_extent, attach_radius must be >= 0 m")
        for name in (
            "plane_iterations",
            "plane_min_points",
            "level_min_points",
            "dbscan_min_points",
            "min_cluster_points",
        ):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.max_planes < 0:
            raise ConfigError(f"max_planes must be >= 0, got {self.max_planes}")
        if not 0.0 <= self.max_tilt_deg < 45.0:
            raise ConfigError(f"max_tilt_deg must be in [0, 45) deg, got {self.max_tilt_deg}")


@dataclass(frozen=True)
class Plane:
    """A removed plane ``normal . x + offset = 0`` (normal: (3,) unit; offset [m])."""

    normal: tuple[float, float, float]
    offset: float
    orientation: Literal["horizontal", "vertical"]
    points: int  #: points removed as part of this plane [-]


@dataclass(frozen=True)
class SegmentInfo:
    """What :func:`segment_unlabelled` found."""

    planes: list[Plane] = field(default_factory=list)
    cluster_sizes: list[int] = field(default_factory=list)  #: DBSCAN points per cluster id 0, 1, ... [-]
    noise_points: int = 0  #: points in no cluster and no plane [-]
    seconds: float = 0.0  #: wall time [s]


def _orientation(normal: NDArray[np.float64], max_tilt_deg: float) -> str:
    tilt = np.cos(np.radians(90.0 - max_tilt_deg))
    if abs(normal[2]) >= np.cos(np.radians(max_tilt_deg)):
        return "horizontal"
    if abs(normal[2]) <= tilt:
        return "vertical"
    return "oblique"


def _large_patches(
    pts: NDArray[np.float64],
    normal: NDArray[np.float64],
    cfg: SegmentConfig,
    min_points: int | None = None,
    min_extent: float | None = None,
) -> NDArray[np.bool_]:
    """(M,) bool: plane inliers that belong to a connected patch large enough to be a support/wall."""
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    ids = np.asarray(pcd.cluster_dbscan(cfg.plane_patch_eps, 3, print_progress=False))
    keep = np.zeros(len(pts), bool)
    axis_u = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
    axis_u /= np.linalg.norm(axis_u)
    axis_v = np.cross(normal, axis_u)
    for cid in range(int(ids.max(initial=-1)) + 1):
        member = ids == cid
        if np.count_nonzero(member) < (cfg.plane_min_points if min_points is None else min_points):
            continue
        span_u = np.ptp(pts[member] @ axis_u)
        span_v = np.ptp(pts[member] @ axis_v)
        if max(span_u, span_v) >= (cfg.plane_min_extent if min_extent is None else min_extent):
            keep |= member
    return keep


def _attach_noise(
    pts: NDArray[np.float64], labels: NDArray[np.int32], candidates: NDArray[np.bool_], radius: float
) -> None:
    """In place: candidate points without a cluster join the cluster of their nearest clustered point
    within ``radius`` [m], repeatedly (so chains of sparse samples grow in). Grazing views sample
    surfaces sparsely and thin parts (handles, spouts) fall apart in DBSCAN; this takes them back."""
    for _ in range(8):
        member = np.flatnonzero(labels >= 0)
        loose = np.flatnonzero(candidates & (labels < 0))
        if len(member) == 0 or len(loose) == 0:
            return
        dist, nearest = cKDTree(pts[member]).query(pts[loose], distance_upper_bound=radius)
        hit = np.isfinite(dist)
        if not hit.any():
            return
        labels[loose[hit]] = labels[member[nearest[hit]]]


def _densest(values: NDArray[np.float64], width: float) -> float:
    """Centre of the window of ``width`` holding the most values (the plane's exact position)."""
    v = np.sort(values)
    ends = np.searchsorted(v, v + width, side="right")
    i = int(np.argmax(ends - np.arange(len(v))))
    return float(np.median(v[i : ends[i]]))


def _snap(
    pts: NDArray[np.float64], found: NDArray[np.int64], normal: NDArray[np.float64], kind: str, dist: float
) -> tuple[NDArray[np.float64], float, NDArray[np.bool_]]:
    """Snap a RANSAC plane to exactly horizontal/vertical at its densest position.

    RANSAC on a small board among big walls often returns a slightly tilted plane that holds only
    part of the board; furniture surfaces are level or plumb, so fix the normal (vertical planes: yaw
    refit to the inliers' xy line), put the plane where the points are densest, recompute inliers.
    Returns (unit normal (3,), offset [m] with normal . x + offset = 0, inlier mask over ``pts``).
    """
    n = np.array([0.0, 0.0, 1.0]) if kind == "horizontal" else np.array([normal[0], normal[1], 0.0])
    n /= np.linalg.norm(n)
    members = found
    for _ in range(2):
        proj = pts @ n
        centre = _densest(proj[members], 2.0 * dist)
        inlier = np.abs(proj - centre) <= dist
        members = np.flatnonzero(inlier)
        if kind == "vertical" and len(members) >= 3:
            xy = pts[members, :2] - pts[members, :2].mean(axis=0)
            direction = np.linalg.svd(xy, full_matrices=False)[2][0]
            refit = np.array([-direction[1], direction[0], 0.0])
            n = refit if refit @ n >= 0.0 else -refit
    proj = pts @ n
    centre = _densest(proj[members], 2.0 * dist) if len(members) else 0.0
    return n, -centre, np.abs(proj - centre) <= dist


def _remove_planes(
    work: NDArray[np.float64], cfg: SegmentConfig
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], list[Plane]]:
    """Repeated RANSAC: (removed (N,), planar (N,): inlier of an accepted plane, removed or not, planes)."""
    o3d.utility.random.seed(cfg.seed)
    removed = np.zeros(len(work), bool)
    planar = np.zeros(len(work), bool)
    searchable = np.ones(len(work), bool)
    planes: list[Plane] = []
    for _ in range(cfg.max_planes):
        pool = np.flatnonzero(searchable & ~removed)
        if len(pool) < max(cfg.plane_min_points, 3):
            break
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(work[pool]))
        model, inliers = pcd.segment_plane(cfg.plane_distance, 3, cfg.plane_iterations)
        found = np.asarray(inliers, dtype=np.int64)
        if len(found) < cfg.plane_min_points:
            break
        normal = np.asarray(model[:3], dtype=np.float64) / float(np.linalg.norm(model[:3]))
        kind = _orientation(normal, cfg.max_tilt_deg)
        if kind == "oblique" or cfg.orientations not in ("both", kind):
            searchable[pool[found]] = False
            continue
        normal, offset, inlier = _snap(work[pool], found, normal, kind, cfg.plane_distance)
        if np.count_nonzero(inlier) < cfg.plane_min_points:
            searchable[pool[found]] = False  # not a level/plumb surface: never refit this sample
            continue
        found = pool[np.flatnonzero(inlier)]
        searchable[found] = False
        patch = found[_large_patches(work[found], normal, cfg)]
        removed[patch] = True
        planar[found] = True
        if len(patch):
            n = (float(normal[0]), float(normal[1]), float(normal[2]))
            planes.append(Plane(n, offset, kind, len(patch)))  # type: ignore[arg-type]
    return removed, planar, planes


def _remove_levels(
    work: NDArray[np.float64],
    removed: NDArray[np.bool_],
    planar: NDArray[np.bool_],
    planes: list[Plane],
    cfg: SegmentConfig,
) -> None:
    """In place (also appends to ``planes``): remove wide horizontal patches RANSAC cannot find
    (too few points, e.g. a board seen edge-on from a camera at its height). A level is a peak of
    the z histogram of the remaining points (3x denser than 2-3 cm above and below, which excludes
    slices of walls and objects); its patches wider than ``level_min_extent`` (more than any object)
    are removed."""
    rest = np.flatnonzero(~removed)
    if len(rest) < cfg.level_min_points:
        return
    dist = cfg.plane_distance
    z = work[rest, 2]
    bins = np.floor((z - z.min()) / dist).astype(np.int64)
    counts = np.bincount(bins)
    window = np.convolve(counts, np.ones(3, np.int64), mode="same")
    padded = np.pad(window, 3)
    shells = np.maximum(padded[:-6], padded[6:])
    local_max = window == np.max(np.lib.stride_tricks.sliding_window_view(np.pad(window, 2), 5), axis=1)
    peaks = np.flatnonzero((window >= cfg.level_min_points) & (window >= 3 * shells) & local_max)
    up = np.array([0.0, 0.0, 1.0])
    for b in peaks:
        near = rest[np.abs(bins - b) <= 1]
        level = _densest(work[near, 2], 2.0 * dist)
        layer = rest[(np.abs(z - level) <= dist) & ~removed[rest]]
        if len(layer) < cfg.level_min_points:
            continue
        wide = _large_patches(work[layer], up, cfg, cfg.level_min_points, cfg.level_min_extent)
        removed[layer[wide]] = True
        planar[layer] = True
        if wide.any():
            planes.append(Plane((0.0, 0.0, 1.0), -level, "horizontal", int(np.count_nonzero(wide))))


def segment_unlabelled(
    points: NDArray[np.floating], config: SegmentConfig | None = None
) -> tuple[NDArray[np.int32], SegmentInfo]:
    """Cluster an unlabelled cloud into objects.

    Args:
        points: (N, 3) [m] world frame (z up), finite.
        config: parameters; default :class:`SegmentConfig`.

    Returns:
        labels: (N,) int32 cluster id per input point; -1 = plane, noise, outside the ROI.
            With ``voxel_size > 0`` every input point gets the id of its voxel's representative.
        info: removed planes, cluster sizes, timing.
    """
    cfg = config or SegmentConfig()
    start = time.perf_counter()
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise CloudError(f"points must have shape (N, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise CloudError("points must be finite (no NaN/inf); drop invalid returns first")
    labels = np.full(len(pts), -1, np.int32)
    index = np.arange(len(pts))
    if cfg.roi_min is not None and cfg.roi_max is not None:
        inside = np.all((pts >= cfg.roi_min) & (pts <= cfg.roi_max), axis=1)
        index = index[inside]
    work = pts[index]
    inverse = np.arange(len(work))
    if cfg.voxel_size > 0.0 and len(work):
        cells = np.floor(work / cfg.voxel_size).astype(np.int64)
        inverse = np.unique(cells, axis=0, return_inverse=True)[1].reshape(-1)
        work = np.stack([np.bincount(inverse, work[:, k]) for k in range(3)], axis=1)
        work /= np.bincount(inverse)[:, None]
    removed, planar, planes = _remove_planes(work, cfg)
    if cfg.level_min_extent > 0.0:
        _remove_levels(work, removed, planar, planes, cfg)
    rest = np.flatnonzero(~removed)
    cluster = np.full(len(work), -1, np.int64)
    if len(rest):
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(work[rest]))
        cluster[rest] = np.asarray(
            pcd.cluster_dbscan(cfg.dbscan_eps, cfg.dbscan_min_points, print_progress=False)
        )
    ids, counts = np.unique(cluster[cluster >= 0], return_counts=True)
    big = counts >= cfg.min_cluster_points
    ids, counts = ids[big], counts[big]
    order = np.lexsort((ids, -counts))
    remap = np.full(int(cluster.max(initial=-1)) + 2, -1, np.int32)
    remap[ids[order] + 1] = np.arange(len(order), dtype=np.int32)
    work_labels = remap[cluster + 1]
    if cfg.attach_radius > 0.0:
        # Leftover strips of a support plane (e.g. cut off by an object's occlusion shadow) stay out.
        _attach_noise(work, work_labels, ~planar, cfg.attach_radius)
    labels[index] = work_labels[inverse]
    info = SegmentInfo(
        planes=planes,
        cluster_sizes=[int(c) for c in counts[order]],
        noise_points=int(np.count_nonzero(~removed & (work_labels < 0))),
        seconds=time.perf_counter() - start,
    )
    _LOG.debug("segment_unlabelled: %d planes, %d clusters in %.2f s", len(planes), len(order), info.seconds)
    return labels, info
