"""The demo video: every task's MuJoCo execution rendered offscreen, one title card per task, one file.

:class:`DemoVideo` opens one MP4 writer (imageio-ffmpeg; an animated GIF when it is not installed). For
each task, :meth:`DemoVideo.recorder` returns a :class:`~hsi_retarget.sim_check.VideoRecorder` looking at
the task's target from behind the robot; :meth:`DemoVideo.add` appends a title card and the recorded
frames to the file (and frees them, so memory stays bounded by one task).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError
from hsi_retarget.sim_check import SimWorld, VideoConfig, VideoRecorder, mp4_available

__all__ = ["DemoVideo", "title_card"]

_log = logging.getLogger(__name__)


def title_card(lines: list[str], width: int, height: int) -> NDArray[np.uint8]:
    """(height, width, 3) dark frame with ``lines`` of white text."""
    from PIL import Image, ImageDraw, ImageFont

    image = Image.new("RGB", (width, height), (20, 24, 32))
    draw = ImageDraw.Draw(image)
    size = max(10, height // 16)
    font = ImageFont.load_default(size=size)
    y = height // 6
    for i, line in enumerate(lines):
        draw.text((width // 16, y), line, fill=(255, 255, 255) if i == 0 else (190, 200, 210), font=font)
        y += int(size * (1.8 if i == 0 else 1.4))
    return np.asarray(image, dtype=np.uint8)


class DemoVideo:
    """One video of all tasks (see the module docstring).

    Args:
        path: ``.mp4`` (``.gif`` is written instead when imageio-ffmpeg is missing).
        config: frame size, rate and camera distance/angles of every task.
        title_s: [s] duration of each task's title card.
    """

    def __init__(self, path: Path, config: VideoConfig | None = None, title_s: float = 1.5) -> None:
        import imageio.v2 as imageio

        self.config = config if config is not None else VideoConfig()
        if title_s < 0.0:
            raise ConfigError(f"title_s must be >= 0 s, got {title_s}")
        self.title_frames = round(title_s * self.config.fps)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.suffix.lower() != ".mp4" or not mp4_available():
            path = path.with_suffix(".gif")
        self.path = path
        options: dict[str, Any] = {"fps": self.config.fps}
        if path.suffix == ".mp4":
            options["macro_block_size"] = 8
        else:
            options = {"duration": 1000.0 / self.config.fps, "loop": 0}
        self._writer = imageio.get_writer(path, **options)
        self.frames = 0

    def recorder(self, world: SimWorld, lookat: tuple[float, float, float]) -> VideoRecorder:
        """A recorder for one execution, its free camera aimed at ``lookat`` (3,) [m] (world frame)."""
        inverse = np.linalg.inv(world.base)
        local = (inverse @ np.array([*lookat, 1.0]))[:3]
        cfg = replace(self.config, lookat=(float(local[0]), float(local[1]), float(local[2])))
        return VideoRecorder(world, cfg)

    def add(self, lines: list[str], recorder: VideoRecorder | None) -> None:
        """Append a title card with ``lines`` and the frames of ``recorder`` (then cleared and closed)."""
        cfg = self.config
        card = title_card(lines, cfg.width, cfg.height)
        for _ in range(self.title_frames):
            self._writer.append_data(card)
            self.frames += 1
        if recorder is None:
            return
        for frame in recorder.frames:
            self._writer.append_data(frame)
            self.frames += 1
        recorder.frames.clear()
        recorder.close()

    def close(self) -> Path:
        """Finish the file; returns its path."""
        self._writer.close()
        _log.info("wrote %s (%d frames)", self.path, self.frames)
        return self.path
