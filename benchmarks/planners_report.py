"""Summaries, the Markdown table (CHOICE Table 3 style) and the plots of ``benchmarks/planners.py``."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
from _common import HUMAN_KEYS, HumanReach

from hsi_planning.metrics import dtw_distance

GROUPS = ("without reshaping", "with reshaping and novel furniture")
LEARNED, MINJERK, ABLATION = "learned (t, o, toa)", "minimum jerk", "learned 2-ch (t, toa)"
METRICS = ("safety", "unsmoothness", "rms_curvature", "path_length")
HUMAN_ALL = (*HUMAN_KEYS, "dtw")
SAFETY_RATIO = 1.1  #: [-] target: learned safety distance ≥ this × minimum jerk's
SUCCESS_TARGET = 0.97  #: [-] target: learned success rate in each group
HUMAN_WINS = 4  #: [-] target: learned closer to HDM05 on at least this many of the 6 measures
_COLOURS = {LEARNED: "tab:blue", MINJERK: "tab:orange", ABLATION: "tab:purple", "teacher": "tab:green"}


def _stats(rows: list[dict[str, Any]]) -> dict[str, Any]:
    planned = [r for r in rows if r["planned"]]
    out: dict[str, Any] = {
        "plans": len(rows),
        "success_rate": float(np.mean([r["success"] for r in rows])) if rows else math.nan,
        "success_rate_sphere": float(np.mean([r["success_sphere"] for r in rows])) if rows else math.nan,
        "success_rate_full_contact": (
            float(np.mean([r["success_full_contact"] for r in rows])) if rows else math.nan
        ),
        "planned_rate": float(np.mean([r["planned"] for r in rows])) if rows else math.nan,
    }
    for key in METRICS:
        vals = np.array([r[key] for r in planned], dtype=np.float64)
        vals = vals[np.isfinite(vals)]
        out[key] = {
            "mean": float(vals.mean()) if vals.size else math.nan,
            "std": float(vals.std()) if vals.size else math.nan,
        }
    secs = np.array([r["seconds"] for r in planned], dtype=np.float64)
    out["time_median_s"] = float(np.median(secs)) if secs.size else math.nan
    out["time_p95_s"] = float(np.percentile(secs, 95)) if secs.size else math.nan
    return out


def _human(rows: list[dict[str, Any]], hdm05: dict[str, float]) -> dict[str, Any]:
    planned = [r for r in rows if r["planned"]]
    out: dict[str, Any] = {}
    for key in HUMAN_ALL:
        vals = np.array([r[key] for r in planned], dtype=np.float64)
        finite = vals[np.isfinite(vals)]
        centre = float(np.median(finite)) if finite.size else math.nan
        if key == "dtw":  # each plan's mean DTW to the HDM05 set is a distance: its median decides
            mean = float(finite.mean()) if finite.size else math.nan
            out[key] = {"median": centre, "mean": mean, "n": int(finite.size), "distance": centre}
        else:
            out[key] = {"median": centre, "n": int(finite.size), "distance": abs(centre - hdm05[key])}
    return out


def _closer(a: float, b: float) -> bool:
    """Is distance ``a`` smaller than ``b`` (NaN: the measure could not be computed = infinitely far)."""
    a = a if math.isfinite(a) else math.inf
    b = b if math.isfinite(b) else math.inf
    return a < b


def summarize(
    rows: list[dict[str, Any]], hdm05: dict[str, float], human: list[HumanReach], runs_present: list[str]
) -> dict[str, Any]:
    """Per group and planner scores, human-likeness against HDM05 and the issue's targets."""
    planners = list(dict.fromkeys(runs_present))
    present = [g for g in GROUPS if any(r["group"] == g for r in rows)]
    table = {
        g: {p: _stats([r for r in rows if r["planner"] == p and g in ("all", r["group"])]) for p in planners}
        for g in (*present, "all")
    }
    learned_runs = {
        g: {
            run: float(np.mean([r["success"] for r in rows if r["run"] == run and g in ("all", r["group"])]))
            for run in dict.fromkeys(r["run"] for r in rows if r["planner"] == LEARNED)
        }
        for g in table
    }
    likeness = {p: _human([r for r in rows if r["planner"] == p], hdm05) for p in planners}
    pairs = list(itertools.combinations(range(len(human)), 2))
    self_dtw = float(np.mean([dtw_distance(human[i].normalized, human[j].normalized) for i, j in pairs]))
    wins = {k: _closer(likeness[LEARNED][k]["distance"], likeness[MINJERK][k]["distance"]) for k in HUMAN_ALL}
    safety_l = table["all"][LEARNED]["safety"]["mean"]
    safety_m = table["all"][MINJERK]["safety"]["mean"]
    targets = {
        "learned_success_each_group": {
            "value": {g: table[g][LEARNED]["success_rate"] for g in present},
            "target": SUCCESS_TARGET,
            "met": all(table[g][LEARNED]["success_rate"] >= SUCCESS_TARGET for g in present),
        },
        "safety_ratio_learned_over_minjerk": {
            "value": safety_l / safety_m if safety_m > 0 else math.nan,
            "target": SAFETY_RATIO,
            "met": bool(safety_l >= SAFETY_RATIO * safety_m),
        },
        "human_likeness_wins": {
            "value": int(sum(wins.values())),
            "per_measure": wins,
            "target": HUMAN_WINS,
            "met": int(sum(wins.values())) >= HUMAN_WINS,
        },
    }
    return {
        "table": table,
        "learned_runs_success": learned_runs,
        "human_likeness": likeness,
        "hdm05_self_dtw": self_dtw,
        "targets": targets,
    }


