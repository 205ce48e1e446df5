"""MJCF export: one self-contained MuJoCo model (primitives only, no asset files) per scene spec.

Body names are the label names (see :mod:`.labels`): ``floor``, furniture carcasses (``cabinet1``),
their parts (``cabinet1/door1``, ``drawer_unit1/drawer2``, ``shelf1/board1``) nested in the carcass,
and free objects by their spec name. Geoms are named ``<body>:<part>``; joints carry the body name.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from hsi_planning.scene.model import FLOOR_HALF_SIZE, scene_bodies
from hsi_planning.scene.shapes import BodyPlan, Prim, matrix_to_quat
from hsi_planning.scene.spec import CameraSpec, SceneSpec

TIMESTEP = 0.002  #: simulation time step [s]
OBJECT_FRICTION_EXTRA = "0.005 0.0001"  #: torsional [m] and rolling [m] friction of objects
SOLREF = "0.005 1"  #: contact time constant [s] and damping ratio [-]
SOLIMP = "0.95 0.99 0.001"  #: contact impedance (min, max, width [m])


def _fmt(values: NDArray[np.float64] | tuple[float, ...] | list[float]) -> str:
    return " ".join(f"{float(v):.9g}" for v in values)


def _set_pose(el: ET.Element, transform: NDArray[np.float64]) -> None:
    """Write ``pos``/``quat`` of a (4, 4) transform, omitting identity parts."""
    if np.any(np.abs(transform[:3, 3]) > 0.0):
        el.set("pos", _fmt(transform[:3, 3]))
    if not np.allclose(transform[:3, :3], np.eye(3), atol=1e-12):
        el.set("quat", _fmt(matrix_to_quat(transform[:3, :3])))


def _geom(parent: ET.Element, body: BodyPlan, prim: Prim, name: str, total_volume: float) -> None:
    el = ET.SubElement(parent, "geom", name=name, type=prim.kind, size=_fmt(prim.size))
    _set_pose(el, prim.matrix)
    el.set("rgba", _fmt(prim.rgba))
    if body.kind == "object":
        el.set("class", "object")
        el.set("mass", f"{body.mass * prim.volume / total_volume:.9g}")
        el.set("friction", f"{body.friction:.6g} {OBJECT_FRICTION_EXTRA}")
    else:
        el.set("class", "furniture")
        if body.joint is not None:
            el.set("density", f"{body.density:.6g}")


def _body(parent: ET.Element, body: BodyPlan, parent_pose: NDArray[np.float64]) -> ET.Element:
    el = ET.SubElement(parent, "body", name=body.name)
    _set_pose(el, np.linalg.inv(parent_pose) @ body.pose)
    if body.kind == "object":
        ET.SubElement(el, "freejoint", name=body.name)
    elif body.joint is not None:
        j = body.joint
        ET.SubElement(
            el,
            "joint",
            name=body.name,
            type=j.kind,
            axis=_fmt(j.axis),
            pos=_fmt(j.pos),
            range=_fmt(j.range),
            limited="true",
            damping=f"{j.damping:.6g}",
            armature="0.01",
            frictionloss="0.05",
        )
    volume = sum(p.volume for p in body.prims)
    used: set[str] = set()
    for prim in body.prims:
        name = f"{body.name}:{prim.part}"
        k = 1
        while name in used:
            k += 1
            name = f"{body.name}:{prim.part}{k}"
        used.add(name)
        _geom(el, body, prim, name, volume)
    return el


def _camera(parent: ET.Element, cam: CameraSpec) -> None:
    pos, target = np.asarray(cam.pos, dtype=float), np.asarray(cam.target, dtype=float)
    fwd = (target - pos) / np.linalg.norm(target - pos)
    up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, fwd)
    ET.SubElement(
        parent,
        "camera",
        name=cam.name,
        mode="fixed",
        pos=_fmt(pos),
        xyaxes=_fmt(np.concatenate([right, cam_up])),
        fovy=f"{cam.fovy:.6g}",
        resolution=f"{cam.resolution[0]} {cam.resolution[1]}",
    )


def _header(root: ET.Element, spec: SceneSpec) -> None:
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    option = ET.SubElement(root, "option", timestep=f"{TIMESTEP}", integrator="implicitfast", cone="elliptic")
    ET.SubElement(option, "flag", multiccd="enable")
    visual = ET.SubElement(root, "visual")
    width = max([640, *(c.resolution[0] for c in spec.cameras)])
    height = max([480, *(c.resolution[1] for c in spec.cameras)])
    ET.SubElement(visual, "global", offwidth=str(width), offheight=str(height))
    ET.SubElement(
        visual, "headlight", ambient="0.35 0.35 0.35", diffuse="0.5 0.5 0.5", specular="0.1 0.1 0.1"
    )
    default = ET.SubElement(root, "default")
    furn = ET.SubElement(default, "default", attrib={"class": "furniture"})
    ET.SubElement(furn, "geom", condim="3", friction="0.8 0.005 0.0001", solref=SOLREF, solimp=SOLIMP)
    obj = ET.SubElement(default, "default", attrib={"class": "object"})
    ET.SubElement(obj, "geom", condim="4", solref=SOLREF, solimp=SOLIMP)
    asset = ET.SubElement(root, "asset")
    ET.SubElement(
        asset, "texture", name="grid", type="2d", builtin="checker", width="512", height="512",
        rgb1="0.55 0.55 0.57", rgb2="0.45 0.45 0.47",
    )  # fmt: skip
    ET.SubElement(asset, "material", name="floor", texture="grid", texrepeat="10 10")


def build_mjcf(spec: SceneSpec) -> str:
    """The scene as one self-contained MJCF document (string)."""
    root = ET.Element("mujoco", model=spec.name)
    _header(root, spec)
    world = ET.SubElement(root, "worldbody")
    ET.SubElement(
        world, "light", name="sun", directional="true", pos="0 0 4", dir="0.3 0.2 -1", castshadow="true"
    )
    ET.SubElement(world, "light", name="fill", pos="-1 0 2.5", dir="1 0 -0.5", diffuse="0.4 0.4 0.4")
    elements: dict[str, tuple[ET.Element, NDArray[np.float64]]] = {}
    for body in scene_bodies(spec):
        if body.kind == "floor":
            floor = ET.SubElement(world, "body", name=body.name)
            h = FLOOR_HALF_SIZE
            ET.SubElement(floor, "geom", name=body.name, type="plane", size=f"{h} {h} 0.05", material="floor",
                          attrib={"class": "furniture"})  # fmt: skip
            continue
        parent_el, parent_pose = elements.get(body.parent or "", (world, np.eye(4)))
        elements[body.name] = (_body(parent_el, body, parent_pose), body.pose)
    for cam in spec.cameras:
        _camera(world, cam)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def write_mjcf(spec: SceneSpec, path: str | Path) -> Path:
    """Write the standalone MJCF file (no assets needed) and return its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(build_mjcf(spec), encoding="utf-8")
    return path
