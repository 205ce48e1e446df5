"""Put a robot into a scene: merge the robot's MJCF into a scene MJCF (one model, one ``home`` keyframe).

The merge is done on the XML (full numeric precision, no MuJoCo attach warnings): the robot's top-level
bodies (root and mocap anchor) are re-posed by ``base_pose``; its default class, actuators, equality
constraints, contact exclusions and sensors are appended; the scene's ``<compiler>``/``<option>`` rule.
Names must not clash (pass a ``prefix`` to rename every robot element, e.g. ``"robot/"``). The merged
``home`` keyframe holds the scene's rest state (free objects at their spec poses, doors and drawers
closed) and the robot's home pose (a floating root and mocap anchor moved by ``base_pose``).
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError, SceneError
from hsi_retarget.robots.mjcf import num_text, quat_wxyz

_LOG = logging.getLogger(__name__)
#: Attributes of robot elements that name other robot elements (renamed with the prefix).
_REFERENCES = (
    "joint",
    "body1",
    "body2",
    "class",
    "childclass",
    "site",
    "geom1",
    "geom2",
    "body",
    "objname",
    "joint1",
    "joint2",
    "actuator",
    "material",
    "texture",
    "tendon",
)
_SECTIONS = ("actuator", "equality", "contact", "sensor", "tendon")


def _base_transform(base_pose: Sequence[float] | NDArray[np.float64]) -> NDArray[np.float64]:
    arr = np.asarray(base_pose, dtype=float)
    if arr.shape == (3,):
        out = np.eye(4)
        c, s = np.cos(arr[2]), np.sin(arr[2])
        out[:2, :2] = [[c, -s], [s, c]]
        out[:2, 3] = arr[:2]
        return out
    if arr.shape == (4, 4) and np.allclose(arr[:3, :3] @ arr[:3, :3].T, np.eye(3), atol=1e-9):
        return arr.copy()
    raise SceneError(
        f"base_pose must be (x [m], y [m], yaw [rad]) or a (4, 4) rigid transform, got {arr.shape}"
    )


def _robot_xml(robot: str) -> tuple[str, Path]:
    """Robot MJCF text and its path: ``robot`` is a robot name (``dual_ur5e``, ``humanoid``) or a file."""
    path = Path(robot)
    if path.suffix != ".xml":
        from hsi_retarget.robots.model import robot_files

        try:
            path = robot_files(robot)[1]
        except ConfigError as exc:
            raise SceneError(str(exc)) from exc
    if not path.is_file():
        raise SceneError(f"robot MJCF {path} does not exist; give a robot name or an .xml path")
    return path.read_text(encoding="utf-8"), path


def _pose_of(el: ET.Element) -> NDArray[np.float64]:
    out = np.eye(4)
    out[:3, 3] = [float(v) for v in el.get("pos", "0 0 0").split()]
    w, x, y, z = (float(v) for v in el.get("quat", "1 0 0 0").split())
    out[:3, :3] = Rotation.from_quat([x, y, z, w]).as_matrix()
    if any(el.get(a) for a in ("euler", "axisangle", "xyaxes", "zaxis")):
        raise SceneError(
            f"robot body {el.get('name')}: only pos/quat orientations are supported at top level"
        )
    return out


def _set_pose(el: ET.Element, pose: NDArray[np.float64]) -> None:
    el.set("pos", num_text(pose[:3, 3]))
    el.set("quat", num_text(quat_wxyz(pose[:3, :3])))


def _names(root: ET.Element) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for el in root.iter():
        name = el.get("class") if el.tag == "default" else el.get("name")
        if name:
            out.setdefault(el.tag, set()).add(name)
    return out


def _rename(root: ET.Element, prefix: str) -> None:
    for el in root.iter():
        if el.tag == "default" and el.get("class"):
            el.set("class", prefix + str(el.get("class")))
            continue
        if el.get("name"):
            el.set("name", prefix + str(el.get("name")))
        for attr in _REFERENCES:
            if el.get(attr) and not (el.tag == "default" and attr == "class"):
                el.set(attr, prefix + str(el.get(attr)))


def _merged_key(xml: str, robot_model: mujoco.MjModel, base: NDArray[np.float64], prefix: str) -> ET.Element:
    """The merged ``home`` keyframe (scene rest state + robot home)."""
    merged = mujoco.MjModel.from_xml_string(xml)
    key = mujoco.MjData(robot_model)
    mujoco.mj_resetDataKeyframe(robot_model, key, 0)
    qpos, ctrl = merged.qpos0.copy(), np.zeros(merged.nu)
    for j in range(robot_model.njnt):
        name = prefix + robot_model.joint(j).name
        mj = merged.joint(name)
        src, dst = int(robot_model.jnt_qposadr[j]), int(merged.jnt_qposadr[mj.id])
        if robot_model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            local = np.eye(4)
            local[:3, 3] = key.qpos[src : src + 3]
            w, x, y, z = key.qpos[src + 3 : src + 7]
            local[:3, :3] = Rotation.from_quat([x, y, z, w]).as_matrix()
            world = base @ local
            qpos[dst : dst + 7] = np.concatenate([world[:3, 3], quat_wxyz(world[:3, :3])])
        else:
            qpos[dst] = key.qpos[src]
    for a in range(robot_model.nu):
        ctrl[merged.actuator(prefix + robot_model.actuator(a).name).id] = key.ctrl[a]
    mocap = np.flatnonzero(merged.body_mocapid >= 0)
    order = np.argsort(merged.body_mocapid[mocap])
    el = ET.Element("key", name="home")
    el.set("qpos", num_text(qpos))
    if merged.nu:
        el.set("ctrl", num_text(ctrl))
    if merged.nmocap:
        el.set("mpos", num_text(merged.body_pos[mocap[order]].ravel()))
        el.set("mquat", num_text(merged.body_quat[mocap[order]].ravel()))
    return el


def attach_robot(
    scene_mjcf: str,
    robot: str,
    base_pose: Sequence[float] | NDArray[np.float64] = (0.0, 0.0, 0.0),
    *,
    prefix: str = "",
) -> str:
    """One MJCF document (string): the scene with the robot placed at ``base_pose``.

    Args:
        scene_mjcf: scene MJCF text (e.g. :func:`hsi_planning.scene.build_mjcf`).
        robot: robot name (``dual_ur5e``/``dual_arm``, ``humanoid``) or a path to a robot MJCF file.
        base_pose: ``(x [m], y [m], yaw [rad])`` on the floor, or a (4, 4) rigid transform of the robot's
            frame in the world. ``(0, 0, 0)``: at the origin facing +x.
        prefix: prepended to every robot element name (joints, bodies, actuators, classes ...).

    Raises:
        SceneError: bad ``base_pose``, unknown robot, name clashes, or a merged model that does not compile.
    """
    base = _base_transform(base_pose)
    robot_text, robot_path = _robot_xml(robot)
    try:
        scene = ET.fromstring(scene_mjcf)
        rob = ET.fromstring(robot_text)
    except ET.ParseError as exc:
        raise SceneError(f"cannot parse MJCF: {exc}") from exc
    robot_model = mujoco.MjModel.from_xml_path(str(robot_path))
    if robot_model.nkey < 1 or robot_model.key(0).name != "home":
        raise SceneError(f"{robot_path}: the robot MJCF needs a 'home' keyframe first")
    if prefix:
        _rename(rob, prefix)
    scene_names, robot_names = _names(scene), _names(rob)
    clashes = sorted(
        f"{tag} {n}" for tag, names in robot_names.items() for n in names & scene_names.get(tag, set())
    )
    clashes = [c for c in clashes if not c.startswith(("mujoco ", "key "))]
    if clashes:
        raise SceneError(f"robot and scene share names {clashes[:10]}; pass a prefix such as 'robot/'")
    world = scene.find("worldbody")
    rob_world = rob.find("worldbody")
    if world is None or rob_world is None:
        raise SceneError("both the scene and the robot MJCF need a <worldbody>")
    for body in list(rob_world):
        if body.tag == "body":
            _set_pose(body, base @ _pose_of(body))
        world.append(body)
    rob_default = rob.find("default")
    if rob_default is not None:
        scene_default = scene.find("default")
        if scene_default is None:
            scene_default = ET.Element("default")
            scene.insert(0, scene_default)
        scene_default.extend(list(rob_default))
    for tag in _SECTIONS:
        section = rob.find(tag)
        if section is None:
            continue
        target = scene.find(tag)
        if target is None:
            target = ET.SubElement(scene, tag)
        target.extend(list(section))
    for old in scene.findall("keyframe"):
        _LOG.warning("dropping the scene's keyframes (the merged model gets one 'home' key)")
        scene.remove(old)
    try:
        key = _merged_key(ET.tostring(scene, encoding="unicode"), robot_model, base, prefix)
    except ValueError as exc:
        raise SceneError(f"scene + robot {robot} does not compile: {exc}") from exc
    ET.SubElement(scene, "keyframe").append(key)
    ET.indent(scene, space="  ")
    return ET.tostring(scene, encoding="unicode") + "\n"
