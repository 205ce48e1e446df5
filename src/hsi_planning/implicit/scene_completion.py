"""Completion of the obstacles a fused cloud sees only in part, from the labels' semantic classes.

Two cameras at head height see a shelf board level with them edge-on: its top is sampled a few points per
10 cm², leaving holes a 4 cm hand sphere passes through. Objects packed in a drawer show only their tops:
their hidden sides reach down to the support. Both are filled in with points at ``spacing``:

- **boards** (classes in :data:`BOARD_CLASSES`): solid slabs spanning their furniture; the horizontal
  convex hull of the board's points and of its parent's (``shelf1`` for ``shelf1/board3``: side panels and
  back bound the board) is filled from its highest height down to its lowest one, at least ``PANEL``
  below it (every ``spacing``).
- **panels** (every other furniture label but the floor): the cameras see a panel from above, not its
  underside; the observed points are repeated ``PANEL`` lower (a hand under a drawer unit's top must
  keep its distance from the underside).
- **round objects** (bottle, can, mug, ...): the cameras see their near side; an upright cylinder fitted to
  the lower half of the visible points (radius within the class's range) is filled over the visible
  height, which adds the far side.
- **objects** (object classes, except the ``exclude`` labels such as the target): under their visible
  bottom, down to the support surface found there
  (:func:`~hsi_planning.implicit.completion.support_height`), the hull of the visible points and of the
  class's widest footprint (a disk of the class's largest width about their centre: a bottle seen by its
  neck is wider below) is filled.

Added points carry the label they complete, so every consumer (fields, clearance, the held object's
support) treats them like observed ones. Clouds without ``label_classes`` are returned unchanged.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError, cKDTree

from hsi_planning.implicit.completion import CLASS_SCALE, SUPPORT_DROP, furniture_mask, support_height
from hsi_planning.scene.objects import DEFAULTS
from hsi_planning.scene.spec import OBJECT_KINDS

__all__ = ["BOARD_CLASSES", "complete_cloud"]

F64 = NDArray[np.float64]
#: Semantic classes of furniture parts that are solid horizontal slabs.
BOARD_CLASSES: tuple[str, ...] = ("shelf_board",)
#: [m] a board thicker than this is not filled (not a slab: a mislabelled or merged part).
_MAX_BOARD_THICKNESS = 0.06
#: [m] thickness of furniture panels: a surface seen from above is the top of a solid this thick.
PANEL = 0.018
#: Furniture classes without thickness below their observed surface.
_SURFACE_ONLY: tuple[str, ...] = ("floor",)
#: Object classes whose default size is (diameter, height): upright cylinders.
ROUND_KINDS: tuple[str, ...] = tuple(k for k, d in DEFAULTS.items() if len(d.size) == 2)
#: [m] points farther than this off a fitted circle are not part of the round body (a mug's handle).
_ROUND_OUTLIER = 0.006
#: [-] points a label needs before it is completed.
_MIN_POINTS = 8
#: [m] furniture this far around an object is searched for its support (and the normals' neighbours).
_SEARCH = 0.15


def fit_round(own: F64, width: float) -> tuple[F64, float]:
    """(centre (2,) [m], radius [m]) of the upright cylinder through the lower half of ``own`` (N, 3) [m]
    (a bottle's body, not its neck): algebraic circle fit of the horizontal coordinates, refitted without
    the points more than :data:`_ROUND_OUTLIER` off the circle (a mug's handle) when most stay, the radius
    clipped to the class's range (``width`` [m] × ``CLASS_SCALE`` / 2) and the centre kept within that
    radius of the visible points' centre (a poor fit of a short arc)."""
    z = own[:, 2]
    low = own[z <= z.min() + 0.5 * (z.max() - z.min())][:, :2]
    mid = low.mean(axis=0)
    r_lo, r_hi = 0.5 * width * CLASS_SCALE[0], 0.5 * width * CLASS_SCALE[1]
    fit = _circle(low)
    if fit is None:
        return mid, r_lo
    off_circle = np.abs(np.linalg.norm(low - fit[0], axis=1) - fit[1])
    body = off_circle <= _ROUND_OUTLIER
    if 0.6 * len(low) <= body.sum() < len(low):
        fit = _circle(low[body]) or fit
    centre, radius = fit[0], float(np.clip(fit[1], r_lo, r_hi))
    off = centre - mid
    if not np.isfinite(off).all():
        return mid, radius
    dist = float(np.linalg.norm(off))
    if dist > radius:
        centre = mid + off * (radius / dist)
    return centre, radius


def round_bounds(
    own: F64, kind: str | None, box: tuple[F64, F64], obstacle_points: F64 | None = None
) -> tuple[F64, F64]:
    """(lo (3,), hi (3,)) [m] ``box`` grown horizontally to the upright cylinder :func:`fit_round` fits
    through ``own`` (N, 3) [m], the visible points of a round object of class ``kind`` (its hidden side:
    the cameras see a packed mug's rim or a bottle's front only); other classes' boxes as they are.
    A short arc does not tell the side its centre lies on: of the fitted centre and its mirror image
    through the visible points' centre, the one whose cylinder holds fewer of ``obstacle_points``
    (M, 3) [m] (over the box's height) is taken."""
    if kind not in ROUND_KINDS or own.shape[0] < 3:
        return box
    centre, radius = fit_round(own, DEFAULTS[kind].size[0])
    if obstacle_points is not None and len(obstacle_points):
        mid = own[:, :2].mean(axis=0)
        op = np.asarray(obstacle_points, dtype=np.float64).reshape(-1, 3)
        op = op[(op[:, 2] >= box[0][2]) & (op[:, 2] <= box[1][2]), :2]

        def inside(c: F64) -> int:
            return int((np.linalg.norm(op - c, axis=1) < radius).sum())

        mirror = 2.0 * mid - centre
        if inside(mirror) < inside(centre):
            centre = mirror
    lo, hi = box[0].copy(), box[1].copy()
    lo[:2] = np.minimum(lo[:2], centre - radius)
    hi[:2] = np.maximum(hi[:2], centre + radius)
    return lo, hi


def _circle(xy: F64) -> tuple[F64, float] | None:
    """Algebraic (Kasa) circle fit of ``xy`` (N, 2) [m]: centre (2,), radius [m]; ``None`` if degenerate."""
    if len(xy) < 3:
        return None
    a = np.column_stack([xy, np.ones(len(xy))])
    b = -(xy**2).sum(axis=1)
    try:
        (d, e, f), *_ = np.linalg.lstsq(a, b, rcond=None)
    except np.linalg.LinAlgError:
        return None
    centre = np.array([-0.5 * d, -0.5 * e])
    r2 = float(centre @ centre - f)
    if not (np.isfinite(centre).all() and r2 > 0.0):
        return None
    return centre, float(np.sqrt(r2))


def _disk(centre: F64, radius: float, spacing: float) -> F64:
    """(K, 2) [m] points on the circle of ``radius`` [m] about ``centre`` (2,), every ~``spacing``."""
    n = max(8, int(np.ceil(2.0 * np.pi * radius / spacing)))
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.column_stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)])


