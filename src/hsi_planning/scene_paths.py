"""Scene names → scene spec files: ``kitchen`` means ``sim/scenes/kitchen.yaml``; paths are taken as given.

The built-in scenes live in ``sim/scenes/`` of the source checkout, or in ``<prefix>/share/hsi/sim/scenes``
of an installed package. A reference that looks like a path (it has a directory part or a ``.yaml``/``.yml``
suffix) must name an existing file; a bare name must be a built-in scene (or an existing file).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

from hsi_planning.errors import SceneError

if TYPE_CHECKING:
    from hsi_planning.scene import SceneSpec

__all__ = ["builtin_scenes", "load_scene", "resolve_scene", "scenes_dir"]

_SUFFIXES = (".yaml", ".yml")
_PACKAGE = "hsi"


def scenes_dir() -> Path:
    """The folder of the built-in scene specs (source checkout first, then the installed share folder).

    Raises:
        SceneError: neither location holds a ``scenes`` folder.
    """
    here = Path(__file__).resolve()
    candidates = [
        here.parents[2] / "sim" / "scenes",
        Path(sys.prefix) / "share" / _PACKAGE / "sim" / "scenes",
    ]
    for cand in candidates:
        if cand.is_dir():
            return cand
    raise SceneError(f"no built-in scene folder found; looked in: {', '.join(str(c) for c in candidates)}")


def builtin_scenes() -> list[str]:
    """Names of the built-in scenes, sorted (e.g. ``['cluttered_drawer', 'kitchen', 'narrow_shelf']``)."""
    folder = scenes_dir()
    return sorted({p.stem for suffix in _SUFFIXES for p in folder.glob(f"*{suffix}") if p.is_file()})


def _looks_like_path(ref: str) -> bool:
    return "/" in ref or "\\" in ref or Path(ref).suffix.lower() in _SUFFIXES


def resolve_scene(scene: str | Path) -> Path:
    """Path of the spec file that ``scene`` (a built-in scene name or a file path) refers to.

    Raises:
        SceneError: empty reference, a path that is no file, or an unknown name (the built-in scenes are
            listed).
    """
    ref = str(scene).strip()
    if not ref:
        raise SceneError(f"empty scene reference; use a built-in scene {builtin_scenes()} or a .yaml path")
    path = Path(ref).expanduser()
    if isinstance(scene, Path) or _looks_like_path(ref):
        if path.is_file():
            return path
        raise SceneError(f"scene file {path} does not exist; built-in scenes: {builtin_scenes()}")
    folder = scenes_dir()
    for suffix in _SUFFIXES:
        cand = folder / f"{ref}{suffix}"
        if cand.is_file():
            return cand
    if path.is_file():
        return path
    raise SceneError(f"unknown scene {ref!r}; built-in scenes: {builtin_scenes()} (or give a .yaml path)")


def load_scene(scene: str | Path) -> SceneSpec:
    """The :class:`~hsi_planning.scene.SceneSpec` of a built-in scene name or a spec file path.

    Raises:
        SceneError: see :func:`resolve_scene`, plus whatever :func:`~hsi_planning.scene.load_scene_spec`
            rejects in the file.
    """
    from hsi_planning.scene import load_scene_spec

    return load_scene_spec(resolve_scene(scene))
