"""Geometric wrist paths of the human-reach model (no timing): curved free part + straight contact tail.

Paths are built in the *approach* direction, from the free pose ``F`` to the contact ``C``:

- the **tail** near the contact: a pre-contact waypoint in front of the container opening
  (``C - axis · insertion``, raised by ``lift`` when an object is carried) followed by a straight
  insertion (and a vertical set-down when carrying), corners rounded;
- the **free part** from ``F`` to the pre-contact waypoint: a cubic Hermite curve that leaves along the
  chord and arrives along the tail's direction, plus a bulge ``shape(u) · (amp · b + noise)`` (``b``
  perpendicular to the chord: elbow-out / upward arc; ``noise`` a random perpendicular vector), which
  vanishes at the ends and is largest mid-reach, plus collision bends.

A leave segment is the same geometry traversed from ``C`` to ``F``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hsi_planning.demos.profiles import arc_length

UP = np.array([0.0, 0.0, 1.0])


def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else np.zeros(3)


def perpendicular(v: NDArray[np.float64], axis: NDArray[np.float64]) -> NDArray[np.float64]:
    """Component of ``v`` (3,) perpendicular to the unit ``axis`` (3,)."""
    return np.asarray(v - np.dot(v, axis) * axis, dtype=np.float64)


def rotate_about(v: NDArray[np.float64], axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """Rodrigues rotation of ``v`` (3,) about the unit ``axis`` (3,) by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.asarray(v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1.0 - c), dtype=np.float64)


def _fillet(polyline: NDArray[np.float64], radius: float, samples: int = 9) -> NDArray[np.float64]:
    """Round the interior corners of a polyline (K, 3) [m] with quadratic Bezier arcs of ``radius`` [m]."""
    if len(polyline) < 3:
        return polyline
    out = [polyline[0]]
    for k in range(1, len(polyline) - 1):
        prev, corner, nxt = polyline[k - 1], polyline[k], polyline[k + 1]
        r = min(
            radius, 0.45 * float(np.linalg.norm(corner - prev)), 0.45 * float(np.linalg.norm(nxt - corner))
        )
        a = corner + r * _unit(prev - corner)
        b = corner + r * _unit(nxt - corner)
        u = np.linspace(0.0, 1.0, samples)[:, None]
        out.extend((1 - u) ** 2 * a + 2 * u * (1 - u) * corner + u**2 * b)
    out.append(polyline[-1])
    return np.asarray(out, dtype=np.float64)


def _densify(polyline: NDArray[np.float64], step: float) -> NDArray[np.float64]:
    s = arc_length(polyline)
    if s[-1] <= 0.0:
        return polyline[[0, -1]]
    n = max(2, int(np.ceil(s[-1] / step)) + 1)
    su = np.linspace(0.0, s[-1], n)
    out = np.column_stack([np.interp(su, s, polyline[:, k]) for k in range(3)])
    out[0], out[-1] = polyline[0], polyline[-1]
    return out


def contact_tail(
    contact: NDArray[np.float64],
    axis: NDArray[np.float64] | None,
    insertion: float,
    lift: float,
    step: float,
) -> NDArray[np.float64]:
    """(K, 3) [m] dense tail from the pre-contact waypoint to ``contact`` (3,) [m] (K = 1: no tail).

    ``axis``: unit direction of the insertion (into the container), or None in free space;
    ``insertion`` [m] straight insertion length; ``lift`` [m] height of the carried object above its
    support while it moves in or out (0 when the hand is empty).
    """
    corners = [contact]
    if lift > 0.0:
        corners.insert(0, contact + lift * UP)
    if axis is not None and insertion > 0.0:
        corners.insert(0, corners[0] - insertion * axis)
    if len(corners) == 1:
        return contact[None, :].copy()
    poly = _fillet(np.asarray(corners), radius=0.3 * max(lift, 1e-3))
    return _densify(poly, step)


def bulge_shape(u: NDArray[np.float64], exponent: float, end_tangent: bool) -> NDArray[np.float64]:
    """(N,) bulge profile along the free part, normalized to max 1, zero at both ends.

    ``u - u^(k+1)`` (k = ``exponent`` >= 1): concave (no inflection, so the path curves one way), zero
    curvature at the start and rising towards the end where the hand hooks into the target; its maximum
    lies at ``u = (k+1)^(-1/k)`` (0.5 for k = 1, 0.58 for k = 2). With ``end_tangent`` it is multiplied by
    ``1 - u²`` so that the end slope vanishes and the path joins a straight insertion tangentially (the
    profile stays positive; the hook into the insertion direction is then done by the base curve).
    """
    k = float(exponent)
    shape = u - u ** (k + 1.0)
    if end_tangent:
        shape = shape * (1.0 - u**2)
    return np.asarray(shape / max(float(shape.max()), 1e-12), dtype=np.float64)


