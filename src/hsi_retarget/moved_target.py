"""Grasps of objects that moved after planning, re-aimed at where they are now.

When a target is pushed a few cm after its grasp was planned and the re-plan on the new layout fails (a
scheduler check at the new spot, an optimizer out of iterations) or its IK misses the grasp, the planned
motion can still be used:
:func:`shift_grasps` moves the grasping hand's wrist goals by the object's displacement, eased in over the
planned approach into the grasp (the straight final approach of :mod:`hsi_retarget.grasp_depth` is laid
out from the moved goal), held through the withdrawal after it, and eased out over the carry up to the
release's approach, so that the object still lands where it was planned to. The carry correction
(:mod:`hsi_retarget.carry_correction`) then re-aims the carry from the pose the grasp actually reached.
The motion is not checked again for collisions here: the IK keeps its margins to the (new) scene.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import RetargetError
from hsi_retarget.easing import ease
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.human_motion import HumanMotion

__all__ = ["MAX_SHIFT", "moved_carries", "shift_grasps"]

F64 = NDArray[np.float64]
MAX_SHIFT = 0.25  #: [m] largest displacement re-aimed this way (farther: plan again)


def shift_grasps(
    motion: HumanMotion, windows: Sequence[GraspWindow], moved: Mapping[str, ArrayLike]
) -> tuple[HumanMotion, list[dict[str, object]]]:
    """A copy of ``motion`` whose grasps of the ``moved`` objects (name -> (3,) [m] world displacement
    since planning) are re-aimed (module docstring), and one record per shifted grasp (hand, object,
    time [s], shift [m]). ``windows``: the motion's grasp windows
    (:func:`~hsi_retarget.grasp_windows.grasp_windows`).

    Raises:
        RetargetError: a displacement that is not a finite (3,) vector of at most :data:`MAX_SHIFT`, or a
            moved object the motion never grasps.
    """
    t = motion.t
    positions = {s: np.array(p) for s, p in motion.wrist_position.items()}
    records: list[dict[str, object]] = []
    for name, offset in moved.items():
        d = np.asarray(offset, dtype=np.float64)
        if d.shape != (3,) or not np.isfinite(d).all() or float(np.linalg.norm(d)) > MAX_SHIFT:
            raise RetargetError(
                f"moved object {name!r}: the displacement must be a finite (3,) vector [m] of at most "
                f"{MAX_SHIFT} m, got {np.asarray(offset).tolist()}"
            )
        grasps = [w for w in windows if w.kind == "grasp" and w.free and w.target == name]
        grasps = [w for w in grasps if w.hand in positions]
        if not grasps:
            raise RetargetError(f"moved object {name!r} is never grasped; grasped: {_grasped(windows)}")
        for w in grasps:
            later = [v for v in windows if v.hand == w.hand and v.target == name and v.time > w.time]
            release = next((v for v in later if v.kind == "release"), None)
            positions[w.hand] += _weight(t, w, release)[:, None] * d[None, :]
            records.append(
                {"hand": w.hand, "object": name, "time_s": float(w.time), "shift_m": d.round(4).tolist()}
            )
    return replace(motion, wrist_position=positions), records


def moved_carries(
    records: Sequence[Mapping[str, Any]], moved: Mapping[str, ArrayLike]
) -> list[Mapping[str, Any]]:
    """A schedule's carry records (:func:`~hsi_retarget.carry_correction.place_carries`) with the
    grasp-time bottom centre of each ``moved`` object (name -> (3,) [m] displacement) moved with it (copies
    where changed): the carry is then re-aimed from where the object is grasped now onto its placement."""
    out: list[Mapping[str, Any]] = []
    for record in records:
        name = str(record.get("object", ""))
        if name in moved and "grasp" in record:
            shift = np.asarray(moved[name], dtype=np.float64)
            out.append({**record, "grasp": np.asarray(record["grasp"], dtype=np.float64) + shift})
        else:
            out.append(record)
    return out


def _grasped(windows: Sequence[GraspWindow]) -> list[str]:
    return sorted({w.target for w in windows if w.kind == "grasp" and w.free})


def _weight(t: F64, grasp: GraspWindow, release: GraspWindow | None) -> F64:
    """(T,) [0..1]: eased in over the grasp's approach, 1 through its withdrawal, eased out from there to
    the release's approach (held to the end without a release)."""
    rise = ease((t - grasp.before[0]) / max(grasp.time - grasp.before[0], 1e-9))
    if release is None:
        return rise
    a = grasp.after[1]
    b = max(release.before[0], a)
    if math.isclose(a, b):
        b = max(release.time, a + 1e-9)
    fall = 1.0 - ease((t - a) / max(b - a, 1e-9))
    return np.asarray(np.minimum(rise, fall))
