"""Scene and robot drawing of the web UI: viser primitives built from a MuJoCo world, posed live.

Every geom of a :class:`~hsi_retarget.sim_check.SimWorld` except planes (the floor is a grid) becomes a
viser mesh in its geom frame (boxes, spheres, capsules, cylinders, ellipsoids, meshes); :meth:`SceneView.
update` re-poses the moving ones (robot, free objects, doors and drawers) from ``data.geom_xpos/xmat``.
The labelled scene cloud, the selected target (highlighted), the placement marker, the schedule's
keyframes, the planned wrist paths (learned and, when toggled, the minimum-jerk baseline planned on the
same requests, :mod:`hsi_nodes.ui.minjerk_overlay`) and the robot's commanded TCP paths are drawn on top.

Clicks are hit-tested against the scene's rest-state meshes (:func:`~hsi_planning.scene.scene_meshes`,
floor excluded): :meth:`SceneView.hit` turns a camera ray into the clicked surface point [m].
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import viser

    from hsi_nodes.ui.minjerk_overlay import MinJerkPath
    from hsi_planning.perception import LabelledCloud
    from hsi_planning.scene import SceneSpec
    from hsi_planning.scheduler import Schedule
    from hsi_retarget.sim_check import SimWorld

__all__ = ["SceneView", "label_colors", "project_to_screen"]

_log = logging.getLogger(__name__)

F64 = NDArray[np.float64]
_HIGHLIGHT = (255, 200, 0)
_HAND_COLORS = {"left": (40, 110, 230), "right": (220, 50, 50)}
_MINJERK_COLORS = {"left": (120, 200, 255), "right": (255, 160, 120)}


def label_colors(labels: NDArray[np.int32]) -> NDArray[np.uint8]:
    """(N, 3) uint8 colours of label ids (N,): a fixed hash per id, grey for unlabelled (-1)."""
    ids = np.asarray(labels, dtype=np.int64)
    rgb = np.stack([(ids * 97 + 40) % 200, (ids * 57 + 90) % 200, (ids * 151 + 60) % 200], axis=1) + 40
    rgb[ids < 0] = 150
    return np.asarray(rgb, dtype=np.uint8)


def project_to_screen(
    point: ArrayLike, position: F64, wxyz: F64, fov: float, aspect: float
) -> tuple[float, float]:
    """Normalised screen coordinates (u, v) in [0, 1] (0, 0 = upper left) of world ``point`` [m] seen by
    a viser camera at ``position`` [m] with orientation ``wxyz`` (OpenCV: +z forward, +y down), vertical
    field of view ``fov`` [rad] and width/height ``aspect`` [-]."""
    w, x, y, z = (float(v) for v in wxyz)
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    cam = rot.T @ (np.asarray(point, dtype=np.float64) - np.asarray(position, dtype=np.float64))
    half = float(np.tan(0.5 * fov))
    u = 0.5 + 0.5 * cam[0] / (cam[2] * half * aspect)
    v = 0.5 + 0.5 * cam[1] / (cam[2] * half)
    return float(u), float(v)


def _wxyz(xmat: NDArray[np.floating[Any]]) -> F64:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.asarray(xmat, dtype=np.float64).reshape(9))
    return quat


def _geom_mesh(model: mujoco.MjModel, g: int) -> Any:
    """The ``trimesh.Trimesh`` of geom ``g`` in its own frame, or None for planes and height fields."""
    kind, size = int(model.geom_type[g]), np.asarray(model.geom_size[g], dtype=np.float64)
    gt = mujoco.mjtGeom
    if kind == gt.mjGEOM_BOX:
        return trimesh.creation.box(extents=2.0 * size)
    if kind == gt.mjGEOM_SPHERE:
        return trimesh.creation.icosphere(subdivisions=2, radius=float(size[0]))
    if kind == gt.mjGEOM_ELLIPSOID:
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        mesh.apply_scale(size)
        return mesh
    if kind == gt.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(height=2.0 * float(size[1]), radius=float(size[0]), count=[12, 12])
    if kind == gt.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=float(size[0]), height=2.0 * float(size[1]), sections=16)
    if kind == gt.mjGEOM_MESH:
        m = int(model.geom_dataid[g])
        va, vn = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
        fa, fn = int(model.mesh_faceadr[m]), int(model.mesh_facenum[m])
        return trimesh.Trimesh(model.mesh_vert[va : va + vn].copy(), model.mesh_face[fa : fa + fn].copy())
    return None


class SceneView:
    """The drawn scene of one viser server (see the module docstring). Thread safe.

    Args:
        server: the viser server.
        world: an idle MuJoCo world of the scene and robot (its rest state is drawn first).
        spec: the scene spec (click hit-testing).
        cloud: the labelled scene cloud (drawn as points).
        max_points: at most this many cloud points are drawn (an even stride through the cloud) [-].
    """

    def __init__(
        self,
        server: viser.ViserServer,
        world: SimWorld,
        spec: SceneSpec,
        cloud: LabelledCloud,
        max_points: int = 50000,
    ) -> None:
        from hsi_planning.scene import scene_meshes
        from hsi_retarget.sim_check.world import KIND_ROBOT

        self._server = server
        self._lock = threading.Lock()
        model = world.model
        scene = server.scene
        scene.set_up_direction("+z")
        scene.add_grid("/floor", width=8.0, height=8.0, cell_size=0.5, position=(0.0, 0.0, 0.0))
        stride = max(1, -(-cloud.points.shape[0] // max(1, max_points)))
        colors = label_colors(cloud.labels[::stride])
        points = np.asarray(cloud.points[::stride], dtype=np.float32)
        self.cloud = scene.add_point_cloud("/cloud", points, colors, point_size=0.006 * np.sqrt(stride))
        self._handles: dict[int, Any] = {}
        self._colors: dict[int, tuple[int, int, int]] = {}
        self._owner: dict[int, str] = {}
        moving: list[int] = []
        for g in range(model.ngeom):
            rgba = model.geom_rgba[g]
            mesh = _geom_mesh(model, g)
            if mesh is None or rgba[3] <= 0.0:
                continue
            color = (int(rgba[0] * 255), int(rgba[1] * 255), int(rgba[2] * 255))
            owner = str(world.geom_owner[g])
            robot = int(world.geom_kind[g]) == KIND_ROBOT
            root = "robot" if robot else ("objects" if owner else "furniture")
            self._handles[g] = scene.add_mesh_simple(
                f"/{root}/g{g}",
                np.asarray(mesh.vertices, dtype=np.float32),
                np.asarray(mesh.faces, dtype=np.uint32),
                color=color,
                opacity=None if robot or owner else 0.85,
                position=np.asarray(world.data.geom_xpos[g], dtype=np.float64),
                wxyz=_wxyz(world.data.geom_xmat[g]),
            )
            self._colors[g], self._owner[g] = color, owner
            if robot or owner:
                moving.append(g)
        self._moving = np.asarray(moving, dtype=np.int64)
        self._rest_pos = np.array(world.data.geom_xpos, dtype=np.float64, copy=True)
        self._rest_mat = np.array(world.data.geom_xmat, dtype=np.float64, copy=True)
        meshes = [m for name, m in scene_meshes(spec).items() if name != "floor"]
        self._hit_mesh: Any = trimesh.util.concatenate(meshes)
        self._marker = scene.add_icosphere(
            "/place", radius=0.025, color=(0, 200, 80), position=(0.0, 0.0, -1.0), visible=False
        )
        self._drawn: list[Any] = []
        self._minjerk: list[Any] = []
        _log.info("scene view: %d geoms drawn (%d moving)", len(self._handles), self._moving.size)

    # ----------------------------------------------------------------------------------- clicking

    def hit(self, origin: ArrayLike, direction: ArrayLike) -> F64 | None:
        """(3,) [m] the nearest scene surface point on the ray, or None when it hits nothing."""
        o = np.asarray(origin, dtype=np.float64).reshape(1, 3)
        d = np.asarray(direction, dtype=np.float64).reshape(1, 3)
        locations, _, _ = self._hit_mesh.ray.intersects_location(o, d, multiple_hits=True)
        if len(locations) == 0:
            return None
        dist = np.linalg.norm(locations - o, axis=1)
        return np.array(locations[int(np.argmin(dist))], dtype=np.float64)

    def highlight(self, target: str) -> None:
        """Colour the geoms of object ``target`` (``''``: none) in the highlight colour."""
        with self._lock:
            for g, handle in self._handles.items():
                if self._owner[g]:
                    handle.color = _HIGHLIGHT if self._owner[g] == target and target else self._colors[g]

    def mark_place(self, point: ArrayLike | None) -> None:
        """Show the placement marker at ``point`` [m] (None hides it)."""
        with self._lock:
            self._marker.visible = point is not None
            if point is not None:
                self._marker.position = np.asarray(point, dtype=np.float64)

    # ------------------------------------------------------------------------------------ posing

    def update(self, geom_xpos: F64, geom_xmat: F64) -> None:
        """Re-pose the moving geoms from (ngeom, 3) [m] positions and (ngeom, 9) rotation matrices."""
        with self._lock, self._server.atomic():
            for g in self._moving:
                handle = self._handles[int(g)]
                handle.position = geom_xpos[g]
                handle.wxyz = _wxyz(geom_xmat[g])

    def reset(self) -> None:
        """Back to the rest state (robot at its start, objects where they were)."""
        self.update(self._rest_pos, self._rest_mat)

    # ----------------------------------------------------------------------------------- planning

    def clear_plan(self) -> None:
        """Remove the drawn keyframes and paths."""
        with self._lock:
            for handle in (*self._drawn, *self._minjerk):
                handle.remove()
            self._drawn, self._minjerk = [], []

    def _line(self, name: str, points: F64, color: tuple[int, int, int], width: float) -> Any:
        pts = np.asarray(points, dtype=np.float32)
        segments = np.stack([pts[:-1], pts[1:]], axis=1)
        return self._server.scene.add_line_segments(
            name, segments, colors=color, thickness=width, thickness_units="screen"
        )

    def draw_schedule(self, schedule: Schedule) -> None:
        """Draw the schedule's wrist keyframes and planned (learned) wrist paths, replacing earlier ones."""
        self.clear_plan()
        with self._lock:
            frames = [k for k in schedule.keyframes if k.key_joint.endswith("wrist")]
            if frames:
                pos = np.array([k.position for k in frames], dtype=np.float32)
                col = np.array([_HAND_COLORS.get(k.hand, (90, 90, 90)) for k in frames], dtype=np.uint8)
                self._drawn.append(
                    self._server.scene.add_point_cloud(
                        "/plan/keyframes", pos, col, point_size=0.03, point_shape="diamond"
                    )
                )
            for i, seg in enumerate(schedule.segments):
                traj = seg.trajectory
                if traj.position.shape[0] < 2:
                    continue
                color = _HAND_COLORS.get(traj.hand, (90, 90, 90))
                self._drawn.append(self._line(f"/plan/learned/s{i}", traj.position, color, 3.0))

    def draw_minjerk(self, paths: Sequence[MinJerkPath], visible: bool) -> None:
        """Draw the minimum-jerk comparison paths (replacing earlier ones), shown when ``visible``."""
        with self._lock:
            for handle in self._minjerk:
                handle.remove()
            self._minjerk = []
            for path in paths:
                if path.position.shape[0] < 2:
                    continue
                color = _MINJERK_COLORS.get(path.hand, (150, 150, 150))
                handle = self._line(f"/plan/minjerk/s{path.index}", path.position, color, 2.0)
                handle.visible = visible
                self._minjerk.append(handle)

    @property
    def minjerk_handles(self) -> list[Any]:
        """The drawn minimum-jerk line handles (a copy of the list)."""
        with self._lock:
            return list(self._minjerk)

    def show_minjerk(self, visible: bool) -> None:
        """Toggle the minimum-jerk comparison paths."""
        with self._lock:
            for handle in self._minjerk:
                handle.visible = visible

    def draw_robot_paths(self, paths: Mapping[str, F64]) -> None:
        """Draw the robot's commanded TCP paths, side -> (K, 3) [m]."""
        with self._lock:
            for side, pts in paths.items():
                if pts.shape[0] >= 2:
                    color = tuple(int(0.5 * c) for c in _HAND_COLORS.get(side, (90, 90, 90)))
                    self._drawn.append(self._line(f"/plan/robot_tcp/{side}", pts, color, 1.5))  # type: ignore[arg-type]
