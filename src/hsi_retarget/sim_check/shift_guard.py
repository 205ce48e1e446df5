"""Clearance guard of the in-hand placement correction (:mod:`hsi_retarget.sim_check.place_feedback`).

The correction translates the carrying hand by a shift ``s`` (3,) [m] off its planned path. The IK kept
the planned path clear of the scene by its margins, not by a centimetre more in every direction: a 3 cm
shift towards a shelf's side wall that the planned fingers pass at 12 mm put a finger pad into the wall
(dual-arm benchmark, cabinet bottle placed next to the shelf side). The guard measures, at the planned
configuration, the distance ``d`` [m] and the unit normal ``n`` (3,) (from the furniture to the hand) of
every hand geom near a furniture geom (MuJoCo's ``mj_geomDistance`` on a probe copy of the scene, the
doors, drawers and objects where they are now), and keeps the translated hand ``clearance_m`` clear:
``n . s >= min(clearance_m - d, 0)`` (a hand planned closer than that is not pushed in further; it is not
pulled out either). The shift is projected onto those half-spaces (cyclic projections; exact for one,
close for a few). The hand's geoms translate with the TCP (the orientation is kept).

The rest of the arm moves less, and not along the shift: :meth:`ShiftGuard.arm_room` checks the shifted
configuration itself against the rest of the robot (the other arm, its mount, the base), each pair of
geoms that MuJoCo collides keeping ``min(clearance_m, d)`` (``d``: the pair's distance at the plan). A
1.4 cm shift of a dual-arm carry put the carrying forearm 0.1 mm into the other arm's mount, planned 14 mm
off (benchmark ``cabinet_bottle/reshape/2``); the feedback then scales its shift down until the check
holds (:class:`~hsi_retarget.sim_check.place_feedback.PlaceFeedback`).
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from hsi_retarget.sim_check.mjcf import HANDS
from hsi_retarget.sim_check.world import KIND_FURNITURE, KIND_ROBOT, SimWorld

F64 = NDArray[np.float64]
_PROJECTIONS = 8  #: [-] rounds of cyclic projection onto the half-spaces


class ShiftGuard:
    """Limits a hand's shift by the clearance of its geoms to the furniture (see the module docstring)."""

    def __init__(self, world: SimWorld, clearance_m: float) -> None:
        """``clearance_m`` [m]: the clearance kept by the shifted hand's geoms."""
        m = world.model
        self.world, self.clearance = world, float(clearance_m)
        self._probe = mujoco.MjData(m)
        solid = (m.geom_contype | m.geom_conaffinity) > 0
        bounded = m.geom_type != mujoco.mjtGeom.mjGEOM_PLANE  # a plane's bounding radius is 0 (infinite)
        self._furniture = np.flatnonzero((world.geom_kind == KIND_FURNITURE) & solid & bounded)
        self._hand = {h: np.flatnonzero((world.geom_hand == i) & solid) for i, h in enumerate(HANDS)}
        self._fromto = np.zeros(6)
        self._arm_pairs = {h: _arm_pairs(world, h) for h in HANDS}

    def arm_room(self, q_plan: F64, q_moved: F64, hands: tuple[str, ...]) -> bool:
        """Whether the arms of ``hands`` at ``q_moved`` (nq,) keep every colliding geom pair with the rest
        of the robot ``min(clearance, distance at q_plan)`` apart (pairs touching at the plan excepted)."""
        w, m, probe = self.world, self.world.model, self._probe
        pairs = np.concatenate([self._arm_pairs[h] for h in hands]) if hands else np.zeros((0, 2), int)
        if pairs.shape[0] == 0:
            return True
        probe.qpos[:] = w.map.q_to_qpos(q_moved, w.data.qpos)
        mujoco.mj_kinematics(m, probe)
        a, b = pairs[:, 0], pairs[:, 1]
        gap = (
            np.linalg.norm(probe.geom_xpos[a] - probe.geom_xpos[b], axis=1)
            - m.geom_rbound[a]
            - m.geom_rbound[b]
        )
        near = pairs[gap < self.clearance]
        if near.shape[0] == 0:
            return True
        moved = [mujoco.mj_geomDistance(m, probe, int(g1), int(g2), self.clearance, None) for g1, g2 in near]
        close = [k for k, d in enumerate(moved) if d < self.clearance]
        if not close:
            return True
        probe.qpos[:] = w.map.q_to_qpos(q_plan, w.data.qpos)
        mujoco.mj_kinematics(m, probe)
        for k in close:
            planned = mujoco.mj_geomDistance(m, probe, int(near[k, 0]), int(near[k, 1]), self.clearance, None)
            if planned > 1e-6 and moved[k] < min(self.clearance, planned) - 1e-6:
                return False
        return True

    def limit(self, q_plan: F64, hands: tuple[str, ...], shift: F64) -> F64:
        """The part of ``shift`` (3,) [m] (world frame) that keeps ``hands`` clear when their TCPs are
        translated by it from the planned configuration ``q_plan`` (nq,)."""
        rows = self._half_spaces(q_plan, hands, float(np.linalg.norm(shift)))
        if not rows:
            return shift
        s = np.array(shift, dtype=np.float64)
        for _ in range(_PROJECTIONS):
            worst = 0.0
            for n, bound in rows:
                short = bound - float(n @ s)
                if short > 1e-9:
                    s += short * n
                    worst = max(worst, short)
            if worst < 1e-6:
                break
        return s

    def _half_spaces(self, q_plan: F64, hands: tuple[str, ...], reach: float) -> list[tuple[F64, float]]:
        """(n (3,), bound [m]) of every hand geom within ``reach`` + clearance of a furniture geom at
        ``q_plan``."""
        w, m, probe = self.world, self.world.model, self._probe
        probe.qpos[:] = w.map.q_to_qpos(q_plan, w.data.qpos)
        mujoco.mj_kinematics(m, probe)
        far = reach + self.clearance
        furniture = self._furniture
        rows: list[tuple[F64, float]] = []
        for hand in hands:
            mine = self._hand[hand]
            gap = (
                np.linalg.norm(probe.geom_xpos[mine][:, None] - probe.geom_xpos[furniture][None], axis=2)
                - m.geom_rbound[mine][:, None]
                - m.geom_rbound[furniture][None]
            )
            for a, b in zip(*np.nonzero(gap < far), strict=True):
                g1, g2 = int(mine[a]), int(furniture[b])
                dist = mujoco.mj_geomDistance(m, probe, g1, g2, far, self._fromto)
                if dist >= far or dist <= 1e-6:  # far, or touching at the plan (no normal to keep)
                    continue
                n = (self._fromto[:3] - self._fromto[3:]) / dist
                rows.append((n, min(self.clearance - dist, 0.0)))
        return rows


