"""The standing pose: where to stand, which way to face and how far to crouch to reach given wrist targets.

Candidates are the free floor cells (clearance >= body radius) within ``search_radius`` of the targets,
headings facing the targets' centre (plus ``yaw_offsets``), and the body's postures (hip height, trunk
pitch). A candidate is feasible when every target is within the reach limit of its hand's shoulder
(and no nearer than ``min_reach``), not behind the shoulder by more than ``max_behind``, the
shoulders, neck and head keep ``torso_clearance`` from the scene's points, and the wrists that rest on the
body there (ready or carry pose: the next planned reach starts from them) keep ``wrist_clearance``.
Among the feasible ones the cheapest wins::

    cost = walk_weight · |root − near| + posture_weight · posture index
           + comfort_weight · Σ_k (d_k − comfort_reach)² + yaw_weight · |yaw offset|
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.scheduler.body import BodyConfig, HipPose, hand_sign
from hsi_planning.scheduler.navigation import FloorMap
from hsi_planning.trajectory import Hand

F64 = NDArray[np.float64]
#: Head centre above the neck along the trunk [m].
_HEAD = 0.22


@dataclass(frozen=True)
class StanceConfig:
    """Search and preferences of the standing pose."""

    search_radius: float = 1.1  #: [m] candidate roots within this distance of the targets' centre
    step: float = 0.05  #: [m] spacing of the candidate roots
    yaw_offsets: tuple[float, ...] = (0.0, -30.0, 30.0)  #: [deg] headings tried around facing the targets
    walk_weight: float = 0.6  #: [1/m] cost per metre between the current root and the candidate
    posture_weight: float = 0.25  #: [-] cost per posture index (more crouched = costlier)
    comfort_reach: float = 0.55  #: [m] the most comfortable wrist distance from the shoulder
    comfort_weight: float = 3.0  #: [1/m²] cost of the squared deviation from the comfortable reach
    yaw_weight: float = 0.2  #: [1/rad] cost of turning away from facing the targets
    max_behind: float = 0.15  #: [m] how far a target may lie behind its shoulder (along the heading)
    #: [m] free space around a wrist resting on the body at the stance (a crouch in front of a counter put
    #: the ready wrist inside it, and no planned reach could start from there); 0 = not checked
    wrist_clearance: float = 0.0

    def __post_init__(self) -> None:
        if not (self.search_radius > 0.0 and 0.0 < self.step <= self.search_radius):
            raise ConfigError("StanceConfig needs search_radius > 0 and 0 < step <= search_radius [m]")
        if not self.yaw_offsets:
            raise ConfigError("StanceConfig.yaw_offsets must list at least one heading offset [deg]")
        weights = (self.walk_weight, self.posture_weight, self.comfort_weight, self.yaw_weight)
        if min(weights) < 0.0 or self.max_behind < 0.0 or not self.wrist_clearance >= 0.0:
            raise ConfigError("StanceConfig weights, max_behind and wrist_clearance must be >= 0")


@dataclass(frozen=True)
class StanceTarget:
    """A wrist position (3,) [m] that ``hand`` must reach from the stance."""

    hand: Hand
    point: F64


def choose_stance(
    targets: Sequence[StanceTarget],
    floor: FloorMap,
    scene_points: cKDTree | None,
    body: BodyConfig,
    config: StanceConfig,
    *,
    near: ArrayLike | None = None,
    accept: Callable[[HipPose], bool] | None = None,
    resting: Sequence[tuple[Hand, tuple[float, float, float], float]] = (),
) -> HipPose:
    """The cheapest feasible stance reaching every target (see the module docstring).

    Args:
        targets: wrist targets with their hands.
        floor: floor map for the root clearance (door leaves already added if they matter).
        scene_points: KD-tree of the scene's non-floor points for the torso clearance (None: no check).
        body: body dimensions and postures.
        config: search settings.
        near: (2,) [m] current root (walking there costs ``walk_weight`` per metre); None = no cost.
        accept: extra test a stance must pass (e.g. a clear straight step from the current root).
        resting: (hand, hip-frame wrist offset [m], extra clearance [m]) of the wrists resting on the body
            (ready or carry pose), which keep ``config.wrist_clearance`` plus the extra (the size of an
            object carried there) from ``scene_points``.

    Raises:
        PlanningError: no feasible stance; the message gives the closest miss.
    """
    if not targets:
        raise PlanningError("choose_stance needs at least one wrist target")
    pts = np.array([t.point for t in targets], dtype=np.float64)
    signs = np.array([hand_sign(t.hand) for t in targets])
    centre = pts[:, :2].mean(axis=0)
    r = np.arange(-config.search_radius, config.search_radius + 1e-9, config.step)
    offsets = np.stack(np.meshgrid(r, r, indexing="ij"), axis=-1).reshape(-1, 2)
    offsets = offsets[np.linalg.norm(offsets, axis=1) <= config.search_radius]
    roots = centre + offsets
    if near is not None:
        roots = np.vstack([roots, np.asarray(near, dtype=np.float64).reshape(1, 2)])
    roots = roots[floor.clearance(roots) >= body.body_radius]
    if len(roots) == 0:
        raise PlanningError(
            f"no free floor within {config.search_radius} m of the targets at {np.round(centre, 2).tolist()} "
            f"for a body radius of {body.body_radius} m"
        )
    towards = centre - roots
    base = np.arctan2(towards[:, 1], towards[:, 0])
    yaw_off = np.radians(np.asarray(config.yaw_offsets, dtype=np.float64))
    heights = np.array([p[0] for p in body.postures])
    pitches = np.radians(np.array([p[1] for p in body.postures]))
    yaw = base[:, None] + yaw_off[None, :]  # (C, Y)
    cy, sy = np.cos(yaw)[..., None, None], np.sin(yaw)[..., None, None]  # (C, Y, 1, 1)
    fwd = (body.shoulder_height * np.sin(pitches))[None, None, :, None]  # (1, 1, P, 1)
    lat = (body.shoulder_lateral * signs)[None, None, None, :]  # (1, 1, 1, K)
    sx = roots[:, 0, None, None, None] + cy * fwd - sy * lat
    sy_ = roots[:, 1, None, None, None] + sy * fwd + cy * lat
    sz = (heights + body.shoulder_height * np.cos(pitches))[None, None, :, None]
    dx, dy, dz = pts[:, 0] - sx, pts[:, 1] - sy_, pts[:, 2] - sz
    dist = np.sqrt(dx**2 + dy**2 + dz**2)  # (C, Y, P, K)
    ahead = dx * cy + dy * sy
    ok = ((dist <= body.reach_limit) & (dist >= body.min_reach) & (ahead >= -config.max_behind)).all(axis=-1)
    if not ok.any():
        worst = dist.max(axis=-1)
        i = np.unravel_index(int(np.argmin(worst)), worst.shape)
        raise PlanningError(
            f"no standing pose reaches {[(t.hand, np.round(t.point, 2).tolist()) for t in targets]}: "
            f"the best candidate still needs {float(worst[i]):.2f} m of reach "
            f"(limit {body.reach_limit:.2f} m)"
        )
    walk = (
        np.zeros(len(roots))
        if near is None
        else np.linalg.norm(roots - np.asarray(near).reshape(1, 2), axis=1)
    )
    cost = (
        config.walk_weight * walk[:, None, None]
        + config.posture_weight * np.arange(len(heights))[None, None, :]
        + config.comfort_weight * ((dist - config.comfort_reach) ** 2).sum(axis=-1)
        + config.yaw_weight * np.abs(yaw_off)[None, :, None]
    )
    cost = np.where(ok, cost, np.inf)
    for flat in np.argsort(cost, axis=None)[: min(200, int(ok.sum()))]:
        c, y, p = np.unravel_index(int(flat), cost.shape)
        pose = HipPose(np.array([roots[c, 0], roots[c, 1], heights[p]]), float(yaw[c, y]), float(pitches[p]))
        if (
            torso_clear(pose, scene_points, body)
            and wrists_clear(pose, resting, scene_points, config.wrist_clearance)
            and (accept is None or accept(pose))
        ):
            return pose
    raise PlanningError(
        f"every standing pose that reaches the targets near {np.round(centre, 2).tolist()} brings the "
        f"shoulders or head within {body.torso_clearance} m of the scene, a resting wrist within "
        f"{config.wrist_clearance} m (or fails the step test)"
    )


def torso_clear(pose: HipPose, scene_points: cKDTree | None, body: BodyConfig) -> bool:
    """Whether the shoulders, neck and head of ``pose`` keep ``torso_clearance`` from the scene points."""
    if scene_points is None or body.torso_clearance <= 0.0:
        return True
    head = pose.neck(body) + pose.rotation().apply([0.0, 0.0, _HEAD])
    probes = np.vstack([pose.shoulder("left", body), pose.shoulder("right", body), pose.neck(body), head])
    dist, _ = scene_points.query(probes, k=1)
    return bool(np.all(np.asarray(dist) >= body.torso_clearance))


def wrists_clear(
    pose: HipPose,
    resting: Sequence[tuple[Hand, tuple[float, float, float], float]],
    scene_points: cKDTree | None,
    clearance: float,
) -> bool:
    """Whether the ``resting`` wrists ((hand, hip-frame offset [m], extra clearance [m])) of ``pose``
    keep ``clearance`` [m] plus their extra from the scene points."""
    if scene_points is None or clearance <= 0.0 or not resting:
        return True
    probes = np.array([pose.wrist_offset(hand, offset) for hand, offset, _ in resting])
    dist, _ = scene_points.query(probes, k=1)
    return bool(np.all(np.asarray(dist) >= clearance + np.array([extra for _, _, extra in resting])))


def yaw_between(a: ArrayLike, b: ArrayLike) -> float:
    """[rad] heading from floor point ``a`` to ``b`` (2,)."""
    d = np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64)
    return math.atan2(float(d[1]), float(d[0]))
