"""Smoothing of the IK's joint paths without giving up its clearances.

The per-frame IK chatters along active collision constraints; :func:`smooth_joints` low-passes the arm
joints and the joints carrying the arms (a fixed base's base and lift, a humanoid's waist; never a
floating root or legs, whose soles must stay in place) at zero phase, which would otherwise force a large
time stretch (humanoid, drawer and shelf layouts: waist joints stepping 0.15 rad per frame, time-scaled
into a fast lean that the waist servos lagged by 0.07 rad, 3 cm at the hand). A low-pass also cuts
corners: where the IK kept an arm exactly at its margin from the other arm or the scene (an opened door
or drawer included), the smoothed path can pass inside it (and the arms touch in MuJoCo).
:func:`keep_clearance` blends the smoothed path back to the IK's own solution around every frame where
smoothing cost more than ``tolerance`` [m] of clearance.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from hsi_planning.mocap import lowpass
from hsi_retarget.easing import ease
from hsi_retarget.human_motion import SIDES
from hsi_retarget.ik import IKSolver
from hsi_retarget.mapping import BASE_JOINTS, LIFT_JOINT
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance

__all__ = ["keep_clearance", "smooth_joints"]

F64 = NDArray[np.float64]
Layer = tuple[SceneDistance | None, str]  #: an opened part's scene and its exempt hand ('' none)


def smoothed_joints(robot: RobotModel) -> list[str]:
    """Names of the joints :func:`smooth_joints` low-passes: the arms and, on a fixed base, the base and
    lift; on a floating robot the joints between its root and its arms (a humanoid's waist), never the
    root or the legs (the soles must stay exactly in place)."""
    names = [j for side in SIDES for j in robot.arm_joints[side]]
    if not robot.floating:
        return names + [j for j in (*BASE_JOINTS, LIFT_JOINT) if j in robot.joint_names]
    model, known = robot.model, set(robot.joint_names)
    for side in SIDES:
        jid = int(model.parents[model.getJointId(robot.arm_joints[side][0])])
        while jid > 0:
            name = str(model.names[jid])
            if name in known and name not in names:
                names.append(name)
            jid = int(model.parents[jid])
    return names


def smooth_joints(robot: RobotModel, t: F64, qs: F64, cutoff_hz: float) -> F64:
    """Zero-phase low-pass (cut-off ``cutoff_hz`` [Hz]) of the joints of :func:`smoothed_joints` in ``qs``
    (T, nq) sampled at ``t`` (T,) [s], clipped to the joint limits."""
    out = np.array(qs)
    if cutoff_hz <= 0.0 or t.shape[0] < 16:
        return out
    fs = 1.0 / float(np.median(np.diff(t)))
    if cutoff_hz >= 0.5 * fs:
        return out
    idx = np.array([robot.q_index(j) for j in smoothed_joints(robot)], dtype=np.int64)
    out[:, idx] = np.clip(lowpass(qs[:, idx], fs, cutoff_hz), robot.q_lower[idx], robot.q_upper[idx])
    return out


def _bad_frames(
    solver: IKSolver,
    raw: F64,
    path: F64,
    check: NDArray[np.bool_],
    tolerance: float,
    *,
    layers: Sequence[Layer] | None,
) -> NDArray[np.bool_]:
    """(T,) frames of ``check`` where ``path`` is closer than ``-tolerance`` to its margins and than the
    raw solution's clearance minus ``tolerance`` [m]: measured without the part layers, then, on the
    frames that have one, with it where it is what ``path`` comes closest to (each clearance is the
    smallest over all pairs: a raw frame already inside the part's margin must not hide a cut elsewhere)."""
    bad = np.zeros(path.shape[0], dtype=bool)
    moved = np.flatnonzero(check & ~np.isclose(raw, path, atol=1e-6).all(axis=1))
    plain = solver.clearances(path[moved], within=-tolerance)  # inf unless it cuts deeper than that
    for j, c in zip(moved, plain, strict=True):
        bad[j] = c < -tolerance and c < solver.clearance(raw[j]) - tolerance
    groups: dict[tuple[int, str], tuple[Layer, list[int]]] = {}
    for k, i in enumerate(moved.tolist()):  # the frames that share a part layer, measured together
        layer = layers[i] if layers is not None else (None, "")
        if layer[0] is not None and not bad[i]:
            groups.setdefault((id(layer[0]), layer[1]), (layer, []))[1].append(k)
    try:
        for layer, ks in groups.values():
            solver.set_part_scene(*layer)
            frames = moved[ks]
            cut = solver.clearances(path[frames], within=-tolerance)  # inf unless it cuts deeper than that
            for i, c, c_plain in zip(frames, cut, plain[ks], strict=True):
                bad[i] = c < min(-tolerance, c_plain) and c < solver.clearance(raw[i]) - tolerance
    finally:
        solver.set_part_scene(None)
    return bad


def _window(t: F64, bad: NDArray[np.bool_], window_s: float) -> F64:
    """(T,) weight: 1 on the ``bad`` frames, easing to 0 over ``window_s`` [s] either side."""
    weight = np.zeros(t.shape[0])
    for i in np.flatnonzero(bad):
        near = np.abs(t - t[i]) < window_s
        weight[near] = np.maximum(weight[near], ease(2.0 * (1.0 - np.abs(t[near] - t[i]) / window_s)))
    return weight


def keep_clearance(
    solver: IKSolver,
    robot: RobotModel,
    t: F64,
    raw: F64,
    cutoff_hz: float,
    *,
    tolerance: float = 0.001,
    window_s: float = 0.3,
    layers: Sequence[Layer] | None = None,
) -> tuple[F64, int]:
    """The IK's solutions ``raw`` (T, nq) at ``t`` (T,) [s] smoothed at ``cutoff_hz`` [Hz]
    (:func:`smooth_joints`), except around the frames where that costs clearance (below both ``-tolerance``
    [m] and the raw clearance minus ``tolerance``): there the path blends (over ``window_s`` [s]) into
    the raw path smoothed at twice, then four times the cut-off, and finally into the raw path. Returns
    the path and the number of frames that needed the raw path or a higher cut-off. ``layers`` (T,): each
    frame's opened door or drawer and its exempt hand as the IK heeded them
    (``diag["layers"]`` of :func:`~hsi_retarget.tracking.track`; default: none), heeded here too."""
    path = smooth_joints(robot, t, raw, cutoff_hz)
    if t.shape[0] == 0 or np.array_equal(path, raw):
        return path, 0
    check = np.ones(t.shape[0], dtype=bool)
    fixed = np.zeros(t.shape[0], dtype=bool)
    for candidate in (2.0 * cutoff_hz, 4.0 * cutoff_hz, 0.0):
        bad = _bad_frames(solver, raw, path, check, tolerance, layers=layers)
        if not bad.any():
            break
        fixed |= bad
        weight = _window(t, bad, window_s)
        target = smooth_joints(robot, t, raw, candidate) if candidate > 0.0 else raw
        path = path + weight[:, None] * (target - path)
        check = weight > 0.0
    return np.asarray(path), int(fixed.sum())