def _arm_pairs(world: SimWorld, hand: str) -> NDArray[np.int64]:
    """(P, 2) geom pairs (one moved by ``hand``'s arm joints, one of the robot that they do not move) that
    MuJoCo collides: contype/conaffinity match, bodies neither the same nor parent and child."""
    m = world.model
    first = int(
        m.jnt_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, world.robot.arm_joints[hand][0])]
    )
    moved = np.zeros(m.nbody, dtype=bool)
    for body in range(m.nbody):  # bodies are numbered parents first
        moved[body] = body == first or (body > 0 and moved[int(m.body_parentid[body])])
    solid = (m.geom_contype | m.geom_conaffinity) > 0
    robot = (world.geom_kind == KIND_ROBOT) & solid
    body = m.geom_bodyid
    mine, rest = np.flatnonzero(robot & moved[body]), np.flatnonzero(robot & ~moved[body])
    a, b = (x.ravel() for x in np.meshgrid(mine, rest, indexing="ij"))
    ba, bb = body[a], body[b]
    collide = ((m.geom_contype[a] & m.geom_conaffinity[b]) | (m.geom_contype[b] & m.geom_conaffinity[a])) > 0
    related = (ba == bb) | (m.body_parentid[ba] == bb) | (m.body_parentid[bb] == ba)
    keep = collide & ~related
    return np.column_stack([a[keep], b[keep]]).astype(np.int64)
