"""``hsi scene cloud SPEC --out F.ply``: render a scene's labelled point cloud and write it as PLY.

The cloud is fused from the scene's cameras (all, or ``--cameras``) at rest, voxel-downsampled, and written
with the properties ``x y z label``; label names and classes travel in PLY comments (see
:func:`hsi_planning.perception.write_ply`). The number of points per label is printed.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["add_cloud_command", "format_label_counts"]


def format_label_counts(labels: Any, names: dict[int, str] | None) -> list[str]:
    """``'  <id> <name>: <points>'`` lines for the labels (N,) of a cloud, by label id."""
    import numpy as np

    ids, counts = np.unique(np.asarray(labels), return_counts=True)
    names = names or {}
    return [
        f"  {int(i):>3} {names.get(int(i), '?'):<24} {int(c):>8}" for i, c in zip(ids, counts, strict=True)
    ]


def _run(args: argparse.Namespace) -> int:
    from hsi_planning.errors import CloudError
    from hsi_planning.perception import CloudConfig, write_ply
    from hsi_planning.perception.render import scene_cloud
    from hsi_planning.scene_paths import load_scene

    spec = load_scene(args.spec)
    cameras = tuple(args.cameras or ())
    known = [c.name for c in spec.cameras]
    if any(c not in known for c in cameras):
        raise CloudError(f"--cameras {list(cameras)}: scene {spec.name!r} has cameras {known}")
    config = CloudConfig(cameras=cameras, width=args.width, height=args.height, voxel_size=args.voxel)
    cloud = scene_cloud(spec, config)
    out = write_ply(args.out, cloud, fmt="ascii" if args.ascii else "binary")
    print(
        f"{out}: {len(cloud.points)} points, {len(set(cloud.labels.tolist()))} labels (scene {spec.name!r})"
    )
    print("\n".join(format_label_counts(cloud.labels, cloud.label_names)))
    return 0


def add_cloud_command(scene_subparsers: Any) -> None:
    """Add ``cloud`` to the ``hsi scene`` sub-command parsers."""
    parser = scene_subparsers.add_parser(
        "cloud",
        help="scene spec -> rendered labelled point cloud (PLY: x y z label)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: hsi scene cloud kitchen --out out/kitchen.ply --voxel 0.01",
    )
    parser.add_argument("spec", help="built-in scene name (e.g. kitchen) or scene spec YAML path")
    parser.add_argument("--out", type=Path, required=True, help="PLY file to write")
    parser.add_argument("--voxel", type=float, default=0.01, metavar="M", help="voxel size [m]; 0 = none")
    parser.add_argument("--width", type=int, default=320, metavar="PX", help="image width [px] (default 320)")
    parser.add_argument(
        "--height", type=int, default=240, metavar="PX", help="image height [px] (default 240)"
    )
    parser.add_argument("--cameras", nargs="+", metavar="CAM", help="cameras to fuse (default: all)")
    parser.add_argument("--ascii", action="store_true", help="ASCII PLY instead of binary")
    parser.set_defaults(func=_run)
