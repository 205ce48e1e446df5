"""Carrying what was actually grasped: the carry re-aimed from the TCP pose the IK reached at the grasp.

The gripper holds an object rigidly from the instant it closes. When the IK ends short of a grasp pose
(a low cabinet shelf at the edge of the arm's reach: centimetres and degrees), the object sits in the hand
with that error, and a carry that follows the planned TCP goals puts it down tilted and shifted by the
same error. :func:`correct_carry` turns the planned goals ``T(t)`` between a free object's grasp and its
release into ``T(t) D`` with the grasp error ``D = T_g^-1 T'_g`` (planned grasp goal ``T_g``, reached
TCP pose ``T'_g``, both (4, 4) world): the goal is the reached pose at the grasp, and the object ends at
its planned placement. ``D`` eases out over ``ease_s`` after the release (the hand leaves from where it
let go). Errors below ``min_position`` and ``min_angle_deg`` are left alone.

The planned goals themselves need not carry the object to its placement: the gripper is turned about its
approach axis at a grasp or a release to grip across an object or where the fingers have room, and a
one-handed place reaches the object's new spot along that support's approach axis, so the hand need not
hold the object at the release as at the grasp. :func:`place_carries` moves each carry's goals by the
translation that puts the object's bottom centre, carried rigidly from its grasp goal to its release goal,
on its placement (eased in over the carry, out after the release), from the schedule's record of both
(``Schedule.info["carries"]``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_retarget.easing import ease
from hsi_retarget.joint_trajectory import ContactEvent
from hsi_retarget.mapping import RobotGoals
from hsi_retarget.robots import RobotModel

__all__ = ["carry_frames", "correct_carry", "place_carries"]

F64 = NDArray[np.float64]


def _carries(events: Sequence[ContactEvent]) -> list[tuple[str, str, float, float | None]]:
    """(hand, object, grasp time [s], release time [s] or None) of every free-object grasp (door and
    drawer parts have a ``/`` in their names)."""
    out = []
    for k, e in enumerate(events):
        if e.kind != "grasp" or "/" in e.object_name:
            continue
        later = (v for v in events[k + 1 :] if v.hand == e.hand and v.kind == "release")
        release = next((v for v in later if v.object_name == e.object_name), None)
        out.append((e.hand, e.object_name, e.time, release.time if release is not None else None))
    return out


def carry_frames(t: F64, events: Sequence[ContactEvent]) -> dict[int, tuple[ContactEvent, ...]]:
    """Sample index (into ``t`` (T,) [s]) of every free-object grasp -> its events (grasp and release, if
    any): once the IK has reached that sample, :func:`correct_carry` with those events re-aims its carry
    (an IK can do so as it goes, in one pass)."""
    out: dict[int, tuple[ContactEvent, ...]] = {}
    for hand, name, t_grasp, t_release in _carries(events):
        i = int(np.clip(np.searchsorted(t, t_grasp - 1e-9), 0, t.shape[0] - 1))
        grasp = ContactEvent(t_grasp, hand, "grasp", name)
        own = (grasp,) if t_release is None else (grasp, ContactEvent(t_release, hand, "release", name))
        out[i] = out.get(i, ()) + own
    return out


def correct_carry(
    goals: RobotGoals,
    qs: F64,
    robot: RobotModel,
    events: Sequence[ContactEvent],
    *,
    min_position: float = 0.003,
    min_angle_deg: float = 1.0,
    ease_s: float = 0.5,
) -> tuple[RobotGoals, list[dict[str, Any]], int | None]:
    """``goals`` with every carry re-aimed from the TCP pose of ``qs`` (T, nq) at its grasp (see the module
    docstring; event times in the goals' time [s]). Returns the goals, one record per corrected carry
    (``hand``, ``object``, ``time_s`` [s], ``position_m`` [m], ``angle_deg`` [deg]) and the first
    changed sample (None: nothing changed)."""
    t = goals.t
    tcp = {s: np.array(p) for s, p in goals.tcp.items()}
    records: list[dict[str, Any]] = []
    first: int | None = None
    for hand, name, t_grasp, t_release in _carries(events):
        if hand not in tcp:
            continue
        i = int(np.clip(np.searchsorted(t, t_grasp - 1e-9), 0, t.shape[0] - 1))
        reached = robot.frame_pose(qs[i], robot.tcp_frames[hand])
        delta = np.linalg.inv(tcp[hand][i]) @ reached
        dp = float(np.linalg.norm(delta[:3, 3]))
        angle = float(np.degrees(np.linalg.norm(pin.log3(delta[:3, :3]))))
        if dp < min_position and angle < min_angle_deg:
            continue
        end = float(t[-1]) if t_release is None else t_release
        weight = np.where(t >= t_grasp - 1e-9, 1.0, 0.0)
        after = t > end
        weight[after] = 1.0 - ease((t[after] - end) / ease_s) if t_release is not None else 1.0
        rotvec = Rotation.from_matrix(delta[:3, :3]).as_rotvec()
        sel = np.flatnonzero(weight > 0.0)
        step = np.tile(np.eye(4), (sel.shape[0], 1, 1))
        step[:, :3, :3] = Rotation.from_rotvec(weight[sel, None] * rotvec[None, :]).as_matrix()
        step[:, :3, 3] = weight[sel, None] * delta[None, :3, 3]
        tcp[hand][sel] = tcp[hand][sel] @ step
        records.append(
            {"hand": hand, "object": name, "time_s": float(t_grasp), "position_m": dp, "angle_deg": angle}
        )
        first = i if first is None else min(first, i)
    return replace(goals, tcp=tcp), records, first


def place_carries(
    goals: RobotGoals,
    events: Sequence[ContactEvent],
    carries: Sequence[dict[str, Any]],
    *,
    min_position: float = 0.003,
    ease_s: float = 0.5,
) -> tuple[RobotGoals, list[dict[str, Any]]]:
    """``goals`` whose carries put each object down on its placement (see the module docstring; event
    times in the goals' time [s]). ``carries``: the schedule's records (``object``, ``hands``, ``grasp`` and
    ``place`` bottom centres (3,) [m]), matched to the grasp events of the same object in order. Shifts
    below ``min_position`` [m] are left alone. Returns the goals and one record per shifted carry
    (``object``, ``time_s`` [s] of its grasp, ``shift_m`` (3,) [m])."""
    t, last = goals.t, goals.t.shape[0] - 1
    tcp = {s: np.array(p) for s, p in goals.tcp.items()}
    records: list[dict[str, Any]] = []
    seen: set[tuple[str, float]] = set()  # a two-handed grasp is one carry
    grasped: dict[str, int] = {}  # grasps of each object so far: the k-th one has its k-th record
    for _, name, t_grasp, t_release in _carries(events):
        if (name, t_grasp) in seen:
            continue
        seen.add((name, t_grasp))
        k = grasped[name] = grasped.get(name, -1) + 1
        own = [c for c in carries if c.get("object") == name]
        if t_release is None or k >= len(own) or not {"grasp", "place"} <= set(own[k]):
            continue
        record = own[k]
        hands = [h for h in record.get("hands", ()) if h in tcp]
        i, r = (int(np.clip(np.searchsorted(t, x - 1e-9), 0, last)) for x in (t_grasp, t_release))
        if not hands or r <= i:
            continue
        bottom = np.append(np.asarray(record["grasp"], dtype=float), 1.0)
        # where the bottom centre lands, held rigidly from the grasp goal to the release goal
        landed = [(tcp[h][r] @ np.linalg.solve(tcp[h][i], bottom))[:3] for h in hands]
        shift = np.asarray(record["place"], dtype=float) - np.mean(landed, axis=0)  # two hands: one shift
        if float(np.linalg.norm(shift)) < min_position:
            continue
        weight = ease((t - t[i]) / max(float(t[r] - t[i]), 1e-9))
        after = t > t[r]
        weight[after] = 1.0 - ease((t[after] - t[r]) / ease_s)
        for h in hands:
            tcp[h][:, :3, 3] += weight[:, None] * shift[None, :]
        records.append({"object": name, "time_s": float(t_grasp), "shift_m": [float(v) for v in shift]})
    return replace(goals, tcp=tcp), records
