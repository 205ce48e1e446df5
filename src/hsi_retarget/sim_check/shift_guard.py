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
close for a few). The hand's geoms translate with the TCP (the orientation is kept); the rest of the arm
moves less and is not checked.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from hsi_retarget.sim_check.mjcf import HANDS
from hsi_retarget.sim_check.world import KIND_FURNITURE, SimWorld

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
