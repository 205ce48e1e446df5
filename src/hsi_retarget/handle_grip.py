"""Gripping a door or drawer handle bar: the fingers close *across* the bar.

The planners give a handle grasp the wrist orientation of a human hand in front of the door or drawer
(x into the front, z up), whatever the bar's direction. A parallel gripper closes its fingers along the
wrist's y axis (:mod:`hsi_retarget.mapping`): around a vertical door bar that is across the bar, but along
a horizontal drawer bar the fingers slide past it and the grasp fails. :func:`turn_across_bars` turns the
wrist goals of every handle grasp about the approach axis (the wrist's x) by the smallest angle that puts
the finger axis perpendicular to the bar (:func:`across_bar_angle`; a parallel gripper is symmetric under a
half turn), from the start of the approach, through the pull or push, to the end of the withdrawal after
the release. The bar directions come from the scene (:func:`handle_bar_axes`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_retarget.grasp_depth import GraspWindow
from hsi_retarget.human_motion import HumanMotion

__all__ = ["across_bar_angle", "handle_bar_axes", "turn_across_bars"]

F64 = NDArray[np.float64]
_HANDLE_PRIM = "handle"  #: the bar primitive's part name (:mod:`hsi_planning.scene.furniture`)


def handle_bar_axes(spec: Any) -> dict[str, F64]:
    """Door/drawer name -> (3,) unit world direction of its handle bar (at rest; sign arbitrary).

    ``spec``: a :class:`~hsi_planning.scene.SceneSpec`. The bar is the longest extent of the part's
    ``handle`` box; parts without one are left out.
    """
    from hsi_planning.scene import scene_bodies

    out: dict[str, F64] = {}
    for body in scene_bodies(spec):
        if body.joint is None:
            continue
        for prim in body.prims:
            if prim.part != _HANDLE_PRIM or prim.kind != "box":
                continue
            local = prim.matrix[:3, int(np.argmax(prim.size))]
            axis = np.asarray(body.pose[:3, :3] @ local, dtype=np.float64)
            out[body.name] = axis / np.linalg.norm(axis)
    return out


def across_bar_angle(rotation: F64, bar: F64) -> float:
    """[rad] in [-pi/2, pi/2]: the turn about the wrist's x axis (``rotation`` (3, 3), world) after which
    its y axis (the finger axis) is perpendicular to ``bar`` (3,); 0 when the bar lies along the x axis."""
    b = np.asarray(bar, dtype=np.float64)
    by, bz = float(rotation[:, 1] @ b), float(rotation[:, 2] @ b)
    if np.hypot(by, bz) < 1e-6 * max(float(np.linalg.norm(b)), 1e-12):
        return 0.0
    angle = float(np.arctan2(-by, bz))  # y' = cos a y + sin a z  is perpendicular to the bar
    if angle > np.pi / 2:
        angle -= np.pi
    elif angle < -np.pi / 2:
        angle += np.pi
    return angle


def _ease(u: F64) -> F64:
    u = np.clip(u, 0.0, 1.0)
    return np.asarray(10 * u**3 - 15 * u**4 + 6 * u**5)


def _weight(t: F64, grasp: GraspWindow, release: GraspWindow | None) -> F64:
    """(T,) share of the turn: easing in over the grasp's approach, 1 until the release, easing out over
    the withdrawal after it (1 to the end without a release)."""
    a0, a1 = grasp.before[0], grasp.time
    w = _ease((t - a0) / max(a1 - a0, 1e-9))
    if release is not None:
        b0, b1 = release.time, release.after[1]
        w = np.where(t > b0, 1.0 - _ease((t - b0) / max(b1 - b0, 1e-9)), w)
    return np.asarray(w)


def turn_across_bars(
    motion: HumanMotion, windows: Sequence[GraspWindow], bars: Mapping[str, F64]
) -> tuple[HumanMotion, list[dict[str, Any]]]:
    """A copy of ``motion`` whose wrists grip every handle bar of ``bars`` (part -> (3,) world axis)
    across it (see the module docstring), and one record per turned grasp (``hand``, ``target``,
    ``time_s`` [s], ``angle_deg`` [deg]). Free-object grasps and parts without a bar are left as they are."""
    rotations = dict(motion.wrist_rotation)
    records: list[dict[str, Any]] = []
    t = motion.t
    for side in motion.wrist_rotation:
        own = sorted((w for w in windows if w.hand == side and not w.free), key=lambda w: w.time)
        rot = Rotation.from_matrix(rotations[side])
        turned = False
        for i, w in enumerate(own):
            if w.kind != "grasp" or w.target not in bars:
                continue
            release = next((v for v in own[i + 1 :] if v.target == w.target and v.kind == "release"), None)
            k = int(np.clip(np.searchsorted(t, w.time - 1e-9), 0, t.shape[0] - 1))
            angle = across_bar_angle(rot[k].as_matrix(), bars[w.target])
            records.append(
                {"hand": side, "target": w.target, "time_s": w.time, "angle_deg": np.degrees(angle)}
            )
            if abs(angle) < 1e-6:
                continue
            turn = _weight(t, w, release) * angle
            rot = rot * Rotation.from_rotvec(np.outer(turn, [1.0, 0.0, 0.0]))
            turned = True
        if turned:
            rotations[side] = np.asarray(rot.as_matrix())
    return replace(motion, wrist_rotation=rotations), records
