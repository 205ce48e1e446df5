"""Furniture geometry: the labelled bodies (carcass, boards, doors, drawers) and support surfaces.

All part bodies share the furniture frame (see :mod:`.spec`): x from the front (x = -depth/2) to the
back, y along the width, z up from the floor. Doors and drawer fronts are overlay panels in front of the
carcass (x < -depth/2), so the carcass depth is ``size[1]`` and the fronts add one panel thickness.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hsi_planning.scene.shapes import BodyPlan, JointPlan, Prim, box_from_bounds, pose_matrix, rot_z
from hsi_planning.scene.spec import CONTAINER_KINDS, FurnitureSpec

GAP = 0.002  #: gap around doors and drawer fronts [m]
DRAWER_CLEARANCE = 0.004  #: clearance between a drawer box and its bay [m]
DRAWER_HEADROOM = 0.015  #: free height between drawer walls and the panel above [m]
HANDLE_STANDOFF = 0.03  #: distance from the front face to the handle bar axis [m]
DOOR_RANGE = math.radians(110.0)  #: door opening range [rad]
DRAWER_TRAVEL = 0.8  #: drawer travel as a fraction of the drawer depth [-]

_WOOD = (0.72, 0.55, 0.38, 1.0)
_BOARD = (0.78, 0.63, 0.46, 1.0)
_FRONT = (0.88, 0.84, 0.76, 1.0)
_METAL = (0.55, 0.56, 0.6, 1.0)
_SEMANTIC = {"cabinet": "cabinet", "drawer_unit": "drawer_unit", "shelf": "shelf", "table": "table"}


@dataclass(frozen=True)
class SupportSurface:
    """A horizontal surface objects can rest on, with the free space above it."""

    name: str  #: support name used in ``ObjectSpec.on``
    body: str  #: label/body the surface belongs to
    furniture: str  #: furniture name (the container)
    frame: NDArray[np.float64]  #: (4, 4) world pose: origin at the surface centre, z up, x inwards [m]
    half_extents: tuple[float, float]  #: usable half size along frame x (depth) and y (width) [m]
    ceiling: float  #: free height above the surface [m]; inf when open above
    opening: NDArray[np.float64]  #: (3,) world unit vector pointing out of the opening

    @property
    def top_z(self) -> float:
        """Height of the surface [m]."""
        return float(self.frame[2, 3])


def furniture_frame(f: FurnitureSpec) -> NDArray[np.float64]:
    """The furniture frame in the world: (4, 4) [m]."""
    return pose_matrix((f.pos[0], f.pos[1], 0.0), rot_z(math.radians(f.yaw)))


def opening_direction(f: FurnitureSpec) -> NDArray[np.float64]:
    """World unit vector (3,) out of the furniture's opening: the front normal, or +z for tables/counters."""
    if f.kind in CONTAINER_KINDS:
        return np.asarray(furniture_frame(f)[:3, :3] @ np.array([-1.0, 0.0, 0.0]), dtype=float)
    return np.array([0.0, 0.0, 1.0])


def _carcass(f: FurnitureSpec) -> list[Prim]:
    w, d, h = f.size
    t = f.thickness
    kw = {"rgba": _WOOD}
    return [
        box_from_bounds((-d / 2, w / 2 - t, 0.0), (d / 2, w / 2, h), "side_left", **kw),
        box_from_bounds((-d / 2, -w / 2, 0.0), (d / 2, -w / 2 + t, h), "side_right", **kw),
        box_from_bounds((-d / 2, -w / 2 + t, 0.0), (d / 2 - t, w / 2 - t, t), "bottom", **kw),
        box_from_bounds((-d / 2, -w / 2 + t, h - t), (d / 2 - t, w / 2 - t, h), "top", **kw),
        box_from_bounds((d / 2 - t, -w / 2 + t, 0.0), (d / 2, w / 2 - t, h), "back", **kw),
    ]


def _handle(front_x: float, y: float, z: float, vertical: bool) -> list[Prim]:
    """A bar handle with two posts, standing off ``HANDLE_STANDOFF`` in front of ``front_x``."""
    bar_half, post_off, r = 0.06, 0.045, 0.006
    x_bar = front_x - HANDLE_STANDOFF
    kw = {"rgba": _METAL}
    if vertical:
        bar = box_from_bounds(
            (x_bar - r, y - r, z - bar_half), (x_bar + r, y + r, z + bar_half), "handle", **kw
        )
        posts = [(y, z - post_off), (y, z + post_off)]
    else:
        bar = box_from_bounds(
            (x_bar - r, y - bar_half, z - r), (x_bar + r, y + bar_half, z + r), "handle", **kw
        )
        posts = [(y - post_off, z), (y + post_off, z)]
    out = [bar]
    for i, (py, pz) in enumerate(posts):
        lo = (x_bar + r, py - 0.004, pz - 0.004)
        out.append(box_from_bounds(lo, (front_x, py + 0.004, pz + 0.004), f"handle_post{i + 1}", **kw))
    return out


