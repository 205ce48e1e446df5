"""Humanoid balance for the IK: soles held on the floor, the centre of mass over the support polygon, and
re-planted feet when the pelvis goal walks away from them.

- :func:`support_rows`: the sole frames as equality rows ``J_sole dq = e_sole`` (pose error,
  LOCAL_WORLD_ALIGNED Jacobians) and the CoM (pinocchio ``centerOfMass`` / ``jacobianCenterOfMass``) as
  inequality rows keeping its horizontal position ``com_margin`` inside the convex hull of the supporting
  soles' rectangles, plus an optional soft CoM goal (weight shift before a step).
- :func:`plan_footsteps`: there is no walking controller. Feet stay planted while the pelvis goal
  ``lookahead`` ahead stays within ``step_threshold`` of its nominal stance; beyond it, a step sequence
  re-plants the feet one at a time (weight shift over the stance foot, then a min-jerk swing with a
  ``swing_height`` arc). A step turns its foot at most ``max_step_yaw`` away from the stance foot's heading
  (the hips' yaw range: the pelvis stands between both feet), so a sharp turn takes more steps. In MuJoCo
  the pelvis is held on the planned root path by the model's
  ``pelvis_anchor`` mocap weld.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation, Slerp

from hsi_planning.errors import ConfigError
from hsi_retarget.foot_clearance import dodge

if TYPE_CHECKING:
    from hsi_retarget.ik_types import IKTargets
    from hsi_retarget.robots import RobotModel
    from hsi_retarget.scene_distance import SceneDistance

F64 = NDArray[np.float64]
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@dataclass(frozen=True)
class SupportConfig:
    """Feet, support polygon and stepping of the humanoid."""

    foot_half_length: float = 0.13  #: [m] sole rectangle half length (x of the sole frame)
    foot_half_width: float = 0.05  #: [m] sole rectangle half width (y of the sole frame)
    com_margin: float = 0.02  #: [m] CoM kept this far inside the support polygon
    com_gain: float = 0.5  #: [-] fraction of the CoM distance to the polygon edge one step may use
    com_weight: float = 10.0  #: [1/m^2] soft CoM goal during a weight shift
    step_threshold: float = 0.12  #: [m] stance foot displacement that triggers a step
    #: [s] the displacement is measured to the stance under the pelvis goal this far ahead: the feet step
    #: before the body moves on (out of the way of a door swinging after the hand)
    lookahead: float = 1.1
    yaw_threshold: float = 0.35  #: [rad] stance heading change that triggers a step
    max_step_length: float = 0.45  #: [m] longest single step
    #: [rad] largest heading of a stepped foot relative to the stance foot: the pelvis turns between the
    #: feet on the hip yaw joints (+-0.7 rad on the humanoid); a 90 deg turn in one step left a stance hip
    #: at its limit and the IK's foot rows infeasible (hands 0.7 m off their goals while turning)
    max_step_yaw: float = 1.0
    step_crouch: float = 0.07  #: [m] the pelvis goal is lowered this much while stepping (leg reach)
    shift_time: float = 0.2  #: [s] weight shift over the stance foot before a swing
    swing_time: float = 0.35  #: [s] swing duration
    swing_height: float = 0.05  #: [m] apex of the swing arc
    #: [m] a step's target sole keeps this far from the region an opened door or drawer sweeps
    #: (:mod:`hsi_retarget.foot_clearance`)
    keep_out_clearance: float = 0.03
    max_dodge: float = 0.15  #: [m] farthest a target sole is moved for that (0: never moved)
    dodge_step: float = 0.02  #: [m] spacing of the offsets tried

    def __post_init__(self) -> None:
        for name in ("foot_half_length", "foot_half_width", "com_gain", "step_threshold", "yaw_threshold"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"SupportConfig.{name} must be > 0, got {getattr(self, name)}")
        if not self.lookahead >= 0.0:
            raise ConfigError(f"SupportConfig.lookahead must be >= 0 s, got {self.lookahead}")
        for name in ("max_step_length", "max_step_yaw", "shift_time", "swing_time"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"SupportConfig.{name} must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.com_margin < min(self.foot_half_length, self.foot_half_width):
            raise ConfigError("SupportConfig.com_margin must be in [0, foot half width) m")
        if min(self.com_weight, self.swing_height, self.step_crouch) < 0.0 or self.com_gain > 1.0:
            raise ConfigError("SupportConfig: com_weight, swing_height, step_crouch >= 0 and com_gain <= 1")
        if not (self.keep_out_clearance >= 0.0 and self.max_dodge >= 0.0 and self.dodge_step > 0.0):
            raise ConfigError(
                "SupportConfig.keep_out_clearance and max_dodge must be >= 0 m and dodge_step > 0 m, got "
                f"{self.keep_out_clearance}, {self.max_dodge}, {self.dodge_step}"
            )


def support_polygon(soles: list[F64], config: SupportConfig) -> tuple[F64, F64]:
    """Half-planes ``normals @ xy <= offsets`` (k, 2), (k,) [m] of the convex hull of the sole rectangles
    (poses (4, 4)), shrunk by ``com_margin``."""
    hl, hw = config.foot_half_length, config.foot_half_width
    local = np.array([[hl, hw, 0.0], [hl, -hw, 0.0], [-hl, -hw, 0.0], [-hl, hw, 0.0]])
    corners = np.concatenate([local @ np.asarray(s)[:3, :3].T + np.asarray(s)[:3, 3] for s in soles])[:, :2]
    hull = ConvexHull(corners)
    normals, offsets = hull.equations[:, :2], -hull.equations[:, 2]
    return np.asarray(normals), np.asarray(offsets - config.com_margin)


def com_inside(com_xy: F64, soles: list[F64], config: SupportConfig, tol: float = 1e-9) -> bool:
    """Whether ``com_xy`` (2,) [m] lies inside the (shrunk) support polygon of ``soles``."""
    normals, offsets = support_polygon(soles, config)
    return bool(np.all(normals @ np.asarray(com_xy) <= offsets + tol))


def support_rows(
    model: pin.Model, data: pin.Data, q: F64, targets: IKTargets, config: SupportConfig
) -> tuple[F64, F64, F64, F64, F64, F64]:
    """Balance rows for one IK step at ``q`` (nq,); ``data`` must hold its frame placements.

    Returns:
        (A_eq (6 f, nv), b_eq (6 f,)) sole equality rows, (A_in (k, nv), lower (k,)) CoM rows
        ``A_in dq >= lower``, and the soft CoM goal's (H (nv, nv), g (nv,)) objective terms.
    """
    nv = model.nv
    eq_a, eq_b = [], []
    for side in sorted(targets.feet):
        fid = model.getFrameId(f"{side}_sole", pin.FrameType.BODY)
        goal = np.asarray(targets.feet[side])
        placement = data.oMf[fid]
        err_p = goal[:3, 3] - np.asarray(placement.translation)
        err_o = pin.log3(goal[:3, :3] @ np.asarray(placement.rotation).T)
        eq_a.append(np.asarray(pin.getFrameJacobian(model, data, fid, _LWA)))
        eq_b.append(np.concatenate([err_p, err_o]))
    com = np.asarray(pin.centerOfMass(model, data, q))
    jac_com = np.asarray(pin.jacobianCenterOfMass(model, data, q))[:2]
    soles = [np.asarray(targets.feet[s]) for s in targets.support if s in targets.feet]
    in_a, in_lo = np.zeros((0, nv)), np.zeros(0)
    if soles:
        normals, offsets = support_polygon(soles, config)
        in_a = -normals @ jac_com
        in_lo = -config.com_gain * (offsets - normals @ com[:2])
    hess, grad = np.zeros((nv, nv)), np.zeros(nv)
    if targets.com is not None and config.com_weight > 0.0:
        hess = config.com_weight * jac_com.T @ jac_com
        grad = -config.com_weight * jac_com.T @ (np.asarray(targets.com) - com[:2])
    a = np.vstack(eq_a) if eq_a else np.zeros((0, nv))
    b = np.concatenate(eq_b) if eq_b else np.zeros(0)
    return a, b, in_a, in_lo, hess, grad


@dataclass(frozen=True, eq=False)
class Footsteps:
    """Planned soles over time: ``feet`` side -> (T, 4, 4), ``support`` (T,) sides on the floor, ``com``
    (T, 2) [m] soft CoM goals (NaN: none), ``crouch`` (T,) [m] pelvis lowering, ``steps`` one dict per step
    (side, times [s], length [m])."""

    feet: dict[str, F64]
    support: tuple[tuple[str, ...], ...]
    com: F64
    crouch: F64
    steps: list[dict[str, float | str]] = field(default_factory=list)


def _stance(robot: RobotModel, pelvis: F64) -> dict[str, F64]:
    """Nominal sole poses (4, 4) on the floor under a pelvis pose (4, 4) (home offsets, pelvis heading)."""
    home = robot.fk(robot.q_home, ("left_sole", "right_sole"))
    yaw = math.atan2(pelvis[1, 0], pelvis[0, 0])
    rot = Rotation.from_euler("z", yaw).as_matrix()
    out = {}
    for side in ("left", "right"):
        offset = home[f"{side}_sole"][:3, 3] - robot.q_home[:3]
        pose = np.eye(4)
        pose[:3, :3] = rot
        pose[:3, 3] = [*(pelvis[:2, 3] + rot[:2, :2] @ offset[:2]), 0.0]
        out[side] = pose
    return out


def plan_footsteps(
    robot: RobotModel,
    t: F64,
    pelvis: F64,
    config: SupportConfig | None = None,
    keep_out: SceneDistance | None = None,
) -> Footsteps:
    """Soles for pelvis goals ``pelvis`` (T, 4, 4) at times ``t`` (T,) [s] (see the module docstring); a
    step's target sole is moved clear of ``keep_out`` (the region an opened part sweeps,
    :func:`~hsi_retarget.foot_clearance.dodge`; the step's ``dodge_m`` says by how much)."""
    cfg = config or SupportConfig()
    n = int(t.shape[0])
    current = _stance(robot, pelvis[0])
    feet = {s: np.zeros((n, 4, 4)) for s in current}
    support: list[tuple[str, ...]] = [("left", "right")] * n
    com = np.full((n, 2), np.nan)
    crouch = np.zeros(n)
    steps: list[dict[str, float | str]] = []
    i = 0
    while i < n:
        for s, track in feet.items():
            track[i] = current[s]
        ahead = min(int(np.searchsorted(t, t[i] + cfg.lookahead)), n - 1)
        nominal = _stance(robot, pelvis[ahead])
        disp = {s: float(np.linalg.norm(nominal[s][:2, 3] - current[s][:2, 3])) for s in current}
        dyaw = abs(_yaw(nominal["left"]) - _yaw(current["left"]))
        dyaw = min(dyaw, 2 * math.pi - dyaw)
        if max(disp.values()) <= cfg.step_threshold and dyaw <= cfg.yaw_threshold:
            i += 1
            continue
        end = int(np.searchsorted(t, t[i] + 2 * (cfg.shift_time + cfg.swing_time)))
        goal = _stance(robot, pelvis[min(end, n - 1)])
        t0 = start = float(t[i])
        shift_from = pelvis[i][:2, 3]  # the weight moves smoothly from here to each stance foot in turn
        for swing in sorted(current, key=lambda s: -disp[s]):
            stance = "right" if swing == "left" else "left"
            reach = _limit_step(current[swing], goal[swing], cfg.max_step_length)
            reach = _limit_turn(reach, current[stance], cfg)
            target, moved = dodge(reach, keep_out, cfg)
            t_shift, t_end = t0 + cfg.shift_time, t0 + cfg.shift_time + cfg.swing_time
            over = current[stance][:2, 3]
            j = i
            while j < n and t[j] < t_end:
                w = _ease((t[j] - t0) / cfg.shift_time)
                com[j] = (1.0 - w) * shift_from + w * over
                crouch[j] = cfg.step_crouch * _ease((t[j] - start) / cfg.shift_time)
                feet[stance][j] = current[stance]
                if t[j] < t_shift:
                    feet[swing][j], support[j] = current[swing], ("left", "right")
                else:
                    u = (t[j] - t_shift) / cfg.swing_time
                    feet[swing][j] = _swing(current[swing], target, u, cfg.swing_height)
                    support[j] = (stance,)
                j += 1
            steps.append(
                {
                    "side": swing,
                    "t_start": t0,
                    "t_end": t_end,
                    "length_m": float(np.linalg.norm(target[:2, 3] - current[swing][:2, 3])),
                    "dodge_m": moved,
                }
            )
            current = {**current, swing: target}
            i, t0, shift_from = j, t_end, over
            if i >= n:
                break
        while i < n and t[i] < t0 + cfg.shift_time:  # both feet down: back under the pelvis goal, upright
            w = _ease((t[i] - t0) / cfg.shift_time)
            com[i] = (1.0 - w) * shift_from + w * pelvis[i][:2, 3]
            crouch[i] = cfg.step_crouch * (1.0 - w)
            for s, track in feet.items():
                track[i] = current[s]
            i += 1
    return Footsteps(feet, tuple(support), com, crouch, steps)