def mid_envelope(u: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) ``sin²(pi u)``: variability envelope, largest mid-reach, zero value and slope at the ends."""
    return np.asarray(np.sin(np.pi * u) ** 2, dtype=np.float64)


@dataclass(frozen=True)
class FreePart:
    """The free part of a path, F -> pre-contact waypoint, as base curve + separable offsets.

    Attributes:
        u: (N,) curve parameter in [0, 1].
        base: (N, 3) [m] Hermite curve.
        bulge: (N, 3) [m] bulge for unit amplitude (direction · shape).
        noise: (N, 3) [m] random via-point perturbation (fixed per sample).
    """

    u: NDArray[np.float64]
    base: NDArray[np.float64]
    bulge: NDArray[np.float64]
    noise: NDArray[np.float64]

    def points(self, amplitude: float, bend: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 3) [m] free-part samples for bulge ``amplitude`` [m] plus ``bend`` (N, 3) [m]."""
        return np.asarray(self.base + amplitude * self.bulge + self.noise + bend, dtype=np.float64)


def free_part(
    start: NDArray[np.float64],
    pre_contact: NDArray[np.float64],
    *,
    end_direction: NDArray[np.float64] | None,
    bulge_direction: NDArray[np.float64],
    bulge_exponent: float,
    noise_std: float,
    rng: np.random.Generator,
    step: float,
) -> FreePart:
    """Build the free part from ``start`` to ``pre_contact`` (3,) [m].

    ``end_direction``: unit tangent at the pre-contact waypoint (None: along the chord);
    ``bulge_direction``: unit (3,) bulge direction; ``bulge_exponent``: see :func:`bulge_shape`;
    ``noise_std`` [m] standard deviation of the random via-point perturbation: a random vector
    perpendicular to the chord (2 components of std ``noise_std``) times the bulge profile, so it is
    largest mid-reach, vanishes at the ends and bends the path without adding inflections.
    """
    chord = pre_contact - start
    length = float(np.linalg.norm(chord))
    n = max(60, int(np.ceil(1.6 * length / step)) + 1)
    u = np.linspace(0.0, 1.0, n)[:, None]
    t0 = chord
    t1 = length * end_direction if end_direction is not None else chord
    h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
    h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
    base = h00 * start + h10 * t0 + h01 * pre_contact + h11 * t1
    uu = u[:, 0]
    shape = bulge_shape(uu, bulge_exponent, end_direction is not None)
    bulge = shape[:, None] * bulge_direction[None, :]
    axis = _unit(chord)
    offset = perpendicular(rng.normal(0.0, noise_std, size=3), axis) if axis.any() else np.zeros(3)
    noise = shape[:, None] * offset[None, :]
    base[0], base[-1] = start, pre_contact
    return FreePart(u=uu, base=np.asarray(base), bulge=bulge, noise=np.asarray(noise))


def bend_bump(u: NDArray[np.float64], center: float, width: float) -> NDArray[np.float64]:
    """(N,) Gaussian bump at ``center`` of ``width`` (parameter units) times the end envelope, scaled so
    that its value at ``center`` is 1 (ends stay fixed)."""
    env = np.sqrt(mid_envelope(u))
    gauss = np.exp(-0.5 * ((u - center) / width) ** 2) * env
    at = float(np.interp(center, u, gauss))
    return np.asarray(gauss / max(at, 0.15), dtype=np.float64)


def max_deviation_ratio(points: NDArray[np.float64]) -> float:
    """Max perpendicular distance of ``points`` (N, 3) [m] from their start–end chord / chord length."""
    chord = points[-1] - points[0]
    length = float(np.linalg.norm(chord))
    if length <= 0.0:
        return 0.0
    rel = points - points[0]
    axis = chord / length
    perp = rel - np.outer(rel @ axis, axis)
    return float(np.linalg.norm(perp, axis=1).max() / length)


def default_bulge_preference(
    start: NDArray[np.float64], contact: NDArray[np.float64], hand_sign: float, weights: tuple[float, float]
) -> NDArray[np.float64]:
    """Unit (3,) preferred bulge direction, perpendicular to the chord ``start -> contact``.

    A weighted sum of upward (``weights[0]``) and the hand's side of the movement heading (elbow out;
    ``hand_sign`` +1 right, -1 left; ``weights[1]``), both made perpendicular to the chord. HDM05
    ``grabHighR`` wrist paths bulge this way (up-perpendicular and to the right of the heading).
    """
    axis = _unit(contact - start)
    heading = _unit(perpendicular(contact - start, UP))
    if not heading.any():
        heading = np.array([1.0, 0.0, 0.0])
    side = hand_sign * np.cross(heading, UP)
    pref = weights[0] * _unit(perpendicular(UP, axis)) + weights[1] * _unit(perpendicular(side, axis))
    pref = _unit(perpendicular(pref, axis))
    if not pref.any():
        pref = _unit(perpendicular(side if side.any() else np.array([0.0, 1.0, 0.0]), axis))
    if not pref.any():
        pref = _unit(np.cross(axis, np.array([1.0, 0.0, 0.0])))
    return pref
