"""The cases of ``benchmarks/pick_place.py``: a randomized layout, the object to pick and a free spot to put
it on, turned into a :class:`~hsi_nodes.demo.tasks.DemoTask`.

Task templates follow the demo (``hsi_nodes.demo.tasks``) on every scene family where its tasks make sense:
the counter pick-and-place, the door-cabinet pick-and-place and the drawer pick in ``kitchen``, the
narrow-shelf pick with a blocker, and the cluttered-drawer pick. Layouts come from the seeded generator
(:func:`hsi_planning.scene.generate_layouts`, seeds ≥ 100000 never used in training) with the template's
object as the kept, reachable target, without and with reshaped containers. The place click is drawn on
the template's support surface of the layout: 10–18 cm behind its front edge (where the demo's clicks are),
clear of the objects resting on it and at least 20 cm from where the picked object starts, and clickable:
the layout's rendered cloud has a point within the click radius of it (a board above the cameras' view,
e.g. the top board of a reshaped tall shelf, gets no clicks; the layout is replaced). The object is named
(as the demo's hidden objects are), not clicked: the benchmark measures planning and execution, not click
resolution.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from hsi_planning.errors import SceneError
from hsi_planning.scene import LayoutConfig, SceneSpec, generate_layouts
from hsi_planning.scene.model import object_pose, support_surface
from hsi_planning.scene.objects import object_size
from hsi_planning.scene_paths import load_scene

FRONT_DEPTH = (0.10, 0.18)  #: [m] place spot distance behind the support's front edge
MIN_MOVE = 0.20  #: [m] the place spot is at least this far (horizontally) from the object's start
GAP = 0.04  #: [m] horizontal gap kept between the placed object and the objects on the support
SIDE_MARGIN = 0.03  #: [m] gap kept to the support's side edges
HEADROOM = 0.04  #: [m] free height needed above the placed object under a board
SPOT_TRIES = 200  #: [-] place spot samples before the layout is skipped
SPARE_LAYOUTS = 12  #: [-] extra layouts per group for those without a free, clickable place spot


@dataclass(frozen=True)
class Template:
    """A demo-like pick-and-place: ``obj`` of scene ``family`` onto support ``place_on``."""

    name: str
    family: str
    obj: str
    place_on: str
    description: str


TEMPLATES: tuple[Template, ...] = (
    Template("counter_can", "kitchen", "can1", "counter1", "counter pick-and-place (can1)"),
    Template("cabinet_bottle", "kitchen", "bottle2", "shelf1/board2", "door cabinet -> shelf (bottle2)"),
    Template("drawer_mug", "kitchen", "mug2", "counter1", "closed drawer -> counter (mug2)"),
    Template("narrow_shelf_can", "narrow_shelf", "can1", "shelf1/board3", "narrow shelf, blocker (can1)"),
    Template("drawer_can", "cluttered_drawer", "can1", "counter1", "cluttered drawer -> counter (can1)"),
)


@dataclass(frozen=True)
class Case:
    """One randomized pick-and-place problem (shared by every robot/planner/perturbation cell).

    Attributes:
        index: case number [-]; tag: ``template/plain|reshape/layout index``.
        template: the task template; reshape: containers reshaped [-].
        seed, layout_index: generator seed and variant index of the layout [-].
        spec: the layout; place_click: (3,) [m] bottom centre of the placed object on ``template.place_on``.
    """

    index: int
    tag: str
    template: Template
    reshape: bool
    seed: int
    layout_index: int
    spec: SceneSpec
    place_click: tuple[float, float, float]


def footprint_radius(spec: SceneSpec, name: str) -> float:
    """[m] radius of the horizontal footprint of object ``name`` (scaled)."""
    o = spec.object_by_name(name)
    size = object_size(o)
    width = math.hypot(size[0], size[1]) if len(size) == 3 else size[0]
    return 0.5 * width * o.scale


def place_spot(
    spec: SceneSpec, obj: str, support: str, rng: np.random.Generator
) -> tuple[float, float, float]:
    """A free spot [m] (bottom centre of ``obj``) on ``support`` of ``spec`` (see the module docstring).

    Raises:
        SceneError: no free spot found in :data:`SPOT_TRIES` samples, or the object does not fit under the
            support's ceiling.
    """
    surf = support_surface(spec, support)
    o = spec.object_by_name(obj)
    size = object_size(o)
    if size[-1] * o.scale + HEADROOM > surf.ceiling:
        raise SceneError(f"{obj} ({size[-1] * o.scale:.2f} m) does not fit under the ceiling of {support}")
    radius = footprint_radius(spec, obj)
    start = object_pose(spec, obj)[:2, 3]
    others = [
        (object_pose(spec, p.name)[:2, 3], footprint_radius(spec, p.name))
        for p in spec.objects
        if p.on == support and p.name != obj
    ]
    hx, hy = surf.half_extents
    y_max = hy - radius - SIDE_MARGIN
    for _ in range(SPOT_TRIES):
        depth = float(rng.uniform(*FRONT_DEPTH))
        local = np.array([-hx + max(depth, radius + SIDE_MARGIN), rng.uniform(-y_max, y_max), 0.0, 1.0])
        world = surf.frame @ local
        xy = world[:2]
        if np.linalg.norm(xy - start) < MIN_MOVE:
            continue
        if all(np.linalg.norm(xy - c) >= radius + r + GAP for c, r in others):
            return (float(world[0]), float(world[1]), float(world[2]))
    raise SceneError(f"no free spot for {obj} on {support} of {spec.name} in {SPOT_TRIES} samples")


def clickable(spec: SceneSpec, spot: tuple[float, float, float]) -> bool:
    """Whether a click at ``spot`` [m] hits the cloud of ``spec`` rendered from its cameras (a labelled point
    within the click radius of :class:`~hsi_planning.scheduler.goals.GoalConfig`)."""
    from scipy.spatial import cKDTree

    from hsi_planning.perception import CloudConfig
    from hsi_planning.perception.cloud import UNLABELLED
    from hsi_planning.scheduler import SceneWorld
    from hsi_planning.scheduler.goals import GoalConfig

    cloud = SceneWorld(spec, cloud_config=CloudConfig(voxel_size=0.01)).cloud()
    pts = cloud.points[cloud.labels != UNLABELLED]
    if pts.shape[0] == 0:
        return False
    return float(cKDTree(pts).query(np.asarray(spot), k=1)[0]) <= GoalConfig().click_radius


def make_cases(n: int, seed: int) -> list[Case]:
    """``n`` cases cycling over the (template, plain/reshape) groups (case ``k`` is of group ``k mod 10``).
    A layout without a free place spot is replaced by the group's next variant."""
    groups = [(t, reshape) for t in TEMPLATES for reshape in (False, True)]
    base = {family: load_scene(family) for family in dict.fromkeys(t.family for t in TEMPLATES)}
    per_group = math.ceil(n / len(groups))
    cases: list[Case] = []
    for g, (template, reshape) in enumerate(groups):
        group_seed = seed + g  # one layout stream per group
        config = LayoutConfig(reshape=reshape, target=template.obj)
        layouts = generate_layouts(base[template.family], per_group + SPARE_LAYOUTS, group_seed, config)
        found = 0
        for i, layout in enumerate(layouts):
            if found == per_group:
                break
            try:
                spot = place_spot(
                    layout, template.obj, template.place_on, np.random.default_rng([seed, g, i])
                )
            except SceneError:
                continue
            if not clickable(layout, spot):
                continue
            tag = f"{template.name}/{'reshape' if reshape else 'plain'}/{i}"
            cases.append(Case(found * len(groups) + g, tag, template, reshape, group_seed, i, layout, spot))
            found += 1
        if found < per_group:
            raise SceneError(f"only {found} of {per_group} layouts of {template.name} have a free place spot")
    cases.sort(key=lambda c: c.index)
    return [dataclasses.replace(c, index=k) for k, c in enumerate(cases[:n])]
