"""The distance field inside CasADi: a callback with exact, sparse first and second derivatives.

CasADi's own B-spline (``casadi.bspline``) evaluates the same spline, but building its Jacobian and
Hessian functions costs ~3 µs per coefficient — 0.3–0.9 s per solver for a 10⁵-node grid, more than
the solve. These callbacks evaluate the spline in NumPy (:meth:`DistanceGrid.derivatives`) on all N
check points at once and declare the true sparsity: output j depends on column j of the (3, N) input
only, so the Jacobian has 3 and the Hessian block 9 non-zeros per point. Building a solver then takes
milliseconds; an IPOPT iteration pays ~1 ms of Python.

The Jacobian function of a CasADi function takes (inputs, nominal outputs) and returns one block per
(output, input) pair of size numel(output) × numel(input) (column-major vectorization); the Hessian is
the Jacobian of that Jacobian function.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from hsi_planning.minjerk.sdf import DistanceGrid

F64 = NDArray[np.float64]


def _jacobian_pattern(n: int) -> ca.Sparsity:
    """(n, 3n): output j depends on inputs 3j, 3j+1, 3j+2 (column j of the (3, n) input)."""
    rows = np.repeat(np.arange(n), 3)
    return ca.Sparsity.triplet(n, 3 * n, rows.tolist(), np.arange(3 * n).tolist())


def _hessian_pattern(n: int) -> ca.Sparsity:
    """(n·3n, 3n): Jacobian entry (j, 3j+a) — vectorized index j + n(3j+a) — depends on input 3j+b."""
    j, a, b = (g.reshape(-1) for g in np.meshgrid(np.arange(n), np.arange(3), np.arange(3), indexing="ij"))
    return ca.Sparsity.triplet(n * 3 * n, 3 * n, (j + n * (3 * j + a)).tolist(), (3 * j + b).tolist())


def _points(arg: Any) -> F64:
    return np.asarray(np.array(arg), dtype=np.float64).reshape(3, -1, order="F").T


class _FieldHessian(ca.Callback):  # type: ignore[misc]
    """Jacobian of :class:`_FieldJacobian`: inputs (X, d, J), outputs (dJ/dX, dJ/dd = 0)."""

    def __init__(self, name: str, grid: DistanceGrid, n: int, opts: Mapping[str, Any]) -> None:
        ca.Callback.__init__(self)
        self._grid, self._n = grid, n
        self._pattern = _hessian_pattern(n)
        self.construct(name, dict(opts))

    def get_n_in(self) -> int:
        return 3

    def get_n_out(self) -> int:
        return 2

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        n = self._n
        return [ca.Sparsity.dense(3, n), ca.Sparsity.dense(1, n), _jacobian_pattern(n)][i]

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        n = self._n
        return self._pattern if i == 0 else ca.Sparsity(n * 3 * n, n)

    def eval(self, arg: Sequence[ca.DM]) -> list[ca.DM]:
        _, _, hess = self._grid.derivatives(_points(arg[0]), order=2)
        # column-major non-zeros: column 3j+b holds rows of a = 0, 1, 2 → order (j, b, a)
        values = hess.transpose(0, 2, 1).reshape(-1)
        return [ca.DM(self._pattern, values), ca.DM(self._n * 3 * self._n, self._n)]


class _FieldJacobian(ca.Callback):  # type: ignore[misc]
    """Jacobian of :class:`FieldFunction`: inputs (X, nominal d), output dd/dX (N, 3N)."""

    def __init__(self, name: str, grid: DistanceGrid, n: int, opts: Mapping[str, Any]) -> None:
        ca.Callback.__init__(self)
        self._grid, self._n = grid, n
        self._pattern = _jacobian_pattern(n)
        self._children: list[ca.Callback] = []
        self.construct(name, dict(opts))

    def get_n_in(self) -> int:
        return 2

    def get_n_out(self) -> int:
        return 1

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(3, self._n) if i == 0 else ca.Sparsity.dense(1, self._n)

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return self._pattern

    def eval(self, arg: Sequence[ca.DM]) -> list[ca.DM]:
        _, grad, _ = self._grid.derivatives(_points(arg[0]), order=1)
        return [ca.DM(self._pattern, grad.reshape(-1))]

    def has_jacobian(self) -> bool:
        return True

    def get_jacobian(
        self, name: str, inames: Sequence[str], onames: Sequence[str], opts: Mapping[str, Any]
    ) -> ca.Function:
        child = _FieldHessian(name, self._grid, self._n, opts)
        self._children.append(child)
        return child

    def has_jac_sparsity(self, oind: int, iind: int) -> bool:
        return True

    def get_jac_sparsity(self, oind: int, iind: int, symmetric: bool) -> ca.Sparsity:
        n = self._n
        return _hessian_pattern(n) if iind == 0 else ca.Sparsity(n * 3 * n, n)


class FieldFunction(ca.Callback):  # type: ignore[misc]
    """CasADi function (3, N) [m] → (1, N) [m]: the grid's cubic-spline distance at N points."""

    def __init__(self, name: str, grid: DistanceGrid, n: int, opts: Mapping[str, Any] | None = None) -> None:
        ca.Callback.__init__(self)
        if n < 1:
            raise ValueError(f"a field function needs n >= 1 points, got {n}")
        self._grid, self._n = grid, int(n)
        self._children: list[ca.Callback] = []
        self.construct(name, dict(opts or {}))

    def get_n_in(self) -> int:
        return 1

    def get_n_out(self) -> int:
        return 1

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(3, self._n)

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(1, self._n)

    def eval(self, arg: Sequence[ca.DM]) -> list[ca.DM]:
        value, _, _ = self._grid.derivatives(_points(arg[0]), order=0)
        return [ca.DM(value).T]

    def has_jacobian(self) -> bool:
        return True

    def get_jacobian(
        self, name: str, inames: Sequence[str], onames: Sequence[str], opts: Mapping[str, Any]
    ) -> ca.Function:
        child = _FieldJacobian(name, self._grid, self._n, opts)
        self._children.append(child)
        return child

    def has_jac_sparsity(self, oind: int, iind: int) -> bool:
        return True

    def get_jac_sparsity(self, oind: int, iind: int, symmetric: bool) -> ca.Sparsity:
        return _jacobian_pattern(self._n)
