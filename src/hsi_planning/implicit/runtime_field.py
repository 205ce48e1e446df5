"""The remaining-time field of one planning segment at run time (CHOICE Eq. 9 and its use).

- :class:`SegmentContext`: what both segments of a plan share (fields, clearance, contact, held object).
- :func:`fit_segment_latent` (Eq. 9) and :func:`remaining_time` (φ̂ = 1 / D̂_toa where needed).
- :func:`wrist_free`: grid nodes the wrist may use (hand sphere and held object clear).
- :func:`point_checked_free`: the free nodes near the contact by the held box's point clearance.
- :func:`repair_field`: φ re-solved by fast marching with the learned speed 1/|∇φ̂| through the free nodes.
- :func:`box_samples`, :func:`free_lift`: the held object's box and how far it can be lifted.

Fields are "time-distances to the contact": remaining time for an approach, time since the contact for
a leave (see :mod:`hsi_planning.implicit.segment`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import skfmm
from numpy.typing import NDArray
from scipy import ndimage

from hsi_planning.errors import PlanningError
from hsi_planning.fields.descent import DescentField, prepare_descent
from hsi_planning.fields.field_set import FieldSet
from hsi_planning.implicit.latent import LatentFitConfig, fit_latent, predict_fields, prior_toa_anchors
from hsi_planning.implicit.model import AutoDecoder, to_unit_cube
from hsi_planning.implicit.path import Clearance, required_clearance
from hsi_planning.implicit.planner_config import ImplicitPlannerConfig
from hsi_planning.trajectory import WristTrajectory

F64 = NDArray[np.float64]
#: [m] height above the held box's bottom from which its points count as "upper" (lift checks).
_UPPER = 0.02
#: [m] horizontal cell size of the columns :func:`free_lift` tells walls from ceilings by.
_COLUMN = 0.025
#: [m] the held box's clearance is searched up to this far (every check needs far less).
_CARRIED_BOUND = 0.05
#: [-] z component of an approach axis that reaches down into a container (drawer, box, counter).
TOP_DOWN = 0.7
#: [m] around such a contact the wrist stays above the contact's height (the unseen rim and bottom).
UNDER_RADIUS = 0.3
#: Share of ``clearance_relax`` used for the free-node mask (distance to the contact < path length).
_MASK_RELAX = 0.7


@dataclass(frozen=True, eq=False)
class SegmentContext:
    """What both segments share.

    Attributes:
        fields: the problem's fields (D_t, D_o, masks) on the grid.
        clearance: distances to the observed obstacle points.
        contact: (3,) [m] wrist contact position.
        contact_clear: [m] observed obstacle clearance of the contact.
        carried: (M, 3) [m] points on the held object's (padded) bounding box relative to the contact;
            they move with the wrist while carrying.
        lift: [m] vertical lift (set-down) at the contact when carrying.
        config: planner settings.
        approach_axis: (3,) direction out of the container opening (None: unknown).
        target: distances to the target's points (None: the empty hand is not kept off the target).
    """

    fields: FieldSet
    clearance: Clearance
    contact: F64
    contact_clear: float
    carried: F64
    lift: float
    config: ImplicitPlannerConfig
    approach_axis: F64 | None = None
    target: Clearance | None = None

    @property
    def target_clear(self) -> float:
        """[m] the contact's distance to the target's points (inf without ``target``)."""
        return float(self.target(self.contact[None])[0]) if self.target is not None else float("inf")

    def carried_clearance(self, wrist: F64, upper: bool = False) -> F64:
        """(N,) [m] observed clearance of the held object's box with the wrist at ``wrist`` (N, 3), at most
        ``_CARRIED_BOUND``; with ``upper`` only of its points more than 2 cm above the box bottom (what a
        vertical lift can hit)."""
        w = np.asarray(wrist, dtype=np.float64).reshape(-1, 3)
        pts = self.carried
        if upper:
            pts = pts[pts[:, 2] >= pts[:, 2].min() + _UPPER]
        moved = (w[:, None, :] + pts[None, :, :]).reshape(-1, 3)
        d = self.clearance(moved, bound=_CARRIED_BOUND)
        return np.asarray(d.reshape(w.shape[0], -1).min(axis=1), dtype=np.float64)

    @property
    def carried_clear(self) -> float:
        """[m] the box's clearance at the contact (about 0: the object stands on its support)."""
        return float(self.carried_clearance(self.contact[None])[0])


