"""Acclaim Motion Capture (AMC) parser.

An AMC file has header keywords (``:FULLY-SPECIFIED``, ``:DEGREES`` or ``:RADIANS``), then frames: a
line with the frame number followed by one line per bone, ``<bone> v1 … vk`` with the values in the
bone's ASF ``dof`` order (the root in its ``order``). Bones without dofs are absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hsi_planning.errors import MotionDataError
from hsi_planning.mocap.skeleton import ROTATION_DOFS, Motion, Skeleton


def load_amc(path: str | Path, skeleton: Skeleton, fps: float = 120.0) -> Motion:
    """Parse an AMC file for ``skeleton``.

    Args:
        path: the ``.amc`` file.
        skeleton: the skeleton from the matching ASF (:func:`~hsi_planning.mocap.asf.load_asf`).
        fps: [Hz] frame rate (AMC files do not store it; HDM05 and CMU clips are 120 Hz).

    Returns:
        :class:`Motion` with angles in [rad] and translations in [m] (source frame).

    Raises:
        MotionDataError: unknown bone, wrong number of values, missing bone in a frame, non-numeric
            value, frames out of sequence or no frames (message names file:line).
    """
    path = Path(path)
    if not path.is_file():
        raise MotionDataError(f"{path}: no such AMC file")
    if not fps > 0:
        raise MotionDataError(f"fps must be > 0 [Hz], got {fps}")
    dofs = {j.name: j.dofs for j in skeleton.joints}
    lines = path.read_text(encoding="latin-1").splitlines()
    degrees = True
    frames: list[dict[str, list[float]]] = []
    frame_lines: list[int] = []
    current: dict[str, list[float]] | None = None
    first_number = 0
    for lineno, raw in enumerate(lines, start=1):
        text = raw.strip()
        if not text or text.startswith("#"):
            continue
        where = f"{path}:{lineno}"
        if text.startswith(":"):
            keyword = text.split()[0].upper()
            if keyword == ":RADIANS":
                degrees = False
            elif keyword == ":DEGREES":
                degrees = True
            continue
        tokens = text.split()
        if len(tokens) == 1 and tokens[0].isdigit():
            if not frames:
                first_number = int(tokens[0])
            elif int(tokens[0]) != first_number + len(frames):
                raise MotionDataError(
                    f"{where}: frame number {tokens[0]} out of sequence "
                    f"(expected {first_number + len(frames)})"
                )
            current = {}
            frames.append(current)
            frame_lines.append(lineno)
            continue
        if current is None:
            raise MotionDataError(f"{where}: bone data before the first frame number: {text[:40]!r}")
        bone = tokens[0]
        if bone not in dofs:
            raise MotionDataError(f"{where}: unknown bone {bone!r}; skeleton bones: {sorted(dofs)}")
        if len(tokens) - 1 != len(dofs[bone]):
            raise MotionDataError(
                f"{where}: bone {bone!r} needs {len(dofs[bone])} values ({' '.join(dofs[bone])}), "
                f"got {len(tokens) - 1}"
            )
        if bone in current:
            raise MotionDataError(f"{where}: bone {bone!r} given twice in one frame")
        try:
            current[bone] = [float(t) for t in tokens[1:]]
        except ValueError as exc:
            raise MotionDataError(f"{where}: non-numeric value for bone {bone!r}") from exc
    if not frames:
        raise MotionDataError(f"{path}: no frames")
    present = [j.name for j in skeleton.joints if j.name in frames[0] and j.dofs]
    if not present:
        raise MotionDataError(f"{path}:{frame_lines[0]}: the first frame has no bone data")
    channels = tuple((b, d) for b in present for d in dofs[b])
    values = np.empty((len(frames), len(channels)))
    for i, (frame, lineno) in enumerate(zip(frames, frame_lines, strict=True)):
        if set(frame) != set(present):
            missing = sorted(set(present) - set(frame))
            extra = sorted(set(frame) - set(present))
            raise MotionDataError(
                f"{path}:{lineno}: frame has missing bone(s) {missing} / extra bone(s) {extra} "
                "compared with the first frame"
            )
        values[i] = [v for b in present for v in frame[b]]
    angle = np.pi / 180.0 if degrees else 1.0
    for c, (_, dof) in enumerate(channels):
        values[:, c] *= angle if dof in ROTATION_DOFS else skeleton.length_unit_m
    return Motion(channels, values, float(fps))
