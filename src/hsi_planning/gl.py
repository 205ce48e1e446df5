"""Headless OpenGL backend selection for MuJoCo rendering.

MuJoCo picks its OpenGL backend from the ``MUJOCO_GL`` environment variable when ``mujoco`` is first
imported, so :func:`ensure_headless_gl` must run before that import. It keeps a value the user set,
otherwise prefers ``egl`` (GPU or Mesa's surfaceless EGL) and falls back to ``osmesa`` (software, the
Debian package ``libosmesa6``) when no EGL library can be found.
"""

from __future__ import annotations

import ctypes.util
import logging
import os
import sys

_LOG = logging.getLogger(__name__)

#: Backends that render without a display.
HEADLESS_BACKENDS = ("egl", "osmesa")


def _library_available(name: str) -> bool:
    """Whether the dynamic loader can find ``lib<name>``."""
    return ctypes.util.find_library(name) is not None


def choose_headless_backend() -> str:
    """The headless backend this machine supports: ``"egl"`` if libEGL is found, else ``"osmesa"``."""
    if _library_available("EGL"):
        return "egl"
    if not _library_available("OSMesa"):
        _LOG.warning("neither libEGL nor libOSMesa found; MuJoCo rendering will fail (install libosmesa6)")
    return "osmesa"


def ensure_headless_gl() -> str:
    """Set ``MUJOCO_GL`` for headless rendering if it is unset; return the backend in effect.

    A value already set (``egl``, ``osmesa``, ``glfw``, ...) is respected. If ``mujoco`` was imported
    before this call, the backend it chose cannot change any more; a warning says so when it differs.
    """
    current = os.environ.get("MUJOCO_GL", "").strip().lower()
    if current:
        return current
    backend = choose_headless_backend()
    if "mujoco" in sys.modules:
        _LOG.warning(
            "mujoco was imported before MUJOCO_GL was set; it keeps its default backend instead of %r "
            "(call ensure_headless_gl() before importing mujoco)",
            backend,
        )
    os.environ["MUJOCO_GL"] = backend
    if backend == "osmesa":
        os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
    _LOG.info("MUJOCO_GL unset; using headless backend %r", backend)
    return backend
