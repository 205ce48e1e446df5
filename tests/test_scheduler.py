"""Bimanual scheduler: acceptance scenarios on the built-in scenes and schedule invariants.

Planner used: :class:`~hsi_planning.scheduler.ReachModelPlanner` (the calibrated human-reach model behind
the Planner interface), because the learned planner's checkpoint is not part of the test environment.
Each scenario's schedule is checked for: monotonic keyframe times, every wrist keyframe within 0.75 m of
its shoulder for the hip keyframe at the same time (shoulders at ±0.18 m lateral, +0.45 m up from the hip
in the trunk frame), the root path clear of the scene by the body radius, and planned segments whose
durations equal the time between their keyframes.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from hsi_planning.errors import HsiError, PlanningError
from hsi_planning.scene import SceneSpec, object_pose
from hsi_planning.scene.model import support_surfaces
from hsi_planning.scene_paths import load_scene
from hsi_planning.scheduler import (
    AuxiliaryConfig,
    HandState,
    ReachModelPlanner,
    SceneWorld,
    Schedule,
    Scheduler,
    SchedulerConfig,
    Task,
    find_blockers,
)
from hsi_planning.scheduler.world import WorldState, label_points

ARM_REACH = 0.75
BODY_RADIUS = 0.25
#: Grid conservativeness and path smoothing leave the root this close to the body radius at worst [m].
ROOT_TOLERANCE = 0.03


def _kitchen_with_cabinet_mug() -> SceneSpec:
    """The kitchen plus a mug (``mug3``) inside the closed cabinet, on its board."""
    doc = load_scene("kitchen").to_dict()
    doc["objects"].append(
        {"name": "mug3", "kind": "mug", "on": "cabinet1/board1", "xy": [0.0, -0.12], "yaw": 90}
    )
    return SceneSpec.from_dict(doc)


@pytest.fixture(scope="module")
def kitchen() -> SceneWorld:
    return SceneWorld(_kitchen_with_cabinet_mug())


@pytest.fixture(scope="module")
def narrow() -> SceneWorld:
    return SceneWorld(load_scene("narrow_shelf"))


def _schedule(world: SceneWorld, target: str, **kwargs: Any) -> Schedule:
    config = kwargs.pop("config", None)
    return Scheduler(world, ReachModelPlanner(), config).schedule(Task(target=target, **kwargs))


@pytest.fixture(scope="module")
def scenarios(kitchen: SceneWorld, narrow: SceneWorld) -> Iterator[dict[str, Schedule]]:
    """Every scenario scheduled once (the checks below share them)."""
    yield {
        "bottle": _schedule(kitchen, "bottle1", task_id="bottle"),
        "mug_free": _schedule(kitchen, "mug3"),
        "mug_holding": _schedule(kitchen, "mug3", hands=HandState(left="bottle1")),
        "drawer": _schedule(kitchen, "mug2"),
        "box": _schedule(kitchen, "box1", place=np.array([0.72, -0.25, 0.9])),
        "blocked": _schedule(narrow, "can1", config=SchedulerConfig(restore_blockers=True)),
    }


def _events(s: Schedule, event: str, obj: str | None = None) -> list[Any]:
    return [k for k in s.events() if k.contact_event == event and (obj is None or k.object_name == obj)]


def _first(s: Schedule, event: str, obj: str) -> float:
    found = _events(s, event, obj)
    assert found, (
        f"no {event} of {obj}: {[(k.time, k.hand, k.contact_event, k.object_name) for k in s.events()]}"
    )
    return float(found[0].time)


# ------------------------------------------------------------------------------------ invariants


@pytest.mark.parametrize("name", ["bottle", "mug_free", "mug_holding", "drawer", "box", "blocked"])
def test_every_keyframe_reachable_from_the_hip(scenarios: dict[str, Schedule], name: str) -> None:
    s = scenarios[name]
    hips = {round(k.time, 9): k for k in s.of("hip")}
    worst = 0.0
    for joint, side in (("left_wrist", 1.0), ("right_wrist", -1.0)):
        frames = s.of(joint)
        assert len(frames) == len(hips)
        for k in frames:
            hip = hips[round(k.time, 9)]
            shoulder = hip.position + Rotation.from_quat(hip.quaternion).apply([0.0, side * 0.18, 0.45])
            worst = max(worst, float(np.linalg.norm(k.position - shoulder)))
    assert worst <= ARM_REACH + 1e-6
    assert worst > 0.3  # the arms do reach out somewhere


@pytest.mark.parametrize("name", ["bottle", "mug_free", "mug_holding", "drawer", "box", "blocked"])
def test_timing_monotonic_and_segments_match_keyframes(scenarios: dict[str, Schedule], name: str) -> None:
    s = scenarios[name]
    times = np.array([k.time for k in s.keyframes])
    assert times[0] == 0.0 and np.all(np.diff(times) >= 0.0)
    for joint in ("left_wrist", "right_wrist", "hip", "root"):
        assert np.all(np.diff([k.time for k in s.of(joint)]) > 0.0)
    assert s.segments
    for seg in s.segments:
        tr = seg.trajectory
        frames = s.of(f"{tr.hand}_wrist")
        start = s.at(f"{tr.hand}_wrist", seg.start_time)
        end = s.at(f"{tr.hand}_wrist", seg.end_time)
        np.testing.assert_allclose(start.position, tr.position[0], atol=1e-9)
        np.testing.assert_allclose(end.position, tr.position[-1], atol=1e-9)
        between = [k for k in frames if seg.start_time + 1e-9 < k.time < seg.end_time - 1e-9]
        assert not between  # consecutive keyframes: segment duration == keyframe time difference
        assert end.time - start.time == pytest.approx(tr.duration, abs=1e-6)


@pytest.mark.parametrize("name", ["bottle", "mug_free", "drawer", "blocked"])
def test_root_path_is_collision_free(
    scenarios: dict[str, Schedule], kitchen: SceneWorld, narrow: SceneWorld, name: str
) -> None:
    s = scenarios[name]
    world = narrow if name == "blocked" else kitchen
    pts = world.cloud().points
    band = pts[(pts[:, 2] > 0.05) & (pts[:, 2] < 1.9), :2]
    tree = cKDTree(band)
    path = s.root_path
    dense = np.vstack([a + np.linspace(0, 1, 20)[:, None] * (b - a) for a, b in itertools.pairwise(path)])
    assert tree.query(dense)[0].min() >= BODY_RADIUS - ROOT_TOLERANCE
    part = s.info["part"]
    if part:  # while the door/drawer is open, the root also keeps clear of it
        opened = world.cloud([part])
        names = opened.label_names or {}
        door = opened.points[opened.labels == next(k for k, v in names.items() if v == part)]
        t_open = max(k.time for k in s.keyframes if k.action == "open")
        t_close = min([k.time for k in s.keyframes if k.action == "close"] or [s.duration])
        roots = np.array([k.position[:2] for k in s.of("root") if t_open < k.time < t_close])
        low = door[(door[:, 2] > 0.05) & (door[:, 2] < 1.9), :2]
        assert cKDTree(low).query(roots)[0].min() >= BODY_RADIUS - ROOT_TOLERANCE


# ------------------------------------------------------------------------------------ scenarios


def test_bottle_on_open_shelf_one_hand_no_auxiliary(scenarios: dict[str, Schedule]) -> None:
    s = scenarios["bottle"]
    assert s.task_id == "bottle"
    assert s.info["strategy"] == "single" and s.info["part"] == "" and s.info["blockers"] == []
    grasps = _events(s, "grasp")
    assert [(k.object_name, k.hand) for k in grasps] == [("bottle1", s.info["grasp_hand"])]
    assert not _events(s, "pull") and not _events(s, "push")
    other = "right" if s.info["grasp_hand"] == "left" else "left"
    assert {k.action for k in s.of(f"{other}_wrist")} <= {"idle", "start"}
    # the take-out ends outside the shelf (x < front at 0.6 m), carrying the bottle
    take_out = [seg for seg in s.segments if seg.step == "take_out"]
    assert len(take_out) == 1 and take_out[0].trajectory.position[-1][0] < 0.6
    assert set(s.info["costs"]) == {"single: left grasps", "single: right grasps"}


def test_mug_in_cabinet_both_free_is_cotemporal(scenarios: dict[str, Schedule]) -> None:
    s = scenarios["mug_free"]
    assert s.info["part"] == "cabinet1/door1"
    assert s.info["strategy"] == "cotemporal", s.info["rejected"]
    door_hand, grasp_hand = s.info["door_hand"], s.info["grasp_hand"]
    assert door_hand != grasp_hand
    costs = s.info["costs"]
    cotemporal = min(v for k, v in costs.items() if k.startswith("cotemporal"))
    sequential = min(v for k, v in costs.items() if k.startswith("sequential"))
    assert cotemporal < sequential
    t_pull = _first(s, "pull", "cabinet1/door1")
    t_grasp = _first(s, "grasp", "mug3")
    t_push = _first(s, "push", "cabinet1/door1")
    assert t_pull < t_grasp < t_push
    # co-temporal: while the grasping hand takes the mug, the other hand still holds the door
    held = s.at(f"{door_hand}_wrist", t_grasp)
    assert held.action == "hold" and held.object_name == "cabinet1/door1"
    assert not [k for k in _events(s, "release", "cabinet1/door1") if k.time < t_push]
    assert s.of(f"{grasp_hand}_wrist")[-1].object_name == "mug3"


def test_mug_in_cabinet_one_hand_holding_is_sequential_door_first(scenarios: dict[str, Schedule]) -> None:
    s = scenarios["mug_holding"]
    assert s.info["strategy"] == "sequential" and s.info["door_hand"] == "right" == s.info["grasp_hand"]
    assert (
        _first(s, "pull", "cabinet1/door1")
        < _first(s, "release", "cabinet1/door1")
        < _first(s, "grasp", "mug3")
    )
    assert all(k.object_name == "bottle1" and k.action == "carry" for k in s.of("left_wrist"))
    assert not _events(s, "push")  # no free hand to close it: left open and said so
    assert any("left open" in line or "open: no free hand" in line for line in s.steps)


def test_object_in_closed_drawer_pull_then_grasp(scenarios: dict[str, Schedule]) -> None:
    s = scenarios["drawer"]
    assert s.info["part"] == "drawer_unit1/drawer1"
    t_pull = _first(s, "pull", "drawer_unit1/drawer1")
    assert t_pull < _first(s, "grasp", "mug2") < _first(s, "push", "drawer_unit1/drawer1")
    # the handle moves straight out along the drawer's slide (-x) by its travel
    door_hand = s.info["door_hand"]
    start = next(k for k in _events(s, "grasp", "drawer_unit1/drawer1") if k.hand == door_hand).position
    handle = [k.position for k in s.of(f"{door_hand}_wrist") if k.action == "open"]
    travel = handle[-1] - start
    assert travel[0] < -0.3 and abs(travel[1]) < 1e-6 and abs(travel[2]) < 1e-6


def test_a_drawer_take_out_lifts_the_object_over_the_front_and_carries_it_level(
    scenarios: dict[str, Schedule], kitchen: SceneWorld
) -> None:
    s = scenarios["drawer"]
    hand = s.info["grasp_hand"]
    lift = next(seg.trajectory for seg in s.segments if seg.step == "take_out")
    bottom = s.info["carries"][0]["grasp"][2] + lift.position[-1, 2] - lift.position[lift.contact_index, 2]
    opened = kitchen.state_cloud(WorldState(opened=frozenset({"drawer_unit1/drawer1"})))
    rim = float(label_points(opened, ["drawer_unit1/drawer1"])[:, 2].max())  # the front panel's top
    assert bottom >= rim + 0.05 - 1e-9
    # then to the carry pose, never lower than the lift's end on the way (level to above a lower carry
    # pose, then down to it)
    after = [k for k in s.of(f"{hand}_wrist") if k.time > _end(s, lift) + 1e-9]
    assert after[0].action == "carry" and after[0].position[2] >= lift.position[-1, 2] - 1e-9
    if after[1].position[2] < after[0].position[2]:
        np.testing.assert_allclose(after[1].position[:2], after[0].position[:2], atol=1e-9)


def _end(s: Schedule, trajectory: Any) -> float:
    seg = next(seg for seg in s.segments if seg.trajectory is trajectory)
    return float(seg.start_time + trajectory.duration)


def test_an_opened_part_keeps_the_points_seen_of_it_at_rest(kitchen: SceneWorld) -> None:
    """The cameras do not see all of a pulled-out drawer's front from where they stand; what they saw of
    it closed is in the predicted cloud, moved by the pull."""
    name = "drawer_unit1/drawer1"
    seen = label_points(kitchen.cloud(), [name])
    moved = seen + kitchen.part_transform(name, 1.0)[:3, 3]
    predicted = label_points(kitchen.cloud([name]), [name])
    assert len(seen) > 100
    distance, _ = cKDTree(predicted).query(moved)
    assert float(distance.max()) < 1e-9


def test_box_two_handed_grasp_carry_and_place(scenarios: dict[str, Schedule], kitchen: SceneWorld) -> None:
    s = scenarios["box"]
    assert s.info["strategy"] == "both"
    grasps = _events(s, "grasp", "box1")
    assert sorted(k.hand for k in grasps) == ["left", "right"] and grasps[0].time == grasps[1].time
    releases = _events(s, "release", "box1")
    assert sorted(k.hand for k in releases) == ["left", "right"] and releases[0].time == releases[1].time
    grip = float(np.linalg.norm(grasps[0].position - grasps[1].position))
    assert 0.15 < grip < 0.45
    # rigid carry: from the grasp to the release the hands keep their distance (keyframes and segments)
    for t in sorted({k.time for k in s.keyframes if grasps[0].time <= k.time <= releases[0].time}):
        gap = s.at("left_wrist", t).position - s.at("right_wrist", t).position
        assert float(np.linalg.norm(gap)) == pytest.approx(grip, abs=1e-6), t
    for step in ("take_out", "place"):
        pair = {seg.trajectory.hand: seg.trajectory for seg in s.segments if seg.step == step}
        gap = np.linalg.norm(pair["left"].position - pair["right"].position, axis=1)
        assert np.ptp(gap) < 1e-6 and gap[0] == pytest.approx(grip, abs=1e-6), step
    lift = {seg.trajectory.hand: seg.trajectory for seg in s.segments if seg.step == "take_out"}["left"]
    assert lift.position[-1][2] > lift.position[0][2] + 0.05  # lifted off the counter
    # put down at the requested spot: the grip's midpoint moved by the placement displacement
    box = object_pose(kitchen.spec, "box1")[:3, 3]
    moved = 0.5 * (releases[0].position + releases[1].position) - 0.5 * (
        grasps[0].position + grasps[1].position
    )
    np.testing.assert_allclose(moved, np.array([0.72, -0.25, 0.9]) - box, atol=0.02)
    # the carry's record for the retargeting: both hands, its bottom centre at the grasp, its placement
    (carry,) = s.info["carries"]
    assert carry["object"] == "box1" and sorted(carry["hands"]) == ["left", "right"]
    np.testing.assert_allclose(carry["grasp"], box, atol=0.02)
    np.testing.assert_allclose(carry["place"], [0.72, -0.25, 0.9], atol=1e-12)


def test_blocker_moved_first_then_target_then_put_back(
    scenarios: dict[str, Schedule], narrow: SceneWorld
) -> None:
    s = scenarios["blocked"]
    assert s.info["blockers"] == ["bottle1"]
    grasps = [k.object_name for k in _events(s, "grasp")]
    assert grasps[:2] == ["bottle1", "can1"] and grasps[2] == "bottle1"
    releases = _events(s, "release", "bottle1")
    assert len(releases) == 2
    assert _first(s, "grasp", "bottle1") < releases[0].time < _first(s, "grasp", "can1") < releases[1].time
    # the bottle went somewhere off the can's way out (lateral offset > both radii), then back home
    places = [seg.trajectory for seg in s.segments if seg.step == "place"]
    can = object_pose(narrow.spec, "can1")[:3, 3]
    aside = places[0].position[-1]
    assert abs(aside[1] - can[1]) > 0.035 + 0.033
    home = object_pose(narrow.spec, "bottle1")[:3, 3]
    assert abs(places[1].position[-1][1] - home[1]) < 0.02
    carried = [(c["object"], "place" in c) for c in s.info["carries"]]  # the can is not put down here
    assert carried == [("bottle1", True), ("can1", False), ("bottle1", True)]
    np.testing.assert_allclose(s.info["carries"][2]["place"][:2], home[:2], atol=0.02)


@pytest.mark.parametrize("corridor", [0.0, 0.05])
def test_a_blocker_is_not_set_aside_beside_the_target(narrow: SceneWorld, corridor: float) -> None:
    # the fingers close around the target and the palm and wrist follow them out: the strip kept free starts
    # at the target's centre, not at the wrist's contact in front of it, and is as wide as the robot's
    # approach corridor where that is wider than the target (the old strip offered spots 7-9 cm beside the
    # can, where the bottle then stood in the gripper's way)
    config = SchedulerConfig(auxiliary=AuxiliaryConfig(corridor_radius=corridor))
    scheduler = Scheduler(narrow, ReachModelPlanner(), config)
    spots = scheduler._spots("bottle1", "can1", WorldState())
    assert len(spots) >= 4
    can = object_pose(narrow.spec, "can1")[:3, 3]
    axis = np.asarray(support_surfaces(narrow.spec)["shelf1/board1"].opening, dtype=np.float64)[:2]
    size = narrow.object_size("bottle1")
    radius = 0.5 * float(size[0])
    half = max(0.5 * narrow.object_size("can1")[0], corridor)
    keep = half + radius + config.auxiliary.corridor_margin
    for _, pos in spots:
        rel = pos[:2] - can[:2]
        along, across = float(rel @ axis), abs(float(rel @ np.array([-axis[1], axis[0]])))
        assert along <= -half or across >= keep - 1e-9, (pos, along, across, keep)
    nearest = min(abs(float((p[:2] - can[:2]) @ np.array([-axis[1], axis[0]]))) for _, p in spots)
    assert nearest < keep + 0.05  # still near the can: the strip does not push every spot far away


def _take_out_reach(world: SceneWorld, obj: str) -> tuple[float, float]:
    """[m] how far past the front of the shelf the deepest point of ``obj`` lies before and after its
    first take-out in the schedule of picking can1 (negative: inside)."""
    s = _schedule(world, "can1")
    out = next(seg.trajectory for seg in s.segments if seg.step == "take_out")  # the blocker's, first
    surface = support_surfaces(world.spec)["shelf1/board1"]
    axis = np.asarray(surface.opening, dtype=np.float64)
    front = surface.frame[:3, 3] + surface.half_extents[0] * axis
    pts = label_points(world.cloud(), [obj])
    moved = pts + (out.position[-1] - out.position[out.contact_index])
    return float(((pts - front) @ axis).min()), float(((moved - front) @ axis).min())


def test_a_tall_blocker_is_taken_out_until_all_of_it_is_past_the_opening(narrow: SceneWorld) -> None:
    # a bottle 29 cm tall, 4 cm under the board above, held by its near side: it cannot rise as far as
    # the retreat does while any of it is under the board; the take-out ends retreat_clearance beyond the
    # shelf front with the whole bottle, not only the wrist, out of the shelf
    doc = narrow.spec.to_dict()
    bottle = next(o for o in doc["objects"] if o["name"] == "bottle1")
    bottle["scale"] = 1.15
    inside, after = _take_out_reach(SceneWorld(SceneSpec.from_dict(doc)), "bottle1")
    assert inside < -0.05  # it stood deep in the shelf
    assert after >= SchedulerConfig().retreat_clearance - 0.01
    # the default bottle (25 cm) has room to rise in place: its take-out ends as far out as the wrist's
    inside, after = _take_out_reach(narrow, "bottle1")
    assert inside < -0.05 and after < SchedulerConfig().retreat_clearance - 0.05


def test_unknown_or_held_target_and_no_free_hand(kitchen: SceneWorld) -> None:
    scheduler = Scheduler(kitchen, ReachModelPlanner())
    with pytest.raises(PlanningError, match=r"'sofa' is not an object.*valid: \['mug1'"):
        scheduler.schedule(Task(target="sofa"))
    with pytest.raises(PlanningError, match="no free hand"):
        scheduler.schedule(Task(target="bottle1", hands=HandState(left="mug1", right="can1")))
    with pytest.raises(PlanningError, match="needs both hands"):
        scheduler.schedule(Task(target="box1", hands=HandState(left="mug1")))
    with pytest.raises(PlanningError, match="already in a hand"):
        scheduler.schedule(Task(target="mug1", hands=HandState(left="mug1")))
    with pytest.raises(HsiError):
        scheduler.schedule(Task(target="bottle1", hand="left", hands=HandState(left="mug1")))
    teapot = object_pose(kitchen.spec, "teapot1")[:3, 3]
    with pytest.raises(PlanningError, match=r"not free: \['teapot1'\]"):
        scheduler.schedule(Task(target="bottle1", place=teapot + np.array([0.05, 0.0, 0.0])))
    with pytest.raises(PlanningError, match="inside closed furniture"):
        scheduler.schedule(
            Task(target="bottle1", place=object_pose(kitchen.spec, "mug3")[:3, 3] + [0, 0.15, 0])
        )
    with pytest.raises(HsiError, match="on no support surface"):
        scheduler.schedule(Task(target="bottle1", place=np.array([0.3, 0.0, 0.5])))


def test_schedule_json_round_trip(scenarios: dict[str, Schedule], tmp_path: Any) -> None:
    s = scenarios["bottle"]
    back = Schedule.read_json(s.write_json(tmp_path / "s.json"))
    assert back.task_id == s.task_id and back.steps == s.steps and len(back.keyframes) == len(s.keyframes)
    for a, b in zip(back.keyframes, s.keyframes, strict=True):
        assert (a.time, a.key_joint, a.action, a.contact_event, a.hand, a.object_name) == (
            b.time, b.key_joint, b.action, b.contact_event, b.hand, b.object_name,
        )  # fmt: skip
        np.testing.assert_allclose(a.position, b.position)
    assert len(back.segments) == len(s.segments)
    np.testing.assert_allclose(back.segments[0].trajectory.position, s.segments[0].trajectory.position)
    row = s.to_dict()["keyframes"][0]
    assert set(row) == {
        "time",
        "key_joint",
        "position",
        "quaternion",
        "hand",
        "action",
        "contact_event",
        "object",
    }


def test_a_neighbour_in_the_straight_approach_corridor_blocks_a_gripper() -> None:
    """The human reach passes a mug beside the can's way out; a gripper following the straight approach
    out of the shelf (``corridor_radius``) does not fit past it, so the mug is moved first."""
    spec = load_scene("narrow_shelf")
    objects = tuple(
        dataclasses.replace(o, xy=(o.xy[0] - 0.04, o.xy[1] - 0.055)) if o.name == "mug1" else o
        for o in spec.objects
        if o.name != "bottle1"
    )
    world = SceneWorld(dataclasses.replace(spec, objects=objects))

    def blockers(radius: float) -> list[str]:
        config = AuxiliaryConfig(hand_radius=0.05, corridor_radius=radius)
        return find_blockers(world, ReachModelPlanner(), "can1", WorldState(), config=config)

    assert blockers(0.0) == []
    assert blockers(0.07) == ["mug1"]
    with pytest.raises(HsiError, match="corridor_radius"):
        AuxiliaryConfig(corridor_radius=-0.01)
