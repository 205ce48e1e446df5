"""The IK's collision candidates: the robot spheres that may be near the scene and the sphere pairs that may
be near each other at one step, measured exactly; and a cache of that choice across steps.

Choosing the candidates (:func:`_cull`: link bounding spheres, the scene's lower-bound grid, the dense
block of pair-centre distances) costs more than measuring the few it leaves. Distances are 1-Lipschitz, so
the choice made with ``slack`` [m] more reach holds until some sphere centre has moved ``slack / 2`` (a
pair's gap closes by at most twice that): :class:`CandidateCache` reuses it until then. The candidates
measured are a superset of the uncached ones and the result is the same, only cheaper (a few IK steps
and frames share one choice). The cache also keeps the exact scene distances measured at the miss: a
sphere that cannot have come within reach since (its distance then minus the way it moved) is not
measured again.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.distance import cdist

from hsi_planning.errors import ConfigError

if TYPE_CHECKING:
    from hsi_retarget.collision import SceneLayer, SphereSet
    from hsi_retarget.culling import LinkBounds

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
#: [m] the pre-filter of sphere pairs keeps this much more than the activation (its distances round
#: differently from the exact ones computed after it)
FILTER_TOLERANCE = 1e-9


@dataclass(frozen=True)
class _Picks:
    """Spheres to measure against each scene layer (ascending indices) and pairs to measure (indices into
    the pairs, ascending; ``None``: not culled)."""

    scene: tuple[I64, ...]
    pairs: I64 | None


class CandidateCache:
    """The candidates chosen at one configuration, reused while every sphere centre stays within
    ``slack / 2`` [m] of where it was then (see the module docstring). Not thread-safe."""

    def __init__(self, slack: float = 0.05) -> None:
        if not slack > 0.0:
            raise ConfigError(f"CandidateCache.slack must be > 0 m, got {slack}")
        self.slack = float(slack)  #: [m] extra reach of the cached choice
        self._key: tuple[object, ...] = ()
        self._centers = np.zeros((0, 3))
        self._activation = -np.inf
        self._picks: _Picks | None = None
        #: exact distances [m] of each layer's picked spheres at ``_centers`` (measured once, at the miss)
        self._dist: list[F64 | None] = []
        self.hits = 0  #: [-] lookups answered from the cache
        self.misses = 0  #: [-] lookups that chose anew
        self.skipped = 0  #: [-] picked spheres left unmeasured: too far by their distance at the miss

    def _lookup(self, key: tuple[object, ...], centers: F64, activation: float) -> _Picks | None:
        if (
            self._picks is None
            or activation > self._activation
            or len(key) != len(self._key)
            or not all(_same(a, b) for a, b in zip(key, self._key, strict=True))
            or centers.shape != self._centers.shape
        ):
            return None
        moved = centers - self._centers
        if 4.0 * float(np.einsum("ij,ij->i", moved, moved).max(initial=0.0)) > self.slack**2:
            return None
        return self._picks

    def _store(self, key: tuple[object, ...], centers: F64, activation: float, picks: _Picks) -> None:
        self._key, self._centers, self._activation, self._picks = key, centers.copy(), activation, picks
        self._dist = [None] * len(picks.scene)


def _same(a: object, b: object) -> bool:
    """Key entries match: the very object, or equal numbers."""
    return a is b or (isinstance(a, float) and a == b)


def find_candidates(
    spheres: SphereSet,
    centers: F64,
    pairs: I64,
    layers: list[SceneLayer],
    grounded: NDArray[np.bool_],
    *,
    margins: tuple[float, float, float],
    activation: float,
    bounds: LinkBounds | None,
    links: F64 | None,
    cache: CandidateCache | None = None,
    extra_margin: F64 | None = None,
) -> tuple[I64, I64, F64, F64]:
    """Sphere index pairs (second -1: a scene layer), gaps [m] and unit directions (first away from second)
    of every candidate closer than ``activation`` [m] beyond its margin (``margins`` = scene, finger tip,
    self [m]): spheres (world ``centers`` (S, 3) [m]) against each of ``layers`` in turn (``grounded`` (S,):
    measured with the ground meshes), then the ``pairs`` (P, 2). With ``bounds`` and ``links`` (their world
    centres (F, 3) at the same configuration) and a finite ``activation`` the candidates are culled first
    (from ``cache`` when it still holds). ``extra_margin`` (S,) [m], >= 0: more scene margin per sphere."""
    scene_margin, tip_margin, self_margin = margins
    base = spheres.radii + np.where(spheres.tips, tip_margin, scene_margin)
    allowance, need = base, activation  # culled for the largest extra margin as more reach: a superset
    if extra_margin is not None:
        allowance = base + extra_margin
        need += float(extra_margin.max(initial=0.0))
    picks: _Picks | None = None
    hit = False  # the picks come from the cache (their exact distances there bound the ones now)
    if bounds is not None and links is not None and np.isfinite(activation):
        spare = 0.0 if cache is None else cache.slack
        key: tuple[object, ...] = (pairs, *(x for layer in layers for x in layer), *map(float, margins))
        picks = None if cache is None else cache._lookup(key, centers, need)
        if picks is None:
            within = (margins, need + spare)
            picks = _cull(
                centers,
                pairs,
                layers,
                grounded=grounded,
                allowance=base,
                within=within,
                bounds=bounds,
                links=links,
            )
            if cache is not None:
                cache._store(key, centers, need, picks)
                cache.misses += 1
        elif cache is not None:
            cache.hits += 1
            hit = True
    first, second, slacks, directions = [], [], [], []
    for i, (layer, mask) in enumerate(layers):
        check = np.flatnonzero(mask) if picks is None else picks.scene[i]
        known = cache._dist[i] if hit and cache is not None else None
        if known is not None and cache is not None:  # 1-Lipschitz: at least the distance then - the way since
            moved = centers[check] - cache._centers[check]
            bound = known - np.sqrt(np.add.reduce(moved * moved, axis=1)) - allowance[check]
            cache.skipped += int(np.count_nonzero(bound >= activation))
            check = check[bound < activation]
        dist, normal = layer.query(centers[check], grounded[check])
        if cache is not None and picks is not None and not hit:
            cache._dist[i] = dist
        slack = dist - allowance[check]
        near = np.flatnonzero(slack < activation)
        first.append(check[near])
        second.append(np.full(near.shape, -1))
        slacks.append(slack[near])
        directions.append(normal[near])
    if pairs.shape[0]:
        a, b = pairs[:, 0], pairs[:, 1]
        if picks is not None and picks.pairs is not None:
            a, b = a[picks.pairs], b[picks.pairs]
        elif np.isfinite(activation):  # every centre distance at once (C), then the pairs that may be near
            gap = cdist(centers, centers)[a, b] - spheres.radii[a] - spheres.radii[b] - self_margin
            maybe = gap < activation + FILTER_TOLERANCE
            a, b = a[maybe], b[maybe]
        delta = centers[a] - centers[b]
        norm = np.sqrt(np.add.reduce(delta * delta, axis=1))  # np.linalg.norm(axis=1) without its wrapper
        slack = norm - spheres.radii[a] - spheres.radii[b] - self_margin
        near = np.flatnonzero(slack < activation)
        first.append(a[near])
        second.append(b[near])
        slacks.append(slack[near])
        directions.append(delta[near] / np.maximum(norm[near], 1e-9)[:, None])
    if not slacks:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3))
    return (
        np.concatenate(first).astype(np.int64),
        np.concatenate(second).astype(np.int64),
        np.concatenate(slacks),
        np.concatenate(directions),
    )


def _cull(
    centers: F64,
    pairs: I64,
    layers: list[SceneLayer],
    *,
    grounded: NDArray[np.bool_],
    allowance: F64,
    within: tuple[tuple[float, float, float], float],
    bounds: LinkBounds,
    links: F64,
) -> _Picks:
    """The spheres and pairs that may be closer than ``reach`` [m] beyond their margins (``within`` =
    (scene, tip, self margins [m]), reach): the links' bounding spheres, then each sphere's lower bound
    (scene), the pairs' centre distances (self)."""
    (scene_margin, tip_margin, self_margin), reach = within
    # a link is kept by the largest margin of its spheres (a wrist sphere's scene margin, not a tip's)
    link_reach = reach + max(tip_margin, scene_margin)
    scene = []
    for layer, mask in layers:
        check = np.flatnonzero(mask & bounds.scene_candidates(layer, links, link_reach))
        bound = layer.lower_bound(centers[check], grounded[check])
        scene.append(check[bound - allowance[check] < reach])
    culled = None
    if pairs.shape[0] and bounds.pairs is pairs:
        culled = bounds.near_pairs(centers, reach + self_margin + FILTER_TOLERANCE)
    return _Picks(tuple(scene), culled)
