"""The implicit neural trajectory planner at run time (CHOICE §4): cloud + target → approach and leave.

Pipeline of :meth:`ImplicitPlanner.plan`:

1. **Fields** of the problem (:mod:`~hsi_planning.implicit.problem`): D_t, D_o on the object-centric grid
   from the labelled cloud (shared by both segments); contact = ``palm_offset`` in front of the target
   along the approach axis (as in training).
2. **Prior matching** per segment: nearest training sample by local feature + condition
   (:class:`~hsi_planning.implicit.prior.PriorMatcher`): τ_prior and the warm-start latent z₀.
3. **Latent fit** (Eq. 9): z fitted to D_t, D_o on the grid and D_toa on the known points — 0 on a
   subsample of the obstacle nodes, τ_prior's last ``prior_tail`` moved onto the contact. The leave
   reuses the approach's scene code z unless ``refit_leave``.
4. **Remaining time** φ̂ = 1/D̂_toa, evaluated where needed (every ``field_stride``-th node).
5. **Start point** x_s (Eq. 11), **descent** of ∇φ̂ to the contact, fast-marching **repair** of φ̂ with
   the learned speed when the learned field leads into a dead end or too close to an obstacle.
6. **Shaping**: smoothed, timed rest to rest under speed/acceleration limits with the matched prior's
   speed profile over normalized arc length (``timing="prior"``; ``"field"``: v = 1/|∇φ̂|),
   resampled at ``sample_rate``; orientation transferred from τ_prior (Eq. 12), the start blended from
   the wrist's current orientation, the leave rotated to start exactly at the approach's contact pose.

See :mod:`~hsi_planning.implicit.segment` for steps 3–6 of one segment.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import time
from collections.abc import Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import CloudError, PlanningError
from hsi_planning.implicit.completion import completed_bounds, furniture_mask, top_slack
from hsi_planning.implicit.latent import LatentFitConfig, fit_latent, predict_fields
from hsi_planning.implicit.path import Clearance, estimate_approach_axis
from hsi_planning.implicit.planner_config import ImplicitPlannerConfig
from hsi_planning.implicit.prior import PriorMatcher, blend_start, contact_point
from hsi_planning.implicit.prior_bank import PriorBank
from hsi_planning.implicit.problem import (
    PLANNER_FIELD_CONFIG,
    condition_vector,
    feature_dim,
    local_feature,
    make_problem,
    problem_fields,
)
from hsi_planning.implicit.runtime_field import (
    SegmentContext,
    box_samples,
    clear_lift,
    fit_segment_latent,
    free_lift,
    remaining_time,
)
from hsi_planning.implicit.scene_completion import round_bounds
from hsi_planning.implicit.segment import SegmentPlan, plan_segment
from hsi_planning.implicit.train import Checkpoint, load_checkpoint
from hsi_planning.perception.cloud import LabelledCloud
from hsi_planning.planning import PlanRequest, PlanResult
from hsi_planning.trajectory import SEGMENTS, Action, Hand, Segment, WristTrajectory

__all__ = ["ImplicitPlanner", "ImplicitPlannerConfig"]

_LOG = logging.getLogger(__name__)
F64 = NDArray[np.float64]
#: Order of the stage timings in :attr:`PlanResult.timings`.
_STAGES = ("prepare", "fields", "match", "fit", "predict", "path")
_GRID_REACH = (
    0.5 * PLANNER_FIELD_CONFIG.size + PLANNER_FIELD_CONFIG.approach_shift + PLANNER_FIELD_CONFIG.resolution
)


def _stage_rank(key: str) -> tuple[int, int]:
    """Sort key of a timing name: shared stages, then the approach's, then the leave's, in pipeline order."""
    stage, _, seg = key.partition("_")
    group = 1 + SEGMENTS.index(seg) if seg in SEGMENTS else 0
    return group, _STAGES.index(stage) if stage in _STAGES else len(_STAGES)


@contextlib.contextmanager
def _torch_threads(threads: int) -> Iterator[None]:
    """Run with ``threads`` torch intra-op threads (0: unchanged), restoring the setting afterwards."""
    old = torch.get_num_threads()
    if threads > 0 and threads != old:
        torch.set_num_threads(threads)
    try:
        yield
    finally:
        if torch.get_num_threads() != old:
            torch.set_num_threads(old)


class ImplicitPlanner:
    """The neural implicit planner (see the module doc); implements :class:`~hsi_planning.planning.Planner`.

    Args:
        checkpoint: path of a checkpoint written by ``hsi train planner`` (network, latents and
            ``meta["prior_bank"]``), or a loaded :class:`Checkpoint`.
        config: run-time settings.

    Raises:
        PlanningError: unreadable checkpoint, no D_toa channel, no or inconsistent prior bank.
    """

    name = "implicit"

    def __init__(
        self, checkpoint: str | Path | Checkpoint, config: ImplicitPlannerConfig | None = None
    ) -> None:
        ckpt = checkpoint if isinstance(checkpoint, Checkpoint) else load_checkpoint(checkpoint)
        if "toa" not in ckpt.model.channels:
            raise PlanningError(
                f"the checkpoint predicts {list(ckpt.model.channels)}; the planner needs 'toa'"
            )
        doc = ckpt.meta.get("prior_bank")
        if not isinstance(doc, Mapping):
            raise PlanningError("the checkpoint has no meta['prior_bank']; train it with `hsi train planner`")
        bank = PriorBank.from_meta(doc)
        if bank.features.shape[1] != feature_dim():
            raise PlanningError(
                f"prior bank features have {bank.features.shape[1]} values, "
                f"local_feature gives {feature_dim()}"
            )
        self.checkpoint = ckpt
        self.model = ckpt.model
        self.bank = bank
        self.matcher = PriorMatcher(bank, ckpt.latents)
        self.config = config or ImplicitPlannerConfig()
        with _torch_threads(self.config.threads):
            self._warm_up()

    def _warm_up(self) -> None:
        """One tiny fit and prediction, so that torch's lazy initialisation is not paid by the first plan."""
        pts = np.zeros((8, 3), dtype=np.float32)
        cond = np.asarray(self.bank.cond[0], dtype=np.float32)
        warm = LatentFitConfig(steps=1, points_per_step=0)
        zero = np.zeros(8)
        z, _ = fit_latent(
            self.model,
            pts,
            cond,
            d_t_obs=zero,
            d_o_obs=zero,
            toa_points=pts,
            toa_values=zero,
            z_init=self.checkpoint.latents[0],
            config=warm,
        )
        predict_fields(self.model, z, cond, pts)

    def plan(
        self,
        request: PlanRequest | LabelledCloud,
        target: str | None = None,
        hand: Hand = "right",
        action: Action = "grasp",
        start_pose: ArrayLike | None = None,
    ) -> PlanResult:
        """Plan approach and leave: ``plan(request)`` or ``plan(cloud, target, hand, action, start_pose)``.

        Args:
            request: a :class:`PlanRequest`, or the labelled world-frame cloud.
            target: label name of the target (with a cloud).
            hand, action: moving hand and action (with a cloud).
            start_pose: (3,) [m] wrist position or (7,) position + [x y z w] quaternion (with a cloud).

        Raises:
            PlanningError: unknown or invisible target, target fully enclosed, start inside an obstacle,
                empty or NaN cloud, no collision-free path.
        """
        if not isinstance(request, PlanRequest):
            request = self._request(request, target, hand, action, start_pose)
        with _torch_threads(self.config.threads):
            return self._plan(request)

    @staticmethod
    def _request(
        cloud: LabelledCloud, target: str | None, hand: Hand, action: Action, start_pose: ArrayLike | None
    ) -> PlanRequest:
        if target is None:
            raise PlanningError("plan(cloud, ...) needs a target label name")
        kwargs: dict[str, Any] = {}
        if start_pose is not None:
            pose = np.asarray(start_pose, dtype=np.float64).reshape(-1)
            if pose.shape not in ((3,), (7,)):
                raise PlanningError(
                    f"start_pose must be 3 (position) or 7 (+ quaternion) numbers, got {pose.shape}"
                )
            kwargs["start_position"] = pose[:3]
            if pose.shape == (7,):
                kwargs["start_quaternion"] = pose[3:]
        return PlanRequest(cloud=cloud, target=target, hand=hand, action=action, **kwargs)

    def _prepare(self, request: PlanRequest) -> tuple[F64, NDArray[np.int64], list[int], F64]:
        """(points, labels, target ids, retreat) with the cloud cropped to the planning region."""
        w = np.asarray(request.start_position, dtype=np.float64)
        retreat = w if request.retreat_position is None else np.asarray(request.retreat_position)
        clip = None  # the completion adds no point outside the crop (unless the target moves first)
        if request.action == "grasp" or request.place_position is None:
            cloud = request.cloud
            try:
                own = np.isin(
                    cloud.labels, [cloud.label_id(n) for n in (request.target, *request.object_labels)]
                )
            except CloudError:  # target_points raises it with the planner's message
                own = np.zeros(0, dtype=bool)
            if own.any():
                clip = self._crop_box(np.asarray(cloud.points)[own], w, retreat)
        points, labels, ids = request.target_points(clip=clip)
        is_target = np.isin(labels, ids)
        lo, hi = self._crop_box(points[is_target], w, retreat)
        keep = is_target | ((points >= lo) & (points <= hi)).all(axis=1)
        return points[keep], labels[keep], ids, np.array(retreat, dtype=np.float64)

    def _crop_box(self, target_pts: F64, w: F64, retreat: F64) -> tuple[F64, F64]:
        """(lo (3,), hi (3,)) [m] the planning region: the grid around the target, the wrist and the
        retreat point, grown by ``crop_margin``."""
        centre = 0.5 * (target_pts.min(axis=0) + target_pts.max(axis=0))
        lo = np.minimum.reduce([centre - _GRID_REACH, w, retreat]) - self.config.crop_margin
        hi = np.maximum.reduce([centre + _GRID_REACH, w, retreat]) + self.config.crop_margin
        return lo, hi

    def _plan(self, request: PlanRequest) -> PlanResult:
        cfg = self.config
        t_start = time.perf_counter()
        timings: dict[str, float] = {}
        points, labels, ids, retreat = self._prepare(request)
        w = np.asarray(request.start_position, dtype=np.float64)
        is_target = np.isin(labels, ids)
        target_pts = points[is_target]
        obstacles = points[~is_target]  # (the cropped cloud is copied once, not per use)
        clearance = Clearance(obstacles)
        axis = request.approach_axis
        if axis is None:
            axis = estimate_approach_axis(target_pts, clearance, w)
        problem = make_problem(
            points,
            labels,
            ids,
            hand=request.hand,
            action=request.action,
            segment="approach",
            approach_axis=axis,
            target_name=request.target,
        )
        timings["prepare"] = time.perf_counter() - t_start
        t0 = time.perf_counter()
        try:
            fields = problem_fields(problem)
        except CloudError as exc:
            raise PlanningError(f"cannot compute the planning fields: {exc}") from exc
        timings["fields"] = time.perf_counter() - t0
        grid = fields.grid
        if float(clearance(w)[0]) < cfg.start_clearance or (
            grid.contains(w)[0] and fields.obstacle_mask[tuple(grid.index(w)[0])]
        ):
            raise PlanningError(
                f"the start position {w.round(3).tolist()} [m] lies inside an obstacle "
                f"(closer than {cfg.start_clearance} m to an obstacle point); move the wrist to free space"
            )
        contact = contact_point(target_pts, axis, cfg.palm_offset)
        if not grid.contains(contact)[0] or float(clearance(contact)[0]) < cfg.start_clearance:
            raise PlanningError(
                f"the contact pose {contact.round(3).tolist()} [m] in front of {request.target!r} is inside "
                "an obstacle; no free side to grasp it from along the approach axis"
            )
        # The held object reaches down to its support where neighbours hide its bottom (packed drawers).
        furniture = furniture_mask(labels, request.cloud.label_classes, ids)
        kind = (request.cloud.label_classes or {}).get(ids[0])
        held = completed_bounds(target_pts, points[furniture], kind, obstacles)
        if cfg.round_completion:
            held = round_bounds(target_pts, kind, held, obstacles)
        ctx = SegmentContext(
            fields=fields,
            clearance=clearance,
            contact=contact,
            contact_clear=float(clearance(contact)[0]),
            carried=box_samples(np.vstack(held), cfg.carried_padding) - contact,
            lift=0.0,
            config=cfg,
            approach_axis=np.asarray(axis, dtype=np.float64),
            target=Clearance(target_pts),
        )
        rise = clear_lift(obstacles, contact, ctx.carried, cfg.lift_pad, cfg.check_margin)
        lift = min(max(cfg.lift_height, rise), cfg.max_lift)
        slack = top_slack(target_pts, held, kind)
        ctx = dataclasses.replace(ctx, lift=free_lift(ctx, obstacles, lift, cfg.check_margin, slack=slack))
        info: dict[str, Any] = {
            "approach_axis": np.asarray(axis).tolist(),
            "contact": contact.tolist(),
            "lift": ctx.lift,
            "top_slack": slack,
            "held_bounds": [np.asarray(b).tolist() for b in held],
        }
        anchors = {"approach": w, "leave": retreat}
        matched = {seg: self._match(problem, request, ctx, seg, timings) for seg in SEGMENTS}
        z: NDArray[np.float32] | None = None
        if not cfg.refit_leave:  # the leave reuses the approach's scene code: fit it first
            cond, match = matched["approach"]
            z = self._fit(ctx, "approach", cond=cond, match=match, timings=timings, info=info)
            timings["fit_leave"] = 0.0

        def run(seg: Segment) -> SegmentPlan:
            cond, match = matched[seg]
            fit = {"cond": cond, "match": match, "timings": timings, "info": info}
            code = z if z is not None else self._fit(ctx, seg, **fit)  # refit_leave: a code per segment
            return self._segment(request, ctx, seg, anchor=anchors[seg], z=code, **fit)

        plans: dict[str, SegmentPlan] = {}
        if cfg.parallel_segments:  # the leave in a second thread (torch, KD-tree and numpy free the GIL)
            with ThreadPoolExecutor(max_workers=1, thread_name_prefix="hsi-leave") as pool:
                pending = pool.submit(run, "leave")
                plans["approach"] = run("approach")
                plans["leave"] = pending.result()
        else:
            plans = {seg: run(seg) for seg in SEGMENTS}
        timings = {k: timings[k] for k in sorted(timings, key=_stage_rank)}
        approach, leave = self._trajectories(request, plans)
        timings["total"] = time.perf_counter() - t_start
        _LOG.info(
            "implicit plan %s/%s %s: %.0f ms (%s)",
            request.hand,
            request.action,
            request.target,
            1e3 * timings["total"],
            ", ".join(f"{k} {1e3 * v:.0f}" for k, v in timings.items() if k != "total"),
        )
        return PlanResult(approach=approach, leave=leave, timings=timings, info=info)

    def _match(
        self, problem: Any, request: PlanRequest, ctx: SegmentContext, seg: Segment, timings: dict[str, float]
    ) -> tuple[NDArray[np.float32], Any]:
        """(condition vector, nearest training sample) of one segment."""
        t0 = time.perf_counter()
        cond = condition_vector(problem.goal_height, request.hand, request.action, seg)
        match = self.matcher.match(local_feature(ctx.fields, cond), ctx.fields.grid.centre)
        timings[f"match_{seg}"] = time.perf_counter() - t0
        return cond, match

    def _fit(
        self,
        ctx: SegmentContext,
        seg: Segment,
        *,
        cond: NDArray[np.float32],
        match: Any,
        timings: dict[str, float],
        info: dict[str, Any],
    ) -> NDArray[np.float32]:
        """The scene code z fitted for one segment (Eq. 9), warm-started from the match."""
        t0 = time.perf_counter()
        z, loss = fit_segment_latent(self.model, ctx, cond, match.demo, match.z_init)
        info[f"fit_loss_{seg}"] = loss
        timings[f"fit_{seg}"] = time.perf_counter() - t0
        return z

    def _segment(
        self,
        request: PlanRequest,
        ctx: SegmentContext,
        seg: Segment,
        *,
        anchor: F64,
        z: NDArray[np.float32],
        cond: NDArray[np.float32],
        match: Any,
        timings: dict[str, float],
        info: dict[str, Any],
    ) -> SegmentPlan:
        """φ̂ of one segment and its path (the dictionaries get this segment's own keys only)."""
        t0 = time.perf_counter()
        phi = remaining_time(self.model, z, cond, ctx)
        timings[f"predict_{seg}"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        carrying = (request.action, seg) in (("grasp", "leave"), ("place", "approach"))
        plan = plan_segment(
            phi,
            ctx,
            anchor,
            match.demo,
            carrying=carrying,
            connect=seg == "approach" or request.retreat_position is not None,
        )
        timings[f"path_{seg}"] = time.perf_counter() - t0
        info[f"prior_{seg}"] = {
            "index": match.index,
            "distance": match.distance,
            "layout": self.bank.layout[match.index],
        }
        info[f"path_{seg}"] = plan.info
        return plan

    def _trajectories(
        self, request: PlanRequest, plans: dict[str, SegmentPlan]
    ) -> tuple[WristTrajectory, WristTrajectory]:
        a, lv = plans["approach"], plans["leave"]
        qa = a.quaternion
        if request.start_quaternion is not None:
            qa = blend_start(qa, request.quaternion, self.config.blend_fraction)
        # The leave starts exactly at the approach's contact orientation.
        fix = Rotation.from_quat(qa[-1]) * Rotation.from_quat(lv.quaternion[-1]).inv()
        ql = (fix * Rotation.from_quat(lv.quaternion)).as_quat()
        if float(ql[-1] @ qa[-1]) < 0.0:
            ql = -ql
        approach = WristTrajectory(
            t=a.t,
            position=a.position,
            quaternion=qa,
            hand=request.hand,
            action=request.action,
            segment="approach",
            contact_index=-1,
            planner=self.name,
            object_name=request.target,
        )
        leave = WristTrajectory(
            t=lv.t[-1] - lv.t[::-1],
            position=lv.position[::-1],
            quaternion=ql[::-1],
            hand=request.hand,
            action=request.action,
            segment="leave",
            contact_index=0,
            planner=self.name,
            object_name=request.target,
        )
        return approach, leave
