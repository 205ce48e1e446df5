"""Training data of the implicit planner: field datasets from rendered clouds plus the motion-prior bank.

Per scene family (``scenes``) and layout group (plain / reshaped containers), ``layouts_per_group``
layouts come from :func:`~hsi_planning.scene.generate_layouts` with ``layout_seed`` (training seeds
0–9999, :data:`~hsi_planning.implicit.problem.TRAIN_SEEDS`; benchmarks and tests use seeds ≥ 100000).
Per layout, up to ``targets_per_layout`` reachable objects become targets (shuffled, seeded); a target
in a closed cabinet or drawer is rendered with the door opened / drawer pulled out. Per target and
condition (hand × action × segment) the human-reach model generates a demonstration from a free wrist
pose near the body — the person stands at (0, target y) facing +x, the free pose is
``start_centre`` (y mirrored to the hand's side) plus Gaussian noise — and the fields (D_t, D_o, D_toa)
are computed from the **rendered cloud** on the problem grid (:mod:`~hsi_planning.implicit.problem`).
A place is the held object put back at its spot: same target, action 1, carrying demonstrations.

One training *problem* (latent) is one (layout, target); its conditions are its samples.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from hsi_planning.demos import ObstacleField, ReachRequest, generate_reach
from hsi_planning.errors import HsiError, PlanningError
from hsi_planning.fields import FieldJob, GridSpec, compute_many
from hsi_planning.implicit.data_config import BUILTIN_SCENES, DataBuildConfig
from hsi_planning.implicit.data_scene import (
    contact_pose,
    object_radius,
    parts_to_open,
    render_opened,
    wrist_frame,
)
from hsi_planning.implicit.dataset import FieldDataset
from hsi_planning.implicit.prior_bank import PriorBank, resample_demo
from hsi_planning.implicit.problem import (
    PLANNER_FIELD_CONFIG,
    PlanningProblem,
    approach_axis_for,
    local_feature,
    make_problem,
    problem_grid,
    unit_points,
)
from hsi_planning.perception.render import CloudConfig, scene_renderer
from hsi_planning.scene import (
    LayoutConfig,
    SceneSpec,
    generate_layouts,
    load_scene_spec,
    support_of,
    target_reachable,
)
from hsi_planning.trajectory import Hand, WristTrajectory

_LOG = logging.getLogger(__name__)

__all__ = ["BUILTIN_SCENES", "DataBuildConfig", "PlannerData", "build_planner_data", "problem_grid_of"]

_MIN_TARGET_POINTS = 10


@dataclass
class PlannerData:
    """Built training data.

    Attributes:
        dataset: the fields of every sample (one latent per (layout, target) problem).
        bank: the motion-prior bank (one entry per sample, same order).
        summary: plain counts and settings (layouts, problems, samples, skipped, seconds).
    """

    dataset: FieldDataset
    bank: PriorBank
    summary: dict[str, int | float | str] = field(default_factory=dict)


@dataclass
class _Sample:
    """One sample's metadata: what the dataset and the bank need besides the fields."""

    cond: NDArray[np.float32]
    target_centre: NDArray[np.float64]
    approach_axis: NDArray[np.float64]
    demo: WristTrajectory
    problem_key: str
    layout: str
    target: str


def _layouts(config: DataBuildConfig, root: Path) -> Iterator[tuple[int, int, str, SceneSpec]]:
    for si, scene in enumerate(config.scenes):
        path = Path(scene) if Path(scene).is_absolute() else root / scene
        spec = load_scene_spec(path)
        for group in config.reshape_groups:
            layouts = generate_layouts(
                spec, config.layouts_per_group, config.layout_seed, LayoutConfig(reshape=group)
            )
            for li, layout in enumerate(layouts):
                tag = f"{spec.name}/{'reshape' if group else 'plain'}/s{config.layout_seed}/v{li:03d}"
                yield si, 2 * li + int(group), tag, layout


def _free_pose(
    centre_y: float, hand: Hand, config: DataBuildConfig, rng: np.random.Generator
) -> NDArray[np.float64]:
    sx, sy, sz = config.start_centre
    side = 1.0 if hand == "left" else -1.0
    return np.array([sx, centre_y + side * sy, sz]) + rng.normal(0.0, config.start_noise, 3)


def _sample(problem: PlanningProblem, demo: WristTrajectory, tag: str) -> _Sample:
    return _Sample(
        cond=problem.condition_vector(),
        target_centre=problem.target_centre,
        approach_axis=problem.approach_axis,
        demo=demo,
        problem_key=f"{tag}:{problem.target_name}",
        layout=tag,
        target=problem.target_name,
    )


