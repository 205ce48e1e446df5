"""Completion of a partly seen target from the cloud: where its hidden bottom is.

The cameras often see only the top of an object packed in a drawer (its neighbours hide the sides) or
only the front of one on a shelf. Objects stand on a support, so the held object's extent reaches down
to the **support surface** under it: the highest upward-facing horizontal surface of the furniture
(labels whose class is not an object kind) below the visible part, near its footprint. Normals come
from a local principal-component fit of the furniture points.

A board in front of the cameras can also hide an object's **top** (a bottle in a cabinet seen from head
height). When the object's class is known and its visible height is below what that class can be
(:func:`class_height`) and its top face was not seen (:func:`top_seen`), the box is extended up to
the class's largest height, but not into the obstacle observed above it.

Used for the held object's box (what must stay clear while carrying), not for the contact, which is
placed from the visible points (:func:`~hsi_planning.implicit.prior.contact_point`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from hsi_planning.scene.objects import DEFAULTS
from hsi_planning.scene.spec import OBJECT_KINDS

F64 = NDArray[np.float64]

#: [m] how far around the visible footprint the support surface is searched (horizontally).
SUPPORT_SEARCH = 0.10
#: [m] the support lies at most this far below the visible bottom (taller objects are not modelled).
SUPPORT_DROP = 0.30
#: [m] a support must lie at least this far below the visible bottom (else the bottom was seen).
SUPPORT_GAP = 0.01
#: [m] furniture this close under the visible bottom (and its footprint) means the bottom was seen.
SEEN_BOTTOM = 0.02
#: [-] scale range of generated objects around their class's default size (layout generator: 0.8–1.25).
CLASS_SCALE = (0.8, 1.25)
#: [m] gap kept between an extended top and the obstacle observed above it (room to lift it off).
CEILING_GAP = 0.06
#: [m] points this close below an object's highest point belong to its top face; [-] share of them on a
#: horizontal surface when the top face was seen.
TOP_BAND, TOP_SHARE = 0.01, 0.5
#: [-] |n_z| of a horizontal surface's normal.
_HORIZONTAL = 0.9
#: [-] neighbours of the normal fit; [-] horizontal points needed in the support layer.
_NEIGHBOURS, _MIN_LAYER = 10, 3


def furniture_mask(
    labels: ArrayLike, label_classes: dict[int, str] | None, exclude: ArrayLike
) -> NDArray[np.bool_]:
    """(N,) points of furniture: labels not in ``exclude`` whose class is not an object kind (every
    non-excluded label when the cloud has no classes)."""
    lab = np.asarray(labels).reshape(-1)
    ok = ~np.isin(lab, np.asarray(exclude))
    if label_classes:
        objects = [k for k, c in label_classes.items() if c in OBJECT_KINDS]
        ok &= ~np.isin(lab, objects)
    return np.asarray(ok)


def _normals_z(points: F64, tree_points: F64) -> F64:
    """(M,) |n_z| of the local plane fitted through each of ``points`` and its nearest ``tree_points``."""
    k = min(_NEIGHBOURS, tree_points.shape[0])
    _, idx = cKDTree(tree_points).query(points, k=k)
    nb = tree_points[np.asarray(idx).reshape(points.shape[0], k)]
    centred = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("mki,mkj->mij", centred, centred)
    _, vec = np.linalg.eigh(cov)
    return np.asarray(np.abs(vec[:, 2, 0]), dtype=np.float64)


def bottom_seen(target_points: ArrayLike, furniture_points: ArrayLike) -> bool:
    """Whether the target (N, 3) [m] was seen standing on furniture (M, 3) [m]: furniture within
    ``SEEN_BOTTOM`` of its visible bottom, under its footprint."""
    tp = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    fp = np.asarray(furniture_points, dtype=np.float64).reshape(-1, 3)
    if tp.shape[0] == 0 or fp.shape[0] == 0:
        return False
    lo, hi = tp.min(axis=0), tp.max(axis=0)
    under = (
        (fp[:, :2] >= lo[:2] - SEEN_BOTTOM).all(axis=1)
        & (fp[:, :2] <= hi[:2] + SEEN_BOTTOM).all(axis=1)
        & (np.abs(fp[:, 2] - lo[2]) <= SEEN_BOTTOM)
    )
    return bool(under.any())


def support_height(target_points: ArrayLike, furniture_points: ArrayLike) -> float | None:
    """[m] height of the support surface under a target seen as ``target_points`` (N, 3) [m], from the
    ``furniture_points`` (M, 3) [m]; None when furniture lies right under the visible bottom (it was
    seen standing on it) or no horizontal surface lies in the searched band (between
    ``SUPPORT_GAP`` and ``SUPPORT_DROP`` below the visible bottom, within ``SUPPORT_SEARCH`` of the
    footprint) — then the visible bottom is the best estimate."""
    tp = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    fp = np.asarray(furniture_points, dtype=np.float64).reshape(-1, 3)
    if tp.shape[0] == 0 or fp.shape[0] < _NEIGHBOURS:
        return None
    lo, hi = tp.min(axis=0), tp.max(axis=0)
    if bottom_seen(tp, fp):  # the target stands on observed furniture
        return None
    near = (
        (fp[:, :2] >= lo[:2] - SUPPORT_SEARCH).all(axis=1)
        & (fp[:, :2] <= hi[:2] + SUPPORT_SEARCH).all(axis=1)
        & (fp[:, 2] <= lo[2] - SUPPORT_GAP)
        & (fp[:, 2] >= lo[2] - SUPPORT_DROP)
    )
    cand = fp[near]
    if cand.shape[0] < _MIN_LAYER:
        return None
    flat = cand[_normals_z(cand, fp) >= _HORIZONTAL]
    if flat.shape[0] < _MIN_LAYER:
        return None
    z = np.sort(flat[:, 2])[::-1]
    # The highest layer with enough horizontal points (a lone rim point does not make a surface).
    layer = z[_MIN_LAYER - 1 :] >= z[: -(_MIN_LAYER - 1)] - 0.01
    first = int(np.argmax(layer)) if layer.any() else None
    return None if first is None else float(z[first])


def top_seen(target_points: ArrayLike) -> bool:
    """Whether the cameras saw the object's top face: most of its points within ``TOP_BAND`` of the
    highest one lie on a horizontal surface (local normal within ~25° of vertical); a view cut off by an
    occluder ends on the object's side instead."""
    tp = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    if tp.shape[0] < _NEIGHBOURS:
        return False
    band = tp[tp[:, 2] >= tp[:, 2].max() - TOP_BAND]
    return bool(np.mean(_normals_z(band, tp) >= _HORIZONTAL) >= TOP_SHARE)