def _board_heights(f: FurnitureSpec) -> list[float]:
    return sorted(f.boards)


def _doors(f: FurnitureSpec, frame: NDArray[np.float64]) -> list[BodyPlan]:
    w, d, h = f.size
    t = f.thickness
    x_back, x_front = -d / 2 - GAP, -d / 2 - GAP - t
    if f.doors == 1:
        left = f.hinge == "left"
        leaves = [(-w / 2 + GAP, w / 2 - GAP, left)]
    else:
        leaves = [(GAP / 2, w / 2 - GAP, True), (-w / 2 + GAP, -GAP / 2, False)]
    handle_z = min(h - 0.1, 1.05)
    out = []
    for i, (y0, y1, hinge_left) in enumerate(leaves):
        # Seen from the front (looking along +x) "left" is +y; the axis sign makes +angle swing outwards.
        hinge_y, axis_z = (y1, -1.0) if hinge_left else (y0, 1.0)
        handle_y = y0 + 0.04 if hinge_left else y1 - 0.04
        panel = box_from_bounds((x_front, y0, GAP), (x_back, y1, h - GAP), "panel", rgba=_FRONT)
        joint = JointPlan("hinge", (0.0, 0.0, axis_z), (x_front, hinge_y, h / 2), (0.0, DOOR_RANGE), 0.5)
        out.append(
            BodyPlan(
                name=f"{f.name}/door{i + 1}",
                semantic_class="cabinet_door",
                kind="furniture",
                pose=frame.copy(),
                prims=(panel, *_handle(x_front, handle_y, handle_z, vertical=True)),
                parent=f.name,
                joint=joint,
                extras={"handle_x": x_front - HANDLE_STANDOFF, "handle_y": handle_y, "handle_z": handle_z},
            )
        )
    return out


def _bays(f: FurnitureSpec) -> list[tuple[float, float]]:
    """Drawer bays (z_lo, z_hi) [m], top bay first."""
    h, t, n = f.size[2], f.thickness, f.drawers
    bay = (h - 2 * t - (n - 1) * t) / n
    return [(h - t - k * (bay + t) - bay, h - t - k * (bay + t)) for k in range(n)]


def _drawer_geometry(f: FurnitureSpec, z_lo: float, z_hi: float) -> dict[str, float]:
    w, d, _ = f.size
    t, c, tb = f.thickness, DRAWER_CLEARANCE, 0.012
    return {
        "x0": -d / 2 - GAP,
        "x1": d / 2 - t - c,
        "y0": -w / 2 + t + c,
        "y1": w / 2 - t - c,
        "z0": z_lo + c,
        "z1": z_hi - DRAWER_HEADROOM,
        "tb": tb,
    }


def _drawers(f: FurnitureSpec, frame: NDArray[np.float64]) -> list[BodyPlan]:
    w, _, _ = f.size
    t = f.thickness
    out = []
    for i, (z_lo, z_hi) in enumerate(_bays(f)):
        g = _drawer_geometry(f, z_lo, z_hi)
        x0, x1, y0, y1, z0, z1, tb = (g[k] for k in ("x0", "x1", "y0", "y1", "z0", "z1", "tb"))
        x_front = x0 - t
        prims = [
            box_from_bounds(
                (x_front, -w / 2 + GAP, z_lo - t / 2 + GAP),
                (x0, w / 2 - GAP, z_hi + t / 2 - GAP),
                "front",
                rgba=_FRONT,
            ),
            box_from_bounds((x0, y0, z0), (x1, y1, z0 + tb), "floor", rgba=_BOARD),
            box_from_bounds((x0, y0, z0 + tb), (x1, y0 + tb, z1), "wall_right", rgba=_BOARD),
            box_from_bounds((x0, y1 - tb, z0 + tb), (x1, y1, z1), "wall_left", rgba=_BOARD),
            box_from_bounds((x0, y0 + tb, z0 + tb), (x0 + tb, y1 - tb, z1), "wall_front", rgba=_BOARD),
            box_from_bounds((x1 - tb, y0 + tb, z0 + tb), (x1, y1 - tb, z1), "wall_back", rgba=_BOARD),
        ]
        handle_z = 0.5 * (z_lo + z_hi)
        prims += _handle(x_front, 0.0, handle_z, vertical=False)
        travel = DRAWER_TRAVEL * (x1 - x0)
        out.append(
            BodyPlan(
                name=f"{f.name}/drawer{i + 1}",
                semantic_class="drawer",
                kind="furniture",
                pose=frame.copy(),
                prims=tuple(prims),
                parent=f.name,
                joint=JointPlan("slide", (-1.0, 0.0, 0.0), (0.0, 0.0, handle_z), (0.0, travel), 5.0),
                extras={"handle_x": x_front - HANDLE_STANDOFF, "handle_y": 0.0, "handle_z": handle_z},
            )
        )
    return out