def _ease(u: float) -> float:
    """Min-jerk ease from 0 to 1 over ``u`` in [0, 1] (clipped; the result too: it rounds past 1)."""
    u = min(max(float(u), 0.0), 1.0)
    return min(max(10 * u**3 - 15 * u**4 + 6 * u**5, 0.0), 1.0)


def _yaw(pose: F64) -> float:
    return math.atan2(pose[1, 0], pose[0, 0])


def _limit_step(start: F64, goal: F64, max_length: float) -> F64:
    delta = goal[:2, 3] - start[:2, 3]
    length = float(np.linalg.norm(delta))
    out = np.array(goal)
    if length > max_length:
        out[:2, 3] = start[:2, 3] + delta * (max_length / length)
    return out


def _limit_turn(target: F64, stance: F64, config: SupportConfig) -> F64:
    """``target`` sole (4, 4) turned about its centre to at most ``max_step_yaw`` from the ``stance`` sole's
    heading."""
    rel = (_yaw(target) - _yaw(stance) + math.pi) % (2.0 * math.pi) - math.pi
    if abs(rel) <= config.max_step_yaw:
        return target
    out = np.array(target)
    out[:3, :3] = Rotation.from_euler("z", _yaw(stance) + math.copysign(config.max_step_yaw, rel)).as_matrix()
    return out


def _swing(start: F64, goal: F64, u: float, height: float) -> F64:
    """Sole pose (4, 4) at phase ``u`` in [0, 1] of a min-jerk swing with an arc of apex ``height`` [m]."""
    s = _ease(u)
    out = np.eye(4)
    rots = Rotation.from_matrix(np.stack([start[:3, :3], goal[:3, :3]]))
    out[:3, :3] = Slerp([0.0, 1.0], rots)(s).as_matrix()
    out[:3, 3] = (1 - s) * start[:3, 3] + s * goal[:3, 3]
    out[2, 3] += 4.0 * height * s * (1.0 - s)
    return out
