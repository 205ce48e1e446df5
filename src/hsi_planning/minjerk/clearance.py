"""Clearance constraints of the minimum-jerk optimizer: spheres carried by the wrist vs a distance field.

A :class:`ClearanceSphere` (the hand; the held object while carrying) must keep its centre at least
``radius + margin`` from the obstacle points, measured on a :class:`~hsi_planning.minjerk.sdf.DistanceGrid`.
Near an end of the segment whose own clearance is smaller (the contact touches the target; a held object
rests on its support) the requirement is **relaxed**::

    required(c) = min(radius + margin, d_end − slack + relax_slope · |c − c_end|)

for each such end (c: sphere centre, c_end: its centre at that end), so the sphere has to move away from
the surface at least at ``relax_slope`` [m/m] of the straight distance travelled from the end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import PlanningError
from hsi_planning.minjerk.sdf import DistanceGrid

F64 = NDArray[np.float64]
#: [m²] smoothing of |c − c_end| = sqrt(|·|² + ε) (differentiable at the end itself).
_NORM_EPS = 1e-6


@dataclass(frozen=True, eq=False)
class ClearanceSphere:
    """A sphere carried by the wrist that must keep clear of the obstacles of ``field``.

    Attributes:
        field: truncated distance [m] to the obstacle points this sphere must avoid.
        radius: [m] sphere radius (hand: 0.04; held object: its bounding-sphere radius).
        margin: [m] extra clearance beyond the radius.
        offsets: (N, 3) [m] world-frame offset of the sphere centre from the wrist at N uniformly spaced
            normalized times τ ∈ [0, 1] (linear in between; the held object turns with the wrist), or
            (3,) for a constant offset (the hand: zeros).
        name: for messages (``hand``, ``held object``).
    """

    field: DistanceGrid
    radius: float
    margin: float
    offsets: F64
    name: str = "hand"

    def __post_init__(self) -> None:
        off = np.array(self.offsets, dtype=np.float64, copy=True)
        off = off.reshape(1, 3) if off.shape == (3,) else off
        if off.ndim != 2 or off.shape[1] != 3 or off.shape[0] < 1 or not np.isfinite(off).all():
            raise PlanningError(f"sphere offsets must be finite (3,) or (N, 3) [m], got shape {off.shape}")
        if not (math.isfinite(self.radius) and self.radius >= 0.0 and math.isfinite(self.margin)):
            raise PlanningError(f"sphere radius ({self.radius} m) must be >= 0 and the margin finite")
        if self.required > self.field.cap:
            raise PlanningError(
                f"{self.name} sphere needs {self.required:.3f} m clearance but the field is capped at "
                f"{self.field.cap:.3f} m; build the field with a larger cap"
            )
        object.__setattr__(self, "offsets", off)

    @property
    def required(self) -> float:
        """[m] clearance the field must show at the sphere centre: radius + margin."""
        return float(self.radius + self.margin)

    def offset_at(self, tau: ArrayLike) -> F64:
        """(N, 3) [m] sphere-centre offsets at normalized times ``tau`` (N,) in [0, 1]."""
        t = np.clip(np.asarray(tau, dtype=np.float64).reshape(-1), 0.0, 1.0)
        if self.offsets.shape[0] == 1:
            return np.repeat(self.offsets, t.shape[0], axis=0)
        grid = np.linspace(0.0, 1.0, self.offsets.shape[0])
        return np.stack([np.interp(t, grid, self.offsets[:, a]) for a in range(3)], axis=1)

    def clearance(self, wrist: ArrayLike, tau: ArrayLike, *, cubic: bool = True) -> F64:
        """(N,) [m] field distance at the sphere centres for wrist positions (N, 3) at times (N,)."""
        return self.field.interpolate(self.centres(wrist, tau), cubic=cubic)

    def centres(self, wrist: ArrayLike, tau: ArrayLike) -> F64:
        """(N, 3) [m] sphere centres for wrist positions (N, 3) [m] at normalized times (N,)."""
        return np.asarray(wrist, dtype=np.float64).reshape(-1, 3) + self.offset_at(tau)

    def end_centres(self, start: F64, goal: F64) -> list[F64]:
        """Sphere centres (3,) [m] at the two ends of the segment."""
        return [start + self.offset_at(0.0)[0], goal + self.offset_at(1.0)[0]]

    def relaxed_ends(self, start: F64, goal: F64, slack: float) -> list[tuple[F64, float]]:
        """(centre, own clearance − slack) of each end whose clearance is below :attr:`required`."""
        out = []
        for c in self.end_centres(start, goal):
            own = float(self.field.interpolate(c)[0]) - slack
            if own < self.required:
                out.append((c, own))
        return out

    def requirement(self, centres: F64, ends: list[tuple[F64, float]], slope: float) -> F64:
        """(N,) [m] the (relaxed) requirement at sphere centres (N, 3) [m] (see the module doc)."""
        req = np.full(centres.shape[0], self.required)
        for c_end, own in ends:
            dist = np.sqrt(np.sum((centres - c_end) ** 2, axis=1) + _NORM_EPS)
            req = np.minimum(req, own + slope * dist)
        return req

    def requirement_casadi(
        self, centres: ca.MX, ends: list[tuple[F64, float]], slope: float
    ) -> ca.MX | float:
        """The same requirement as :meth:`requirement` for symbolic centres (3, N)."""
        req: ca.MX | float = self.required
        for c_end, own in ends:
            diff = centres - ca.repmat(ca.DM(c_end), 1, centres.shape[1])
            req = ca.fmin(req, own + slope * ca.sqrt(ca.sum1(diff * diff) + _NORM_EPS))
        return req

    def margin_at(self, wrist: ArrayLike, tau: ArrayLike, ends: list[tuple[F64, float]], slope: float) -> F64:
        """(N,) [m] clearance minus requirement for wrist positions (N, 3) at normalized times (N,)."""
        c = self.centres(wrist, tau)
        return self.field.interpolate(c) - self.requirement(c, ends, slope)
