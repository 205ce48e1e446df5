"""Human-reach model vs real HDM05 reaches: are the generated demonstrations human-like?

Generates reaches with :func:`hsi_planning.demos.generate_reach` between the start and contact poses of
the real HDM05 clips (``grabHighR``: reach up to a high shelf; ``depositFloorR``: place on the floor),
processes them exactly like the mocap (6 Hz zero-phase low-pass, onset/contact at 5 % of peak speed)
and compares per statistic the generated median with the HDM05 median and interquartile range
(:func:`hsi_planning.mocap.hdm05.hdm05_reach_stats`). A ``grabHighR`` variant reaching into an open shelf
compartment (insertion along its depth axis, collision-checked) is reported too.

Usage::

    python benchmarks/human_reach.py [--quick] [--out benchmarks/results] [--hdm05 DIR] [--config FILE]

Writes ``human_reach.json``, ``human_reach.md`` and ``human_reach_speed.png`` to ``--out``.
HDM05 data: M. Müller et al., Tech. Rep. CG-2007-2, Universität Bonn, 2007 (CC BY-SA 3.0).
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.config import from_mapping, load_yaml
from hsi_planning.demos import ObstacleField, ReachModelConfig, ReachRequest, box_mesh, generate_reach
from hsi_planning.errors import PlanningError
from hsi_planning.mocap.amc import load_amc
from hsi_planning.mocap.asf import load_asf
from hsi_planning.mocap.hdm05 import hdm05_clips, hdm05_reach_stats, reach_metrics
from hsi_planning.mocap.reach import ReachConfig, lowpass, segment_reaches, wrist_rotations, wrist_trajectory
from hsi_planning.mocap.skeleton import forward_kinematics
from hsi_planning.trajectory import Action, WristTrajectory

REPO = Path(__file__).resolve().parents[1]
DEFAULT_HDM05 = REPO.parent / "shared" / "data" / "hdm05"
STATS = (
    "duration",
    "peak_speed",
    "peak_time_ratio",
    "max_deviation_ratio",
    "speed_curvature_exponent",
    "sparc",
)
UNITS = {"duration": "s", "peak_speed": "m/s"}
ACTIONS: dict[str, Action] = {"grabHighR": "grasp", "depositFloorR": "place"}
_LOG = logging.getLogger("human_reach")


@dataclass(frozen=True)
class ClipReach:
    """Start and contact pose of one real reach, and its normalized speed profile."""

    clip: str
    action: str
    start: NDArray[np.float64]  #: (3,) [m]
    contact: NDArray[np.float64]  #: (3,) [m]
    q_start: NDArray[np.float64]  #: (4,) [x y z w]
    q_contact: NDArray[np.float64]  #: (4,) [x y z w]
    speed: NDArray[np.float64]  #: (T,) [m/s] approach speed, onset..contact


def load_clip_reaches(directory: Path) -> list[ClipReach]:
    """The segmented approach of every HDM05 clip (right wrist), as :func:`hdm05_reach_stats` sees it."""
    cfg = ReachConfig()
    skeletons: dict[str, Any] = {}
    out: list[ClipReach] = []
    for path in hdm05_clips(directory):
        actor, action = path.stem.split("_")[1:3]
        if actor not in skeletons:
            skeletons[actor] = load_asf(path.parent / f"HDM_{actor}.asf")
        fk = forward_kinematics(skeletons[actor], load_amc(path, skeletons[actor], fps=120.0))
        wrist = wrist_trajectory(fk, "right")
        quats = Rotation.from_matrix(wrist_rotations(fk, "right")).as_quat()
        smooth = lowpass(wrist, 120.0, cfg.cutoff_hz, cfg.filter_order)
        for reach in segment_reaches(wrist, 120.0, cfg):
            approach = smooth[reach.approach]
            speed = np.linalg.norm(np.gradient(approach, 1.0 / 120.0, axis=0), axis=1)
            out.append(
                ClipReach(
                    path.stem,
                    action,
                    approach[0],
                    approach[-1],
                    quats[reach.onset],
                    quats[reach.contact],
                    speed,
                )
            )
    return out


def processed_approach(traj: WristTrajectory, fps: float) -> NDArray[np.float64]:
    """The generated path processed like mocap: padded with rest, low-passed (6 Hz, zero phase), cut at
    5 % of peak speed (onset and contact) — ``(T, 3) [m]``."""
    pos = traj.position if traj.segment == "approach" else traj.position[::-1]
    pad = int(0.5 * fps)
    padded = np.vstack([np.repeat(pos[:1], pad, axis=0), pos, np.repeat(pos[-1:], pad, axis=0)])
    smooth = lowpass(padded, fps, 6.0, 2)
    speed = np.linalg.norm(np.gradient(smooth, 1.0 / fps, axis=0), axis=1)
    peak = int(np.argmax(speed))
    thr = 0.05 * speed[peak]
    before = np.flatnonzero(speed[: peak + 1] < thr)
    after = np.flatnonzero(speed[peak:] < thr)
    onset = int(before[-1]) if before.size else 0
    contact = peak + int(after[0]) if after.size else len(speed) - 1
    return np.asarray(smooth[onset : contact + 1])


def _heading(start: NDArray[np.float64], contact: NDArray[np.float64]) -> NDArray[np.float64]:
    h = contact - start
    h[2] = 0.0
    return h / max(float(np.linalg.norm(h)), 1e-9)


def shelf_field(contact: NDArray[np.float64], axis: NDArray[np.float64]) -> ObstacleField:
    """An open shelf compartment (0.35 m high, 0.5 m wide, 0.3 m deep) around ``contact`` whose opening
    faces ``-axis`` (horizontal unit vector): boards 8 cm below and 26 cm above the wrist, back wall."""
    yaw = np.arctan2(axis[1], axis[0])
    rot = Rotation.from_euler("z", yaw).as_matrix()
    centre = contact + 0.05 * axis  # wrist 5 cm in front of the compartment centre
    parts = []
    for offset, size in (
        ((0.0, 0.0, -0.09), (0.30, 0.50, 0.02)),
        ((0.0, 0.0, 0.27), (0.30, 0.50, 0.02)),
        ((0.16, 0.0, 0.09), (0.02, 0.50, 0.38)),
    ):
        mesh = box_mesh([0.0, 0.0, 0.0], size)
        transform = np.eye(4)
        transform[:3, :3] = rot
        transform[:3, 3] = centre + rot @ np.asarray(offset)
        parts.append(mesh.apply_transform(transform))
    shelf = trimesh.util.concatenate(parts)
    assert isinstance(shelf, trimesh.Trimesh)
    return ObstacleField({"shelf": shelf})


def generate_set(
    clips: list[ClipReach], action: str, count: int, *, config: ReachModelConfig, seed: int, shelf: bool
) -> tuple[list[dict[str, float]], list[NDArray[np.float64]], int]:
    """Generate ``count`` reaches between the poses of ``clips`` of ``action``; rows of metrics, speed
    profiles and the number of failed generations."""
    pool = [c for c in clips if c.action == action]
    rows, speeds, failures = [], [], 0
    for k in range(count):
        clip = pool[k % len(pool)]
        rng = np.random.default_rng([seed, k, list(ACTIONS).index(action), int(shelf)])
        axis = _heading(clip.start, clip.contact) if shelf else None
        request = ReachRequest(
            clip.start,
            clip.q_start,
            clip.contact,
            clip.q_contact,
            approach_axis=axis,
            hand="right",
            action=ACTIONS[action],
            segment="approach",
        )
        field = shelf_field(clip.contact, axis) if axis is not None else None
        try:
            traj = generate_reach(request, field, config, rng)
        except PlanningError as exc:  # report, keep going
            _LOG.warning("%s #%d failed: %s", action, k, exc)
            failures += 1
            continue
        approach = processed_approach(traj, config.sample_rate)
        row = reach_metrics(approach, config.sample_rate)
        if field is not None:
            row["min_clearance"] = float(field.distance(traj.position).min())
        rows.append(row)
        speeds.append(np.linalg.norm(np.gradient(approach, 1.0 / config.sample_rate, axis=0), axis=1))
    return rows, speeds, failures


def _summary(values: list[float]) -> dict[str, float]:
    arr = np.asarray(values, dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    if arr.size == 0:
        return {"median": float("nan"), "q25": float("nan"), "q75": float("nan"), "n": 0}
    q25, med, q75 = np.percentile(arr, [25, 50, 75])
    return {"median": float(med), "q25": float(q25), "q75": float(q75), "n": int(arr.size)}


def compare(reference: list[dict[str, Any]], generated: list[dict[str, float]]) -> dict[str, Any]:
    """Per statistic: HDM05 median/IQR, generated median/IQR, and whether the generated median is inside."""
    out: dict[str, Any] = {}
    for stat in STATS:
        ref = _summary([r[stat] for r in reference])
        gen = _summary([r[stat] for r in generated])
        inside = ref["q25"] <= gen["median"] <= ref["q75"]
        out[stat] = {"hdm05": ref, "generated": gen, "inside_iqr": bool(inside)}
    return out


def _markdown(results: dict[str, Any]) -> str:
    lines = ["# Human-reach model vs HDM05", ""]
    lines.append(
        f"Generated per set: {results['count']} reaches (seed {results['seed']}); HDM05 rows from "
        "`hdm05_reach_stats` (all detected reaches). Generated reaches are low-passed and cut at 5 % "
        "of peak speed like the mocap."
    )
    for name, block in results["sets"].items():
        lines += ["", f"## {name}", ""]
        lines.append(
            f"HDM05 reference: `{block['reference']}` (n = {block['n_reference']}); generated "
            f"n = {block['n_generated']}, failures {block['failures']}"
            + (f", min wrist clearance {block['min_clearance']:.3f} m" if "min_clearance" in block else "")
        )
        lines += [
            "",
            "| statistic | HDM05 median [IQR] | generated median [IQR] | inside IQR |",
            "|---|---|---|---|",
        ]
        for stat, cmp in block["comparison"].items():
            unit = f" [{UNITS[stat]}]" if stat in UNITS else ""
            ref, gen = cmp["hdm05"], cmp["generated"]
            lines.append(
                f"| {stat}{unit} | {ref['median']:.3f} [{ref['q25']:.3f}, {ref['q75']:.3f}] | "
                f"{gen['median']:.3f} [{gen['q25']:.3f}, {gen['q75']:.3f}] | "
                f"{'yes' if cmp['inside_iqr'] else 'no'} |"
            )
        dev = block["comparison"]["max_deviation_ratio"]["generated"]["median"]
        lines.append(
            f"\nMedian path deviation {100 * dev:.1f} % (must be >= 5 %): {'ok' if dev >= 0.05 else 'FAIL'}"
        )
    lines += [
        "",
        f"Calibration target (grabHighR, every generated median inside the HDM05 IQR): "
        f"**{'met' if results['calibrated'] else 'NOT met'}**",
        "",
    ]
    return "\n".join(lines)


def _plot(
    path: Path, ref: dict[str, list[NDArray[np.float64]]], gen: dict[str, list[NDArray[np.float64]]]
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = np.linspace(0.0, 1.0, 101)

    def norm(v: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(np.interp(grid, np.linspace(0.0, 1.0, len(v)), v / v.max()))

    fig, axes = plt.subplots(1, len(ref), figsize=(5 * len(ref), 3.6), squeeze=False)
    for ax, name in zip(axes[0], ref, strict=True):
        for v in ref[name]:
            ax.plot(grid, norm(v), color="0.6", lw=0.8)
        for v in gen[name]:
            ax.plot(grid, norm(v), color="tab:blue", lw=0.5, alpha=0.35)
        ax.plot(
            grid, np.median([norm(v) for v in ref[name]], axis=0), color="k", lw=2.2, label="HDM05 median"
        )
        ax.plot(
            grid,
            np.median([norm(v) for v in gen[name]], axis=0),
            color="tab:blue",
            lw=2.2,
            label="generated median",
        )
        ax.set_title(name)
        ax.set_xlabel("normalized time (onset → contact)")
        ax.set_ylabel("speed / peak speed")
        ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="10 reaches per set instead of 50")
    parser.add_argument("--count", type=int, default=None, help="reaches per set (overrides --quick)")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    parser.add_argument("--hdm05", type=Path, default=DEFAULT_HDM05)
    parser.add_argument(
        "--config", type=Path, default=None, help="YAML mapping of ReachModelConfig overrides"
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    count = args.count or (10 if args.quick else 50)
    config = from_mapping(ReachModelConfig, load_yaml(args.config) if args.config else {})
    t0 = time.perf_counter()
    reference = hdm05_reach_stats(args.hdm05)
    clips = load_clip_reaches(args.hdm05)
    sets: dict[str, Any] = {}
    ref_speeds: dict[str, list[NDArray[np.float64]]] = {}
    gen_speeds: dict[str, list[NDArray[np.float64]]] = {}
    timing: dict[str, float] = {}
    for name, action, shelf in (
        ("grabHighR", "grabHighR", False),
        ("depositFloorR", "depositFloorR", False),
        ("grabHighR, open shelf", "grabHighR", True),
    ):
        start = time.perf_counter()
        rows, speeds, failures = generate_set(
            clips, action, count, config=config, seed=args.seed, shelf=shelf
        )
        timing[name] = (time.perf_counter() - start) / max(count, 1)
        ref_rows = [r for r in reference if r["action"] == action]
        block: dict[str, Any] = {
            "reference": action,
            "n_reference": len(ref_rows),
            "n_generated": len(rows),
            "failures": failures,
            "comparison": compare(ref_rows, rows),
            "seconds_per_reach": timing[name],
        }
        if shelf and rows:
            block["min_clearance"] = float(min(r["min_clearance"] for r in rows))
        sets[name] = block
        if not shelf:
            ref_speeds[name] = [c.speed for c in clips if c.action == action]
            gen_speeds[name] = speeds
    calibrated = all(c["inside_iqr"] for c in sets["grabHighR"]["comparison"].values())
    results = {
        "count": count,
        "seed": args.seed,
        "config": {k: getattr(config, k) for k in config.__dataclass_fields__},
        "sets": sets,
        "calibrated": calibrated,
        "deviation_ok": all(
            b["comparison"]["max_deviation_ratio"]["generated"]["median"] >= 0.05 for b in sets.values()
        ),
        "wall_time_s": time.perf_counter() - t0,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "human_reach.json").write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    markdown = _markdown(results)
    (args.out / "human_reach.md").write_text(markdown, encoding="utf-8")
    _plot(args.out / "human_reach_speed.png", ref_speeds, gen_speeds)
    print(markdown)
    print(
        f"wrote {args.out}/human_reach.{{json,md}} and human_reach_speed.png "
        f"({results['wall_time_s']:.1f} s; {1000 * timing['grabHighR']:.1f} ms per free-space reach)"
    )
    return 0 if calibrated and results["deviation_ok"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
