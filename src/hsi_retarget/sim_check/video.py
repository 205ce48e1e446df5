"""Offscreen video of an execution: every k-th control step rendered small, saved as MP4 or GIF.

MP4 needs the ``imageio-ffmpeg`` package; without it (the default venv) the video is an animated GIF
written by imageio with pillow. Pass a :class:`VideoRecorder` as ``on_frame`` to
:func:`hsi_retarget.sim_check.execute`, then :meth:`VideoRecorder.save`.
"""

from __future__ import annotations

import importlib.util
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError
from hsi_retarget.sim_check.world import SimWorld

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class VideoConfig:
    """Size, rate and view of the execution video."""

    width: int = 320  #: frame width [px] (at most the model's offscreen width, 640 for the scenes)
    height: int = 240  #: frame height [px]
    every: int = 4  #: keep every k-th control step [-]
    fps: float = 25.0  #: playback rate [frames/s]
    camera: str = ""  #: a model camera name; "" = a free camera looking at ``lookat`` [-]
    lookat: tuple[float, float, float] = (0.5, 0.0, 0.9)  #: free camera target, in the robot frame [m]
    distance: float = 2.6  #: free camera distance [m]
    azimuth: float = 160.0  #: free camera azimuth [deg]
    elevation: float = -35.0  #: free camera elevation [deg]
    max_frames: int = 2000  #: frames kept at most (memory bound) [-]
    shadows: bool = False  #: render shadows (about 15x slower with software OpenGL) [-]

    def __post_init__(self) -> None:
        if self.width < 16 or self.height < 16 or self.every < 1 or self.max_frames < 1:
            raise ConfigError(f"VideoConfig: width/height >= 16 [px], every/max_frames >= 1; got {self}")
        if not (self.fps > 0.0 and math.isfinite(self.fps) and self.distance > 0.0):
            raise ConfigError(f"VideoConfig.fps and .distance must be > 0, got {self.fps}, {self.distance}")


def mp4_available() -> bool:
    """Whether imageio can write MP4 here (the ``imageio_ffmpeg`` package is importable)."""
    return importlib.util.find_spec("imageio_ffmpeg") is not None


class VideoRecorder:
    """Collects rendered frames of a :class:`SimWorld`; call it once per control step."""

    def __init__(self, world: SimWorld, config: VideoConfig | None = None) -> None:
        self.config = config if config is not None else VideoConfig()
        cfg = self.config
        m = world.model
        if cfg.width > m.vis.global_.offwidth or cfg.height > m.vis.global_.offheight:
            raise ConfigError(
                f"video {cfg.width}x{cfg.height} exceeds the model's offscreen buffer "
                f"{m.vis.global_.offwidth}x{m.vis.global_.offheight}"
            )
        self.frames: list[NDArray[np.uint8]] = []
        self._calls = 0
        self._renderer = mujoco.Renderer(m, cfg.height, cfg.width)
        self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = int(cfg.shadows)
        self._camera: mujoco.MjvCamera | str = cfg.camera
        if not cfg.camera:
            cam = mujoco.MjvCamera()
            cam.type = mujoco.mjtCamera.mjCAMERA_FREE
            cam.lookat[:] = (world.base @ np.array([*cfg.lookat, 1.0]))[:3]
            cam.distance, cam.azimuth, cam.elevation = cfg.distance, cfg.azimuth, cfg.elevation
            self._camera = cam

    def __call__(self, world: SimWorld) -> None:
        """Render the current state if this is a k-th call (and the frame budget is not used up)."""
        self._calls += 1
        if (self._calls - 1) % self.config.every or len(self.frames) >= self.config.max_frames:
            return
        self._renderer.update_scene(world.data, camera=self._camera)
        self.frames.append(np.array(self._renderer.render(), dtype=np.uint8))

    def close(self) -> None:
        """Free the renderer (frames are kept)."""
        self._renderer.close()

    def save(self, path: str | Path) -> Path:
        """Write the frames to ``path``: MP4 if the suffix is ``.mp4`` and MP4 is available, otherwise a GIF
        (the suffix becomes ``.gif``). Returns the path written.

        Raises:
            ConfigError: no frames were recorded.
        """
        import imageio.v2 as imageio

        if not self.frames:
            raise ConfigError(
                "no video frames recorded; pass the recorder as execute(..., on_frame=recorder)"
            )
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        if out.suffix.lower() == ".mp4" and mp4_available():
            imageio.mimwrite(out, self.frames, fps=self.config.fps, macro_block_size=8)  # type: ignore[arg-type]
            return out
        if out.suffix.lower() != ".gif":
            _LOG.info("imageio-ffmpeg is not installed: writing a GIF instead of %s", out.name)
            out = out.with_suffix(".gif")
        imageio.mimwrite(out, self.frames, format="GIF", duration=1000.0 / self.config.fps, loop=0)  # type: ignore[arg-type]
        return out
