"""Write the committed robot files (``urdf/<robot>.urdf``, ``sim/robots/<robot>.xml``) from the descriptions.

Run ``python -m hsi_retarget.robots.build_models [repo_root]`` after changing a description; a test checks
that the committed files equal :func:`generated_files`.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from hsi_retarget.robots.catalog import DESCRIPTIONS, relative_paths
from hsi_retarget.robots.mjcf import build_robot_mjcf
from hsi_retarget.robots.urdf import build_urdf

_LOG = logging.getLogger(__name__)


def generated_files() -> dict[Path, str]:
    """Repository-relative path -> file content, for every robot."""
    out: dict[Path, str] = {}
    for name, factory in DESCRIPTIONS.items():
        desc = factory()
        urdf_path, mjcf_path = relative_paths(name)
        out[urdf_path] = build_urdf(desc)
        out[mjcf_path] = build_robot_mjcf(desc)
    return out


def write_models(repo_root: Path) -> list[Path]:
    """Write every generated file under ``repo_root``; returns the paths written."""
    written = []
    for rel, text in generated_files().items():
        path = repo_root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        _LOG.info("wrote %s", path)
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    """Command-line entry: write the files under the given repository root (default: this checkout)."""
    args = sys.argv[1:] if argv is None else argv
    root = Path(args[0]) if args else Path(__file__).resolve().parents[3]
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    write_models(root)
    return 0


if __name__ == "__main__":
    sys.exit(main())