def blocked_nodes(fields: FieldSet) -> NDArray[np.bool_]:
    """(n, n, n) nodes a path may not use: obstacles, the target and nodes without a way to it."""
    far = fields.config.unreachable_distance
    return np.asarray(fields.obstacle_mask | fields.target_mask | (fields.dist_t >= far))


def fit_segment_latent(
    model: AutoDecoder,
    ctx: SegmentContext,
    cond: NDArray[np.float32],
    prior: WristTrajectory,
    z_init: NDArray[np.float32],
) -> tuple[NDArray[np.float32], float]:
    """Eq. 9: z fitted to the observed D_t, D_o and the known D_toa. Returns (z, final loss)."""
    cfg, fs = ctx.config, ctx.fields
    grid = fs.grid
    half = 0.5 * grid.size
    rng = np.random.default_rng(cfg.seed)
    obstacle = np.flatnonzero(fs.obstacle_mask.reshape(-1))
    if obstacle.shape[0] > cfg.obstacle_anchors:
        obstacle = np.sort(rng.choice(obstacle, cfg.obstacle_anchors, replace=False))
    ordered = prior.position if prior.segment == "approach" else prior.position[::-1]
    times = prior.t if prior.segment == "approach" else (prior.t[-1] - prior.t)[::-1]
    tail, tail_val = prior_toa_anchors(ordered, times, cfg.prior_tail, fs.config.epsilon_time)
    tail = tail + (ctx.contact - ordered[-1])
    points = grid.points()
    toa_pts = np.vstack([points[obstacle], tail])
    toa_val = np.concatenate([np.zeros(obstacle.shape[0]), tail_val])
    fit = LatentFitConfig(
        steps=cfg.fit_steps,
        lr=cfg.fit_lr,
        points_per_step=cfg.fit_points,
        latent_reg=cfg.latent_reg,
        seed=cfg.seed,
        threads=0,  # the planner sets the thread count for the whole plan
    )
    z, info = fit_latent(
        model,
        to_unit_cube(points, grid.centre, half),
        cond,
        d_t_obs=fs.d_t.reshape(-1),
        d_o_obs=fs.d_o.reshape(-1),
        toa_points=to_unit_cube(toa_pts, grid.centre, half),
        toa_values=toa_val,
        z_init=z_init,
        config=fit,
    )
    return z, float(info.loss[-1])


def remaining_time(
    model: AutoDecoder, z: NDArray[np.float32], cond: NDArray[np.float32], ctx: SegmentContext
) -> F64:
    """(n, n, n) [s] φ̂ = 1 / D̂_toa, evaluated on every ``field_stride``-th node and refined trilinearly;
    blocked nodes hold ``unreachable_time``."""
    fs, stride = ctx.fields, ctx.config.field_stride
    grid, n = fs.grid, fs.grid.n
    idx = np.arange(0, n, stride)
    if idx[-1] != n - 1:
        idx = np.append(idx, n - 1)
    axes = [grid.axes()[a][idx] for a in range(3)]
    mesh = np.stack([g.reshape(-1) for g in np.meshgrid(*axes, indexing="ij")], axis=1)
    toa = predict_fields(model, z, cond, to_unit_cube(mesh, grid.centre, 0.5 * grid.size))["toa"]
    coarse = toa.reshape(len(idx), len(idx), len(idx)).astype(np.float64)
    if stride > 1:
        full = np.arange(n, dtype=np.float64)
        coords = np.meshgrid(*(np.interp(full, idx, np.arange(len(idx))),) * 3, indexing="ij")
        coarse = ndimage.map_coordinates(coarse, coords, order=1, mode="nearest")
    far = fs.config.unreachable_time
    phi = 1.0 / np.maximum(coarse, 1.0 / far)
    phi[blocked_nodes(fs)] = far
    return np.asarray(phi, dtype=np.float64)


