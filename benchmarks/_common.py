"""Shared parts of the planner benchmarks: one unseen-layout case turned into a request, a plan scored
against the ground-truth meshes, and the HDM05 reaches processed like planned ones.

:func:`prepare` and :func:`score` are :func:`benchmarks.planner.evaluate` split in two (the case is
rendered once and every planner is scored on the same cloud): success, safety distance, unsmoothness,
RMS curvature and path length exactly as ``benchmarks/planner.py`` defines them (its module doc).
:func:`human_metrics` processes a planned approach like the mocap (``benchmarks/human_reach.py``) and
returns the human-likeness measures of :func:`hsi_planning.mocap.hdm05.reach_metrics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from human_reach import processed_approach
from numpy.typing import NDArray
from planner import CONTACT_TOLERANCE, MIN_TARGET_POINTS, START_CENTRE, Case, check_segment, visible_surface

from hsi_planning.demos import ObstacleField
from hsi_planning.errors import MotionDataError
from hsi_planning.implicit.data_build import DataBuildConfig
from hsi_planning.implicit.data_scene import contact_pose, parts_to_open, render_opened
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
from hsi_planning.trajectory import WristTrajectory

F64 = NDArray[np.float64]
#: human-likeness measures of :func:`human_metrics` (``dtw`` is added by the caller against HDM05).
HUMAN_KEYS = ("peak_time_ratio", "max_deviation_ratio", "speed_curvature_exponent", "sparc", "ldlj")
DTW_SAMPLES = 50  #: [-] samples of a normalized trajectory compared by DTW


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
    """Render ``case`` with its target's container opened and build the request (as in training)."""
    data = DataBuildConfig()  # open doors/drawers as far as in the training data
    for target in case.targets:  # the first target the cameras see (as the training data build)
        scene = render_opened(
            case.spec,
            parts_to_open(case.spec, target),
            cloud_config=CloudConfig(),
            door_fraction=data.door_fraction,
            drawer_fraction=data.drawer_fraction,
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
    request = PlanRequest(
        cloud=scene.cloud,
        target=target,
        hand=case.hand,  # type: ignore[arg-type]
        action="grasp",
        start_position=start,
        approach_axis=axis,
    )
    field = ObstacleField({k: m for k, m in scene.meshes.items() if k != target})
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
