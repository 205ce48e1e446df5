"""Benchmark of the implicit planner on unseen layouts (seeds ≥ 100000, all three scene families).

Per layout: one reachable target that the cameras see (seeded pick, ≥ 10 cloud points), rendered with
its container opened (as the scheduler would), a hand (alternating), grasp, a free start pose near the
body like the training demonstrations (the person stands at (0, target y) facing +x); the planner gets
the labelled cloud and the approach axis from the spec. Checked against the **ground-truth meshes**
(open3d distance, :class:`hsi_planning.demos.ObstacleField`, every mesh but the target's):

- success: approach and leave keep a ``--hand-radius`` sphere and, on the carrying leave, the held
  object's mesh (moved with the wrist) clear of the meshes, and the approach ends within 2 cm of the
  reference contact position.
- reference contact: the planner's rule (:func:`hsi_planning.implicit.prior.contact_point`, ``palm_offset``
  beyond the target along the approach axis, centred on its extent) applied to the **part of the ground-
  truth mesh surface the scene's cameras see** (mesh surface samples ray-cast from every camera against
  every mesh, inside the camera's field of view). A cloud-based planner cannot know where the hidden part
  of an object ends (a bottle whose top is hidden under a board: which height is its middle?), so the
  reference is what the cameras can know, computed from the true geometry instead of the cloud; any such
  contact lies on the object. The contact of the whole mesh (the old reference) is reported as well:
  ``end_error_full`` per case and ``success (full-mesh contact)`` in the summary.
- Within 10 cm of path before the contact the required clearance relaxes linearly to what the reference
  contact pose itself has (a wrist at a low object next to a board cannot keep 4 cm from it; the object
  starts on its support). ``success (sphere)``: the same with the held object's bounding sphere
  (centred on its box centre) instead of its mesh.
- safety distance: mean clearance of the hand and held object within 20 cm of the contact [m];
  unsmoothness: mean |acceleration| [m/s²]; RMS curvature [1/m]; path length [m]; planning time.

With ``--ablation PATH`` (default ``models/planner_2ch.pt`` when it exists) the same cases are planned
with a 2-channel (t, toa) checkpoint. Writes ``<out>/planner.{json,md}``. ``--quick``: 6 layouts.

Usage: ``python benchmarks/planner.py [--checkpoint models/planner.pt] [--layouts 60] [--quick]``
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from hsi_planning.demos import ObstacleField
from hsi_planning.errors import HsiError
from hsi_planning.implicit.data_build import DataBuildConfig
from hsi_planning.implicit.data_scene import contact_pose, parts_to_open, render_opened
from hsi_planning.implicit.path import arc_length, required_clearance
from hsi_planning.implicit.planner import ImplicitPlanner, ImplicitPlannerConfig
from hsi_planning.implicit.prior import contact_point
from hsi_planning.implicit.problem import TEST_SEED_START, approach_axis_for
from hsi_planning.metrics import mean_acceleration, rms_curvature
from hsi_planning.perception.render import CloudConfig
from hsi_planning.planning import PlanRequest, PlanResult
from hsi_planning.scene import LayoutConfig, SceneSpec, generate_layouts, load_scene_spec, target_reachable
from hsi_planning.trajectory import WristTrajectory

REPO = Path(__file__).resolve().parents[1]
SCENES = ("kitchen", "narrow_shelf", "cluttered_drawer")
START_CENTRE = (0.2, 0.25, 1.0)  #: [m] free wrist pose like the training data (y: to the hand's side)
RELAX = 0.10  #: [m] path length before the contact over which the required clearance relaxes
SAFETY_RADIUS = 0.20  #: [m] the safety distance is averaged within this distance of the contact
CONTACT_TOLERANCE = 0.02  #: [m] the approach must end this close to the ground-truth contact
MIN_TARGET_POINTS = 10  #: [-] a target needs this many cloud points to be planned for (as in training)


@dataclass(frozen=True)
class Case:
    """One benchmark problem: the first of ``targets`` (seeded order) visible in the rendered cloud is
    planned for (the start pose is completed from its position)."""

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
                names = [o.name for o in layout.objects if target_reachable(layout, o.name)]
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
    c_clear = float(field.distance(contact[None])[0])
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


def evaluate(planner: ImplicitPlanner, case: Case, hand_radius: float) -> dict[str, Any]:
    """Plan one case and score it against the ground truth."""
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
    row: dict[str, Any] = {"case": case.tag, "target": target, "hand": case.hand}
    request = PlanRequest(
        cloud=scene.cloud,
        target=target,
        hand=case.hand,  # type: ignore[arg-type]
        action="grasp",
        start_position=start,
        approach_axis=axis,
    )
    t0 = time.perf_counter()
    try:
        result: PlanResult = planner.plan(request)
    except HsiError as exc:
        row.update(
            success=False,
            success_sphere=False,
            success_full_contact=False,
            planned=False,
            error=str(exc),
            seconds=time.perf_counter() - t0,
        )
        return row
    field = ObstacleField({k: m for k, m in scene.meshes.items() if k != target})
    a = check_segment(result.approach, field, gt_contact, hand_radius, None)
    lv = check_segment(result.leave, field, gt_contact, hand_radius, mesh)
    end_error = float(np.linalg.norm(result.approach.position[-1] - gt_contact))
    reached = end_error <= CONTACT_TOLERANCE and a["hand"] >= 0.0 and lv["hand"] >= 0.0
    trajs = (result.approach, result.leave)
    clear = a["hand"] >= 0.0 and lv["hand"] >= 0.0 and lv["mesh"] >= 0.0
    end_full = float(np.linalg.norm(result.approach.position[-1] - full_contact))
    row.update(
        success_full_contact=bool(clear and end_full <= CONTACT_TOLERANCE),
        end_error_full=end_full,
        success=bool(reached and lv["mesh"] >= 0.0),
        success_sphere=bool(reached and lv["sphere"] >= 0.0),
        planned=True,
        seconds=result.total_seconds,
        end_error=end_error,
        margin_hand=min(a["hand"], lv["hand"]),
        margin_mesh=lv["mesh"],
        margin_sphere=lv["sphere"],
        safety=float(np.nanmean([a["safety"], lv["safety"]])),
        unsmoothness=float(np.mean([mean_acceleration(t.position, t.t) for t in trajs])),
        rms_curvature=float(np.mean([rms_curvature(t.position, t.t) for t in trajs])),
        path_length=float(np.mean([t.path_length() for t in trajs])),
        duration=float(np.mean([t.duration for t in trajs])),
        field_approach=result.info["path_approach"]["field"],
        field_leave=result.info["path_leave"]["field"],
        learned_share=float(
            np.mean([result.info[f"path_{s}"]["learned_share"] for s in ("approach", "leave")])
        ),
        timings=result.timings,
    )
    return row


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Success rate and means / percentiles over the cases."""
    planned = [r for r in rows if r["planned"]]
    secs = np.array([r["seconds"] for r in planned]) if planned else np.array([math.nan])

    def mean(key: str) -> float:
        vals = [r[key] for r in planned if np.isfinite(r[key])]
        return float(np.mean(vals)) if vals else math.nan

    return {
        "cases": len(rows),
        "success_rate": float(np.mean([r["success"] for r in rows])) if rows else math.nan,
        "success_rate_sphere": float(np.mean([r["success_sphere"] for r in rows])) if rows else math.nan,
        "success_rate_full_contact": (
            float(np.mean([r["success_full_contact"] for r in rows])) if rows else math.nan
        ),
        "planned_rate": float(np.mean([r["planned"] for r in rows])) if rows else math.nan,
        "safety_distance_m": mean("safety"),
        "unsmoothness_m_s2": mean("unsmoothness"),
        "rms_curvature_1_m": mean("rms_curvature"),
        "path_length_m": mean("path_length"),
        "end_error_m": mean("end_error"),
        "end_error_full_m": mean("end_error_full"),
        "time_median_s": float(np.median(secs)),
        "time_p95_s": float(np.percentile(secs, 95)),
        "learned_share": mean("learned_share"),
    }