def _carried_blocked(ctx: SegmentContext, pad: int) -> NDArray[np.bool_]:
    """(n, n, n) wrist nodes at which the held object's box, grown by ``pad`` cells, overlaps an obstacle
    node: the obstacle occupancy dilated by the reflected box (cell-accurate, on the safe side), computed
    as a separable box maximum filter."""
    fs = ctx.fields
    res, n = fs.grid.resolution, fs.grid.n
    lo = np.rint(-ctx.carried.max(axis=0) / res).astype(np.int64) - pad
    hi = np.rint(-ctx.carried.min(axis=0) / res).astype(np.int64) + pad
    k = int(max(np.abs(lo).max(), np.abs(hi).max()))
    size = hi - lo + 1
    padded = np.pad(fs.obstacle_mask, k).astype(np.uint8)
    wide = ndimage.maximum_filter(padded, size=tuple(int(v) for v in size), mode="constant")
    d = k - hi + size // 2  # out[x] = max over offsets e in [-hi, -lo] of occupancy[x + e]
    return np.asarray(wide[d[0] : d[0] + n, d[1] : d[1] + n, d[2] : d[2] + n] > 0)


def wrist_free(ctx: SegmentContext, *, carrying: bool) -> Callable[[float], NDArray[np.bool_]]:
    """Nodes where the wrist may be, as a function of a safety margin [m] → (n, n, n) bool: open, the hand
    sphere (radius + margin) clear of the observed obstacles (relaxed towards the contact over
    ``clearance_relax``), not under the contact when reaching down into a container and, when carrying,
    the held object's box clear of the obstacle nodes (except in the lift above the contact)."""
    cfg, fs = ctx.config, ctx.fields
    grid = fs.grid
    nodes = grid.points()
    r = np.linalg.norm(nodes - ctx.contact, axis=1).reshape(grid.shape)
    open_nodes = ~blocked_nodes(fs)
    rel = nodes - ctx.contact
    lifting = (
        (np.linalg.norm(rel[:, :2], axis=1) <= 0.75 * grid.resolution)
        & (rel[:, 2] >= -grid.resolution)
        & (rel[:, 2] <= ctx.lift + grid.resolution)
    ).reshape(grid.shape)  # the vertical lift above the contact, where the object leaves its support

    relax = _MASK_RELAX * cfg.clearance_relax  # paths are longer than the straight distance r
    open_nodes = open_nodes & ~_under_contact(ctx, rel).reshape(grid.shape)

    def free(margin: float) -> NDArray[np.bool_]:
        need = required_clearance(r, cfg.hand_radius + margin, ctx.contact_clear, relax)
        ok = open_nodes & (fs.dist_o >= need)
        if carrying:
            ok &= ~_carried_blocked(ctx, round(margin / grid.resolution)) | lifting
        return np.asarray(ok)

    return free


def _under_contact(ctx: SegmentContext, rel: F64) -> NDArray[np.bool_]:
    """(N,) nodes at ``rel`` (N, 3) [m] from the contact that lie under it when the hand reaches down into
    a container (approach axis within ~45° of vertical; all False otherwise): the unseen rim and bottom."""
    axis = ctx.approach_axis
    if axis is None or float(axis[2]) <= TOP_DOWN:
        return np.zeros(rel.shape[0], dtype=bool)
    res = ctx.fields.grid.resolution
    return np.asarray((np.linalg.norm(rel[:, :2], axis=1) <= UNDER_RADIUS) & (rel[:, 2] < -2.0 * res))


