"""Shared parts of the planner benchmarks (``planner.py``, ``planners.py``): the unseen-layout cases, one
case turned into a request, a plan scored against the ground-truth meshes, and the HDM05 reaches processed
like planned ones.

:func:`make_cases` draws the cases; :func:`prepare` renders a case once (so every planner is scored on the
same cloud) and :func:`score` scores a plan of it: success, safety distance, unsmoothness, RMS curvature
and path length as ``benchmarks/planner.py`` defines them (its module doc). :func:`human_metrics`
processes a planned approach like the mocap (``benchmarks/human_reach.py``) and returns the
human-likeness measures of :func:`hsi_planning.mocap.hdm05.reach_metrics`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from human_reach import processed_approach  # also used by planners.py (via _common)
from numpy.typing import NDArray

from hsi_planning.demos import ObstacleField
from hsi_planning.errors import HsiError, MotionDataError
from hsi_planning.implicit.data_build import DataBuildConfig
from hsi_planning.implicit.data_scene import contact_pose, parts_to_open, render_opened
from hsi_planning.implicit.path import arc_length, required_clearance
from hsi_planning.implicit.prior import contact_point
from hsi_planning.implicit.problem import approach_axis_for
from hsi_planning.metrics import mean_acceleration, normalized_trajectory, rms_curvature
from hsi_planning.mocap.amc import load_amc
from hsi_planning.mocap.asf import load_asf
from hsi_planning.mocap.hdm05 import hdm05_clips, reach_metrics
from hsi_planning.mocap.reach import ReachConfig, lowpass, segment_reaches, wrist_trajectory
from hsi_planning.mocap.skeleton import forward_kinematics
from hsi_planning.perception.render import CloudConfig
from hsi_planning.planning import PlanRequest, PlanResult
from hsi_planning.scene import (
    LayoutConfig,
    SceneSpec,
    exposing_fraction,
    generate_layouts,
    load_scene_spec,
    target_reachable,
)
from hsi_planning.scheduler.world import DOOR_FRACTION, DRAWER_FRACTION
from hsi_planning.trajectory import WristTrajectory

REPO = Path(__file__).resolve().parents[1]
SCENES = ("kitchen", "narrow_shelf", "cluttered_drawer")
START_CENTRE = (0.2, 0.25, 1.0)  #: [m] free wrist pose like the training data (y: to the hand's side)
START_FREE = 0.08  #: [m] the start wrist keeps this far from the ground truth (else the person steps back)
START_BACK_STEP = 0.02  #: [m] step back (−x) of a start wrist too close to an opened drawer or door
START_BACK_MAX = 0.40  #: [m] at most this far
RELAX = 0.10  #: [m] path length before the contact over which the required clearance relaxes
SAFETY_RADIUS = 0.20  #: [m] the safety distance is averaged within this distance of the contact
CONTACT_TOLERANCE = 0.02  #: [m] the approach must end this close to the ground-truth contact
MIN_TARGET_POINTS = 10  #: [-] a target needs this many cloud points to be planned for (as in training)
F64 = NDArray[np.float64]
#: human-likeness measures of :func:`human_metrics` (``dtw`` is added by the caller against HDM05).
HUMAN_KEYS = ("peak_time_ratio", "max_deviation_ratio", "speed_curvature_exponent", "sparc", "ldlj")
DTW_SAMPLES = 50  #: [-] samples of a normalized trajectory compared by DTW


@dataclass(frozen=True)
class Case:
    """One benchmark problem: the first of ``targets`` (seeded order) visible in the rendered cloud is
    planned for (the start pose is completed from its position). Targets are reachable in one reach
    (:func:`~hsi_planning.scene.target_reachable` with ``direct``): one behind a blocker needs the
    scheduler's move of the blocker first (tested with the scheduler), not a single approach."""

    tag: str
    spec: SceneSpec
    targets: tuple[str, ...]
    hand: str
    noise: tuple[float, float, float]


