"""Obstacle distance field from a point cloud, evaluable in NumPy and inside CasADi expressions.

The field is the **truncated Euclidean distance** [m] from the nodes of an axis-aligned grid to the
nearest cloud point, ``min(d(x, points), cap)``, computed with a KD-tree. Points farther than ``cap``
from the grid box cannot change the truncated values, so they are cropped before the query (exact).
Between nodes the field is a **cubic B-spline** through the node values (C², so IPOPT gets exact
smooth gradients and Hessians): the coefficients come from :func:`scipy.ndimage.spline_filter`, and
the same spline is evaluated by :meth:`DistanceGrid.interpolate` (``map_coordinates(order=3)``),
:meth:`DistanceGrid.derivatives` (value, gradient, Hessian) and :meth:`DistanceGrid.casadi_function`
(a CasADi callback on those, :mod:`.field_callback`), which agree to rounding. The spline is valid
one cell in from the grid faces (:attr:`DistanceGrid.lower` .. :attr:`DistanceGrid.upper`).
Alternatives measured: CasADi's ``'bspline'`` interpolant fits the same spline but takes ~20 s on 10⁵
nodes; ``casadi.bspline`` with these coefficients needs 0.3–0.9 s per solver to build its derivatives;
the ``'linear'`` interpolant has piecewise-constant gradients on which IPOPT converges poorly.

The distance is **unsigned**: a cloud only samples surfaces, so the inside of a thick body is not known
to be occupied. The optimizer keeps a sphere outside by constraining the field at closely spaced points
along the path (a sphere cannot cross a sampled surface between two checks without violating one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

from hsi_planning.errors import PlanningError

F64 = NDArray[np.float64]


def _points(points: ArrayLike, what: str) -> F64:
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise PlanningError(f"{what} must have shape (N, 3) [m], got {arr.shape}")
    if not np.isfinite(arr).all():
        raise PlanningError(f"{what} contain NaN or infinite values")
    return arr


@dataclass(frozen=True, eq=False)
class DistanceGrid:
    """Truncated distance [m] to a point set, sampled on an axis-aligned grid.

    Attributes:
        origin: (3,) [m] position of node (0, 0, 0) (the minimum corner).
        resolution: [m] node spacing along every axis.
        values: (nx, ny, nz) [m] ``min(distance to the nearest point, cap)`` at each node, indexed
            ``values[i, j, k]`` with i along x, j along y, k along z.
        cap: [m] truncation distance (values never exceed it).
    """

    origin: F64
    resolution: float
    values: F64
    cap: float
    _coeffs: F64 = field(init=False, repr=False)  #: cubic B-spline coefficients of ``values``

    def __post_init__(self) -> None:
        origin = np.array(self.origin, dtype=np.float64, copy=True).reshape(-1)
        values = np.array(self.values, dtype=np.float64, copy=True)
        if origin.shape != (3,) or not np.isfinite(origin).all():
            raise PlanningError(f"origin must be 3 finite numbers [m], got {origin.tolist()}")
        if values.ndim != 3 or min(values.shape) < 4 or not np.isfinite(values).all():
            raise PlanningError(f"values must be a finite (nx, ny, nz) array with n >= 4, got {values.shape}")
        if not (math.isfinite(self.resolution) and self.resolution > 0.0):
            raise PlanningError(f"resolution must be > 0 [m], got {self.resolution}")
        if not (math.isfinite(self.cap) and self.cap > 0.0):
            raise PlanningError(f"cap must be > 0 [m], got {self.cap}")
        values.setflags(write=False)
        coeffs = np.asarray(ndimage.spline_filter(values, order=3, mode="mirror"), dtype=np.float64)
        coeffs.setflags(write=False)
        object.__setattr__(self, "_coeffs", coeffs)
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "resolution", float(self.resolution))
        object.__setattr__(self, "cap", float(self.cap))

    @property
    def shape(self) -> tuple[int, int, int]:
        """Nodes per axis (nx, ny, nz)."""
        nx, ny, nz = self.values.shape
        return (int(nx), int(ny), int(nz))

    @property
    def last_node(self) -> F64:
        """(3,) [m] position of the last node (the maximum corner node)."""
        return np.asarray(self.origin + (np.asarray(self.shape) - 1) * self.resolution, dtype=np.float64)

    @property
    def lower(self) -> F64:
        """(3,) [m] minimum corner of the box where the spline is valid (one cell in from the nodes)."""
        return np.asarray(self.origin + self.resolution, dtype=np.float64)

    @property
    def upper(self) -> F64:
        """(3,) [m] maximum corner of the box where the spline is valid (one cell in from the nodes)."""
        return np.asarray(self.last_node - self.resolution, dtype=np.float64)

    def axes(self) -> tuple[F64, F64, F64]:
        """Node coordinates along x, y and z [m], each (n_axis,)."""
        out = [
            self.origin[a] + self.resolution * np.arange(n, dtype=np.float64)
            for a, n in enumerate(self.shape)
        ]
        return (out[0], out[1], out[2])

    def points(self) -> F64:
        """(nx·ny·nz, 3) [m] node positions in C order (matching ``values.reshape(-1)``)."""
        grids = np.meshgrid(*self.axes(), indexing="ij")
        return np.stack([g.reshape(-1) for g in grids], axis=1)

    def contains(self, points: ArrayLike) -> NDArray[np.bool_]:
        """(N,) True where a point (N, 3) [m] lies in the valid box :attr:`lower` .. :attr:`upper`."""
        pts = _points(points, "points")
        return np.asarray(((pts >= self.lower - 1e-9) & (pts <= self.upper + 1e-9)).all(axis=1))

    def interpolate(self, points: ArrayLike, *, cubic: bool = True) -> F64:
        """(N,) [m] cubic-spline distance at ``points`` (N, 3) [m]; points outside the valid box are
        clamped onto it (keep queries inside with :meth:`contains`). ``cubic=False``: trilinear in the
        node values (faster, for coarse checks; not what the optimizer sees)."""
        pts = np.clip(_points(points, "points"), self.lower, self.upper)
        idx = ((pts - self.origin) / self.resolution).T
        if cubic:
            out = ndimage.map_coordinates(self._coeffs, idx, order=3, mode="mirror", prefilter=False)
        else:
            out = ndimage.map_coordinates(self.values, idx, order=1, mode="nearest")
        return np.asarray(out, dtype=np.float64)

    def minimum(self, other: DistanceGrid) -> DistanceGrid:
        """The node-wise minimum of two fields on the same grid (the distance to the union of their
        point sets).

        Raises:
            PlanningError: the grids differ in origin, resolution, shape or cap.
        """
        same = (
            self.shape == other.shape
            and np.allclose(self.origin, other.origin, atol=1e-12)
            and self.resolution == other.resolution
            and self.cap == other.cap
        )
        if not same:
            raise PlanningError(
                "fields can only be combined on the same grid (origin, resolution, shape, cap)"
            )
        return DistanceGrid(self.origin, self.resolution, np.minimum(self.values, other.values), self.cap)

    def derivatives(self, points: ArrayLike, order: int = 2) -> tuple[F64, F64, F64]:
        """Exact cubic-spline value (N,) [m], gradient (N, 3) [-] and Hessian (N, 3, 3) [1/m] at
        ``points`` (N, 3) [m], clamped into the valid box like :meth:`interpolate` (the gradient and
        Hessian are zero arrays when ``order`` is 0, the Hessian when it is 1)."""
        pts = np.clip(_points(points, "points"), self.lower, self.upper)
        u = (pts - self.origin) / self.resolution
        cell = np.clip(np.floor(u).astype(np.int64), 1, np.asarray(self.shape) - 3)
        frac = u - cell
        taps = np.arange(-1, 3)
        ix, iy, iz = (cell[:, a, None] + taps for a in range(3))
        block = self._coeffs[ix[:, :, None, None], iy[:, None, :, None], iz[:, None, None, :]]
        w = [[_bspline_weights(frac[:, a], d) for d in range(order + 1)] for a in range(3)]
        by_z = [np.einsum("nabc,nc->nab", block, w[2][d]) for d in range(order + 1)]

        def part(dx: int, dy: int, dz: int) -> F64:
            return np.asarray(np.einsum("nab,na,nb->n", by_z[dz], w[0][dx], w[1][dy]), dtype=np.float64)

        n = pts.shape[0]
        value = part(0, 0, 0)
        grad = np.zeros((n, 3))
        hess = np.zeros((n, 3, 3))
        if order >= 1:
            grad = np.stack([part(1, 0, 0), part(0, 1, 0), part(0, 0, 1)], axis=1) / self.resolution
        if order >= 2:
            for a in range(3):
                for b in range(a, 3):
                    d = [0, 0, 0]
                    d[a] += 1
                    d[b] += 1
                    hess[:, a, b] = hess[:, b, a] = part(d[0], d[1], d[2]) / self.resolution**2
        return value, grad, hess

    def casadi_function(self, points: int, name: str = "distance") -> ca.Function:
        """CasADi function (3, ``points``) [m] → (1, ``points``) [m]: the same cubic spline as
        :meth:`interpolate` at each column, with exact sparse Jacobian and Hessian (a callback into
        :meth:`derivatives`; see :mod:`.field_callback`). Valid inside :attr:`lower` .. :attr:`upper`.
        Keep the returned function alive while it is used."""
        from hsi_planning.minjerk.field_callback import FieldFunction

        return FieldFunction(name, self, points)


def _bspline_weights(frac: F64, derivative: int) -> F64:
    """(N, 4) weights of the 4 cubic B-spline coefficients around a cell (σ-derivative 0, 1 or 2)."""
    f = frac
    if derivative == 0:
        rows = [
            (1 - f) ** 3 / 6,
            (3 * f**3 - 6 * f**2 + 4) / 6,
            (-3 * f**3 + 3 * f**2 + 3 * f + 1) / 6,
            f**3 / 6,
        ]
    elif derivative == 1:
        rows = [-((1 - f) ** 2) / 2, (3 * f**2 - 4 * f) / 2, (-3 * f**2 + 2 * f + 1) / 2, f**2 / 2]
    else:
        rows = [1 - f, 3 * f - 2, 1 - 3 * f, f]
    return np.stack(rows, axis=-1)


def distance_grid(
    points: ArrayLike,
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    resolution: float = 0.02,
    cap: float = 0.3,
    max_nodes: int = 600_000,
) -> DistanceGrid:
    """Truncated Euclidean distance field of ``points`` on a grid covering ``lower``..``upper``.

    Args:
        points: (N, 3) [m] obstacle points (may be empty: the field is then ``cap`` everywhere).
        lower: (3,) [m] minimum corner of the box to cover (the field is valid on it).
        upper: (3,) [m] maximum corner; the grid is extended to a whole number of cells.
        resolution: [m] node spacing; coarsened by factors of 1.25 until the node count fits
            ``max_nodes``.
        cap: [m] truncation distance; queries never see more than this.
        max_nodes: most nodes allowed (bounds time and memory).

    Raises:
        PlanningError: bad shapes, non-finite numbers, an empty box, or non-positive parameters.
    """
    pts = _points(points, "obstacle points") if np.size(points) else np.zeros((0, 3))
    lo = _points(lower, "lower")[0]
    hi = _points(upper, "upper")[0]
    if np.any(hi <= lo):
        raise PlanningError(f"upper {hi.tolist()} must exceed lower {lo.tolist()} on every axis [m]")
    if not (math.isfinite(resolution) and resolution > 0.0 and math.isfinite(cap) and cap > 0.0):
        raise PlanningError(f"resolution ({resolution} m) and cap ({cap} m) must be > 0")
    if max_nodes < 64:
        raise PlanningError(f"max_nodes must be >= 64, got {max_nodes}")
    res = float(resolution)
    while True:
        counts = np.ceil((hi - lo) / res - 1e-9).astype(np.int64) + 3
        if int(np.prod(counts)) <= max_nodes:
            break
        res *= 1.25
    grid_lo = lo - res  # one extra node layer: the spline is valid from lo to >= hi
    grid_hi = grid_lo + (counts - 1) * res
    near = (pts >= grid_lo - cap).all(axis=1) & (pts <= grid_hi + cap).all(axis=1)
    crop = pts[near]
    nodes = np.stack(
        [
            g.reshape(-1)
            for g in np.meshgrid(*(grid_lo[a] + res * np.arange(counts[a]) for a in range(3)), indexing="ij")
        ],
        axis=1,
    )
    if crop.shape[0] == 0:
        values = np.full(tuple(int(c) for c in counts), float(cap))
    else:
        tree = cKDTree(crop, balanced_tree=False, compact_nodes=False)
        dist, _ = tree.query(nodes, k=1, distance_upper_bound=cap)
        values = np.minimum(np.asarray(dist, dtype=np.float64), cap).reshape(tuple(int(c) for c in counts))
    return DistanceGrid(origin=grid_lo, resolution=res, values=values, cap=float(cap))


def nearest_distance(points: ArrayLike, queries: ArrayLike) -> F64:
    """(M,) [m] exact Euclidean distance from each query (M, 3) [m] to the nearest of ``points`` (N, 3);
    ``inf`` when ``points`` is empty."""
    q = _points(queries, "queries")
    pts = _points(points, "points") if np.size(points) else np.zeros((0, 3))
    if pts.shape[0] == 0:
        return np.full(q.shape[0], np.inf)
    dist, _ = cKDTree(pts).query(q, k=1)
    return np.asarray(dist, dtype=np.float64)
