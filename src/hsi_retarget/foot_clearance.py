"""Footholds clear of a swinging door or a sliding drawer.

The humanoid's footstep plan (:func:`~hsi_retarget.humanoid_ik.plan_footsteps`) puts each sole at its
nominal offset under the pelvis goal. A door opened towards the robot sweeps the floor in front of its
cabinet; a foot planted there is hit by the panel's lower edge (MuJoCo reports the sole against the door).
:func:`part_sweep` is the opened part at 25 openings between closed and as scheduled (a 0.6 m door
between two of them is within about 1 cm of one), one distance
query for the whole region the part passes through; :func:`dodge` moves a step's target sole by the least
horizontal offset (rings ``dodge_step`` [m] apart, up to ``max_dodge`` [m]) that keeps the sole box
``keep_out_clearance`` [m] from it. A target already clear, or one no offset within reach clears, stays
as planned (the IK's balance rows are unchanged; only where the foot lands moves).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from hsi_retarget.scene_distance import SceneDistance

if TYPE_CHECKING:
    from hsi_retarget.humanoid_ik import SupportConfig
    from hsi_retarget.part_scene import PartPhase

F64 = NDArray[np.float64]
_SOLE_TOP = 0.05  #: [m] height of the sole box above the sole frame (the humanoid's foot geom)
_DIRECTIONS = 16  #: [-] offsets tried per ring


def part_sweep(part: PartPhase | None, openings: int = 25) -> SceneDistance | None:
    """The meshes of ``part`` (and what rides in it) at ``openings`` evenly spaced openings from closed
    (0) to as scheduled (1), as one distance query; ``None`` without a part or without its meshes and
    motion."""
    if part is None or part.meshes is None or part.motion is None or openings < 2:
        return None
    posed = {}
    for k, fraction in enumerate(np.linspace(0.0, 1.0, openings)):
        motion = part.motion(float(fraction))
        for name, mesh in part.meshes.items():
            copy = mesh.copy()
            copy.apply_transform(motion)
            posed[f"{name}@{k}"] = copy
    return SceneDistance(posed, ground=())


def sole_points(pose: F64, config: SupportConfig) -> F64:
    """(18, 3) [m] points on the sole box of a sole frame ``pose`` (4, 4): its rectangle's corners, edge
    midpoints and centre at the sole and at the top of the foot."""
    hx, hy = config.foot_half_length, config.foot_half_width
    grid = np.array([(x, y) for x in (-hx, 0.0, hx) for y in (-hy, 0.0, hy)])
    local = np.concatenate(
        [np.column_stack([grid, np.full(len(grid), z)]) for z in (0.005, _SOLE_TOP)], axis=0
    )
    return np.asarray(local @ pose[:3, :3].T + pose[:3, 3])


def sole_clearance(pose: F64, keep_out: SceneDistance, config: SupportConfig) -> float:
    """[m] least distance of the sole box at ``pose`` (4, 4) to ``keep_out`` (negative: inside)."""
    dist, _ = keep_out.query(sole_points(pose, config))
    return float(dist.min())


def dodge(pose: F64, keep_out: SceneDistance | None, config: SupportConfig) -> tuple[F64, float]:
    """The sole ``pose`` (4, 4) moved horizontally by the least offset [m] that keeps it
    ``config.keep_out_clearance`` from ``keep_out`` (among rings up to ``config.max_dodge``, the clearest
    on the first ring that clears), and that offset's length [m] (0: unchanged: clear already, no
    ``keep_out``, or nothing within reach clears)."""
    if keep_out is None or config.max_dodge <= 0.0:
        return pose, 0.0
    need = config.keep_out_clearance
    if sole_clearance(pose, keep_out, config) >= need:
        return pose, 0.0
    angles = np.linspace(0.0, 2.0 * math.pi, _DIRECTIONS, endpoint=False)
    rings = np.arange(config.dodge_step, config.max_dodge + 1e-9, config.dodge_step)
    for radius in rings:
        best: tuple[float, F64] | None = None
        for a in angles:
            moved = np.array(pose)
            moved[:2, 3] += radius * np.array([math.cos(a), math.sin(a)])
            gap = sole_clearance(moved, keep_out, config)
            if gap >= need and (best is None or gap > best[0]):
                best = (gap, moved)
        if best is not None:
            return best[1], float(radius)
    return pose, 0.0