def _interleave(layout: SceneSpec, names: list[str], rng: np.random.Generator) -> list[str]:
    """``names`` shuffled, then taken round-robin over their supports' furniture (diverse targets first)."""
    groups: dict[str, list[str]] = {}
    for i in rng.permutation(len(names)):
        groups.setdefault(support_of(layout, names[int(i)]).furniture, []).append(names[int(i)])
    queues = list(groups.values())
    out: list[str] = []
    while any(queues):
        out.extend(q.pop(0) for q in queues if q)
    return out


def _layout_samples(
    layout: SceneSpec, tag: str, seed_key: list[int], config: DataBuildConfig
) -> tuple[list[tuple[FieldJob, _Sample]], int]:
    """(field job, sample) pairs of one layout and the number of demonstrations that failed."""
    rng = np.random.default_rng(seed_key)
    candidates = _interleave(
        layout, [o.name for o in layout.objects if target_reachable(layout, o.name)], rng
    )
    cloud_cfg = CloudConfig(
        width=config.cloud_width, height=config.cloud_height, voxel_size=config.cloud_voxel
    )
    samples: list[tuple[FieldJob, _Sample]] = []
    failed = picked = 0
    model, data, renderer = scene_renderer(layout)
    try:
        for ci, target in enumerate(candidates):
            if picked >= config.targets_per_layout:
                break
            scene = render_opened(
                layout,
                parts_to_open(layout, target),
                cloud_config=cloud_cfg,
                door_fraction=config.door_fraction,
                drawer_fraction=config.drawer_fraction,
                renderer=(model, data, renderer),
            )
            lid = scene.label_ids[target]
            if int((scene.cloud.labels == lid).sum()) < _MIN_TARGET_POINTS:
                _LOG.debug("%s: target %s not visible in the cloud, skipped", tag, target)
                continue
            axis = approach_axis_for(layout, target)
            mesh = scene.meshes[target]
            contact, contact_q = contact_pose(mesh, axis, config.palm_offset)
            obstacles = ObstacleField({k: m for k, m in scene.meshes.items() if k != target})
            got: list[tuple[FieldJob, _Sample]] = []
            for k, (hand, action, segment) in enumerate(config.conditions):
                demo_rng = np.random.default_rng([*seed_key, int(ci), k])
                free = _free_pose(float(mesh.bounds.mean(axis=0)[1]), hand, config, demo_rng)
                request = ReachRequest(
                    start_position=free,
                    start_quaternion=wrist_frame(np.array([1.0, 0.0, 0.0])),
                    contact_position=contact,
                    contact_quaternion=contact_q,
                    approach_axis=-axis,
                    hand=hand,
                    action=action,
                    segment=segment,
                    object_name=target,
                    carried_radius=object_radius(mesh),
                )
                try:
                    demo = generate_reach(request, obstacles, rng=demo_rng)
                    problem = make_problem(
                        scene.cloud.points,
                        scene.cloud.labels,
                        [lid],
                        hand=hand,
                        action=action,
                        segment=segment,
                        approach_axis=axis,
                        contact_position=contact,
                        contact_quaternion=contact_q,
                        target_name=target,
                    )
                except HsiError as exc:
                    _LOG.debug(
                        "%s: %s %s: demonstration failed: %s", tag, target, (hand, action, segment), exc
                    )
                    failed += 1
                    continue
                job = FieldJob(
                    points=problem.points,
                    labels=problem.labels,
                    target_labels=problem.target_labels,
                    obstacle_labels=problem.obstacle_labels,
                    demo=demo,
                    config=PLANNER_FIELD_CONFIG,
                    grid=problem_grid(problem, PLANNER_FIELD_CONFIG),
                    name=f"{tag}:{target}:{hand}/{action}/{segment}",
                )
                got.append((job, _sample(problem, demo, tag)))
            if got:
                picked += 1
                samples.extend(got)
    finally:
        renderer.close()
    return samples, failed


@dataclass
class _Collected:
    targets: list[NDArray[np.float32]] = field(default_factory=list)
    samples: list[_Sample] = field(default_factory=list)
    features: list[NDArray[np.float32]] = field(default_factory=list)
    grid_centres: list[NDArray[np.float64]] = field(default_factory=list)
    failed_fields: int = 0


def _flush(
    pending: list[tuple[FieldJob, _Sample]], out: _Collected, config: DataBuildConfig, cache_dir: Path | None
) -> None:
    if not pending:
        return
    results = compute_many(
        [job for job, _ in pending],
        workers=config.workers,
        cache_dir=cache_dir,
        progress=False,
        skip_errors=True,
    )
    for (_, sample), fs in zip(pending, results, strict=True):
        if fs is None or fs.d_toa is None:
            out.failed_fields += 1
            continue
        out.targets.append(np.stack([fs.d_t, fs.d_o, fs.d_toa], axis=-1).reshape(-1, 3).astype(np.float32))
        out.features.append(local_feature(fs, sample.cond))
        out.grid_centres.append(np.asarray(fs.grid.centre, dtype=np.float64))
        out.samples.append(sample)
    pending.clear()


