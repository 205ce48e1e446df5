"""The scheduler's world model: the scene spec (what is where, what opens how) plus labelled clouds.

The observed cloud shows the scene at rest (doors and drawers closed). For a state with parts opened the
world *predicts* the cloud by rendering the scene's MuJoCo model with those joints set (a door swung to
``door_fraction`` of its range, a drawer pulled to ``drawer_fraction`` of its travel, the objects in the
drawer moved along), the way a person expects the cabinet to look once opened; what the cameras saw of an
opened part at rest moves with it into that cloud (they may not see a pulled-out drawer's front). Objects
that were moved by the task (blockers put aside) are shifted in the cloud and held objects are taken out
of it (:meth:`SceneWorld.state_cloud`).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import SceneError
from hsi_planning.perception import CloudConfig, scene_renderer
from hsi_planning.perception.cloud import LabelledCloud
from hsi_planning.scene.geometry import handle_position, support_of
from hsi_planning.scene.model import object_pose, scene_bodies
from hsi_planning.scene.objects import object_size
from hsi_planning.scene.spec import SceneSpec

_LOG = logging.getLogger(__name__)
F64 = NDArray[np.float64]
DOOR_FRACTION = 0.9  #: [-] a door the schedule opens swings to this fraction of its hinge range
DRAWER_FRACTION = 0.9  #: [-] a drawer the schedule opens is pulled to this fraction of its travel
#: Fewer points than this: an object counts as hidden in the cloud.
MIN_VISIBLE = 30


@dataclass(frozen=True, eq=False)
class PartInfo:
    """A door or drawer: its joint in the world and its handle at rest."""

    name: str  #: part (label) name, e.g. ``cabinet1/door1``
    furniture: str  #: the furniture it belongs to
    kind: str  #: ``hinge`` (door) or ``slide`` (drawer)
    axis: F64  #: (3,) world joint axis (hinge: rotation axis; slide: pull-out direction)
    point: F64  #: (3,) [m] a point on the hinge axis (slide: the body origin)
    open_value: float  #: joint value of the opened state [rad] or [m]
    handle: F64  #: (3,) [m] handle bar centre with the part closed
    width: float  #: [m] door leaf width (hinge to free edge) or drawer front width


@dataclass(frozen=True)
class WorldState:
    """What the task has changed so far: opened parts, moved objects, held objects."""

    opened: frozenset[str] = frozenset()  #: doors/drawers open
    moved: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)  #: object -> shift [m]
    held: frozenset[str] = frozenset()  #: objects in a hand (not in the scene)

    def with_opened(self, part: str, is_open: bool) -> WorldState:
        opened = self.opened | {part} if is_open else self.opened - {part}
        return WorldState(frozenset(opened), dict(self.moved), self.held)

    def with_held(self, obj: str, held: bool) -> WorldState:
        new = self.held | {obj} if held else self.held - {obj}
        return WorldState(self.opened, dict(self.moved), frozenset(new))

    def with_moved(self, obj: str, shift: F64) -> WorldState:
        moved = dict(self.moved)
        moved[obj] = (float(shift[0]), float(shift[1]), float(shift[2]))
        return WorldState(self.opened, moved, self.held)


class SceneWorld:
    """Scene knowledge and predicted clouds for the scheduler (see the module docstring).

    Args:
        spec: the scene.
        observed: the observed cloud at rest (None: rendered from ``spec`` with ``cloud_config``).
        cloud_config: rendering of predicted clouds.
        door_fraction: [-] opened door angle as a fraction of its hinge range.
        drawer_fraction: [-] opened drawer as a fraction of its travel.
    """

    def __init__(
        self,
        spec: SceneSpec,
        observed: LabelledCloud | None = None,
        cloud_config: CloudConfig | None = None,
        door_fraction: float = DOOR_FRACTION,
        drawer_fraction: float = DRAWER_FRACTION,
    ) -> None:
        if not (0.0 < door_fraction <= 1.0 and 0.0 < drawer_fraction <= 1.0):
            raise SceneError("door_fraction and drawer_fraction must be in (0, 1]")
        self.spec = spec
        self.cloud_config = cloud_config or CloudConfig()
        self.door_fraction = door_fraction
        self.drawer_fraction = drawer_fraction
        self._bodies = {b.name: b for b in scene_bodies(spec)}
        self._clouds: dict[frozenset[str], LabelledCloud] = {}
        if observed is not None:
            self._clouds[frozenset()] = observed
        self._parts = {name: self._part(name) for name, b in self._bodies.items() if b.joint is not None}

    # ------------------------------------------------------------------------------------ parts

    def _part(self, name: str) -> PartInfo:
        body = self._bodies[name]
        joint = body.joint
        assert joint is not None
        rot, origin = body.pose[:3, :3], body.pose[:3, 3]
        axis = rot @ np.asarray(joint.axis, dtype=np.float64)
        point = origin + rot @ np.asarray(joint.pos, dtype=np.float64)
        lo, hi = joint.range
        frac = self.door_fraction if joint.kind == "hinge" else self.drawer_fraction
        handle = handle_position(self.spec, name)
        if joint.kind == "hinge":
            radial = handle - point - ((handle - point) @ axis) * axis
            width = float(np.linalg.norm(radial)) + 0.04
        else:
            width = self.spec.furniture_by_name(str(body.parent)).size[0]
        return PartInfo(name, str(body.parent), joint.kind, axis, point, lo + frac * (hi - lo), handle, width)

    @property
    def parts(self) -> dict[str, PartInfo]:
        """Every door and drawer by name."""
        return dict(self._parts)

    def part(self, name: str) -> PartInfo:
        """One door or drawer; :class:`SceneError` lists the valid names otherwise."""
        if name not in self._parts:
            raise SceneError(f"{name!r} is no door or drawer; valid: {sorted(self._parts)}")
        return self._parts[name]

    def part_transform(self, name: str, fraction: float) -> F64:
        """(4, 4) world motion of part ``name`` opened to ``fraction`` [-] of its opened state."""
        info = self.part(name)
        value = fraction * info.open_value
        out = np.eye(4)
        if info.kind == "slide":
            out[:3, 3] = info.axis * value
            return out
        a = info.axis
        k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        rot = np.eye(3) + np.sin(value) * k + (1.0 - np.cos(value)) * (k @ k)
        out[:3, :3] = rot
        out[:3, 3] = info.point - rot @ info.point
        return out

    def handle_at(self, name: str, fraction: float) -> F64:
        """(3,) [m] handle position with part ``name`` opened to ``fraction`` [-] (0 closed, 1 opened)."""
        m = self.part_transform(name, fraction)
        return np.asarray(m[:3, :3] @ self.part(name).handle + m[:3, 3], dtype=np.float64)

    def door_panel(self, name: str, fraction: float) -> F64:
        """(2, 2) [m] floor segment (hinge, free edge) of door ``name`` opened to ``fraction`` [-]."""
        info = self.part(name)
        handle = self.handle_at(name, fraction)
        radial = handle - info.point
        radial[2] = 0.0
        radial /= max(float(np.linalg.norm(radial)), 1e-9)
        return np.array([info.point[:2], info.point[:2] + info.width * radial[:2]])

    def wall_segments(self, length: float = 3.0) -> list[F64]:
        """(2, 2) [m] floor segments along the back faces of cabinets, drawer units, shelves and counters,
        extended ``length`` [m] to each side: the walls such furniture stands against."""
        out = []
        for f in self.spec.furniture:
            if f.kind == "table":
                continue
            frame = self._bodies[f.name].pose
            back = frame[:2, 3] + frame[:2, 0] * (0.5 * f.size[1])
            along = frame[:2, 1] * (0.5 * f.size[0] + length)
            out.append(np.array([back - along, back + along]))
        return out

    # ---------------------------------------------------------------------------------- objects

    def object_kind(self, name: str) -> str:
        return self.spec.object_by_name(name).kind

    def object_size(self, name: str) -> tuple[float, ...]:
        """Box (lx, ly, lz) or round (diameter, height) [m]."""
        return object_size(self.spec.object_by_name(name))

    def object_position(self, name: str, state: WorldState) -> F64:
        """(3,) [m] bottom centre of object ``name`` in ``state`` (drawer pulls and moves applied)."""
        pos = np.asarray(object_pose(self.spec, name)[:3, 3], dtype=np.float64)
        body = support_of(self.spec, name).body
        if body in state.opened and body in self._parts:
            pos = pos + self.part_transform(body, 1.0)[:3, 3]
        return np.asarray(pos + np.asarray(state.moved.get(name, (0.0, 0.0, 0.0))), dtype=np.float64)

    def surface_points(self, name: str, state: WorldState, spacing: float = 0.01) -> F64:
        """(M, 3) [m] points on object ``name``'s surface in ``state`` (about one per ``spacing``² of area),
        sampled from its shape in the spec (seeded): what the cameras would show if nothing hid it."""
        import trimesh

        mesh = self._bodies[name].mesh()
        count = max(50, int(mesh.area / spacing**2))
        pts, _ = trimesh.sample.sample_surface(mesh, count, seed=0)
        rest = np.asarray(object_pose(self.spec, name)[:3, 3], dtype=np.float64)
        return np.asarray(pts, dtype=np.float64) + (self.object_position(name, state) - rest)

    def neighbours(self, name: str) -> list[str]:
        """Objects on the same support as object ``name`` (spec order), itself included."""
        on = self.spec.object_by_name(name).on
        return [o.name for o in self.spec.objects if o.on == on]

    def is_object(self, name: str) -> bool:
        return any(o.name == name for o in self.spec.objects)

    # ----------------------------------------------------------------------------------- clouds

    def cloud(self, opened: Iterable[str] = ()) -> LabelledCloud:
        """The cloud with ``opened`` parts open (observed for none, predicted by rendering otherwise)."""
        key = frozenset(opened)
        unknown = sorted(key - set(self._parts))
        if unknown:
            raise SceneError(f"cannot open {unknown}: not doors or drawers; valid: {sorted(self._parts)}")
        if key not in self._clouds:
            rendered = self._render(key)
            self._clouds[key] = self._with_seen_parts(rendered, key) if key else rendered
        return self._clouds[key]

    def _with_seen_parts(self, cloud: LabelledCloud, opened: frozenset[str]) -> LabelledCloud:
        """``cloud`` plus what the cameras saw of each ``opened`` part at rest, moved with it: from where
        they stand they may not see a pulled-out drawer's front or a swung door's panel, which are still
        there (a planner would reach through the hole)."""
        rest = self.cloud(())
        seen = {v: k for k, v in (rest.label_names or {}).items()}
        ids = {v: k for k, v in (cloud.label_names or {}).items()}
        points, labels = [cloud.points], [cloud.labels]
        for name in sorted(opened):
            if name not in seen or name not in ids:
                continue
            m = self.part_transform(name, 1.0)
            pts = rest.points[rest.labels == seen[name]]
            points.append(pts @ m[:3, :3].T + m[:3, 3])
            labels.append(np.full(len(pts), ids[name], dtype=cloud.labels.dtype))
        if len(points) == 1:
            return cloud
        merged = np.concatenate(labels)
        return LabelledCloud(np.vstack(points), merged, cloud.label_names, cloud.label_classes)

    def _render(self, opened: frozenset[str]) -> LabelledCloud:
        import mujoco

        model, data, renderer = scene_renderer(self.spec)
        with renderer:
            for name in sorted(opened):
                jid = model.body_jntadr[model.body(name).id]
                data.qpos[model.jnt_qposadr[jid]] = self.part(name).open_value
                if self.part(name).kind == "slide":
                    shift = self.part_transform(name, 1.0)[:3, 3]
                    for obj in self.spec.objects:
                        if support_of(self.spec, obj.name).body == name:
                            adr = model.jnt_qposadr[model.body_jntadr[model.body(obj.name).id]]
                            data.qpos[adr : adr + 3] += shift
            mujoco.mj_forward(model, data)
            cloud = renderer.render_cloud(data, self.cloud_config)
        _LOG.debug("rendered the predicted cloud with %s open: %d points", sorted(opened), len(cloud))
        return cloud

    def state_cloud(
        self, state: WorldState, inject: Mapping[str, F64] | None = None, complete: Iterable[str] = ()
    ) -> LabelledCloud:
        """The cloud of ``state``: held objects removed, moved objects shifted.

        ``inject`` maps an object name to world points (M, 3) [m] that replace its points (e.g. a held
        object shown at its placement for a place request). ``complete`` names objects that must be in the
        cloud: one the cameras barely see (fewer than ``MIN_VISIBLE`` points: hidden behind others) is
        replaced by points sampled from its known shape (:meth:`surface_points`).
        """
        base = self.cloud(state.opened)
        inject = dict(inject or {})
        names0 = {v: k for k, v in (base.label_names or {}).items()}
        for obj in complete:
            if obj in inject or obj in state.held or obj not in names0:
                continue
            if int(np.count_nonzero(base.labels == names0[obj])) < MIN_VISIBLE:
                _LOG.debug("%s is hidden from the cameras; using its known shape", obj)
                inject[obj] = self.surface_points(obj, state)
        points = np.array(base.points, dtype=np.float64, copy=True)
        labels = np.array(base.labels, copy=True)
        names = base.label_names or {}
        ids = {v: k for k, v in names.items()}
        for obj, shift in state.moved.items():
            if obj in ids:
                points[labels == ids[obj]] += np.asarray(shift, dtype=np.float64)
        drop = [ids[o] for o in (*state.held, *(inject or {})) if o in ids]
        keep = ~np.isin(labels, drop)
        points, labels = points[keep], labels[keep]
        for obj, pts in (inject or {}).items():
            if obj not in ids:
                raise SceneError(f"cannot show {obj!r} in the cloud: no such label; valid: {sorted(ids)}")
            extra = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
            points = np.vstack([points, extra])
            labels = np.concatenate([labels, np.full(len(extra), ids[obj], dtype=labels.dtype)])
        return LabelledCloud(points, labels, base.label_names, base.label_classes)


def label_points(cloud: LabelledCloud, names: Iterable[str]) -> F64:
    """(M, 3) [m] the points of ``cloud`` carrying any of the label ``names`` (unknown names: none)."""
    table = cloud.label_names or {}
    ids = [k for k, v in table.items() if v in set(names)]
    return np.asarray(cloud.points[np.isin(cloud.labels, ids)], dtype=np.float64)
