"""``hsi retarget``: retarget a recorded human motion (ASF/AMC or BVH) onto a robot, frame by frame.

Writes the timed joint trajectory as JSON (:meth:`hsi_retarget.joint_trajectory.JointTrajectory.to_dict`)
and prints the retargeting rate against the source frame rate, the wrist tracking error after scaling,
unreachable goals and the time scaling; ``--sim`` plays the result in MuJoCo (robot alone, or attached to
a scene with ``--scene``) and reports the TCP tracking error there.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path
from typing import Any

from hsi_planning.errors import ConfigError, MotionDataError

_LOG = logging.getLogger("hsi.retarget")


def register(subparsers: Any) -> None:
    """Add the ``retarget`` sub-command."""
    p = subparsers.add_parser(
        "retarget",
        help="retarget a recorded human motion (.amc/.bvh) onto a robot",
        description=__doc__.splitlines()[0],
    )
    p.add_argument("motion", type=Path, help="motion file: .amc (ASF next to it or --asf) or .bvh")
    p.add_argument("--robot", default="dual_arm", help="dual_arm (dual_ur5e) or humanoid [default: dual_arm]")
    p.add_argument("--out", type=Path, default=Path("traj.json"), help="output JSON [default: traj.json]")
    p.add_argument(
        "--asf", type=Path, default=None, help="skeleton for an .amc (default: HDM_<actor>.asf beside)"
    )
    p.add_argument("--fps", type=float, default=120.0, help="AMC frame rate [Hz] (default 120, HDM05/CMU)")
    p.add_argument("--bvh-unit", type=float, default=0.01, help="BVH length unit [m] (default 0.01: cm)")
    p.add_argument("--start", type=int, default=0, help="first frame to use")
    p.add_argument("--frames", type=int, default=0, help="number of frames to use (0: all)")
    p.add_argument("--anchor", choices=("shoulder", "world"), default="shoulder", help="goal mapping anchor")
    p.add_argument("--lowpass", type=float, default=6.0, help="low-pass cut-off of the motion [Hz] (0: none)")
    p.add_argument("--sim", action="store_true", help="play the result in MuJoCo and report tracking")
    p.add_argument("--scene", default="", help="with --sim: scene spec (name or YAML) to play it in")
    p.set_defaults(func=run)


def _skeleton_path(motion: Path, asf: Path | None) -> Path:
    """``--asf``, else the HDM05 skeleton ``HDM_<actor>.asf`` beside the clip, else the only ``.asf``."""
    if asf is not None:
        return asf
    hdm05 = motion.with_name("_".join(motion.stem.split("_")[:2]) + ".asf")
    if hdm05.is_file():
        return hdm05
    others = sorted(motion.parent.glob("*.asf"))
    if len(others) == 1:
        return others[0]
    raise ConfigError(
        f"no skeleton for {motion}: expected {hdm05.name} or a single .asf beside it; pass --asf"
    )


def _load(args: argparse.Namespace) -> tuple[Any, Any]:
    from hsi_planning.mocap import Motion, load_amc, load_asf, load_bvh

    path: Path = args.motion
    if not path.is_file():
        raise MotionDataError(f"{path}: no such motion file")
    suffix = path.suffix.lower()
    if suffix == ".amc":
        skeleton = load_asf(_skeleton_path(path, args.asf))
        motion = load_amc(path, skeleton, fps=args.fps)
    elif suffix == ".bvh":
        skeleton, motion = load_bvh(path, unit_m=args.bvh_unit)
    else:
        raise ConfigError(f"{path}: motion files are .amc or .bvh, got {suffix!r}")
    if args.start < 0 or args.frames < 0:
        raise ConfigError("--start and --frames must be >= 0")
    stop = motion.n_frames if args.frames == 0 else min(motion.n_frames, args.start + args.frames)
    if stop - args.start < 2:
        raise ConfigError(f"frames {args.start}..{stop} of {motion.n_frames}: need at least 2")
    return skeleton, Motion(motion.channels, motion.values[args.start : stop], motion.fps)


def run(args: argparse.Namespace) -> int:
    """Handler of ``hsi retarget``."""
    from hsi_retarget.mapping import MappingConfig
    from hsi_retarget.retarget import RetargetConfig, retarget
    from hsi_retarget.robots import RobotModel
    from hsi_retarget.sources import human_motion_from_mocap

    skeleton, motion = _load(args)
    robot = RobotModel(args.robot)
    wall = time.perf_counter()
    human = human_motion_from_mocap(skeleton, motion, lowpass_hz=args.lowpass, source=str(args.motion))
    config = RetargetConfig(mapping=MappingConfig(anchor=args.anchor))
    traj = retarget(human, robot, config=config)
    wall = time.perf_counter() - wall
    meta = traj.meta
    n, fps = int(meta["frames"]), float(motion.fps)
    traj.meta["retarget_time_s"] = wall
    traj.meta["retarget_rate_fps"] = n / wall
    traj.meta["real_time_factor"] = n / wall / fps
    summary: dict[str, Any] = {
        "robot": robot.name,
        "frames": n,
        "source_fps": fps,
        "retarget_rate_fps": round(n / wall, 1),
        "ik_rate_fps": round(float(meta["ik_rate_fps"]), 1),
        "real_time_factor": round(n / wall / fps, 2),
        "scale": round(float(meta["scale"]), 3),
        "tracking": meta["tracking"],
        "unreachable": meta["unreachable"],
        "ik_unreached": meta["ik_unreached"][:5],
        "time_scaling": {
            k: meta["time_scaling"][k] for k in ("duration_in_s", "duration_out_s", "max_scale")
        },
    }
    if args.sim:
        from hsi_retarget.playback import play

        scene = None
        if args.scene:
            from hsi_planning.scene_paths import load_scene

            scene = load_scene(args.scene)
        report = play(traj, robot, scene)
        traj.meta["sim"] = report.to_dict()
        summary["sim"] = report.to_dict()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    traj.write_json(args.out)
    print(json.dumps(summary, indent=1, default=float))
    _LOG.info("wrote %s (%d samples, %.2f s)", args.out, traj.t.shape[0], traj.duration)
    return 0