def _hull_fill(xy: F64, spacing: float, box: tuple[F64, F64] | None = None) -> F64:
    """(K, 2) [m] grid points every ``spacing`` inside the convex hull of ``xy`` (N, 2); empty when the
    points are degenerate (collinear or too few). ``box``: (lo (≥2,), hi (≥2,)) [m]; only the grid
    points inside it (the same ones, found faster)."""
    if xy.shape[0] < 3:
        return np.zeros((0, 2))
    try:
        hull = ConvexHull(xy)
    except QhullError:
        return np.zeros((0, 2))
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    axes = [np.arange(lo[i], hi[i] + 0.5 * spacing, spacing) for i in range(2)]
    if box is not None:
        axes = [a[(a >= box[0][i]) & (a <= box[1][i])] for i, a in enumerate(axes)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    inside = (grid @ hull.equations[:, :2].T + hull.equations[:, 2] <= 1e-9).all(axis=1)
    return np.asarray(grid[inside], dtype=np.float64)


def _levels(z_lo: float, z_hi: float, spacing: float, box: tuple[F64, F64] | None = None) -> F64:
    """(L,) [m] heights from ``z_lo`` to ``z_hi`` every ≤ ``spacing`` (both ends included); with ``box``
    (lo (3,), hi (3,)) [m] only those within its height range."""
    n = max(1, int(np.ceil((z_hi - z_lo) / spacing)))
    z = np.linspace(z_lo, z_hi, n + 1)
    return z if box is None else z[(z >= box[0][2]) & (z <= box[1][2])]


def _slab(xy: F64, levels: F64) -> F64:
    """(K·L, 3) [m] the 2-D points ``xy`` repeated at every height of ``levels``."""
    if xy.shape[0] == 0:
        return np.zeros((0, 3))
    z = np.repeat(levels, xy.shape[0])
    return np.column_stack([np.tile(xy, (levels.shape[0], 1)), z])


def _parent_points(pts: F64, lab: NDArray[np.int64], names: dict[int, str] | None, label_id: int) -> F64:
    """(M, 3) [m] points of the furniture ``label_id`` is a part of (``a`` for ``a/b``); empty if none."""
    name = (names or {}).get(label_id, "")
    if "/" not in name:
        return np.zeros((0, 3))
    parent = name.split("/", 1)[0]
    ids = [k for k, v in (names or {}).items() if v == parent]
    return pts[np.isin(lab, ids)]


def _furniture_near(furniture: F64, by_x: NDArray[np.intp], xs: F64, lo: F64, hi: F64) -> F64:
    """(M, 3) [m] the ``furniture`` points (in their order) within ``_SEARCH`` of the box ``lo``..``hi``
    (down to ``SUPPORT_DROP`` further below it); ``by_x`` sorts ``furniture`` by x, ``xs`` = the sorted x."""
    a = int(np.searchsorted(xs, lo[0] - _SEARCH, side="left"))
    b = int(np.searchsorted(xs, hi[0] + _SEARCH, side="right"))
    f = furniture[np.sort(by_x[a:b])]
    near = (
        (f[:, 1] >= lo[1] - _SEARCH)
        & (f[:, 1] <= hi[1] + _SEARCH)
        & (f[:, 2] >= lo[2] - _SEARCH - SUPPORT_DROP)
        & (f[:, 2] <= hi[2] + _SEARCH)
    )
    return np.asarray(f[near], dtype=np.float64)


def complete_cloud(
    points: ArrayLike,
    labels: ArrayLike,
    label_classes: dict[int, str] | None,
    exclude: ArrayLike = (),
    *,
    spacing: float = 0.0125,
    label_names: dict[int, str] | None = None,
    keep_clear: float = 0.02,
    region: tuple[ArrayLike, ArrayLike] | None = None,
    clip: tuple[ArrayLike, ArrayLike] | None = None,
) -> tuple[F64, NDArray[np.int64]]:
    """The cloud with the hidden parts of boards and objects filled in (see the module doc).

    Args:
        points: (N, 3) [m] world-frame points; labels: (N,) label ids.
        label_classes: label id → semantic class (None: nothing is completed).
        exclude: label ids left as observed (the target and the objects held with it).
        spacing: [m] distance between added points.
        label_names: label id → name (finds a board's furniture; without it a board spans its own points).
        keep_clear: [m] added points this close to an ``exclude`` point are dropped (a neighbour's guessed
            width does not reach into the target the cameras see).
        region: (lo (3,), hi (3,)) [m] box; labels with no point in it are not completed (speed).
        clip: (lo (3,), hi (3,)) [m] box; no point outside it is added (speed, for a caller that crops
            the cloud to that box: the points it keeps are the same).

    Returns:
        (points (N + K, 3) [m], labels (N + K,)): the input followed by the added points.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lab = np.asarray(labels, dtype=np.int64).reshape(-1)
    if not label_classes or pts.shape[0] == 0:
        return pts.copy(), lab.copy()
    skip = set(np.asarray(exclude, dtype=np.int64).reshape(-1).tolist())
    furniture = pts[furniture_mask(lab, label_classes, np.asarray(sorted(skip), dtype=np.int64))]
    r_lo, r_hi = (
        np.asarray(v, dtype=np.float64) for v in (region or (-np.inf * np.ones(3), np.inf * np.ones(3)))
    )
    box = None if clip is None else (np.asarray(clip[0], np.float64), np.asarray(clip[1], np.float64))
    by_x = np.argsort(furniture[:, 0], kind="stable")  # furniture near an object, found by bisection
    xs = furniture[by_x, 0]
    added: list[F64] = []
    added_labels: list[NDArray[np.int64]] = []
    order = np.argsort(lab, kind="stable")  # each label's points in cloud order, found by bisection
    sorted_lab = lab[order]
    for label_id, cls in label_classes.items():
        if label_id in skip:
            continue
        a, b = np.searchsorted(sorted_lab, [label_id, label_id + 1])
        own = pts[order[a:b]]
        if own.shape[0] < _MIN_POINTS:
            continue
        if region is not None and not ((own >= r_lo) & (own <= r_hi)).all(axis=1).any():
            continue
        lo, hi = own.min(axis=0), own.max(axis=0)
        if cls in BOARD_CLASSES and hi[2] - lo[2] <= _MAX_BOARD_THICKNESS:
            xy = np.vstack([own[:, :2], _parent_points(pts, lab, label_names, label_id)[:, :2]])
            fill = _slab(
                _hull_fill(xy, spacing, box), _levels(min(lo[2], hi[2] - PANEL), hi[2], spacing, box)
            )
        elif cls in OBJECT_KINDS:
            z = support_height(own, _furniture_near(furniture, by_x, xs, lo, hi))
            parts = []
            if cls in ROUND_KINDS:  # the far side the cameras miss: a fitted upright cylinder
                centre, radius = fit_round(own, DEFAULTS[cls].size[0])
                parts.append(
                    _slab(
                        _hull_fill(_disk(centre, radius, spacing), spacing, box),
                        _levels(lo[2], hi[2], spacing, box),
                    )
                )
            if z is not None and lo[2] - z >= 0.5 * spacing:
                centre = 0.5 * (lo[:2] + hi[:2])
                xy = np.vstack(
                    [own[:, :2], _disk(centre, 0.5 * CLASS_SCALE[1] * DEFAULTS[cls].size[0], spacing)]
                )
                parts.append(_slab(_hull_fill(xy, spacing, box), _levels(z, lo[2], spacing, box)))
            if not parts:
                continue
            fill = np.vstack(parts)
        elif cls not in _SURFACE_ONLY:  # a panel seen from above has its underside PANEL lower
            inside = ((own >= r_lo) & (own <= r_hi)).all(axis=1)
            fill = own[inside] - np.array([0.0, 0.0, PANEL])
        else:
            continue
        if box is not None:
            fill = fill[((fill >= box[0]) & (fill <= box[1])).all(axis=1)]
        if fill.shape[0]:
            added.append(fill)
            added_labels.append(np.full(fill.shape[0], label_id, dtype=np.int64))
    if not added:
        return pts.copy(), lab.copy()
    fill, fill_labels = np.vstack(added), np.concatenate(added_labels)
    kept = pts[np.isin(lab, np.asarray(sorted(skip), dtype=np.int64))]
    if kept.shape[0] and keep_clear > 0.0:  # a guessed hidden part does not overlap what is seen
        far = cKDTree(kept).query(fill, distance_upper_bound=keep_clear)[0] > keep_clear
        fill, fill_labels = fill[far], fill_labels[far]
    return np.vstack([pts, fill]), np.concatenate([lab, fill_labels])
