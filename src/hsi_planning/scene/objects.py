"""Free objects: their compound primitive shapes, default sizes, masses and friction.

Shapes are built in the object frame: origin at the centre of the bottom, z up, so an object rests on
a surface when its frame sits on it. Handles and spouts point along local +x (handle of a mug,
spout of a teapot; the teapot handle is on -x).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hsi_planning.scene.shapes import Prim, box_from_bounds, rot_tuple
from hsi_planning.scene.spec import ObjectSpec

Rgba = tuple[float, float, float, float]


@dataclass(frozen=True)
class ObjectDefaults:
    """Per-kind defaults."""

    size: tuple[float, ...]  #: box (lx, ly, lz), round kinds (diameter, height) [m]
    mass: float  #: [kg]
    friction: float  #: sliding friction coefficient [-]
    rgba: Rgba  #: colour [0..1]


DEFAULTS: dict[str, ObjectDefaults] = {
    "bottle": ObjectDefaults((0.07, 0.25), 0.5, 0.7, (0.2, 0.55, 0.3, 1.0)),
    "mug": ObjectDefaults((0.082, 0.095), 0.3, 0.8, (0.85, 0.25, 0.2, 1.0)),
    "bowl": ObjectDefaults((0.16, 0.065), 0.3, 0.8, (0.9, 0.85, 0.55, 1.0)),
    "can": ObjectDefaults((0.066, 0.122), 0.35, 0.8, (0.75, 0.1, 0.15, 1.0)),
    "box": ObjectDefaults((0.15, 0.08, 0.2), 0.7, 0.6, (0.3, 0.45, 0.8, 1.0)),
    "teapot": ObjectDefaults((0.15, 0.12), 0.8, 0.8, (0.35, 0.3, 0.6, 1.0)),
}


def object_size(o: ObjectSpec) -> tuple[float, ...]:
    """Dimensions after ``scale``: box (lx, ly, lz), round kinds (diameter, height) [m]."""
    base = o.size if o.size is not None else DEFAULTS[o.kind].size
    return tuple(o.scale * v for v in base)


def object_mass(o: ObjectSpec) -> float:
    """Mass [kg] (an explicit ``mass`` wins, else the kind default times scale^3)."""
    return o.mass if o.mass is not None else DEFAULTS[o.kind].mass * o.scale**3


def object_friction(o: ObjectSpec) -> float:
    """Sliding friction coefficient [-]."""
    return o.friction if o.friction is not None else DEFAULTS[o.kind].friction


def _cyl(r: float, z0: float, z1: float, part: str, rgba: Rgba) -> Prim:
    return Prim("cylinder", (r, 0.5 * (z1 - z0)), pos=(0.0, 0.0, 0.5 * (z0 + z1)), rgba=rgba, part=part)


def _axis_pose(
    a: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[tuple[float, float, float], tuple[float, ...]]:
    """Pose (pos, row-major rot) of a primitive whose local z runs from ``a`` to ``b`` (3,) [m]."""
    axis = (b - a) / np.linalg.norm(b - a)
    ref = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(ref, axis)
    x /= np.linalg.norm(x)
    rot = np.column_stack([x, np.cross(axis, x), axis])
    mid = 0.5 * (a + b)
    return (float(mid[0]), float(mid[1]), float(mid[2])), rot_tuple(rot)


def _bar_handle(x_in: float, x_out: float, z0: float, z1: float, rgba: Rgba) -> list[Prim]:
    """A squared handle on the +x side (x_out > x_in) or -x side (x_out < x_in), bar 12 mm."""
    s, r = math.copysign(1.0, x_out - x_in), 0.006
    lo_x, hi_x = sorted((x_in, x_out + s * r))
    kw = {"rgba": rgba}
    return [
        box_from_bounds((lo_x, -r, z0 - r), (hi_x, r, z0 + r), "handle_low", **kw),
        box_from_bounds((lo_x, -r, z1 - r), (hi_x, r, z1 + r), "handle_high", **kw),
        box_from_bounds(
            (min(x_out - r, x_out + r), -r, z0 + r), (max(x_out - r, x_out + r), r, z1 - r), "handle", **kw
        ),
    ]


def _bowl(d: float, h: float, rgba: Rgba) -> list[Prim]:
    base_r, base_t, wall_t, n = 0.3 * d, 0.012 * d / 0.16, 0.006 * d / 0.16, 12
    prims = [_cyl(base_r, 0.0, base_t, "base", rgba)]
    r0, z0, r1, z1 = base_r - wall_t, 0.5 * base_t, 0.5 * d - wall_t / 2, h - wall_t / 2
    seg = 2.0 * math.pi * (0.5 * d) / n * 0.55
    for i in range(n):
        th = 2.0 * math.pi * i / n
        u = np.array([math.cos(th), math.sin(th), 0.0])
        a, b = r0 * u + np.array([0.0, 0.0, z0]), r1 * u + np.array([0.0, 0.0, z1])
        half_len = 0.5 * float(np.linalg.norm(b - a))
        pos, _ = _axis_pose(a, b)
        axis = (b - a) / (2.0 * half_len)
        tangent = np.array([-math.sin(th), math.cos(th), 0.0])
        rot = np.column_stack([np.cross(tangent, axis), tangent, axis])
        prims.append(
            Prim("box", (wall_t / 2, seg, half_len), pos=pos, rot=rot_tuple(rot), rgba=rgba, part=f"wall{i}")
        )
    return prims


def object_prims(o: ObjectSpec) -> list[Prim]:
    """The object's primitives in its own frame (bottom centre at the origin), lowest point at z = 0."""
    rgba = DEFAULTS[o.kind].rgba
    size = object_size(o)
    if o.kind == "box":
        lx, ly, lz = size
        return [box_from_bounds((-lx / 2, -ly / 2, 0.0), (lx / 2, ly / 2, lz), "box", rgba=rgba)]
    d, h = size
    r = d / 2
    if o.kind == "can":
        return [_cyl(r, 0.0, h, "body", rgba)]
    if o.kind == "bottle":
        return [
            _cyl(r, 0.0, 0.65 * h, "body", rgba),
            _cyl(0.7 * r, 0.65 * h, 0.75 * h, "shoulder", rgba),
            _cyl(0.4 * r, 0.75 * h, h, "neck", rgba),
        ]
    if o.kind == "mug":
        return [
            _cyl(r, 0.0, h, "body", rgba),
            *_bar_handle(r - 0.004, r + 0.03 * d / 0.082, 0.25 * h, 0.78 * h, rgba),
        ]
    if o.kind == "bowl":
        return _bowl(d, h, rgba)
    # teapot: pot, lid, knob, spout (+x), handle (-x)
    spout_r = 0.08 * r
    a = np.array([0.8 * r, 0.0, 0.35 * h])
    b = a + 0.55 * r * np.array([1.0, 0.0, 1.0])
    pos, rot = _axis_pose(a, b)
    spout = Prim(
        "capsule", (spout_r, 0.5 * float(np.linalg.norm(b - a))), pos=pos, rot=rot, rgba=rgba, part="spout"
    )
    return [
        _cyl(r, 0.0, 0.78 * h, "pot", rgba),
        _cyl(0.6 * r, 0.78 * h, 0.88 * h, "lid", rgba),
        _cyl(0.15 * r, 0.88 * h, h, "knob", rgba),
        spout,
        *_bar_handle(-r + 0.004, -r - 0.4 * r, 0.22 * h, 0.65 * h, rgba),
    ]
