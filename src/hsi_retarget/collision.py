"""Collision geometry for the IK margins: spheres on the robot's links, a distance query to the scene, and the
linearized distance constraints of the closest sphere pairs (:func:`collision_rows`). Spheres are derived
from the robot description's collision primitives: for each arm, the links between the body and the elbow
joint (upper arm, shoulder, mount; *proximal*: kept off the scene and the other arm, but not checked
against the body they hang from) and every link from the elbow joint's link outwards (forearm, wrist,
gripper body, and the fingers as *tip* spheres, which get a smaller scene margin since they must get close
to what they grasp), and for the body the links that carry the arms (torso, pelvis/base) with their fixed
children (head) and, on a floating robot, the jointed links hanging from them (a humanoid's thighs, which
pass close to drawer fronts and counters). A capsule/cylinder becomes spheres of its radius along its
axis, a box spheres of its smallest half extent over its two larger axes (a finger box: columns of
spheres along its longest axis, each through its part of the cross-section's corners, close enough that
it sticks out at most 1.5 mm;
the box of a gripper's palm, which comes close to the other arm, is covered completely, corners included,
by a grid of spheres bulging at most about 15 mm). Distances to the scene come from
:class:`~hsi_retarget.scene_distance.SceneDistance`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from hsi_planning.errors import RetargetError
from hsi_retarget.candidates import CandidateCache, find_candidates
from hsi_retarget.culling import LinkBounds
from hsi_retarget.robots import Geom, RobotModel
from hsi_retarget.scene_distance import SceneDistance

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
GROUPS = ("left", "right", "body")  #: sphere groups (index = group code)
_BODY = GROUPS.index("body")
#: One more scene for some spheres: (distance query, (S,) True for the spheres that heed it).
SceneLayer = tuple[SceneDistance, NDArray[np.bool_]]
EDGE_RADIUS = 0.05  #: [m] spheres along the edges of a big body box (:func:`_edge_columns`)
EDGE_MIN_HALF = 0.1  #: [m] smallest half extent of a body box that gets edge columns
FINGER_UNCOVERED = 0.0015  #: [m] most a finger box sticks out of its spheres (well inside the tip margin)


@dataclass(frozen=True, eq=False)
class SphereSet:
    """Spheres fixed to robot frames.

    Attributes:
        frame_ids: (S,) pinocchio frame index of the link each sphere is fixed to.
        frames: (S,) the link names.
        centers: (S, 3) [m] sphere centres in their link frames.
        radii: (S,) [m].
        groups: (S,) group code, index into :data:`GROUPS`.
        tips: (S,) True for finger spheres.
        proximal: (S,) True for upper-arm spheres (no arm-vs-body pairs).
        fixed: (S,) True for spheres on an arm's mount (no joint: no pairs with the other arm's mount).
        palm: (S,) True for spheres on a gripper link (the fingers' parent).
    """

    frame_ids: I64
    frames: tuple[str, ...]
    centers: F64
    radii: F64
    groups: I64
    tips: NDArray[np.bool_]
    proximal: NDArray[np.bool_]
    fixed: NDArray[np.bool_]
    palm: NDArray[np.bool_]

    @functools.cached_property
    def everyone(self) -> NDArray[np.bool_]:
        """(S,) True: every sphere (one array per set, so that a cached choice sees the same scene layer)."""
        mask = np.ones(self.radii.shape[0], dtype=bool)
        mask.flags.writeable = False
        return mask

    @functools.cached_property
    def grounded(self) -> NDArray[np.bool_]:
        """(S,) True for the arm spheres: measured with the floor (the body's base stands on it)."""
        mask = self.groups != _BODY
        mask.flags.writeable = False
        return np.asarray(mask)

    @functools.cached_property
    def _supports(self) -> dict[tuple[int, int, int], NDArray[np.bool_]]:
        return {}

    def support(self, model: pin.Model) -> NDArray[np.bool_]:
        """(S, nv) True where a velocity of ``model`` (the model the spheres were made for) moves the
        sphere: the joints from the root to its link's joint (computed once per model)."""
        key = (id(model), model.nv, model.njoints)  # the model's identity and shape
        if key not in self._supports:
            mask = np.zeros((self.radii.shape[0], model.nv), dtype=bool)
            for s, fid in enumerate(self.frame_ids.tolist()):
                for j in model.supports[model.frames[fid].parentJoint]:
                    if j > 0:
                        mask[s, model.idx_vs[j] : model.idx_vs[j] + model.nvs[j]] = True
            mask.flags.writeable = False
            self._supports[key] = mask
        return self._supports[key]

    def of(self, group: str) -> I64:
        """Indices of the spheres of ``group`` (``left``, ``right`` or ``body``)."""
        return np.flatnonzero(self.groups == GROUPS.index(group)).astype(np.int64)

    def world(self, data: pin.Data) -> F64:
        """(S, 3) [m] sphere centres in the world; needs ``data.oMf`` up to date."""
        unique, inverse = np.unique(self.frame_ids, return_inverse=True)
        placements = [data.oMf[int(fid)] for fid in unique]
        rot = np.stack([p.rotation for p in placements])[inverse]
        pos = np.stack([p.translation for p in placements])[inverse]
        return np.asarray(np.einsum("sij,sj->si", rot, self.centers) + pos)

    def pairs(self) -> I64:
        """(P, 2) sphere index pairs checked for self-collision: left arm vs right arm, each arm below its
        upper arm vs body."""
        left, right, body = self.of("left"), self.of("right"), self.of("body")
        distal = [a[~self.proximal[a]] for a in (left, right)]
        blocks = [
            np.array(np.meshgrid(a, b, indexing="ij")).reshape(2, -1).T
            for a, b in ((left, right), (distal[0], body), (distal[1], body))
        ]
        blocks[0] = blocks[0][~(self.fixed[blocks[0][:, 0]] & self.fixed[blocks[0][:, 1]])]
        return np.concatenate(blocks).astype(np.int64) if blocks else np.zeros((0, 2), dtype=np.int64)


def _covering_grid(pose: F64, half_ext: F64, max_per_axis: int) -> list[tuple[F64, float]]:
    """Spheres through every corner of their grid cell: the box (half extents (3,) [m]) is inside them."""
    cell = max(0.5 * float(half_ext.min()), 0.0125)
    counts = [min(max_per_axis, max(1, math.ceil(float(h) / cell))) for h in half_ext]
    halves = half_ext / np.asarray(counts)
    radius = float(np.linalg.norm(halves))
    grids = [np.linspace(-(h - c), h - c, n) for h, c, n in zip(half_ext, halves, counts, strict=True)]
    return [
        (pose[:3, :3] @ np.array([u, v, w]) + pose[:3, 3], radius)
        for u in grids[0]
        for v in grids[1]
        for w in grids[2]
    ]


def _finger_column(pose: F64, half_ext: F64) -> list[tuple[F64, float]]:
    """Spheres in columns along a finger box's longest axis, as many side by side as make each column's
    cross-section about square (a thin finger stays thin), each sphere through the corners of its column's
    cross-section and as close along the axis as leaves no point of the box more than
    :data:`FINGER_UNCOVERED` outside them (the ends stick out ``radius - spacing / 2``)."""
    order = np.argsort(half_ext)
    thin, wide, half = (float(half_ext[k]) for k in order)
    columns = max(1, math.ceil(wide / thin - 1e-9))
    part = wide / columns  # half width of one column
    corner = float(np.hypot(part, thin))
    reach = math.sqrt((corner + FINGER_UNCOVERED) ** 2 - corner**2)  # covered this far either side
    n = max(1, math.ceil((2.0 * half - 2.0 * reach) / (2.0 * reach)) + 1)
    along = np.linspace(-(half - reach), half - reach, n) if n > 1 else np.zeros(1)
    across = np.linspace(-(wide - part), wide - part, columns) if columns > 1 else np.zeros(1)
    ax_along, ax_across = np.eye(3)[order[2]], np.eye(3)[order[1]]
    return [
        (pose[:3, :3] @ (u * ax_along + v * ax_across) + pose[:3, 3], corner) for u in along for v in across
    ]


def _edge_columns(pose: F64, half_ext: F64) -> list[tuple[F64, float]]:
    """Columns of :data:`EDGE_RADIUS` spheres along the four edges parallel to the smallest axis of a big
    box (smallest half extent >= :data:`EDGE_MIN_HALF`; e.g. a mobile base's chassis), whose spheres of the
    smallest half extent leave its corners open. The edges lie on them (they bulge 15 mm out of the faces);
    the 8 corners stay within 6 mm of them, well inside the scene margin."""
    thin = int(np.argmin(half_ext))
    if half_ext[thin] < EDGE_MIN_HALF:
        return []
    inset = EDGE_RADIUS / math.sqrt(2.0)  # the edge lies on the sphere
    axes = [a for a in range(3) if a != thin]
    span = float(half_ext[thin]) - 0.5 * EDGE_RADIUS
    heights = np.linspace(-span, span, max(2, math.ceil(2.0 * span / EDGE_RADIUS) + 1))
    out = []
    for su in (-1.0, 1.0):
        for sv in (-1.0, 1.0):
            for h in heights:
                local = np.zeros(3)
                local[axes[0]] = su * (half_ext[axes[0]] - inset)
                local[axes[1]] = sv * (half_ext[axes[1]] - inset)
                local[thin] = h
                out.append((pose[:3, :3] @ local + pose[:3, 3], EDGE_RADIUS))
    return out


def _geom_spheres(
    geom: Geom, max_per_axis: int, finger: bool = False, palm: bool = False
) -> list[tuple[F64, float]]:
    """(centre (3,) in the link frame [m], radius [m]) covering one primitive."""
    pose = np.asarray(geom.pose, dtype=np.float64)
    if palm and geom.kind == "box":
        return _covering_grid(pose, np.asarray(geom.size, dtype=np.float64), max_per_axis)
    if finger and geom.kind == "box":
        return _finger_column(pose, np.asarray(geom.size, dtype=np.float64))
    if geom.kind == "sphere":
        return [(pose[:3, 3].copy(), float(geom.size[0]))]
    if geom.kind in ("capsule", "cylinder"):
        radius, half = float(geom.size[0]), float(geom.size[1])
        n = min(max_per_axis, max(2, math.ceil(2.0 * half / radius) + 1))
        return [
            (pose[:3, :3] @ np.array([0.0, 0.0, u]) + pose[:3, 3], radius)
            for u in np.linspace(-half, half, n)
        ]
    half_ext = np.asarray(geom.size, dtype=np.float64)
    thin = int(np.argmin(half_ext))
    radius = float(half_ext[thin])
    axes = [a for a in range(3) if a != thin]
    grids = []
    for a in axes:
        n = min(max_per_axis, max(1, math.ceil(half_ext[a] / radius)))
        grids.append(np.linspace(-(half_ext[a] - radius), half_ext[a] - radius, n) if n > 1 else np.zeros(1))
    out = []
    for u in grids[0]:
        for v in grids[1]:
            local = np.zeros(3)
            local[axes[0]], local[axes[1]] = u, v
            out.append((pose[:3, :3] @ local + pose[:3, 3], radius))
    return out


def robot_spheres(robot: RobotModel, max_per_axis: int = 12) -> SphereSet:
    """The collision spheres of ``robot`` (see the module docstring for which links get them)."""
    desc = robot.description
    links = {link.name: link for link in desc.links}
    finger_joints = {j for side in robot.gripper_joints.values() for j in side}
    owner = {j.name: link.name for link in desc.links for j in link.joints}
    selected: list[tuple[str, str]] = []  # (link, group)
    arm_roots: set[str] = set()
    upper: set[str] = set()
    for side in ("left", "right"):
        joints = robot.arm_joints[side]
        elbow = next((j for j in joints if "elbow" in j), joints[len(joints) // 2])
        start = owner[elbow]
        arm_roots.add(str(links[owner[joints[0]]].parent))
        parent = links[start].parent
        while parent is not None and links[parent].group == side:  # upper arm, shoulder, arm mount
            upper.add(parent)
            selected.append((parent, side))
            parent = links[parent].parent
        chain = {start}
        for link in desc.links:  # parents come first: one pass collects the subtree
            if link.parent in chain:
                chain.add(link.name)
        selected += [(n, side) for n in sorted(chain)]
    carriers: set[str] = set()
    for root in arm_roots:
        name: str | None = root
        while name is not None and links[name].group != "body":  # up to the arm's body carrier
            name = links[name].parent
        while name is not None and links[name].group == "body":
            carriers.add(name)
            name = links[name].parent
    carriers |= {
        link.name
        for link in desc.links
        if link.parent in carriers and not link.joints and link.group == "body"
    }
    selected += [(n, "body") for n in sorted(carriers)]
    if robot.floating:  # a humanoid's thighs: they pass close to fronts and counters it stands at
        legs = {
            link.name
            for link in desc.links
            if link.parent in carriers and link.joints and link.group == "body" and link.name not in carriers
        }
        selected += [(n, "body") for n in sorted(legs)]
    finger_links = {link.name for link in desc.links if any(j.name in finger_joints for j in link.joints)}
    palms = {links[n].parent for n in finger_links}
    frame_ids, frames, centers, radii, groups = [], [], [], [], []
    tips, proximal, fixed, palm = [], [], [], []
    for name, group in selected:
        finger = name in finger_links
        for geom in links[name].geoms:
            found = _geom_spheres(geom, max_per_axis, finger, name in palms)
            if group == "body" and geom.kind == "box":
                found += _edge_columns(np.asarray(geom.pose), np.asarray(geom.size, dtype=np.float64))
            for centre, radius in found:
                tips.append(finger)
                proximal.append(name in upper)
                fixed.append(name in upper and not links[name].joints)
                palm.append(name in palms)
                frame_ids.append(robot.model.getFrameId(name, pin.FrameType.BODY))
                frames.append(name)
                centers.append(centre)
                radii.append(radius)
                groups.append(GROUPS.index(group))
    if not radii:
        raise RetargetError(f"robot {robot.name}: no collision primitives on the arm links")
    return SphereSet(
        np.array(frame_ids, dtype=np.int64),
        tuple(frames),
        np.array(centers, dtype=np.float64),
        np.array(radii, dtype=np.float64),
        np.array(groups, dtype=np.int64),
        np.array(tips, dtype=bool),
        np.array(proximal, dtype=bool),
        np.array(fixed, dtype=bool),
        np.array(palm, dtype=bool),
    )


def collision_rows(
    model: pin.Model,
    data: pin.Data,
    spheres: SphereSet,
    pairs: I64,
    scene: SceneDistance | None,
    *,
    margins: tuple[float, float, float],
    activation: float,
    gain: float,
    max_rows: int,
    bounds: LinkBounds | None = None,
    extra: SceneLayer | None = None,
    cache: CandidateCache | None = None,
    extra_margin: F64 | None = None,
    world: tuple[F64, F64] | None = None,
    inside: list[tuple[I64, F64, F64]] | None = None,
) -> tuple[F64, F64, float]:
    """Linearized clearance constraints ``A dq >= lower`` for one IK step.

    ``data`` must hold the frame placements and joint Jacobians of the step's configuration. Every sphere
    near the scene and every pair of ``pairs`` (P, 2) closer than ``activation`` [m] beyond its margin
    (``margins`` = scene, finger tip, self [m]) is a candidate; the ``max_rows`` closest get a row
    ``n^T (J_a - J_b) dq >= -gain (d - margin)`` (a velocity damper: one step closes at most ``gain`` of the
    gap). The pairs that may be near are picked from sphere-centre distances computed at once (only those
    of the pairs when ``pairs`` is ``bounds.pairs``, the very array; else all of them), and ``bounds``
    (built from the same spheres) skips the links that cannot be near the scene (same result, cheaper).
    ``extra`` = (scene, spheres (S,) that heed it): one more scene, e.g. an opened door that one hand
    holds. ``cache`` keeps the culled candidates across calls (:mod:`hsi_retarget.candidates`; same
    result). ``extra_margin`` (S,) [m], >= 0: more scene margin per sphere. ``world``: ``bounds.world`` of
    ``data`` when already computed. ``inside``: gets (spheres, gaps [m] (negative), unit normals (., 3)) of
    the sphere-scene candidates inside their margin, all of them. Returns A (k, nv), lower (k,) and the
    smallest gap [m] (``inf`` without candidates).
    """
    links: F64 | None
    if world is not None and bounds is not None:
        links, centers = world
    else:
        links, centers = bounds.world(data, spheres) if bounds is not None else (None, spheres.world(data))
    ia, ib, gaps, dirs = find_candidates(
        spheres,
        centers,
        pairs,
        scene_layers(spheres, scene, extra),
        spheres.grounded,  # the base stands on the floor: body spheres ignore it
        margins=margins,
        activation=activation,
        bounds=bounds,
        links=links,
        cache=cache,
        extra_margin=extra_margin,
    )
    if inside is not None:
        deep = (ib < 0) & (gaps < 0.0)
        inside.append((ia[deep], gaps[deep], dirs[deep]))
    if gaps.size == 0:
        return np.zeros((0, model.nv)), np.zeros(0), math.inf
    if max_rows <= 0:  # no rows asked for: the smallest gap is still reported
        return np.zeros((0, model.nv)), np.zeros(0), float(gaps.min())
    order = np.argsort(gaps)[:max_rows]
    ia, ib, dirs = ia[order], ib[order], dirs[order]
    both = point_rows(
        model, data, spheres, centers, idx=np.concatenate([ia, ib]), dirs=np.vstack([dirs, -dirs])
    )
    rows = both[: ia.shape[0]] + both[ia.shape[0] :]
    return rows, -gain * gaps[order], float(gaps[order[0]])


def min_gap(
    spheres: SphereSet,
    centers: F64,
    pairs: I64,
    scene: SceneDistance | None,
    margins: tuple[float, float, float],
    *,
    activation: float = math.inf,
    bounds: LinkBounds | None = None,
    links: F64 | None = None,
    extra: SceneLayer | None = None,
    cache: CandidateCache | None = None,
) -> float:
    """[m] smallest clearance minus its margin over the spheres (world ``centers`` (S, 3)) against the
    scene and over ``pairs`` (P, 2) (``margins`` = scene, finger tip, self [m]); ``inf`` with neither,
    or when nothing is within ``activation`` [m] beyond its margin. ``bounds`` (with ``links``, their world
    centres (F, 3) of the same configuration, :meth:`LinkBounds.world`) culls as in :func:`collision_rows`,
    ``cache`` too."""
    gaps = find_candidates(
        spheres,
        centers,
        pairs,
        scene_layers(spheres, scene, extra),
        spheres.grounded,
        margins=margins,
        activation=activation,
        bounds=bounds,
        links=links,
        cache=cache,
    )[2]
    return float(gaps.min(initial=math.inf))


def scene_layers(
    spheres: SphereSet, scene: SceneDistance | None, extra: SceneLayer | None
) -> list[SceneLayer]:
    """The scene (every sphere heeds it) and the ``extra`` layer, those present."""
    layers: list[SceneLayer] = [] if scene is None else [(scene, spheres.everyone)]
    return layers + ([] if extra is None else [extra])


def point_rows(
    model: pin.Model, data: pin.Data, spheres: SphereSet, centers: F64, *, idx: I64, dirs: F64
) -> F64:
    """Rows (k, nv): ``dirs[k]`` (3,) times the point Jacobian of sphere ``idx[k]`` (zero where -1), from the
    joint Jacobians in ``data.J`` (world frame: the velocity of the point at the origin v and the angular
    velocity w per column): ``d . (v + w x p) = d . v + (p x d) . w`` on the joints that move the sphere."""
    rows = np.zeros((idx.shape[0], model.nv))
    used = idx >= 0
    if not used.any():
        return rows
    jac = data.J
    d, p = dirs[used], centers[idx[used]]
    lever = np.column_stack(  # p x d (np.cross's formula, without its overhead)
        (
            p[:, 1] * d[:, 2] - p[:, 2] * d[:, 1],
            p[:, 2] * d[:, 0] - p[:, 0] * d[:, 2],
            p[:, 0] * d[:, 1] - p[:, 1] * d[:, 0],
        )
    )
    rows[used] = (d @ jac[:3] + lever @ jac[3:]) * spheres.support(model)[idx[used]]
    return rows
