"""Turning the gripper about its approach axis so its fingers close across what they grip.

The planners give every grasp the wrist orientation of a human hand; a parallel gripper closes its
fingers along the wrist's y axis (:mod:`hsi_retarget.mapping`), and that axis is often the wrong one:

- **handle bars**: in front of a door or drawer the wrist has x into the front and z up, so the fingers
  close horizontally. Around a vertical door bar that is across the bar, but along a horizontal drawer
  bar the fingers slide past it. The finger axis is turned perpendicular to the bar
  (:func:`across_bar_angle`; bar directions from :func:`handle_bar_axes`).
- **free objects** wider along the finger axis than the gripper opens (a mug with its handle along the
  finger axis): the finger axis is turned to the object's narrowest side across the approach
  (:func:`narrow_side_angle`; shapes from :func:`object_prims`).

A parallel gripper is symmetric under a half turn, so the turn is the smallest one, in [-90, 90] deg. It
eases in over the approach of the grasp, stays through the pull, push or carry, and eases out over the
withdrawal after the release (:func:`turn_grips`); a carried object is therefore released in the turned
grip too. Everything else is unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError
from hsi_retarget.easing import ease
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.human_motion import HumanMotion

__all__ = [
    "GripTurnConfig",
    "across_bar_angle",
    "grip_phases",
    "handle_bar_axes",
    "narrow_side_angle",
    "object_prims",
    "object_width",
    "turn_grips",
    "turn_weight",
]

F64 = NDArray[np.float64]
_HANDLE_PRIM = "handle"  #: the bar primitive's part name (:mod:`hsi_planning.scene.furniture`)


DEFAULT_OPENING = 0.085  #: [m] finger opening assumed without a robot (:attr:`GripTurnConfig.opening` 0)


@dataclass(frozen=True)
class GripTurnConfig:
    """When and how far the gripper turns about its approach axis."""

    bars: bool = True  #: fingers across door/drawer handle bars [-]
    objects: bool = True  #: fingers across the narrow side of free objects too wide for them [-]
    #: [m] the gripper's full finger opening; 0: the robot's (its two fingers' travel, set by the retargeting)
    opening: float = 0.0
    clearance: float = 0.005  #: [m] free space wanted on each side of an object between the open fingers
    step_deg: float = 5.0  #: [deg] resolution of the search for an object's narrowest side
    turn_s: float = 1.0  #: [s] shortest time the turn eases in before a grasp and out after a release

    def __post_init__(self) -> None:
        half = 0.5 * (self.opening or DEFAULT_OPENING)
        if not (0.0 <= self.opening < 0.5 and 0.0 <= self.clearance < half):
            raise ConfigError(
                f"GripTurnConfig: opening in [0, 0.5) m (0: the robot's), clearance in [0, opening/2) m, got "
                f"{self.opening}, {self.clearance}"
            )
        if not 0.1 <= self.step_deg <= 45.0:
            raise ConfigError(f"GripTurnConfig.step_deg must be in [0.1, 45] deg, got {self.step_deg}")
        if not 0.0 < self.turn_s <= 10.0:
            raise ConfigError(f"GripTurnConfig.turn_s must be in (0, 10] s, got {self.turn_s}")


def handle_bar_axes(spec: Any) -> dict[str, F64]:
    """Door/drawer name -> (3,) unit world direction of its handle bar (at rest; sign arbitrary).

    ``spec``: a :class:`~hsi_planning.scene.SceneSpec`. The bar is the longest extent of the part's
    ``handle`` box; parts without one are left out.
    """
    from hsi_planning.scene.model import scene_bodies

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


def object_prims(spec: Any) -> dict[str, list[Any]]:
    """Free object name -> its collision primitives (:class:`~hsi_planning.scene.shapes.Prim`) in the
    world at rest."""
    from hsi_planning.scene.model import scene_bodies

    return {b.name: b.world_prims() for b in scene_bodies(spec) if b.kind == "object"}


def object_width(prims: Sequence[Any], u: F64) -> float:
    """[m] extent of ``prims`` along the unit direction ``u`` (3,)."""
    lo, hi = np.inf, -np.inf
    for p in prims:
        m = p.matrix
        c = float(m[:3, 3] @ u)
        local = m[:3, :3].T @ u
        if p.kind == "box":
            h = float(np.abs(local) @ np.asarray(p.size))
        else:  # cylinder / capsule: axis = local z
            along = min(abs(float(local[2])), 1.0)
            h = p.size[0] * float(np.sqrt(1.0 - along**2)) + p.size[1] * along
            h += p.size[0] * along if p.kind == "capsule" else 0.0
        lo, hi = min(lo, c - h), max(hi, c + h)
    return float(hi - lo)


def _turned(rotation: F64, angle: float) -> F64:
    """(3,) the wrist's y axis after a turn by ``angle`` [rad] about its x axis."""
    return np.asarray(np.cos(angle) * rotation[:, 1] + np.sin(angle) * rotation[:, 2])


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


