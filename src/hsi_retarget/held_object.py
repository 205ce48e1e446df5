"""A grasped object as collision geometry of the hand that holds it (MoveIt's *attached collision object*).

The retargeting's scene leaves out every object the task touches, so without this the IK would carry an
object through a cabinet's top as long as the hand itself passes under it; in MuJoCo the object then
catches on the furniture and wrenches the wrist off its command. From the frame at which the IK has
reached a grasp (:func:`~hsi_retarget.carry_correction.carry_frames`) until the release, the object's
surface points and the spheres inside it along its long axis (:func:`inner_spheres`: a shelf board
thinner than the points' spacing cannot pass between them), fixed to the TCP frame as the hand reached
it (:func:`attach`), keep ``held_margin``
(:class:`~hsi_retarget.ik.IKConfig`) from the scene: :func:`held_rows` adds the linearized distance
constraints of the closest points to the IK step, as :func:`~hsi_retarget.collision.collision_rows` does
for the robot's spheres. The margin shrinks with the hand's contact closeness (1 at the grasp and the
release, where the object rests on its support: no rows there).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from numpy.typing import NDArray

from hsi_planning.errors import RetargetError
from hsi_retarget.scene_distance import SceneDistance

__all__ = ["HeldObject", "attach", "held_rows", "surface_points"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
SPACING = 0.02  #: [m] largest spacing of an object's surface points (one per cell of this size)
MAX_POINTS = 96  #: [-] most surface points of one object
_SAMPLES = 2000  #: [-] surface samples drawn (seeded) before the thinning to one per cell
_MIN_RADIUS = 0.003  #: [m] thinner inner spheres are left out (:func:`inner_spheres`)


@dataclass(frozen=True, eq=False)
class HeldObject:
    """An object held by one hand: points in that hand's TCP frame, each the centre of a sphere of its
    radius (0: a surface point)."""

    name: str  #: the object's name in the scene
    side: str  #: the hand holding it (``left``/``right``)
    points: F64  #: (K, 3) [m] surface points and inner sphere centres in the TCP frame
    #: (K,) [m] sphere radii (empty: all 0, surface points only)
    radii: F64 = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        k = np.asarray(self.points).shape[0]
        radii = np.asarray(self.radii, dtype=np.float64)
        radii = np.zeros(k) if radii.size == 0 else radii
        if radii.shape != (k,) or np.any(radii < 0.0):
            raise RetargetError(f"HeldObject.radii must be ({k},) radii >= 0 m, got shape {radii.shape}")
        object.__setattr__(self, "radii", radii)


def inner_spheres(mesh: trimesh.Trimesh) -> tuple[F64, F64]:
    """Spheres inside ``mesh`` (world frame) along its oriented bounding box's longest axis, one per
    smallest half extent of the box along it (ends inset by that), each as large as fits inside the mesh
    at its centre (a bottle's neck gets smaller ones; none thinner than 3 mm). Surface points about
    :data:`SPACING` apart let a board thinner than that pass between them (an 18 mm shelf board went
    through a held bottle); a slab through the object's middle meets these. Returns centres (S, 3) [m] and
    radii (S,) [m]."""
    box = mesh.bounding_box_oriented
    extents = np.asarray(box.primitive.extents, dtype=np.float64)
    frame = np.asarray(box.primitive.transform, dtype=np.float64)
    order = np.argsort(extents)
    radius = 0.5 * float(extents[order[0]])
    half = 0.5 * float(extents[order[-1]]) - radius
    if radius <= 0.0:
        return np.zeros((0, 3)), np.zeros(0)
    along = np.linspace(-half, half, int(np.ceil(2.0 * half / radius)) + 1)  # half >= 0: one sphere at least
    axis = frame[:3, order[-1]]
    centres = frame[:3, 3] + along[:, None] * axis
    depth, _ = SceneDistance({"object": mesh}, ground=()).query(centres)
    radii = np.minimum(radius, -np.asarray(depth, dtype=np.float64))
    keep = radii > _MIN_RADIUS
    return centres[keep], radii[keep]


def surface_points(mesh: trimesh.Trimesh, spacing: float = SPACING, max_points: int = MAX_POINTS) -> F64:
    """(K, 3) [m] points on the surface of ``mesh`` (world frame), at most one per ``spacing`` [m] cell and
    at most ``max_points`` (the cell grows until they fit); its vertices (corners, rims) come first, then
    seeded surface samples fill the faces between them.

    Raises:
        RetargetError: an empty mesh or a non-positive spacing.
    """
    if not spacing > 0.0 or max_points < 1:
        raise RetargetError(f"surface_points: spacing must be > 0 m and max_points >= 1, got {spacing}")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    if vertices.shape[0] == 0 or len(mesh.faces) == 0:
        raise RetargetError("surface_points: the object's mesh is empty")
    samples = np.asarray(trimesh.sample.sample_surface(mesh, _SAMPLES, seed=0)[0], dtype=np.float64)
    points = np.vstack([vertices, samples])
    cell = spacing
    while True:
        keys = np.floor((points - points.min(axis=0)) / cell).astype(np.int64)
        _, first = np.unique(keys, axis=0, return_index=True)
        if first.shape[0] <= max_points:
            return points[np.sort(first)]
        cell *= 1.25


def attach(name: str, side: str, mesh: trimesh.Trimesh, tcp: F64, shift: F64 | None = None) -> HeldObject:
    """``mesh`` (the object at rest, world frame; moved by ``shift`` (4, 4), e.g. with the drawer it stands
    in) held by the hand ``side`` whose TCP is at ``tcp`` (4, 4) [m] (world)."""
    surface = surface_points(mesh)
    centres, radii = inner_spheres(mesh)
    points = np.vstack([surface, centres])
    if shift is not None:
        points = points @ np.asarray(shift)[:3, :3].T + np.asarray(shift)[:3, 3]
    inv = np.linalg.inv(np.asarray(tcp, dtype=np.float64))
    all_radii = np.concatenate([np.zeros(surface.shape[0]), radii])
    return HeldObject(name, side, points @ inv[:3, :3].T + inv[:3, 3], all_radii)


def held_rows(
    held: HeldObject,
    tcp: F64,
    jacobian: F64,
    layers: list[SceneDistance],
    *,
    margin: float,
    activation: float,
    gain: float,
    max_rows: int,
) -> tuple[F64, F64]:
    """Rows ``A dq >= lower`` keeping ``held``'s points ``margin`` [m] from each scene of ``layers``: the
    ``max_rows`` closest points within ``activation`` [m] beyond the margin, each ``n^T J_p dq >= -gain (d -
    margin)`` with ``J_p`` the point's Jacobian from the TCP frame's ``jacobian`` (6, nv) (world-aligned,
    linear rows first) at the TCP pose ``tcp`` (4, 4). Returns A (k, nv) and lower (k,)."""
    nv = jacobian.shape[1]
    if max_rows <= 0 or not layers:
        return np.zeros((0, nv)), np.zeros(0)
    world = held.points @ tcp[:3, :3].T + tcp[:3, 3]
    found = [layer.query(world) for layer in layers]
    dist = np.concatenate([d - held.radii for d, _ in found])
    normal = np.concatenate([n for _, n in found])
    which = np.tile(np.arange(world.shape[0]), len(layers))
    slack = dist - margin
    near = np.flatnonzero(slack < activation)
    if near.size == 0:
        return np.zeros((0, nv)), np.zeros(0)
    near = near[np.argsort(slack[near])[:max_rows]]
    n, lever = normal[near], world[which[near]] - tcp[:3, 3]
    # n . (v + w x r) = n . v + (r x n) . w
    rows = n @ jacobian[:3] + np.cross(lever, n) @ jacobian[3:]
    return rows, -gain * slack[near]


def near_spheres(
    held: HeldObject,
    tcp: F64,
    centers: F64,
    radii: F64,
    *,
    margin: float,
    activation: float,
    max_rows: int,
) -> tuple[F64, I64, F64, F64]:
    """The ``max_rows`` closest pairs of ``held``'s points (its hand's TCP at ``tcp`` (4, 4)) and robot
    spheres (centres (S, 3) [m], ``radii`` (S,) [m]) within ``activation`` [m] beyond ``margin`` [m]: the
    points (k, 3) [m] (world), sphere indices (k,), unit normals (k, 3) from the sphere to the point and
    gaps beyond the margin (k,) [m]."""
    empty = (np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0))
    if max_rows <= 0 or centers.shape[0] == 0:
        return empty
    world = held.points @ tcp[:3, :3].T + tcp[:3, 3]
    diff = world[:, None, :] - centers[None, :, :]
    dist = np.sqrt(np.einsum("psk,psk->ps", diff, diff))
    gap = dist - radii[None, :] - held.radii[:, None] - margin
    p, s = np.nonzero(gap < activation)
    if p.size == 0:
        return empty
    order = np.argsort(gap[p, s])[:max_rows]
    p, s = p[order], s[order]
    normal = diff[p, s] / np.maximum(dist[p, s], 1e-9)[:, None]
    return world[p], s.astype(np.int64), normal, gap[p, s]