def markdown(results: dict[str, Any]) -> str:
    """A Markdown table of the summaries."""
    cols = [
        ("success_rate", "success", "{:.1%}"),
        ("success_rate_sphere", "success (sphere)", "{:.1%}"),
        ("success_rate_full_contact", "success (full-mesh contact)", "{:.1%}"),
        ("planned_rate", "planned", "{:.1%}"),
        ("safety_distance_m", "safety [m]", "{:.3f}"),
        ("unsmoothness_m_s2", "mean |a| [m/s²]", "{:.2f}"),
        ("rms_curvature_1_m", "RMS curvature [1/m]", "{:.2f}"),
        ("path_length_m", "path [m]", "{:.3f}"),
        ("time_median_s", "time median [s]", "{:.3f}"),
        ("time_p95_s", "time p95 [s]", "{:.3f}"),
        ("learned_share", "learned path", "{:.0%}"),
    ]
    lines = [
        f"# Implicit planner benchmark ({results['cases']} unseen layouts, seed {results['seed']})",
        "",
        "| model | " + " | ".join(c[1] for c in cols) + " |",
        "|---" * (len(cols) + 1) + "|",
    ]
    for name, summary in results["models"].items():
        lines.append(f"| {name} | " + " | ".join(f.format(summary[k]) for k, _, f in cols) + " |")
    lines += [
        "",
        f"Hand sphere {results['hand_radius']} m; contact tolerance {CONTACT_TOLERANCE} m.",
        "success: hand sphere and held object's mesh (moved with the wrist) clear of the ground-truth",
        "meshes, approach ends at the reference contact (the contact rule applied to the part of the",
        "ground-truth mesh the cameras see); success (sphere): the held object's bounding sphere instead",
        "of its mesh; success (full-mesh contact): the contact of the whole mesh instead (a hidden part",
        "moves it, which no cloud-based planner can know). learned path: mean share of the path length",
        "descended on the learned field (the rest on the fast-marching repair, see",
        "hsi_planning.implicit.segment).",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=REPO / "models" / "planner.pt")
    parser.add_argument("--ablation", type=Path, default=REPO / "models" / "planner_2ch.pt")
    parser.add_argument("--layouts", type=int, default=60, help="number of layouts (≥ 50 for acceptance)")
    parser.add_argument("--seed", type=int, default=TEST_SEED_START, help="layout seed (≥ 100000: unseen)")
    parser.add_argument("--hand-radius", type=float, default=0.04, help="[m] hand sphere radius")
    parser.add_argument("--quick", action="store_true", help="6 layouts, one per family and group")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    parser.add_argument("--verbose", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING)
    if args.seed < TEST_SEED_START:
        parser.error(f"--seed must be ≥ {TEST_SEED_START}: lower seeds are used for training")
    cases = make_cases(6 if args.quick else args.layouts, args.seed)
    models = {"implicit (t, o, toa)": args.checkpoint}
    if args.ablation.is_file():
        models["implicit (t, toa)"] = args.ablation
    results: dict[str, Any] = {"seed": args.seed, "cases": len(cases), "hand_radius": args.hand_radius}
    results["models"], results["rows"] = {}, {}
    for name, path in models.items():
        planner = ImplicitPlanner(path, ImplicitPlannerConfig(hand_radius=args.hand_radius))
        rows = []
        for case in cases:
            row = evaluate(planner, case, args.hand_radius)
            rows.append(row)
            status = "ok  " if row["success"] else "FAIL"
            detail = row.get("error", "") or (
                f"end {row['end_error']:.3f} m, margins hand {row['margin_hand']:.3f} "
                f"object {row['margin_mesh']:.3f} (sphere {row['margin_sphere']:.3f}) m"
            )
            print(f"{status} {name:22s} {case.tag:28s} {row['target']:10s} {row['seconds']:.3f} s  {detail}")
        results["models"][name] = summarize(rows)
        results["rows"][name] = rows
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "planner.json").write_text(json.dumps(results, indent=1, default=float))
    text = markdown(results)
    (args.out / "planner.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
