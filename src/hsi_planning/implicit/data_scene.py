"""Training scenes for the planner: a layout with the target's container opened, rendered and meshed.

For a target inside a closed container the scheduler opens it first, so the training cloud is rendered
in that state: the cabinet's door(s) swung open (hinge at ``door_fraction`` of its range) or the
target's drawer pulled out (slide at ``drawer_fraction`` of its travel, the objects in it moved along).
The ground-truth meshes used by the human-reach model are posed from the same MuJoCo state, so the
demonstration and the cloud agree.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import SceneError
from hsi_planning.perception.cloud import LabelledCloud
from hsi_planning.perception.render import CloudConfig, CloudRenderer, scene_renderer
from hsi_planning.scene.geometry import articulated_parts, scene_meshes, support_of
from hsi_planning.scene.labels import scene_labels
from hsi_planning.scene.spec import SceneSpec

if TYPE_CHECKING:  # mujoco itself is imported after perception has chosen a headless GL backend
    import mujoco

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class OpenedScene:
    """A layout rendered with some articulated parts opened.

    Attributes:
        spec: the layout.
        opened: names of the doors/drawers that were opened.
        cloud: the rendered, labelled world-frame cloud.
        meshes: label name -> world-frame mesh in the opened state [m].
        label_ids: label name -> label id.
    """

    spec: SceneSpec
    opened: tuple[str, ...]
    cloud: LabelledCloud
    meshes: dict[str, trimesh.Trimesh]
    label_ids: dict[str, int]


def parts_to_open(spec: SceneSpec, target: str) -> tuple[str, ...]:
    """Doors of the target's cabinet, or the target's drawer; () for open shelves, counters, tables."""
    support = support_of(spec, target)
    parts = articulated_parts(spec)
    kind = spec.furniture_by_name(support.furniture).kind
    if kind == "cabinet":
        return tuple(p for p in parts if p.startswith(f"{support.furniture}/door"))
    if kind == "drawer_unit":
        return (support.body,) if support.body in parts else ()
    return ()


def _pose(data: mujoco.MjData, bid: int) -> F64:
    out = np.eye(4)
    out[:3, :3] = np.asarray(data.xmat[bid], dtype=np.float64).reshape(3, 3)
    out[:3, 3] = data.xpos[bid]
    return out


def _open_state(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    spec: SceneSpec,
    opened: Sequence[str],
    *,
    door_fraction: float,
    drawer_fraction: float,
) -> None:
    """Set ``data`` to the rest state with ``opened`` parts opened (objects in drawers moved along)."""
    import mujoco

    data.qpos[:] = model.qpos0
    mujoco.mj_forward(model, data)
    rest = {name: _pose(data, model.body(name).id) for name in opened}
    for name in opened:
        jid = model.body_jntadr[model.body(name).id]
        if jid < 0:
            raise SceneError(f"{name!r} has no joint; valid articulated parts: {articulated_parts(spec)}")
        lo, hi = model.jnt_range[jid]
        frac = door_fraction if model.jnt_type[jid] == mujoco.mjtJoint.mjJNT_HINGE else drawer_fraction
        data.qpos[model.jnt_qposadr[jid]] = lo + frac * (hi - lo)
    mujoco.mj_forward(model, data)
    for name in opened:
        shift = _pose(data, model.body(name).id)[:3, 3] - rest[name][:3, 3]
        for obj in spec.objects:
            if support_of(spec, obj.name).body != name:
                continue
            adr = model.jnt_qposadr[model.body_jntadr[model.body(obj.name).id]]
            data.qpos[adr : adr + 3] += shift
    mujoco.mj_forward(model, data)


def render_opened(
    spec: SceneSpec,
    opened: Sequence[str] = (),
    *,
    cloud_config: CloudConfig | None = None,
    door_fraction: float = 0.9,
    drawer_fraction: float = 1.0,
    renderer: tuple[mujoco.MjModel, mujoco.MjData, CloudRenderer] | None = None,
) -> OpenedScene:
    """Render ``spec`` with ``opened`` parts opened; pose the ground-truth meshes the same way.

    Args:
        opened: door/drawer names (:func:`parts_to_open`).
        door_fraction / drawer_fraction: [-] joint position as a fraction of the joint range.
        renderer: a ``scene_renderer(spec)`` triple to reuse (not closed here); None = make and close one.
    """
    import mujoco

    own = renderer is None
    model, data, rend = scene_renderer(spec) if renderer is None else renderer
    try:
        data.qpos[:] = model.qpos0
        mujoco.mj_forward(model, data)
        names = [model.body(i).name for i in range(model.nbody)]
        rest = {n: _pose(data, i) for i, n in enumerate(names)}
        _open_state(model, data, spec, opened, door_fraction=door_fraction, drawer_fraction=drawer_fraction)
        cloud = rend.render_cloud(data, cloud_config or CloudConfig())
        meshes = scene_meshes(spec)
        for i, n in enumerate(names):
            if n not in meshes:
                continue
            delta = _pose(data, i) @ np.linalg.inv(rest[n])
            if not np.allclose(delta, np.eye(4), atol=1e-9):
                meshes[n] = meshes[n].copy().apply_transform(delta)
    finally:
        if own:
            rend.close()
    ids = {lab.name: lab.id for lab in scene_labels(spec)}
    return OpenedScene(spec=spec, opened=tuple(opened), cloud=cloud, meshes=meshes, label_ids=ids)


def wrist_frame(direction: F64, up: F64 | None = None) -> F64:
    """(4,) [x y z w] wrist orientation whose x axis points along ``direction`` (3,) (into the target).

    The z axis is the component of ``up`` (default world +z; world +x when ``direction`` is vertical)
    orthogonal to x; y completes a right-handed frame.
    """
    x = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    hint = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=np.float64)
    if abs(float(x @ hint)) / max(float(np.linalg.norm(hint)), 1e-12) > 0.95:
        hint = np.array([1.0, 0.0, 0.0])
    z = hint - (hint @ x) * x
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.asarray(Rotation.from_matrix(np.column_stack([x, y, z])).as_quat(), dtype=np.float64)


def contact_pose(mesh: trimesh.Trimesh, axis: F64, palm_offset: float) -> tuple[F64, F64]:
    """Wrist contact pose for an object: ``palm_offset`` [m] outside its bounding box along ``axis``.

    Returns:
        (position (3,) [m] = box centre + (box half-extent along axis + palm_offset)·axis,
         quaternion (4,) [x y z w] with the wrist x axis along −axis).
    """
    lo, hi = (np.asarray(b, dtype=np.float64) for b in mesh.bounds)
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    reach = float(np.abs(a) @ half) + palm_offset
    return centre + reach * a, wrist_frame(-a)


def object_radius(mesh: trimesh.Trimesh) -> float:
    """[m] horizontal bounding radius of an object mesh (half the diagonal of its xy box)."""
    lo, hi = mesh.bounds
    return float(0.5 * np.hypot(hi[0] - lo[0], hi[1] - lo[1]))