def class_height(kind: str) -> tuple[float, float]:
    """(smallest, largest) [m] height of an object of class ``kind`` (its default size × ``CLASS_SCALE``)."""
    h = DEFAULTS[kind].size[-1]
    return CLASS_SCALE[0] * h, CLASS_SCALE[1] * h


def completed_bounds(
    target_points: ArrayLike,
    furniture_points: ArrayLike,
    kind: str | None = None,
    obstacle_points: ArrayLike | None = None,
) -> tuple[F64, F64]:
    """(lo (3,), hi (3,)) [m] box of the target: its visible points' box extended down to the support
    surface (:func:`support_height`) when one is found below it. For an object of class ``kind`` that
    looks shorter than the class can be: with its bottom known (support found or seen) and its top not
    seen, up to the class's largest height, below the lowest of the ``obstacle_points`` (M, 3) [m] above
    its footprint (less ``CEILING_GAP``); with its bottom unknown (a deep drawer hides it), down to the
    class's largest height below its top, not below the highest obstacle point under its footprint."""
    tp = np.asarray(target_points, dtype=np.float64).reshape(-1, 3)
    fp = np.asarray(furniture_points, dtype=np.float64).reshape(-1, 3)
    lo, hi = tp.min(axis=0).copy(), tp.max(axis=0).copy()
    z = support_height(tp, fp)
    if z is not None:
        lo[2] = min(lo[2], z)
    if kind not in DEFAULTS:
        return lo, hi
    smallest, largest = class_height(kind)
    if hi[2] - lo[2] >= smallest:
        return lo, hi
    op = (
        np.zeros((0, 3))
        if obstacle_points is None
        else np.asarray(obstacle_points, np.float64).reshape(-1, 3)
    )
    over = (op[:, :2] >= lo[:2]).all(axis=1) & (op[:, :2] <= hi[:2]).all(axis=1)
    if z is not None or bottom_seen(tp, fp):
        if not top_seen(tp):
            top = lo[2] + largest
            above = over & (op[:, 2] > hi[2])
            if above.any():
                top = min(top, float(op[above, 2].min()) - CEILING_GAP)
            hi[2] = max(hi[2], top)
    else:
        bottom = hi[2] - largest
        below = over & (op[:, 2] < lo[2])
        if below.any():
            bottom = max(bottom, float(op[below, 2].max()))
        lo[2] = min(lo[2], bottom)
    return lo, hi


def top_slack(target_points: ArrayLike, bounds: tuple[F64, F64], kind: str | None) -> float:
    """[m] how far above the box ``bounds`` (lo (3,), hi (3,)) [m] the held object's top may still
    reach: 0 when the cameras saw its top face or its class is unknown, else up to its class's largest
    height above the box's bottom (a board in front of the cameras hides a tall bottle's top, and
    :func:`completed_bounds` keeps ``CEILING_GAP`` under what is observed above it)."""
    if kind not in DEFAULTS or top_seen(target_points):
        return 0.0
    lo, hi = bounds
    return float(max(0.0, float(lo[2]) + class_height(kind)[1] - float(hi[2])))