def point_checked_free(
    ctx: SegmentContext, free: NDArray[np.bool_], margin: float, radius: float | None = None
) -> NDArray[np.bool_]:
    """``free`` (n, n, n) with the nodes within ``radius`` [m] (default ``clearance_relax``) of the contact
    decided by the held box's point-based clearance instead of the cell-dilated mask of :func:`wrist_free`
    (which errs on the safe side by up to a cell and can leave no free node around a contact with little
    room to lift, or no way out of a slot only a few cm taller than the object: a tall object under a
    board). A node there is free when the hand sphere keeps ``hand_radius + margin`` (relaxed towards the
    contact) and the padded box keeps half of ``carried_margin``; the final path check
    (:func:`hsi_planning.implicit.segment._violation`) still decides."""
    cfg, fs = ctx.config, ctx.fields
    grid = fs.grid
    nodes = grid.points()
    r = np.linalg.norm(nodes - ctx.contact, axis=1)
    need = required_clearance(
        r, cfg.hand_radius + margin, ctx.contact_clear, _MASK_RELAX * cfg.clearance_relax
    )
    hand_ok = ~blocked_nodes(fs).reshape(-1) & (fs.dist_o.reshape(-1) >= need)
    hand_ok &= ~_under_contact(ctx, nodes - ctx.contact)  # as in wrist_free: not under a top-down contact
    sel = np.flatnonzero((r <= (cfg.clearance_relax if radius is None else radius)) & hand_ok)
    out = free.copy().reshape(-1)
    out[sel] = ctx.carried_clearance(nodes[sel]) >= 0.5 * cfg.carried_margin
    return out.reshape(free.shape)


def repair_field(
    phi: F64, ctx: SegmentContext, free: NDArray[np.bool_], prepared: DescentField | None = None
) -> F64:
    """φ re-solved by fast marching from the contact with the learned speed 1/|∇φ̂| through the ``free``
    nodes (n, n, n) (see :func:`wrist_free`); other nodes hold ``unreachable_time``. ``prepared``:
    ``phi``'s :class:`~hsi_planning.fields.descent.DescentField` when already computed."""
    cfg, fs = ctx.config, ctx.fields
    grid, far = fs.grid, fs.config.unreachable_time
    if prepared is None:
        prepared = prepare_descent(grid, phi, far)
    grad = np.linalg.norm(prepared.gradient, axis=-1)
    speed = np.clip(1.0 / np.maximum(grad, 1e-6), cfg.min_speed, cfg.max_speed)
    r = np.linalg.norm(grid.points() - ctx.contact, axis=1).reshape(grid.shape)
    r0 = 1.5 * grid.resolution
    near = r <= r0
    sample = near & ~blocked_nodes(fs)
    v_contact = float(np.median(speed[sample])) if sample.any() else cfg.min_speed
    passable = free | near
    try:
        tt = skfmm.travel_time(np.ma.MaskedArray(r - r0, mask=~passable), speed, dx=grid.resolution, order=1)
    except ValueError as exc:  # skfmm: no free node next to the contact's seed sphere
        raise PlanningError(
            f"no free space around the contact {ctx.contact.round(3).tolist()} [m] for the hand "
            f"(and a carried object) with a {cfg.hand_radius:.3f} m hand sphere ({exc})"
        ) from exc
    blocked = np.ma.getmaskarray(tt)
    out = np.asarray(np.ma.filled(tt, far), dtype=np.float64) + r0 / v_contact
    out[near] = r[near] / v_contact
    out[blocked & ~near] = far
    return np.minimum(out, far)