def _bank(out: _Collected, scene_id: NDArray[np.int64], config: DataBuildConfig) -> PriorBank:
    t, pos, quat, ci = [], [], [], []
    for sample, centre in zip(out.samples, out.grid_centres, strict=True):
        ts, ps, qs = resample_demo(sample.demo, config.bank_samples)
        t.append(ts)
        pos.append(ps - centre)
        quat.append(qs)
        ci.append(0 if sample.demo.segment == "leave" else config.bank_samples - 1)
    centres = np.stack(out.grid_centres)
    return PriorBank(
        features=np.stack(out.features),
        cond=np.stack([s.cond for s in out.samples]),
        scene_id=scene_id,
        grid_centre=centres,
        target_centre=np.stack([s.target_centre for s in out.samples]) - centres,
        approach_axis=np.stack([s.approach_axis for s in out.samples]),
        t=np.stack(t),
        position=np.stack(pos),
        quaternion=np.stack(quat),
        contact_index=np.asarray(ci, dtype=np.int64),
        layout=tuple(s.layout for s in out.samples),
        target=tuple(s.target for s in out.samples),
    )


def build_planner_data(
    config: DataBuildConfig | None = None,
    root: str | Path = ".",
    cache_dir: str | Path | None = None,
    progress: bool = True,
) -> PlannerData:
    """Build the field dataset and prior bank (see the module doc); deterministic for a config.

    Args:
        config: what to build.
        root: [path] base of relative scene paths (the repository root).
        cache_dir: field cache folder (``<key>.npz`` per sample); None = no cache.
        progress: show a progress bar over layouts.

    Raises:
        ConfigError: bad config; PlanningError: no sample could be built.
    """
    cfg = config or DataBuildConfig()
    t0 = time.perf_counter()
    cache = None if cache_dir is None else Path(cache_dir)
    n_layouts = len(cfg.scenes) * len(cfg.reshape_groups) * cfg.layouts_per_group
    out = _Collected()
    pending: list[tuple[FieldJob, _Sample]] = []
    failed_demos = 0
    bar = tqdm(total=n_layouts, desc="planner data", unit="layout", disable=not progress)
    try:
        for si, li, tag, layout in _layouts(cfg, Path(root)):
            samples, failed = _layout_samples(layout, tag, [cfg.demo_seed, si, li], cfg)
            failed_demos += failed
            pending.extend(samples)
            if len(pending) >= cfg.chunk_jobs:
                _flush(pending, out, cfg, cache)
            bar.update(1)
            bar.set_postfix(samples=len(out.samples) + len(pending))
        _flush(pending, out, cfg, cache)
    finally:
        bar.close()
    if not out.samples:
        raise PlanningError("no training sample could be built; check the scenes and the reach model")
    keys = list(dict.fromkeys(s.problem_key for s in out.samples))  # first-seen order
    index = {k: i for i, k in enumerate(keys)}
    scene_id = np.array([index[s.problem_key] for s in out.samples], dtype=np.int64)
    grid = problem_grid_of(out.grid_centres[0])
    dataset = FieldDataset(
        unit_points(grid),
        np.stack(out.targets),
        scene_id,
        np.stack([s.cond for s in out.samples]),
        channels=("t", "o", "toa"),
    )
    bank = _bank(out, scene_id, cfg)
    seconds = time.perf_counter() - t0
    summary: dict[str, int | float | str] = {
        "layouts": n_layouts,
        "problems": len(keys),
        "samples": len(out.samples),
        "failed_demonstrations": failed_demos,
        "failed_fields": out.failed_fields,
        "grid_nodes": dataset.n_points,
        "seconds": round(seconds, 1),
    }
    _LOG.info("planner data: %s", summary)
    return PlannerData(dataset=dataset, bank=bank, summary=summary)


def problem_grid_of(centre: NDArray[np.float64]) -> GridSpec:
    """The planner's grid (:data:`PLANNER_FIELD_CONFIG` size and resolution) at ``centre`` (3,) [m]."""
    c = np.asarray(centre, dtype=np.float64).reshape(3)
    return GridSpec(
        (float(c[0]), float(c[1]), float(c[2])), PLANNER_FIELD_CONFIG.size, PLANNER_FIELD_CONFIG.resolution
    )