def make_cases(n_layouts: int, seed: int) -> list[Case]:
    """About ``n_layouts`` cases spread evenly over the 3 scene families × (plain, reshaped) groups."""
    per_group = max(1, math.ceil(n_layouts / (2 * len(SCENES))))
    rng = np.random.default_rng(seed)
    cases: list[Case] = []
    for family in SCENES:
        spec = load_scene_spec(REPO / "sim" / "scenes" / f"{family}.yaml")
        for reshape in (False, True):
            for i, layout in enumerate(
                generate_layouts(spec, per_group, seed, LayoutConfig(reshape=reshape))
            ):
                names = [o.name for o in layout.objects if target_reachable(layout, o.name, direct=True)]
                if names:
                    order = tuple(names[int(k)] for k in rng.permutation(len(names)))
                    noise = rng.normal(0.0, 0.03, 3)
                    tag = f"{family}/{'reshape' if reshape else 'plain'}/{i}"
                    hand = ("left", "right")[len(cases) % 2]
                    cases.append(Case(tag, layout, order, hand, (noise[0], noise[1], noise[2])))
    return cases


def visible_surface(
    spec: SceneSpec, meshes: dict[str, trimesh.Trimesh], target: str, samples: int = 4000
) -> np.ndarray:
    """(K, 3) [m] samples of the target mesh's surface seen by at least one camera of ``spec``: inside its
    field of view (aspect of its resolution) and the first hit of the ray from the camera (all meshes)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for mesh in meshes.values():
        scene.add_triangles(
            o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
        )
    pts = np.asarray(trimesh.sample.sample_surface(meshes[target], samples, seed=0)[0], dtype=np.float64)
    seen = np.zeros(len(pts), dtype=bool)
    for cam in spec.cameras:
        pos = np.asarray(cam.pos, dtype=np.float64)
        fwd = np.asarray(cam.target, dtype=np.float64) - pos
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        ray = pts - pos
        dist = np.linalg.norm(ray, axis=1)
        depth = ray @ fwd
        tan_y = math.tan(math.radians(cam.fovy) / 2.0)
        tan_x = tan_y * cam.resolution[0] / cam.resolution[1]
        in_view = (
            (depth > 0.05) & (np.abs(ray @ right) <= tan_x * depth) & (np.abs(ray @ up) <= tan_y * depth)
        )
        rays = np.hstack([np.broadcast_to(pos, pts.shape), ray / dist[:, None]]).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        seen |= in_view & (hit >= dist - 0.003)
    return pts[seen]


def _sphere(mesh: trimesh.Trimesh) -> tuple[np.ndarray, float]:
    """(centre (3,) [m] of the bounding box, radius [m] enclosing every vertex)."""
    centre = np.asarray(mesh.bounds, dtype=np.float64).mean(axis=0)
    return centre, float(np.linalg.norm(np.asarray(mesh.vertices) - centre, axis=1).max())


def _relaxed_margin(dist: np.ndarray, from_contact: np.ndarray, full: float) -> float:
    """Worst (clearance − required) [m]: ``full`` away from the contact, relaxed to the contact's value."""
    at_contact = float(dist[int(np.argmin(from_contact))])
    return float((dist - required_clearance(from_contact, full, at_contact, RELAX, 0.0)).min())