def box_samples(points: F64, padding: float, step: float = 0.02) -> F64:
    """(M, 3) [m] points every ~``step`` [m] on the faces of the bounding box of ``points`` (N, 3) [m]
    grown by ``padding`` [m]."""
    lo, hi = points.min(axis=0) - padding, points.max(axis=0) + padding
    axes = [np.linspace(lo[i], hi[i], max(2, int(np.ceil((hi[i] - lo[i]) / step)) + 1)) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    on_face = np.isclose(grid, lo).any(axis=1) | np.isclose(grid, hi).any(axis=1)
    return np.asarray(grid[on_face], dtype=np.float64)


def clear_lift(obstacle_points: F64, contact: F64, carried: F64, pad: float, margin: float) -> float:
    """[m] vertical lift that brings the bottom of the held object's box (``carried`` (M, 3) [m] relative
    to the wrist at ``contact`` (3,) [m]) ``margin`` [m] above every one of ``obstacle_points`` (K, 3) [m]
    over its footprint grown by ``pad`` [m] (neighbours and container walls it must rise above before it
    can move sideways); 0 when nothing stands there."""
    lo, hi = contact + carried.min(axis=0), contact + carried.max(axis=0)
    pts = np.asarray(obstacle_points, dtype=np.float64).reshape(-1, 3)
    near = (
        (pts[:, :2] >= lo[:2] - pad).all(axis=1)
        & (pts[:, :2] <= hi[:2] + pad).all(axis=1)
        & (pts[:, 2] > lo[2] + 0.005)
    )
    return float(max(0.0, pts[near, 2].max() - lo[2] + margin)) if near.any() else 0.0


def _ceiling_room(ctx: SegmentContext, obstacle_points: F64, margin: float) -> float:
    """[m] how far the top of the held object's box can rise until it is ``margin`` [m] under the lowest
    of ``obstacle_points`` (K, 3) [m] above its unpadded footprint (a shelf board or lid); walls and
    neighbours beside it, whose points also stand below its top, are not a ceiling; ``inf`` when nothing
    is above it."""
    lo, hi = ctx.contact + ctx.carried.min(axis=0), ctx.contact + ctx.carried.max(axis=0)
    pts = np.asarray(obstacle_points, dtype=np.float64).reshape(-1, 3)
    pad = ctx.config.carried_padding  # over the object itself, not over its padding (neighbours stand there)
    pts = pts[(pts[:, :2] >= lo[:2] + pad).all(axis=1) & (pts[:, :2] <= hi[:2] - pad).all(axis=1)]
    # A wall or neighbour reaching into the footprint also has points beside the box, below its top: its
    # columns (``_COLUMN`` cells) are not a ceiling.
    cells = np.floor(pts[:, :2] / _COLUMN).astype(np.int64)
    beside = (pts[:, 2] <= hi[2]) & (pts[:, 2] >= lo[2] + _UPPER)
    walls = np.isin(cells @ np.array([1, 1 << 32]), (cells[beside] @ np.array([1, 1 << 32])))
    over = (pts[:, 2] > hi[2]) & ~walls
    return float(pts[over, 2].min() - hi[2] - margin) if over.any() else math.inf


def free_lift(
    ctx: SegmentContext,
    obstacle_points: F64,
    lift: float,
    margin: float,
    *,
    step: float = 0.005,
    slack: float = 0.0,
) -> float:
    """[m] the largest vertical lift ≤ ``lift`` of the held object from the contact that keeps the top of
    its box ``margin`` [m] under the lowest of ``obstacle_points`` (K, 3) [m] above its unpadded
    footprint (a shelf board or lid right above it; walls and neighbours beside it, whose points also
    stand below its top, do not stop a vertical lift), and the hand sphere as clear as a path there
    must keep (relaxed towards the contact). When the object's hidden top may reach ``slack`` [m] above
    its box (:func:`~hsi_planning.implicit.completion.top_slack`), the lift keeps that higher top under
    the ceiling too, but is allowed ``hidden_top_lift`` (a slide just off the support)."""
    cfg = ctx.config
    heights = np.arange(step, lift + 1e-9, step)
    wrist = ctx.contact + heights[:, None] * np.array([0.0, 0.0, 1.0])
    room = _ceiling_room(ctx, obstacle_points, margin)
    if slack > 0.0 and math.isfinite(room):
        room = min(room, max(room - slack, cfg.hidden_top_lift))
    need = required_clearance(heights, cfg.hand_radius + margin, ctx.contact_clear, cfg.clearance_relax)
    blocked = np.flatnonzero((heights > room) | (ctx.clearance(wrist) < need))
    return float(lift if blocked.shape[0] == 0 else heights[blocked[0]] - step)
