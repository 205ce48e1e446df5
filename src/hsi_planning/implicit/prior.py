"""Motion-prior matching and orientation transfer of the implicit planner (CHOICE §4, Eq. 12).

- :class:`PriorMatcher`: the nearest training sample of the checkpoint's :class:`PriorBank` to a
  problem's local feature (:func:`~hsi_planning.implicit.problem.local_feature`), searched among the
  samples of the same hand, action and segment (KD-tree per group, :class:`LatentBank`); gives the warm-
  start latent and the matched demonstration τ_prior moved onto the current grid (bank positions are
  grid-local, quaternions world-frame).
- :func:`transfer_orientation` (Eq. 12): the wrist orientation of τ_prior carried onto a new path. At
  equal normalised arc length u the prior's orientation is rotated by the minimal rotation that maps
  the prior's path tangent onto the new path's tangent; over the last ``blend_fraction`` of the path the
  result is slerped back into the prior's own orientation, so the contact orientation is the prior's.
- :func:`contact_point`: the wrist contact position in front of the target along the approach axis,
  placed like the training contacts (``palm_offset`` outside the target's extent along the axis).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation, Slerp

from hsi_planning.errors import PlanningError
from hsi_planning.implicit.latent import LatentBank
from hsi_planning.implicit.prior_bank import PriorBank
from hsi_planning.trajectory import WristTrajectory

_LOG = logging.getLogger(__name__)

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PriorMatch:
    """The matched prior sample.

    Attributes:
        index: sample index in the bank.
        distance: [-] feature distance to the query.
        scene_id: latent index of the sample's training problem.
        z_init: (latent_dim,) warm-start latent (a copy of that problem's code).
        demo: τ_prior as a world-frame trajectory on the current grid.
        exact_group: whether a sample of the same hand, action and segment was found.
    """

    index: int
    distance: float
    scene_id: int
    z_init: NDArray[np.float32]
    demo: WristTrajectory
    exact_group: bool


def _group_key(cond: NDArray[np.float32]) -> tuple[int, int, int]:
    return (int(cond[1] > 0.0), int(cond[2] > 0.5), int(cond[3] > 0.5))


class PriorMatcher:
    """Nearest-prior search over a :class:`PriorBank`, one KD-tree per (hand, action, segment) group.

    Args:
        bank: the checkpoint's prior bank.
        latents: (S, latent_dim) trained latents (``bank.scene_id`` indexes them).
    """

    def __init__(self, bank: PriorBank, latents: ArrayLike) -> None:
        lat = np.asarray(latents, dtype=np.float32)
        if lat.ndim != 2 or int(bank.scene_id.max()) >= lat.shape[0]:
            raise PlanningError(
                f"the prior bank references latent {int(bank.scene_id.max())} but the checkpoint has "
                f"{lat.shape[0] if lat.ndim == 2 else 0} latents"
            )
        self.bank = bank
        self._all = LatentBank(bank.features, bank.scene_id, lat)
        self._groups: dict[tuple[int, int, int], tuple[NDArray[np.int64], LatentBank]] = {}
        keys = [_group_key(c) for c in bank.cond]
        for key in sorted(set(keys)):
            idx = np.flatnonzero([k == key for k in keys]).astype(np.int64)
            self._groups[key] = (idx, LatentBank(bank.features[idx], bank.scene_id[idx], lat))

    @property
    def feature_dim(self) -> int:
        """Length F of the bank's features."""
        return int(self.bank.features.shape[1])

    def match(self, feature: ArrayLike, grid_centre: ArrayLike) -> PriorMatch:
        """The nearest prior to ``feature`` (F,) with the same condition group (its last 4 entries).

        Args:
            feature: (F,) query feature (``local_feature`` of the problem's fields and condition).
            grid_centre: (3,) [m] world centre of the current grid (τ_prior is moved onto it).
        """
        f = np.asarray(feature, dtype=np.float32).reshape(-1)
        if f.shape != (self.feature_dim,):
            raise PlanningError(
                f"feature has {f.shape[0]} values but the prior bank's features have {self.feature_dim}; "
                "the checkpoint was built with another local_feature definition"
            )
        cond = self._cond_of(f)
        group = self._groups.get(_group_key(cond))
        if group is None:
            _LOG.warning("no prior with hand/action/segment %s; matching over the whole bank", cond[1:])
            z, k, dist = self._all.warm_start(f)
        else:
            idx, bank = group
            z, local, dist = bank.warm_start(f)
            k = int(idx[local])
        return PriorMatch(
            index=k,
            distance=dist,
            scene_id=int(self.bank.scene_id[k]),
            z_init=z,
            demo=self.bank.trajectory(k, grid_centre),
            exact_group=group is not None,
        )

    def _cond_of(self, feature: NDArray[np.float32]) -> NDArray[np.float32]:
        """The (unscaled) condition a feature was built with: its last 4 values / the bank's scaling."""
        from hsi_planning.implicit.problem import CONDITION_FEATURE_SCALE

        return np.asarray(feature[-4:] / np.asarray(CONDITION_FEATURE_SCALE), dtype=np.float32)


def contact_point(target_points: ArrayLike, axis: ArrayLike, palm_offset: float) -> F64:
    """(3,) [m] wrist contact: ``palm_offset`` [m] beyond the target's extent along ``axis`` (3,), on the
    line through the centre of the target points' bounding box (as the training contacts)."""
    pts = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    if pts.shape[0] == 0:
        raise PlanningError("contact_point needs at least one target point")
    a = np.asarray(axis, dtype=np.float64).reshape(3)
    a = a / np.linalg.norm(a)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    s_max = float((pts @ a).max())
    return np.asarray(centre - float(centre @ a) * a + (s_max + palm_offset) * a, dtype=np.float64)


def _arc(points: F64) -> F64:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def path_tangents(points: ArrayLike, smooth: float = 0.02) -> F64:
    """(T, 3) unit tangents of a path (T, 3) [m], Gaussian-smoothed over ``smooth`` [m] of arc length.

    Repeated points take the neighbouring tangent; a path that does not move gives NaN rows.
    """
    p = np.asarray(points, dtype=np.float64)
    arc = _arc(p)
    if p.shape[0] < 2 or arc[-1] < 1e-9:
        return np.full(p.shape, np.nan)
    step = max(arc[-1] / max(p.shape[0] - 1, 1), 1e-6)
    sm = gaussian_filter1d(p, sigma=max(smooth / step, 1e-3), axis=0, mode="nearest")
    tan = np.gradient(sm, axis=0)
    norm = np.linalg.norm(tan, axis=1)
    good = norm > 1e-9
    if not good.any():
        return np.full(p.shape, np.nan)
    idx = np.arange(p.shape[0])
    for c in range(3):
        tan[:, c] = np.interp(idx, idx[good], tan[good, c] / norm[good])
    return np.asarray(tan / np.linalg.norm(tan, axis=1, keepdims=True), dtype=np.float64)


def rotation_between(a: ArrayLike, b: ArrayLike) -> Rotation:
    """Minimal rotations (one per row) taking unit vectors ``a`` (N, 3) onto ``b`` (N, 3)."""
    u = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    cross = np.cross(u, v)
    sin = np.linalg.norm(cross, axis=1)
    cos = np.einsum("ij,ij->i", u, v)
    angle = np.arctan2(sin, cos)
    axis = np.zeros_like(u)
    ok = sin > 1e-9
    axis[ok] = cross[ok] / sin[ok, None]
    anti = ~ok & (cos < 0.0)  # opposite vectors: any axis perpendicular to u
    if anti.any():
        helper = np.where(np.abs(u[anti, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        perp = np.cross(u[anti], helper)
        axis[anti] = perp / np.linalg.norm(perp, axis=1, keepdims=True)
    return Rotation.from_rotvec(axis * angle[:, None])


def _end_weight(u: F64, fraction: float) -> F64:
    """(N,) smoothstep weight over the last ``fraction`` of the normalised arc length ``u`` (N,): 0 before
    it, 1 at the end."""
    x = np.clip((u - (1.0 - fraction)) / max(fraction, 1e-9), 0.0, 1.0)
    return np.asarray(x * x * (3.0 - 2.0 * x))


def _continuous(quat: F64) -> F64:
    out = np.array(quat, dtype=np.float64, copy=True)
    for i in range(1, out.shape[0]):
        if float(out[i] @ out[i - 1]) < 0.0:
            out[i] = -out[i]
    return np.asarray(out / np.linalg.norm(out, axis=1, keepdims=True), dtype=np.float64)


def transfer_orientation(
    prior_positions: ArrayLike,
    prior_quaternions: ArrayLike,
    positions: ArrayLike,
    blend_fraction: float = 0.2,
    smooth: float = 0.02,
) -> F64:
    """Eq. 12: orientations (N, 4) [x y z w] for the path ``positions`` (N, 3) [m] from τ_prior.

    Both paths run towards the contact (their **last** sample; reverse a leave before and after).

    Args:
        prior_positions: (P, 3) [m] τ_prior's path; prior_quaternions: (P, 4) its orientations.
        positions: (N, 3) [m] the new path.
        blend_fraction: [-] share of the new path's arc length, before the contact, over which the
            transferred orientation is slerped into the prior's (1 at the contact).
        smooth: [m] arc-length smoothing of the tangents.

    Returns:
        (N, 4) unit quaternions, sign-continuous; the last equals τ_prior's last orientation.
    """
    pp = np.asarray(prior_positions, dtype=np.float64)
    pq = np.asarray(prior_quaternions, dtype=np.float64)
    p = np.asarray(positions, dtype=np.float64)
    if pp.ndim != 2 or pp.shape[1] != 3 or pq.shape != (pp.shape[0], 4) or pp.shape[0] < 2:
        raise PlanningError(
            f"prior must be (P, 3) positions and (P, 4) quaternions, got {pp.shape}, {pq.shape}"
        )
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 1:
        raise PlanningError(f"positions must be (N, 3), got {p.shape}")
    if not (np.isfinite(pp).all() and np.isfinite(pq).all() and np.isfinite(p).all()):
        raise PlanningError("orientation transfer got NaN or infinite input")
    if not 0.0 <= blend_fraction <= 1.0:
        raise PlanningError(f"blend_fraction={blend_fraction} must be in [0, 1]")
    arc_p, arc_n = _arc(pp), _arc(p)
    # The prior's orientation at each normalised arc length (duplicated arc values dropped).
    # The last sample of each run of repeated positions is kept (the contact orientation survives).
    keep = np.concatenate([np.diff(arc_p) > 1e-9, [True]])
    if keep.sum() >= 2:
        a = arc_p[keep]
        u_p = (a - a[0]) / (a[-1] - a[0])
        prior_rot = Rotation.from_quat(pq[keep])
    else:
        u_p = np.array([0.0, 1.0])
        prior_rot = Rotation.from_quat(pq[[0, -1]])
    u_n = arc_n / arc_n[-1] if arc_n[-1] > 1e-9 else np.ones(p.shape[0])
    q_prior = Slerp(u_p, prior_rot)(np.clip(u_n, 0.0, 1.0))
    t_p, t_n = path_tangents(pp, smooth), path_tangents(p, smooth)
    if np.isnan(t_p).any() or np.isnan(t_n).any():
        out = q_prior  # a degenerate path has no tangent: keep the prior's orientation
    else:
        tp_at = np.stack([np.interp(u_n, arc_p / arc_p[-1], t_p[:, c]) for c in range(3)], axis=1)
        tp_at /= np.linalg.norm(tp_at, axis=1, keepdims=True)
        out = rotation_between(tp_at, t_n) * q_prior
        if blend_fraction > 0.0:
            w = _end_weight(u_n, blend_fraction)
            rel = (out.inv() * q_prior).as_rotvec()
            out = out * Rotation.from_rotvec(rel * w[:, None])
    quat = np.asarray(out.as_quat(), dtype=np.float64)
    quat = _continuous(quat)
    end = pq[-1] / np.linalg.norm(pq[-1])
    if float(quat[-1] @ end) < 0.0:
        quat = -quat
    return quat


def blend_start(quat: F64, q0: F64, fraction: float) -> F64:
    """Slerp the first ``fraction`` of the samples from ``q0`` (4,) into ``quat`` (T, 4)."""
    n = quat.shape[0]
    u = np.linspace(0.0, 1.0, n)
    x = np.clip(u / max(fraction, 1e-9), 0.0, 1.0)
    w = 1.0 - x * x * (3.0 - 2.0 * x)
    target = Rotation.from_quat(quat)
    rel = (target.inv() * Rotation.from_quat(np.tile(q0, (n, 1)))).as_rotvec()
    out = (target * Rotation.from_rotvec(rel * w[:, None])).as_quat()
    for i in range(1, n):
        if float(out[i] @ out[i - 1]) < 0.0:
            out[i] = -out[i]
    return np.asarray(out, dtype=np.float64)


def face_approach(quat: F64, positions: F64, axis: ArrayLike, max_angle: float, fraction: float) -> F64:
    """The orientations ``quat`` (N, 4) [x y z w] of a path ``positions`` (N, 3) [m] (approach order, the
    contact last) turned so that the contact's wrist x axis lies within ``max_angle`` [rad] of
    ``-axis`` (3,) (the hand moves in against the approach axis): when it is farther off, the minimal
    world-frame rotation onto ``-axis`` is eased in over the last ``fraction`` of the arc length (full at
    the contact). Within ``max_angle`` the orientations are returned unchanged."""
    q = np.asarray(quat, dtype=np.float64)
    want = -np.asarray(axis, dtype=np.float64).reshape(3)
    want = want / max(float(np.linalg.norm(want)), 1e-12)
    wrist_x = Rotation.from_quat(q[-1]).apply([1.0, 0.0, 0.0])
    if float(np.arccos(np.clip(wrist_x @ want, -1.0, 1.0))) <= max_angle:
        return q
    turn = rotation_between(wrist_x[None], want[None])[0].as_rotvec()
    arc = _arc(np.asarray(positions, dtype=np.float64))
    u = arc / arc[-1] if arc[-1] > 1e-9 else np.ones(q.shape[0])
    weight = _end_weight(u, fraction)
    out = (Rotation.from_rotvec(weight[:, None] * turn[None]) * Rotation.from_quat(q)).as_quat()
    return _continuous(np.asarray(out, dtype=np.float64))
