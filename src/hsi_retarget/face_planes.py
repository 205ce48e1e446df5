"""Face planes kept for one IK step: no chatter at a furniture edge.

A collision row holds a sphere off the scene along the normal at its closest point only
(:func:`~hsi_retarget.collision.collision_rows`). Next to an edge of a board the closest feature flips
between two faces from one step to the next (under the board, then in front of it): each step moves the
sphere out along one face's normal and, unconstrained along the other, back towards that face. A
humanoid's head below a shelf board stayed 1-2 cm from it for a second this way, inside its 4 cm margin.

:class:`FacePlanes` remembers, after each step, the plane through the closest point of every sphere inside
its margin (from the step's collision candidates: no extra distance query), and gives the next step a row
for it as well (a velocity damper on the distance to that plane, like the scene rows). Only the step
right after is constrained, and only while the sphere stays within ``reach`` of where it was: a plane
describes the face near its point, not the whole scene.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from hsi_retarget.collision import SphereSet, point_rows

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class FacePlanes:
    """The face planes of the last step's spheres inside their scene margin (see the module docstring)."""

    def __init__(self, spheres: SphereSet, reach: float = 0.05) -> None:
        """``reach`` [m]: farthest a sphere may have moved since its plane was taken for the plane to
        still constrain it."""
        self.spheres, self.reach = spheres, float(reach)
        self._idx: I64 = np.zeros(0, dtype=np.int64)
        self._normal: F64 = np.zeros((0, 3))
        self._point: F64 = np.zeros((0, 3))
        self._center: F64 = np.zeros((0, 3))

    def clear(self) -> None:
        """Forget the planes (a new scene)."""
        self._idx = np.zeros(0, dtype=np.int64)

    def remember(self, centers: F64, margin: F64, idx: I64, gap: F64, normal: F64) -> None:
        """Take the planes of the spheres ``idx`` (k,) that are ``gap`` (k,) [m] (negative) inside their
        ``margin`` (S,) [m] of the scene along ``normal`` (k, 3) (the collision candidates of the step;
        ``centers`` (S, 3) [m] the sphere centres)."""
        dist = gap + self.spheres.radii[idx] + margin[idx]
        self._idx = np.asarray(idx, dtype=np.int64).copy()
        self._normal = np.array(normal, dtype=np.float64)
        self._point = centers[idx] - dist[:, None] * self._normal
        self._center = centers[idx].copy()

    def rows(
        self, model: pin.Model, data: pin.Data, centers: F64, margin: F64, gain: float
    ) -> tuple[F64, F64]:
        """Rows A (k, nv) and lower bounds (k,) ``n^T J dq >= -gain (d_plane - margin)`` for the remembered
        planes of the spheres still within ``reach`` of where they were; needs ``data.J`` at the step's
        configuration (``centers`` (S, 3) [m] there)."""
        if self._idx.size == 0:
            return np.zeros((0, model.nv)), np.zeros(0)
        now = centers[self._idx]
        near = np.linalg.norm(now - self._center, axis=1) < self.reach
        idx, normal = self._idx[near], self._normal[near]
        plane = np.einsum("ij,ij->i", now[near] - self._point[near], normal) - self.spheres.radii[idx]
        rows = point_rows(model, data, self.spheres, centers, idx=idx, dirs=normal)
        return rows, -gain * (plane - margin[idx])
