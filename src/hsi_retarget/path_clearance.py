"""Clearances of many robot configurations at once (a whole joint path): the same numbers as
:func:`~hsi_retarget.collision.min_gap` at each configuration, with the culling done for all of them
together.

A path check (:func:`~hsi_retarget.smoothing.keep_clearance`) asks, for every frame, whether the robot cuts
into its margins. Frame by frame that is a forward kinematics pass, a culling of the candidates and a few
small distance queries each, most of the time Python overhead. Here the link bounding spheres of all frames
are bounded against the scene's lower-bound grid in one go, the spheres of near links in one more, and the
spheres left are measured exactly in one distance query; the self-collision pairs are culled per frame by
:meth:`~hsi_retarget.culling.LinkBounds.near_pairs` (one dense block of centre distances) and measured as
:func:`~hsi_retarget.candidates.find_candidates` measures them. Distances are 1-Lipschitz and every bound is
a lower bound, so nothing closer than ``reach`` is culled: the result is exactly the per-frame one.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import RetargetError
from hsi_retarget.candidates import FILTER_TOLERANCE
from hsi_retarget.collision import SceneLayer, scene_layers

if TYPE_CHECKING:
    from hsi_retarget.collision import SphereSet
    from hsi_retarget.culling import LinkBounds
    from hsi_retarget.scene_distance import SceneDistance

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def path_gaps(
    spheres: SphereSet,
    centers: F64,
    links: F64,
    pairs: I64,
    scene: SceneDistance | None,
    *,
    margins: tuple[float, float, float],
    reach: float,
    bounds: LinkBounds,
    extra: SceneLayer | None = None,
) -> F64:
    """(N,) [m] per configuration, the smallest sphere clearance minus its margin (``margins`` = scene,
    finger tip, self [m]) against ``scene`` and the ``extra`` layer (as
    :func:`~hsi_retarget.collision.min_gap`) and over ``pairs`` (P, 2), or ``inf`` where nothing is closer
    than ``reach`` [m] beyond its margin. ``centers`` (N, S, 3) [m]: world sphere centres of each
    configuration, ``links`` (N, F, 3) [m]: the link bounding centres of ``bounds`` there
    (:meth:`~hsi_retarget.culling.LinkBounds.world`).

    Raises:
        RetargetError: ``centers`` and ``links`` do not match the spheres and the bounds.
    """
    n, s_count = centers.shape[0], spheres.radii.shape[0]
    if centers.shape != (n, s_count, 3) or links.shape != (n, bounds.radii.shape[0], 3):
        raise RetargetError(
            f"path_gaps: centers (N, {s_count}, 3) and links (N, {bounds.radii.shape[0]}, 3) expected, "
            f"got {centers.shape} and {links.shape}"
        )
    if not math.isfinite(reach):
        raise RetargetError(f"path_gaps: reach must be finite [m], got {reach}")
    scene_margin, tip_margin, self_margin = margins
    out = np.full(n, np.inf)
    allowance = spheres.radii + np.where(spheres.tips, tip_margin, scene_margin)
    link_reach = reach + max(tip_margin, scene_margin)
    for layer, mask in scene_layers(spheres, scene, extra):
        link_bound = layer.lower_bound(links.reshape(-1, 3)).reshape(links.shape[:2]) - bounds.radii[None, :]
        frame, sphere = np.nonzero((link_bound < link_reach)[:, bounds.owner] & mask[None, :])
        pts = centers[frame, sphere]
        grounded = spheres.grounded[sphere]
        maybe = layer.lower_bound(pts, grounded) - allowance[sphere] < reach
        frame, sphere, pts, grounded = frame[maybe], sphere[maybe], pts[maybe], grounded[maybe]
        slack = layer.query(pts, grounded)[0] - allowance[sphere]
        near = slack < reach
        np.minimum.at(out, frame[near], slack[near])
    if pairs.shape[0]:
        culled = bounds.pairs is pairs
        for i in range(n):
            c = centers[i]
            if culled:
                a, b = pairs[bounds.near_pairs(c, reach + self_margin + FILTER_TOLERANCE)].T
            else:
                a, b = pairs[:, 0], pairs[:, 1]
            if a.shape[0] == 0:
                continue
            norm = np.linalg.norm(c[a] - c[b], axis=1)
            slack = norm - spheres.radii[a] - spheres.radii[b] - self_margin
            near = slack < reach
            if near.any():
                out[i] = min(out[i], float(slack[near].min()))
    return out