def furniture_bodies(f: FurnitureSpec) -> list[BodyPlan]:
    """The labelled bodies of one piece of furniture: carcass first, then boards, doors, drawers."""
    frame = furniture_frame(f)
    w, d, h = f.size
    t = f.thickness
    if f.kind == "counter":
        top = box_from_bounds((-d / 2, -w / 2, 0.0), (d / 2, w / 2, h), "block", rgba=(0.85, 0.85, 0.82, 1.0))
        return [BodyPlan(f.name, "counter", "furniture", frame.copy(), (top,))]
    if f.kind == "table":
        tt, leg, inset = 1.5 * t, 0.05, 0.03
        prims = [box_from_bounds((-d / 2, -w / 2, h - tt), (d / 2, w / 2, h), "top", rgba=_WOOD)]
        for i, (sx, sy) in enumerate(((-1, -1), (-1, 1), (1, -1), (1, 1))):
            cx, cy = sx * (d / 2 - inset - leg / 2), sy * (w / 2 - inset - leg / 2)
            lo, hi = (cx - leg / 2, cy - leg / 2, 0.0), (cx + leg / 2, cy + leg / 2, h - tt)
            prims.append(box_from_bounds(lo, hi, f"leg{i + 1}", rgba=_WOOD))
        return [BodyPlan(f.name, "table", "furniture", frame.copy(), tuple(prims))]
    carcass = _carcass(f)
    if f.kind == "drawer_unit":
        for k, (z_lo, _) in enumerate(_bays(f)[:-1]):
            lo, hi = (-d / 2, -w / 2 + t, z_lo - t), (d / 2 - t, w / 2 - t, z_lo)
            carcass.append(box_from_bounds(lo, hi, f"divider{k + 1}", rgba=_WOOD))
    bodies = [BodyPlan(f.name, _SEMANTIC[f.kind], "furniture", frame.copy(), tuple(carcass))]
    x_board = -d / 2 + (0.01 if f.kind == "cabinet" else 0.0)
    for name, z in zip(f.board_names, _board_heights(f), strict=True):
        board = box_from_bounds((x_board, -w / 2 + t, z - t), (d / 2 - t, w / 2 - t, z), "board", rgba=_BOARD)
        bodies.append(BodyPlan(name, "shelf_board", "furniture", frame.copy(), (board,), parent=f.name))
    if f.kind == "cabinet":
        bodies += _doors(f, frame)
    elif f.kind == "drawer_unit":
        bodies += _drawers(f, frame)
    return bodies


def _surface(
    name: str, f: FurnitureSpec, *, x: tuple[float, float], y: tuple[float, float], z: float, ceil: float
) -> SupportSurface:
    frame = furniture_frame(f) @ pose_matrix((0.5 * (x[0] + x[1]), 0.5 * (y[0] + y[1]), z))
    half = (0.5 * (x[1] - x[0]), 0.5 * (y[1] - y[0]))
    return SupportSurface(name, name, f.name, frame, half, ceil, opening_direction(f))


def furniture_supports(f: FurnitureSpec) -> list[SupportSurface]:
    """The support surfaces of one piece of furniture, in the order of ``f.support_names``."""
    w, d, h = f.size
    t = f.thickness
    if f.kind in ("counter", "table"):
        return [_surface(f.name, f, x=(-d / 2, d / 2), y=(-w / 2, w / 2), z=h, ceil=math.inf)]
    if f.kind == "drawer_unit":
        out = []
        for i, (z_lo, z_hi) in enumerate(_bays(f)):
            g = _drawer_geometry(f, z_lo, z_hi)
            tb, floor = g["tb"], g["z0"] + g["tb"]
            xs, ys = (g["x0"] + tb, g["x1"] - tb), (g["y0"] + tb, g["y1"] - tb)
            name = f"{f.name}/drawer{i + 1}"
            out.append(_surface(name, f, x=xs, y=ys, z=floor, ceil=z_hi - floor))
        return out
    ys = (-w / 2 + t, w / 2 - t)
    x_board = -d / 2 + (0.01 if f.kind == "cabinet" else 0.0)
    tops = [t, *_board_heights(f)]
    ceilings = [*[b - t for b in _board_heights(f)], h - t]
    bodies = (f.name, *f.board_names)
    out = [_surface(f.name, f, x=(-d / 2, d / 2 - t), y=ys, z=t, ceil=ceilings[0] - t)]
    for name, z, ceil in zip(bodies[1:], tops[1:], ceilings[1:], strict=True):
        out.append(_surface(name, f, x=(x_board, d / 2 - t), y=ys, z=z, ceil=ceil - z))
    return out