def _pm(stat: dict[str, float], fmt: str) -> str:
    return f"{fmt.format(stat['mean'])} ± {fmt.format(stat['std'])}"


def markdown(results: dict[str, Any]) -> str:
    """The benchmark as Markdown: one table per group, human-likeness, targets."""
    lines = [
        f"# Planner comparison ({results['cases']} unseen layouts, seed {results['seed']})",
        "",
        f"Command: `{results['command'].strip()}` — wall time {results['wall_time_s']:.0f} s "
        "(2 shared CPU cores).",
        f"Learned planner run {len(results['learned_seeds'])}× per layout (planner seed "
        f"{results['learned_seeds']}: latent-fit subsampling and anchors); its rows pool the runs.",
    ]
    head = (
        "| planner | success | success (sphere) | success (full-mesh contact) | planned | safety [m] | "
        "mean abs. accel. [m/s²] | RMS curvature [1/m] | path [m] | time median [s] | time p95 [s] |"
    )
    for group, per in results["table"].items():
        n = next(iter(per.values()))["plans"] if per else 0
        lines += ["", f"## {group}", "", head, "|---" * 11 + "|"]
        for name, s in per.items():
            lines.append(
                f"| {name} | {s['success_rate']:.1%} | {s['success_rate_sphere']:.1%} | "
                f"{s['success_rate_full_contact']:.1%} | "
                f"{s['planned_rate']:.1%} | {_pm(s['safety'], '{:.3f}')} | "
                f"{_pm(s['unsmoothness'], '{:.2f}')} | "
                f"{_pm(s['rms_curvature'], '{:.1f}')} | {_pm(s['path_length'], '{:.3f}')} | "
                f"{s['time_median_s']:.3f} | {s['time_p95_s']:.3f} |"
            )
        if results.get("ablation_checkpoint") is None:
            lines.append(f"| {ABLATION} | missing: no `models/planner_2ch.pt` | | | | | | | | | |")
        runs = results["learned_runs_success"].get(group, {})
        lines.append("")
        lines.append(
            f"Plans per planner row: {n} (learned: all runs). Learned success per run: "
            + ", ".join(f"{k.split()[-1]} {v:.1%}" for k, v in runs.items())
        )
    hd = results["hdm05"]["medians"]
    cols = [
        ("peak_time_ratio", "peak-speed time", "{:.3f}"),
        ("max_deviation_ratio", "max deviation / distance", "{:.3f}"),
        ("speed_curvature_exponent", "speed–curvature exponent", "{:.3f}"),
        ("sparc", "SPARC", "{:.2f}"),
        ("ldlj", "LDLJ", "{:.2f}"),
    ]
    lines += [
        "",
        f"## Human-likeness of the approach vs HDM05 grabHighR (n = {results['hdm05']['n']})",
        "",
        "Median per planner (|median − HDM05 median| in brackets); DTW: each plan's mean distance of its",
        "normalized trajectory to every HDM05 reach [chord units], median over the plans like every other",
        "column (mean over the plans in brackets; HDM05 row: mean over HDM05 pairs).",
        "",
        "| planner | " + " | ".join(c[1] for c in cols) + " | DTW |",
        "|---" * (len(cols) + 2) + "|",
        "| HDM05 | "
        + " | ".join(f.format(hd[k]) for k, _, f in cols)
        + f" | {results['hdm05_self_dtw']:.3f} |",
    ]
    for name, h in results["human_likeness"].items():
        cells = [f"{f.format(h[k]['median'])} ({f.format(h[k]['distance'])})" for k, _, f in cols]
        lines.append(
            f"| {name} | " + " | ".join(cells) + f" | {h['dtw']['median']:.3f} ({h['dtw']['mean']:.3f}) |"
        )
    t = results["targets"]
    succ = t["learned_success_each_group"]
    wins = t["human_likeness_wins"]
    lines += [
        "",
        "## Targets",
        "",
        f"- learned success ≥ {succ['target']:.0%} in both groups: "
        + ", ".join(f"{g} {v:.1%}" for g, v in succ["value"].items())
        + f" — **{'met' if succ['met'] else 'missed'}**",
        f"- learned safety distance ≥ {SAFETY_RATIO}× minimum jerk's: ratio "
        f"{t['safety_ratio_learned_over_minjerk']['value']:.2f} — "
        f"**{'met' if t['safety_ratio_learned_over_minjerk']['met'] else 'missed'}**",
        f"- learned closer to HDM05 than minimum jerk on ≥ {HUMAN_WINS} of 6 measures: {wins['value']} "
        f"({', '.join(k for k, v in wins['per_measure'].items() if v) or 'none'}) — "
        f"**{'met' if wins['met'] else 'missed'}**",
        "",
        "success: hand sphere (radius "
        f"{results['hand_radius']} m) and the held object's mesh clear of the ground-truth meshes, approach",
        "ending within 2 cm of the reference contact (the planner's contact rule on the mesh surface the",
        "cameras see; full-mesh contact: on the whole mesh; benchmarks/planner.py). Minimum jerk reuses the",
        "seed-0 learned plan's contact pose, retreat and durations. Teacher: the human-reach model.",
        "",
    ]
    return "\n".join(lines)


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_speeds(path: Path, human: list[list[float]], speeds: dict[str, list[list[float]]]) -> None:
    """Normalized speed profiles (speed / peak over normalized time) of each planner over HDM05's."""
    plt = _plt()
    grid = np.linspace(0.0, 1.0, 101)
    names = [n for n in speeds if speeds[n]]
    fig, axes = plt.subplots(1, max(len(names), 1), figsize=(4.5 * max(len(names), 1), 3.6), squeeze=False)
    for ax, name in zip(axes[0], names, strict=False):
        for v in human:
            ax.plot(grid, v, color="0.65", lw=0.8)
        for v in speeds[name]:
            ax.plot(grid, v, color=_COLOURS.get(name, "tab:red"), lw=0.4, alpha=0.25)
        ax.plot(grid, np.median(human, axis=0), color="k", lw=2.2, label="HDM05 median")
        ax.plot(
            grid, np.median(speeds[name], axis=0), color=_COLOURS.get(name, "tab:red"), lw=2.2, label=name
        )
        ax.set_title(f"{name} (n = {len(speeds[name])})")
        ax.set_xlabel("normalized time (onset → contact)")
        ax.set_ylabel("speed / peak speed")
        ax.set_ylim(0.0, 1.1)
        ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_paths(path: Path, overlays: list[dict[str, Any]]) -> None:
    """3D overlays of every planner's approach + leave for a few layouts, over the cloud near the target."""
    plt = _plt()
    n = max(len(overlays), 1)
    fig = plt.figure(figsize=(5.5 * n, 5.0))
    rng = np.random.default_rng(0)
    for i, item in enumerate(overlays):
        ax = fig.add_subplot(1, n, i + 1, projection="3d")
        cloud = item["cloud"]
        near = cloud[np.linalg.norm(cloud - item["contact"], axis=1) < 0.6]
        if len(near) > 3000:
            near = near[rng.choice(len(near), 3000, replace=False)]
        ax.scatter(near[:, 0], near[:, 1], near[:, 2], s=1.0, c="0.5", alpha=0.5)
        for name, pos in item["paths"].items():
            ax.plot(pos[:, 0], pos[:, 1], pos[:, 2], color=_COLOURS.get(name, "tab:red"), lw=1.6, label=name)
        c = item["contact"]
        ax.scatter([c[0]], [c[1]], [c[2]], color="k", s=25, marker="x")
        ax.set_title(f"{item['case']} ({item['target']})", fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        ax.legend(loc="upper left", fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