def narrow_side_angle(rotation: F64, prims: Sequence[Any], config: GripTurnConfig | None = None) -> float:
    """[rad] in [-pi/2, pi/2]: 0 when the object (``prims``, world) fits between the open fingers with
    ``clearance`` on both sides along the wrist's y axis (``rotation`` (3, 3), world); else the smallest turn
    about the wrist's x axis to the object's narrowest side (within 1 mm)."""
    cfg = config if config is not None else GripTurnConfig()
    opening = cfg.opening or DEFAULT_OPENING
    if not prims or object_width(prims, rotation[:, 1]) <= opening - 2.0 * cfg.clearance:
        return 0.0
    n = round(90.0 / cfg.step_deg)
    angles = np.radians(cfg.step_deg) * np.arange(-n, n + 1)
    widths = np.array([object_width(prims, _turned(rotation, float(a))) for a in angles])
    near = widths <= widths.min() + 1e-3
    best = int(np.flatnonzero(near)[np.argmin(np.abs(angles[near]))])
    # the middle of the run of narrowest sides around it (circular: -90 and 90 deg are the same turn),
    # so that a protrusion (a mug's handle) is as far from the fingers as the shape allows
    m = angles.shape[0] - 1  # distinct turns (the last angle repeats the first)
    lo = hi = 0
    while lo < m and near[(best - lo - 1) % m]:
        lo += 1
    while hi < m - lo - 1 and near[(best + hi + 1) % m]:
        hi += 1
    mid = float(angles[best] + 0.5 * (hi - lo) * (angles[1] - angles[0]))
    return float((mid + 0.5 * np.pi) % np.pi - 0.5 * np.pi)


def turn_weight(
    t: F64, grasp: GraspWindow, release: GraspWindow | None, span: tuple[float, float], turn_s: float
) -> F64:
    """(T,) share of the turn: easing in over the grasp's approach (at least ``turn_s`` [s], not before
    ``span[0]``), 1 until the release, easing out over the withdrawal after it (at least ``turn_s``, not
    after ``span[1]``); 1 to the end without a release."""
    a1 = grasp.time
    a0 = max(min(grasp.before[0], a1 - turn_s), span[0])
    w = ease((t - a0) / max(a1 - a0, 1e-9))
    if release is not None:
        b0 = release.time
        b1 = min(max(release.after[1], b0 + turn_s), span[1])
        w = np.where(t > b0, 1.0 - ease((t - b0) / max(b1 - b0, 1e-9)), w)
    return np.asarray(w)


def grip_phases(
    windows: Sequence[GraspWindow], side: str
) -> list[tuple[GraspWindow, GraspWindow | None, tuple[float, float]]]:
    """Per grasp of hand ``side`` (time order): the grasp window, its release (``None``: held to the end)
    and the span [s] a change of the grip may use (from the hand's previous event to its next one after
    the release; infinite where there is none)."""
    own = sorted((w for w in windows if w.hand == side), key=lambda w: w.time)
    out = []
    for i, w in enumerate(own):
        if w.kind != "grasp":
            continue
        release = next((v for v in own[i + 1 :] if v.target == w.target and v.kind == "release"), None)
        after = [v.time for v in own if release is not None and v.time > release.time]
        out.append((w, release, (own[i - 1].time if i > 0 else -np.inf, min(after, default=np.inf))))
    return out


def turn_grips(
    motion: HumanMotion,
    windows: Sequence[GraspWindow],
    bars: Mapping[str, F64],
    objects: Mapping[str, Sequence[Any]],
    config: GripTurnConfig | None = None,
) -> tuple[HumanMotion, list[dict[str, Any]]]:
    """A copy of ``motion`` whose wrists grip across handle bars (``bars``: part -> (3,) world axis) and
    free objects (``objects``: name -> world prims), and one record per grasp looked at (``hand``,
    ``target``, ``time_s`` [s], ``angle_deg`` [deg]); see the module docstring."""
    cfg = config if config is not None else GripTurnConfig()
    rotations = dict(motion.wrist_rotation)
    records: list[dict[str, Any]] = []
    t = motion.t
    for side in motion.wrist_rotation:
        rot = Rotation.from_matrix(rotations[side])
        turned = False
        for w, release, span in grip_phases(windows, side):
            k = int(np.clip(np.searchsorted(t, w.time - 1e-9), 0, t.shape[0] - 1))
            planned = rot[k].as_matrix()
            if not w.free and cfg.bars and w.target in bars:
                angle = across_bar_angle(planned, bars[w.target])
            elif w.free and cfg.objects and w.target in objects:
                angle = narrow_side_angle(planned, objects[w.target], cfg)
            else:
                continue
            records.append(
                {"hand": side, "target": w.target, "time_s": w.time, "angle_deg": float(np.degrees(angle))}
            )
            if abs(angle) < 1e-9:
                continue
            turn = turn_weight(t, w, release, span, cfg.turn_s) * angle
            rot = rot * Rotation.from_rotvec(np.outer(turn, [1.0, 0.0, 0.0]))
            turned = True
        if turned:
            rotations[side] = np.asarray(rot.as_matrix())
    return replace(motion, wrist_rotation=rotations), records
