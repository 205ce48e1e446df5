"""One segment (approach or leave) of the implicit planner: latent fit, remaining-time field, descent.

Everything here works in *approach order*: the path runs from a free anchor (the wrist for an approach,
the retreat point for a leave) **to the contact**, and φ̂ is the time-distance to the contact (remaining
time for an approach, time since the contact for a leave; the planner reverses a leave at the end).
See :mod:`hsi_planning.implicit.planner` for the pipeline.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import PlanningError
from hsi_planning.fields.descent import DescentConfig, DescentField, descend_field, prepare_descent
from hsi_planning.implicit.path import (
    arc_length,
    required_clearance,
    resample_uniform,
    select_start,
    smooth_path,
    time_path,
)
from hsi_planning.implicit.prior import face_approach, transfer_orientation
from hsi_planning.implicit.runtime_field import (
    TOP_DOWN,
    UNDER_RADIUS,
    SegmentContext,
    point_checked_free,
    repair_field,
    wrist_free,
)
from hsi_planning.trajectory import WristTrajectory

__all__ = ["SegmentContext", "SegmentPlan", "plan_segment"]

F64 = NDArray[np.float64]
_LOG = logging.getLogger(__name__)
#: [-] growth of the time corridor of Eq. 11's candidates when none in it connects (repaired fields).
_WIDE_CAP = 3.0
#: [-] radius of the held box's point check, in ``clearance_relax``, when the cell mask closes the way from
#: the wrist (:func:`_repair`). Measured on a bottle placed under a board with 8 cm to spare: 1 leaves the
#: slot closed, 2 opens it (0.1 s), 3 (0.3 s) keeps a margin for deeper slots.
_WIDE_POINT_CHECK = 3.0


@dataclass(frozen=True, eq=False)
class SegmentPlan:
    """A planned segment in approach order (last sample = contact).

    Attributes:
        t: (T,) [s] sample times from 0; position: (T, 3) [m]; quaternion: (T, 4) [x y z w].
        info: plain diagnostics (start point, repair used, clearance margin [m], fit loss).
        timings: [s] per stage.
    """

    t: F64
    position: F64
    quaternion: F64
    info: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


def _violation(positions: F64, ctx: SegmentContext, carrying: bool) -> tuple[float, str]:
    """(worst clearance − required [m] along a path in approach order (< 0: too close), where)."""
    cfg = ctx.config
    from_contact = arc_length(positions[::-1])[::-1]
    full = cfg.hand_radius + cfg.check_margin
    need = required_clearance(from_contact, full, ctx.contact_clear, cfg.clearance_relax)
    margins = ctx.clearance(positions, bound=full + 0.01) - need  # (beyond: no violation)
    what = "the hand"
    if carrying:  # the held object: free of the support once lifted, then keeping check_margin
        after = np.clip((from_contact - ctx.lift) / cfg.clearance_relax, 0.0, 1.0)
        obj = ctx.carried_clearance(positions) - cfg.carried_margin * (0.5 + 0.5 * after)
        lifting = from_contact <= ctx.lift + 0.005  # leaving the support: only the upper part can hit
        obj[lifting] = ctx.carried_clearance(positions[lifting], upper=True)
        if obj.min() < margins.min():
            margins, what = obj, "the carried object"
    elif ctx.target is not None and ctx.approach_axis is not None:  # the empty hand: not past the target
        floor = ctx.target_clear - cfg.target_slack
        near = ctx.target(positions, bound=floor + 0.01) - floor
        axis = ctx.approach_axis / max(float(np.linalg.norm(ctx.approach_axis)), 1e-9)
        near = np.maximum(near, (positions - ctx.contact) @ axis)  # (in front of the contact: free)
        if near.min() < margins.min():
            margins, what = near, "the hand (nearer the target than at the contact)"
    i = int(np.argmin(margins))
    where = f"{what} at {positions[i].round(3).tolist()} [m], {from_contact[i]:.2f} m from the contact"
    return float(margins[i]), where


def _keep_above_lift(path: F64, ctx: SegmentContext) -> F64:
    """The path (approach order, last two samples: lift top and contact) with every earlier sample over
    the container around the contact (horizontally within the held object's footprint + ``lift_pad``)
    raised to at least the lift top: the carried object stays above the walls and neighbours it was
    lifted over (what stands behind a wall is hidden from the cameras). For an empty hand reaching
    down into a container (approach axis within ~45° of vertical), within ``UNDER_RADIUS`` of the
    contact the path only rises away from it (both ways: it enters from above and leaves upwards, not
    under the unseen rim or into what stands hidden behind the walls)."""
    top_down = ctx.approach_axis is not None and float(ctx.approach_axis[2]) > TOP_DOWN
    if (ctx.lift <= 0.0 and not top_down) or path.shape[0] < 3:
        return path
    top = ctx.contact[2] + ctx.lift
    reach = ctx.config.lift_pad + 0.5 * float(np.linalg.norm(np.ptp(ctx.carried[:, :2], axis=0)))
    out = path.copy()
    head = out[:-2]
    over = np.linalg.norm(head[:, :2] - ctx.contact[:2], axis=1) <= reach
    head[over, 2] = np.maximum(head[over, 2], top)
    if top_down:  # over the container, away from the contact, the path only rises
        rev = out[::-1]
        near = np.linalg.norm(rev[:, :2] - ctx.contact[:2], axis=1) <= UNDER_RADIUS
        k = int(np.argmin(near)) if not near.all() else near.shape[0]
        rev[:k, 2] = np.maximum.accumulate(rev[:k, 2])
    return out


def _waypoint(anchor: F64, x: F64) -> F64:
    """(N, 3) [m] the corner of a vertical-then-level connection anchor → waypoint → x (N, 3): straight up
    or down from ``anchor`` to the height of each x, then level to it (up and over a drawer front or a
    board; or, for a tall object carried under a board, level out of the opening and then up/down
    outside it)."""
    w = np.repeat(anchor[None], x.shape[0], axis=0)
    w[:, 2] = x[:, 2]
    return w


def _connect_clear(
    ctx: SegmentContext, anchor: F64, carrying: bool, margin: float, up: bool = False
) -> Callable[[F64], NDArray[np.bool_]]:
    """(B, 3) start candidates → (B,) whether the connection from ``anchor`` is clear: a straight segment,
    or with ``up`` the vertical-then-level polyline of :func:`_waypoint`; the hand sphere (radius +
    ``margin``) and, ``carrying``, the corners of the held object's box (``margin``)."""
    radius = ctx.config.hand_radius + margin
    offsets = [(np.zeros(3), radius)]
    if carrying:
        corners = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
        box = np.where(corners, ctx.carried.max(axis=0), ctx.carried.min(axis=0))
        offsets += [(corner, margin) for corner in box]

    def straight(a: F64, x: F64) -> NDArray[np.bool_]:
        ok = np.ones(x.shape[0], dtype=bool)
        for off, r in offsets:
            if ok.any():
                ok[ok] = ctx.clearance.segments_clear(a + off, x[ok] + off, r)
        return ok

    def clear(x: F64) -> NDArray[np.bool_]:
        if not up:
            return straight(anchor, x)
        ok = np.zeros(x.shape[0], dtype=bool)
        corner = _waypoint(anchor, x)
        for z in np.unique(corner[:, 2]):
            level = np.flatnonzero(corner[:, 2] == z)
            w = corner[level[0]]
            if straight(anchor, w[None])[0]:
                ok[level] = straight(w, x[level])
        return ok

    return clear


def _prior_speed(prior: WristTrajectory, arc: F64) -> F64:
    """(N,) [m/s] the matched demonstration's speed profile over normalized arc length (approach order),
    scaled to a path of arc lengths ``arc`` (N,) [m] so that it takes the demonstration's duration."""
    pos = prior.position if prior.segment == "approach" else prior.position[::-1]
    t = prior.t if prior.segment == "approach" else (prior.t[-1] - prior.t)[::-1]
    arc_p = arc_length(pos)
    if arc_p[-1] < 1e-6 or t.shape[0] < 2:
        return np.full(arc.shape[0], arc[-1] / max(prior.duration, 1e-3))
    v_p = np.gradient(arc_p, t)
    return np.asarray(np.interp(arc / arc[-1], arc_p / arc_p[-1], v_p) * (arc[-1] / arc_p[-1]), np.float64)


def _always(x: F64) -> NDArray[np.bool_]:
    return np.ones(x.shape[0], dtype=bool)


def _descends_from(grid: Any, phi: F64, x: F64, far: float) -> bool:
    """Whether ``x`` (3,) [m] lies in the grid with a finite time on its node (a path leads from it)."""
    if not bool(grid.contains(x[None])[0]):
        return False
    return bool(phi[tuple(grid.index(x[None])[0])] < far)


class _Prepared:
    """φ → its :class:`DescentField`, computed once per field array (the fields of one segment are
    descended, timed and repaired several times; none of them changes after it is made)."""

    def __init__(self, grid: Any, far: float) -> None:
        self._grid, self._far = grid, far
        self._done: dict[int, DescentField] = {}

    def __call__(self, phi: F64) -> DescentField:
        hit = self._done.get(id(phi))
        if hit is None or hit.phi is not phi:  # (an entry keeps its float64 phi alive: ids stay unique)
            hit = prepare_descent(self._grid, phi, self._far)
            self._done[id(phi)] = hit
        return hit


def _field_speed(grid: Any, field: DescentField, points: F64) -> F64:
    """(N,) [m/s] speed 1/|∇φ| of a prepared time field at ``points`` (N, 3) inside the grid."""
    g = np.linalg.norm(grid.interpolate_gradient(field.gradient, points), axis=1)
    return np.asarray(1.0 / np.maximum(g, 1e-6), dtype=np.float64)


def _descend(
    phi: F64,
    ctx: SegmentContext,
    anchor: F64,
    prior: WristTrajectory,
    *,
    free: NDArray[np.bool_],
    margin: float,
    connect: bool,
    prepared: _Prepared,
    finish: Callable[[], F64] | None = None,
    capped: bool = True,
) -> tuple[F64, F64, float]:
    """(path in approach order, speeds [m/s], length [m] descended on ``phi``) from Eq. 11's start point
    down ∇φ to the contact. Where the descent stalls (a local minimum), it continues on ``finish()``
    (the repaired field) when given. With ``connect`` the path starts at ``anchor`` (a straight, clear
    connection, else vertically to the start point's height first and then level: a drawer front or
    board in the way, or a tall carried object under a board),
    else at the start point. Eq. 11's candidates lie in the prior's time corridor; unless
    ``capped``, a corridor ``_WIDE_CAP`` times as long is tried when none of them connects (a repaired
    field's times grow slowly off the corridor), and when none of those does either, the descent starts
    at the anchor itself (the repaired field leads through the free nodes from wherever it is finite)."""
    cfg, fs = ctx.config, ctx.fields
    grid, far = fs.grid, fs.config.unreachable_time
    flat = phi.reshape(-1)
    cap = cfg.phi_cap_factor * max(prior.duration, 0.2)
    points = grid.points()
    mean_speed = prior.path_length() / max(prior.duration, 1e-6)
    lift = ctx.lift
    caps = (cap,) if capped else (cap, _WIDE_CAP * cap)
    tries = [(c, up) for up in ((False, True) if connect else (False,)) for c in caps]
    at_anchor = False
    for k, (c, up) in enumerate(tries):
        clear = _connect_clear(ctx, anchor, lift > 0.0, margin, up) if connect else _always
        cand = np.flatnonzero((flat < min(c, far)) & free.reshape(-1))
        try:
            start = points[cand[select_start(points[cand], flat[cand], anchor, mean_speed, clear)]]
            break
        except PlanningError:
            if k < len(tries) - 1:
                continue
            # A repaired field leads through free space from wherever it is finite: start at the anchor.
            if capped or not connect or not _descends_from(grid, phi, anchor, far):
                raise
            start, at_anchor = np.array(anchor, dtype=np.float64), True
    descent = DescentConfig(
        step=cfg.descent_step, stop_radius=max(lift, cfg.descent_step), max_steps=cfg.max_descent_steps
    )
    desc = descend_field(
        grid, phi, start, ctx.contact, blocked_value=far, config=descent, prepared=prepared(phi)
    )
    parts = [(phi, desc.positions)]
    if not desc.reached and finish is not None:
        fixed = finish()
        rest = descend_field(
            grid,
            fixed,
            desc.positions[-1],
            ctx.contact,
            blocked_value=far,
            config=descent,
            prepared=prepared(fixed),
        )
        parts.append((finish(), rest.positions[1:]))
        desc = rest
    if not desc.reached:
        raise PlanningError(
            f"descent from {start.round(3).tolist()} stopped "
            f"{np.linalg.norm(desc.positions[-1] - ctx.contact):.3f} m before the contact "
            "(local minimum of the remaining-time field)"
        )
    tail = [ctx.contact + np.array([0.0, 0.0, lift])] if lift > 0.0 else []
    head = [anchor[None]] if connect and not at_anchor else []
    if connect and up and not at_anchor and abs(start[2] - anchor[2]) > 1e-9:
        head.append(_waypoint(anchor, start[None]))
    path = np.vstack([*head, *(p for _, p in parts), *tail, ctx.contact[None]])
    speeds = [np.full(len(head), mean_speed)]
    speeds += [_field_speed(grid, prepared(f), p) for f, p in parts]
    speeds.append(np.full(len(tail) + 1, cfg.min_speed))
    learned_length = float(arc_length(parts[0][1])[-1]) if len(parts[0][1]) > 1 else 0.0
    return path, np.concatenate(speeds), learned_length


def _repair(
    phi: F64,
    ctx: SegmentContext,
    free: NDArray[np.bool_],
    *,
    margin: float,
    carrying: bool,
    prep: DescentField,
    anchor: F64,
) -> F64:
    """:func:`repair_field` through ``free``; when carrying and the cell-accurate mask leaves no free node
    around the contact, through :func:`point_checked_free` instead. When carrying and the field leads
    nowhere from ``anchor`` (3,) [m] (in the grid), the point check decides the nodes within
    ``_WIDE_POINT_CHECK`` times ``clearance_relax`` of the contact: the cell mask can close a slot only
    a few cm taller than the held object (a bottle placed under a board)."""
    try:
        fixed = repair_field(phi, ctx, free, prepared=prep)
    except PlanningError:
        if not carrying:
            raise
        _LOG.debug("no free node around the contact for the held box's cell mask; point check near it")
        fixed = repair_field(phi, ctx, point_checked_free(ctx, free, margin), prepared=prep)
    grid, far = ctx.fields.grid, ctx.fields.config.unreachable_time
    if not carrying or not bool(grid.contains(anchor[None])[0]) or _descends_from(grid, fixed, anchor, far):
        return fixed
    radius = _WIDE_POINT_CHECK * ctx.config.clearance_relax
    _LOG.debug("the held box's cell mask closes the way from the wrist; point check within %.2f m", radius)
    wider = point_checked_free(ctx, free, margin, radius=radius)
    return repair_field(phi, ctx, wider, prepared=prep)


def plan_segment(
    phi: F64,
    ctx: SegmentContext,
    anchor: F64,
    prior: WristTrajectory,
    *,
    carrying: bool,
    connect: bool = True,
) -> SegmentPlan:
    """Start point, descent, shaping, timing and orientation of one segment.

    ``anchor`` (3,) [m] is the free wrist pose of Eq. 11 (the wrist for an approach, the retreat target
    for a leave); with ``connect`` the path is joined to it by a straight, clear segment, else it ends
    (approach order: starts) at the selected start point x_s.

    Tried in order until the path keeps its clearance: the learned field, then (``repair`` =
    ``fallback``) the repaired field with ``repair_retries`` growing safety margins. When none keeps it,
    the closest one is returned (``info["relaxed"]``, logged) if it misses by at most ``relaxed_margin``.
    """
    cfg = ctx.config
    t0 = time.perf_counter()
    margins = [cfg.clearance_margin + k * cfg.repair_margin_step for k in range(cfg.repair_retries + 1)]
    attempts = {
        "never": [("learned", margins[0])],
        "fallback": [("learned", margins[0]), *(("repaired", m) for m in margins)],
        "always": [("repaired", m) for m in margins],
    }[cfg.repair]
    error: PlanningError | None = None
    best: _Found | None = None
    failures: list[str] = []
    lifted = dataclasses.replace(ctx, lift=ctx.lift if carrying else 0.0)
    free_at = wrist_free(lifted, carrying=carrying)
    prepared = _Prepared(ctx.fields.grid, ctx.fields.config.unreachable_time)
    by_margin: dict[float, tuple[NDArray[np.bool_], Callable[[], F64]]] = {}  # learned and repaired share
    for kind, margin in attempts:
        if margin not in by_margin:
            free_m = free_at(margin)
            by_margin[margin] = (
                free_m,
                functools.cache(
                    lambda free=free_m, margin=margin: _repair(
                        phi,
                        lifted,
                        free,
                        margin=margin,
                        carrying=carrying,
                        prep=prepared(phi),
                        anchor=anchor,
                    )
                ),
            )
        free, repaired = by_margin[margin]
        try:
            field_used = phi if kind == "learned" else repaired()
            finish = repaired if kind == "learned" and cfg.repair != "never" else None
            raw, speed, learned_length = _descend(
                field_used,
                lifted,
                anchor,
                prior,
                free=free,
                margin=margin,
                connect=connect,
                prepared=prepared,
                finish=finish,
                capped=kind == "learned",
            )
        except PlanningError as exc:
            error = exc
            failures.append(f"{kind} (margin {margin:.3f} m): {exc}")
            continue
        if kind == "repaired":
            learned_length = 0.0
        raw = _keep_above_lift(raw, lifted)
        path = smooth_path(raw, cfg.path_smoothing, cfg.path_step)
        arc_raw, arc_new = arc_length(raw), arc_length(path)
        v = np.interp(arc_new / arc_new[-1], arc_raw / arc_raw[-1], speed)
        if cfg.timing == "prior":
            v = _prior_speed(prior, arc_new)
        t = time_path(
            path,
            v,
            max_speed=cfg.max_speed,
            min_speed=cfg.min_speed,
            max_accel=cfg.max_accel,
            smooth=cfg.speed_smoothing,
        )
        tt, pos = resample_uniform(t, path, cfg.sample_rate)
        clear, where = _violation(pos, lifted, carrying)
        share = learned_length / max(float(arc_length(raw)[-1]), 1e-9)
        found = _Found(clear, kind, margin, tt, pos, share)
        if clear < 0.0:
            error = PlanningError(
                f"no collision-free path: the {kind} one brings {where} "
                f"{-clear:.3f} m too close to an obstacle"
            )
            failures.append(f"{kind} (margin {margin:.3f} m): {error}")
            best = found if best is None or clear > best.clear else best
            continue
        return _finish(found, prior, ctx, failures, t0)
    if best is not None and best.clear >= -cfg.relaxed_margin:
        _LOG.warning(
            "no path keeps the full clearance; taking the %s one %.1f mm short of it (relaxed_margin "
            "%.1f mm)",
            best.kind,
            -1e3 * best.clear,
            1e3 * cfg.relaxed_margin,
        )
        return _finish(best, prior, ctx, failures, t0)
    assert error is not None
    raise PlanningError("no collision-free path; tried " + "; ".join(failures)) from error


@dataclass(frozen=True, eq=False)
class _Found:
    """A timed candidate path (approach order) and its clearance against the required one [m]."""

    clear: float
    kind: str
    margin: float
    t: F64
    position: F64
    share: float


def _finish(
    found: _Found, prior: WristTrajectory, ctx: SegmentContext, failures: list[str], t0: float
) -> SegmentPlan:
    """The segment plan of ``found`` with the orientation transferred from ``prior`` (its contact turned
    to face along the approach axis where it points elsewhere)."""
    pp = prior.position if prior.segment == "approach" else prior.position[::-1]
    pq = prior.quaternion if prior.segment == "approach" else prior.quaternion[::-1]
    blend = ctx.config.blend_fraction
    quat = transfer_orientation(pp, pq, found.position, blend)
    if ctx.approach_axis is not None:
        limit = math.radians(ctx.config.contact_facing_angle)
        quat = face_approach(quat, found.position, ctx.approach_axis, limit, blend)
    info = {
        "field": "hybrid" if found.kind == "learned" and found.share < 0.999 else found.kind,
        "learned_share": found.share,
        "margin": found.margin,
        "clearance_margin": found.clear,
        "relaxed": found.clear < 0.0,
        "length": float(arc_length(found.position)[-1]),
        "failed_attempts": failures,
    }
    return SegmentPlan(found.t, found.position, quat, info, {"path": time.perf_counter() - t0})