def check_segment(
    traj: WristTrajectory,
    field: ObstacleField,
    contact: np.ndarray,
    hand_radius: float,
    held: trimesh.Trimesh | None,
) -> dict[str, float]:
    """Ground-truth clearance of one segment (see the module doc).

    Returns the worst margins [m] (clearance − required; ≥ 0 is collision-free) of the hand sphere, the
    held object's bounding sphere and the held object's mesh (moved with the wrist), and the safety
    distance [m] (mean clearance of hand and held object within 20 cm of the contact).
    """
    pos = traj.position
    ordered = pos if traj.segment == "approach" else pos[::-1]
    from_contact = arc_length(ordered[::-1])[::-1]
    from_contact = from_contact if traj.segment == "approach" else from_contact[::-1]
    hand_d = field.distance(pos)
    # The segment's contact sample may stand up to CONTACT_TOLERANCE from the reference contact, and a
    # distance changes by at most the displacement: what it must keep there is the reference contact's
    # clearance less that offset (else a contact 5 mm off, 0.5 mm nearer a neighbour, "collides").
    offset = float(np.linalg.norm(pos[traj.contact_index] - contact))
    c_clear = float(field.distance(contact[None])[0]) - offset
    out = {"hand": float((hand_d - required_clearance(from_contact, hand_radius, c_clear, RELAX)).min())}
    near = np.linalg.norm(pos - contact, axis=1) <= SAFETY_RADIUS
    safety = [hand_d[near]]
    out["sphere"] = out["mesh"] = math.inf
    if held is not None:
        start = pos[traj.contact_index]
        centre, radius = _sphere(held)
        sphere_d = field.distance(centre + (pos - start)) - radius
        out["sphere"] = _relaxed_margin(sphere_d, from_contact, 0.0)
        samples = np.vstack([held.vertices, trimesh.sample.sample_surface(held, 200, seed=0)[0]])
        every = max(1, len(pos) // 60)
        idx = np.unique(np.concatenate([np.arange(0, len(pos), every), [len(pos) - 1]]))
        moved = (samples[None, :, :] + (pos[idx] - start)[:, None, :]).reshape(-1, 3)
        mesh_d = field.distance(moved).reshape(len(idx), -1).min(axis=1)
        out["mesh"] = _relaxed_margin(mesh_d, from_contact[idx], 0.0)
        safety.append(mesh_d[near[idx]])
    vals = np.concatenate(safety)
    out["safety"] = float(vals.mean()) if vals.size else math.nan
    return out


@dataclass(frozen=True)
class Prepared:
    """One case rendered and ready to plan: the request and the ground truth to score against.

    Attributes:
        case: the benchmark case; target: the planned target (first one the cameras see).
        request: the planner input (labelled cloud, hand, grasp, start pose, approach axis).
        field: ground-truth meshes of everything but the target; mesh: the target's mesh.
        gt_contact: (3,) [m] reference wrist contact: the planner's rule on the mesh surface the cameras see.
        full_contact: (3,) [m] the same rule on the whole target mesh.
    """

    case: Case
    target: str
    request: PlanRequest
    field: ObstacleField
    mesh: trimesh.Trimesh
    gt_contact: F64
    full_contact: F64


def prepare(case: Case) -> Prepared:
    """Render ``case`` with its target's container opened (doors as far as the scheduler opens them,
    :data:`~hsi_planning.scheduler.world.DOOR_FRACTION`; a drawer as far as the target needs to come out
    from under the carcass, :func:`~hsi_planning.scene.exposing_fraction`: at least as far as in the
    training data, at most as far as the scheduler pulls, ``DRAWER_FRACTION``) and build the request."""
    data = DataBuildConfig()
    for target in case.targets:  # the first target the cameras see (as the training data build)
        scene = render_opened(
            case.spec,
            parts_to_open(case.spec, target),
            cloud_config=CloudConfig(),
            door_fraction=DOOR_FRACTION,
            drawer_fraction=exposing_fraction(case.spec, target, data.drawer_fraction, DRAWER_FRACTION),
        )
        if int((scene.cloud.labels == scene.label_ids[target]).sum()) >= MIN_TARGET_POINTS:
            break
    mesh = scene.meshes[target]
    axis = approach_axis_for(case.spec, target)
    full_contact, _ = contact_pose(mesh, axis, data.palm_offset)
    seen = visible_surface(case.spec, scene.meshes, target)
    gt_contact = contact_point(seen, axis, data.palm_offset) if len(seen) else full_contact
    side = 1.0 if case.hand == "left" else -1.0
    y = float(np.asarray(mesh.bounds).mean(axis=0)[1])
    sx, sy, sz = START_CENTRE
    start = np.array([sx, y + side * sy, sz]) + np.asarray(case.noise)
    field = ObstacleField({k: m for k, m in scene.meshes.items() if k != target})
    for _ in range(round(START_BACK_MAX / START_BACK_STEP)):  # a drawer pulled out to the body: step back
        if float(field.distance(start[None])[0]) >= START_FREE:
            break
        start[0] -= START_BACK_STEP
    request = PlanRequest(
        cloud=scene.cloud,
        target=target,
        hand=case.hand,  # type: ignore[arg-type]
        action="grasp",
        start_position=start,
        approach_axis=axis,
    )
    return Prepared(
        case,
        target,
        request,
        field,
        mesh,
        np.array(gt_contact, dtype=np.float64),
        np.array(full_contact, dtype=np.float64),
    )


def score(result: PlanResult, prep: Prepared, hand_radius: float) -> dict[str, Any]:
    """Ground-truth scores of a plan of ``prep`` (keys as the rows of ``benchmarks/planner.py``)."""
    a = check_segment(result.approach, prep.field, prep.gt_contact, hand_radius, None)
    lv = check_segment(result.leave, prep.field, prep.gt_contact, hand_radius, prep.mesh)
    end_error = float(np.linalg.norm(result.approach.position[-1] - prep.gt_contact))
    reached = end_error <= CONTACT_TOLERANCE and a["hand"] >= 0.0 and lv["hand"] >= 0.0
    trajs = (result.approach, result.leave)
    clear = a["hand"] >= 0.0 and lv["hand"] >= 0.0 and lv["mesh"] >= 0.0
    end_full = float(np.linalg.norm(result.approach.position[-1] - prep.full_contact))
    return {
        "success_full_contact": bool(clear and end_full <= CONTACT_TOLERANCE),
        "end_error_full": end_full,
        "success": bool(reached and lv["mesh"] >= 0.0),
        "success_sphere": bool(reached and lv["sphere"] >= 0.0),
        "planned": True,
        "seconds": result.total_seconds,
        "end_error": end_error,
        "margin_hand": min(a["hand"], lv["hand"]),
        "margin_mesh": lv["mesh"],
        "margin_sphere": lv["sphere"],
        "safety": float(np.nanmean([a["safety"], lv["safety"]])),
        "unsmoothness": float(np.mean([mean_acceleration(t.position, t.t) for t in trajs])),
        "rms_curvature": float(np.mean([rms_curvature(t.position, t.t) for t in trajs])),
        "path_length": float(np.mean([t.path_length() for t in trajs])),
        "duration": float(np.mean([t.duration for t in trajs])),
    }


def failed(exc: HsiError, t0: float) -> dict[str, Any]:
    """Row fields of a plan that raised ``exc``; ``t0``: [s] ``time.perf_counter()`` when planning began."""
    return {
        "success": False,
        "success_sphere": False,
        "success_full_contact": False,
        "planned": False,
        "error": str(exc),
        "seconds": time.perf_counter() - t0,
    }


def sample_rate(traj: WristTrajectory) -> float:
    """[Hz] sample rate of a uniformly sampled trajectory."""
    return float(1.0 / np.median(np.diff(traj.t)))


def human_metrics(traj: WristTrajectory) -> tuple[dict[str, float], F64 | None]:
    """Human-likeness of an approach processed like the mocap (6 Hz low-pass, cut at 5 % of peak speed).

    Returns:
        ({measure: value} for :data:`HUMAN_KEYS` (NaN where it cannot be computed), normalized trajectory
        (:data:`DTW_SAMPLES`, 3) [-] for DTW, or None when the path has no chord).
    """
    fps = sample_rate(traj)
    approach = processed_approach(traj, fps)
    if len(approach) < 8:
        return {k: math.nan for k in HUMAN_KEYS}, None
    metrics = reach_metrics(approach, fps)
    out = {k: float(metrics[k]) for k in HUMAN_KEYS}
    try:
        norm = normalized_trajectory(approach, DTW_SAMPLES)
    except MotionDataError:
        norm = None
    return out, norm


@dataclass(frozen=True)
class HumanReach:
    """One HDM05 approach (right wrist, low-passed, onset → contact) with its measures."""

    clip: str
    position: F64  #: (T, 3) [m]
    fps: float  #: [Hz]
    metrics: dict[str, float]
    normalized: F64  #: (DTW_SAMPLES, 3) [-]


def hdm05_approaches(directory: Path, action: str = "grabHighR") -> list[HumanReach]:
    """Every detected approach of ``action`` in the HDM05 clips of ``directory``."""
    cfg = ReachConfig()
    skeletons: dict[str, Any] = {}
    out: list[HumanReach] = []
    for path in hdm05_clips(directory, (action,)):
        actor, fps = path.stem.split("_")[1], float(path.stem.split("_")[-1])
        if actor not in skeletons:
            skeletons[actor] = load_asf(path.parent / f"HDM_{actor}.asf")
        wrist = wrist_trajectory(
            forward_kinematics(skeletons[actor], load_amc(path, skeletons[actor], fps=fps))
        )
        smooth = lowpass(wrist, fps, cfg.cutoff_hz, cfg.filter_order)
        for reach in segment_reaches(wrist, fps, cfg):
            approach = np.asarray(smooth[reach.approach], dtype=np.float64)
            metrics = {k: float(v) for k, v in reach_metrics(approach, fps).items() if k in HUMAN_KEYS}
            norm = normalized_trajectory(approach, DTW_SAMPLES)
            out.append(HumanReach(path.stem, approach, fps, metrics, norm))
    return out
