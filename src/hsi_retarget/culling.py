"""Exact culling of the IK's scene collision candidates by a bounding sphere per robot link.

Every link frame that carries collision spheres gets the smallest-radius-about-the-mean sphere that holds
all of them. Distances are 1-Lipschitz, so a link whose bounding sphere is farther than the activation
distance from the scene cannot have a sphere closer than that: only the spheres of near links are queried
against the scene. The result is the same as querying every sphere; it is just cheaper. Self-collision
pairs (~16000 on the dual-arm robot) are pre-filtered by one dense block of sphere-centre distances (the
pairs' first spheres x their second spheres, ~20000 entries, far fewer than all ~57000 sphere pairs) with
the radii sums precomputed, so that only the few pairs that may be near are measured exactly
(:meth:`LinkBounds.near_pairs`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial.distance import cdist

from hsi_planning.errors import RetargetError

if TYPE_CHECKING:
    from hsi_retarget.collision import SphereSet
    from hsi_retarget.scene_distance import SceneDistance

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class LinkBounds:
    """Bounding spheres of the links of a :class:`~hsi_retarget.collision.SphereSet`."""

    def __init__(self, spheres: SphereSet, pairs: I64 | None = None) -> None:
        """Bounds of the links of ``spheres``; ``pairs`` (P, 2), sphere index pairs: the self-collision
        pairs that :meth:`near_pairs` culls (kept as :attr:`pairs`; a copy)."""
        unique, owner = np.unique(spheres.frame_ids, return_inverse=True)
        self.frame_ids: I64 = unique.astype(np.int64)  #: (F,) pinocchio frame of each link
        self.owner: I64 = owner.astype(np.int64)  #: (S,) link index of each sphere
        self._frame_list = [int(f) for f in unique]
        centers = np.zeros((unique.shape[0], 3))
        radii = np.zeros(unique.shape[0])
        for f in range(unique.shape[0]):
            sel = owner == f
            centers[f] = spheres.centers[sel].mean(axis=0)
            reach = np.linalg.norm(spheres.centers[sel] - centers[f], axis=1) + spheres.radii[sel]
            radii[f] = reach.max()
        self.centers: F64 = centers  #: (F, 3) [m] bounding centres in the link frames
        self.radii: F64 = radii  #: (F,) [m] bounding radii (sphere radii included)
        self.pairs: I64 | None = None if pairs is None else np.array(pairs, dtype=np.int64).reshape(-1, 2)
        # the pairs as a dense block: first spheres (R,) x second spheres (C,), the radii sums (R, C) [m]
        # (-inf where no pair: never near) and the pair index of each entry (R, C) (-1 where none)
        self._firsts = self._seconds = np.zeros(0, dtype=np.int64)
        self._radii_sum, self._pair_index = np.zeros((0, 0)), np.zeros((0, 0), dtype=np.int64)
        if self.pairs is not None and self.pairs.shape[0]:
            a, b = self.pairs[:, 0], self.pairs[:, 1]
            if np.unique(self.pairs, axis=0).shape[0] != a.shape[0]:
                raise RetargetError(f"LinkBounds: {a.shape[0]} sphere pairs, some repeated: give each once")
            self._firsts, self._seconds = np.unique(a), np.unique(b)
            row, col = np.searchsorted(self._firsts, a), np.searchsorted(self._seconds, b)
            self._radii_sum = np.full((self._firsts.shape[0], self._seconds.shape[0]), -np.inf)
            self._radii_sum[row, col] = spheres.radii[a] + spheres.radii[b]
            self._pair_index = np.full(self._radii_sum.shape, -1, dtype=np.int64)
            self._pair_index[row, col] = np.arange(a.shape[0])

    def placements(self, data: pin.Data) -> tuple[F64, F64]:
        """(F, 3, 3) rotations and (F, 3) [m] positions of the links in the world (``data.oMf``)."""
        frames = np.array([data.oMf[fid].homogeneous for fid in self._frame_list])
        return frames[:, :3, :3], frames[:, :3, 3]

    def world(self, data: pin.Data, spheres: SphereSet) -> tuple[F64, F64]:
        """(F, 3) [m] bounding centres and (S, 3) [m] centres of ``spheres`` (those the bounds were built
        from) in the world, from one read of the link placements; needs ``data.oMf`` up to date."""
        rot, pos = self.placements(data)
        links = np.einsum("fij,fj->fi", rot, self.centers) + pos
        centers = np.einsum("sij,sj->si", rot[self.owner], spheres.centers) + pos[self.owner]
        return np.asarray(links), np.asarray(centers)

    def scene_candidates(self, scene: SceneDistance, link_centers: F64, reach: float) -> NDArray[np.bool_]:
        """(S,) spheres whose link's bounding sphere may be within ``reach`` [m] (beyond its surface) of
        the scene."""
        near = scene.lower_bound(link_centers) - self.radii < reach
        return np.asarray(near[self.owner])

    def near_pairs(self, centers: F64, reach: float) -> I64:
        """Indices (ascending) into :attr:`pairs` of the sphere pairs whose surfaces (world sphere centres
        ``centers`` (S, 3) [m]) are closer than ``reach`` [m] (empty without :attr:`pairs`)."""
        if self._firsts.shape[0] == 0:
            return np.zeros(0, dtype=np.int64)
        gap = cdist(centers[self._firsts], centers[self._seconds]) - self._radii_sum
        return np.sort(self._pair_index.ravel()[np.flatnonzero(gap.ravel() < reach)])
