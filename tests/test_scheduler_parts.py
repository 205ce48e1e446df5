"""Scheduler components: click/ray goals, floor map and fast marching (Eq. 23), stances, hand assignment
(Eq. 24), auxiliary objects, schedule validation, the reach-model planner adapter."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.planning import PlanRequest
from hsi_planning.scene import object_pose
from hsi_planning.scene_paths import load_scene
from hsi_planning.scheduler import (
    BodyConfig,
    CloudObstacles,
    FloorMap,
    HandConfig,
    HandState,
    HipPose,
    Keyframe,
    NavigationConfig,
    PickGoal,
    PlaceGoal,
    ReachModelPlanner,
    SceneWorld,
    Schedule,
    StanceConfig,
    StanceTarget,
    WorldState,
    approach_cost,
    camera_ray,
    candidate_assignments,
    choose_stance,
    deviation_cost,
    enclosing_part,
    hand_crossing,
    plan_root_path,
    ray_hit,
    resolve_click,
)
from hsi_planning.scheduler.stance import wrists_clear


@pytest.fixture(scope="module")
def kitchen() -> SceneWorld:
    return SceneWorld(load_scene("kitchen"))


# ---------------------------------------------------------------------------------------- goals


def test_click_on_object_resolves_to_pick(kitchen: SceneWorld) -> None:
    centre = object_pose(kitchen.spec, "bottle1")[:3, 3] + [-0.035, 0.0, 0.1]  # front face of the bottle
    goal = resolve_click(centre + np.array([-0.01, 0.0, 0.0]), kitchen.cloud(), kitchen.spec)
    assert isinstance(goal, PickGoal) and goal.object_name == "bottle1"


def test_click_on_free_counter_top_is_a_place_occupied_spot_is_not(kitchen: SceneWorld) -> None:
    goal = resolve_click([0.72, -0.2, 0.9], kitchen.cloud(), kitchen.spec, footprint=(0.04, 0.12))
    assert isinstance(goal, PlaceGoal) and goal.support == "counter1"
    np.testing.assert_allclose(goal.position, [0.72, -0.2, 0.9], atol=1e-9)
    beside_teapot = object_pose(kitchen.spec, "teapot1")[:3, 3] + [-0.12, 0.0, 0.0]
    with pytest.raises(PlanningError, match=r"not free: \['teapot1'\]"):
        resolve_click(beside_teapot, kitchen.cloud(), kitchen.spec, footprint=(0.06, 0.12))


@pytest.mark.parametrize(
    ("point", "message"),
    [
        ([0.3, 0.0, 1.5], r"hits nothing: the nearest point of the cloud \(\w+\) is 0\.\d+ m away"),
        ([2.5, -2.0, 0.0], r"3\.20 m from the person, beyond max_distance 3\.0 m"),
        (
            [0.0, 1.2, 0.0],
            r"is on the floor, 1\.20 m from the person; the floor is not a pick or place target",
        ),
        ([0.6, -0.45, 0.3], r"is on 'cabinet1/door1', fixed furniture that cannot be picked"),
    ],
)
def test_bad_clicks_raise_clear_errors(kitchen: SceneWorld, point: list[float], message: str) -> None:
    with pytest.raises(PlanningError, match=message):
        resolve_click(point, kitchen.cloud(), kitchen.spec)


def test_click_on_shelf_carcass_is_fixed_furniture(kitchen: SceneWorld) -> None:
    cloud = kitchen.cloud()
    side = cloud.points[cloud.mask("shelf1") & (cloud.points[:, 2] > 1.0) & (cloud.points[:, 2] < 1.2)]
    assert len(side) > 10
    with pytest.raises(PlanningError, match=r"is on 'shelf1', fixed furniture that cannot be picked"):
        resolve_click(side[0], cloud, kitchen.spec)


def test_camera_ray_through_projected_object_hits_it(kitchen: SceneWorld) -> None:
    cam = kitchen.spec.cameras[0]
    target = object_pose(kitchen.spec, "teapot1")[:3, 3] + [0.0, 0.0, 0.06]
    pos, look = np.asarray(cam.pos), np.asarray(cam.target)
    fwd = (look - pos) / np.linalg.norm(look - pos)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    d = target - pos
    half_h = math.tan(math.radians(cam.fovy) / 2)
    w, h = cam.resolution
    u = (d @ right / (d @ fwd) / (half_h * w / h) + 1.0) * w / 2
    v = (1.0 - d @ up / (d @ fwd) / half_h) * h / 2
    origin, direction = camera_ray(cam, (u, v))
    np.testing.assert_allclose(direction, d / np.linalg.norm(d), atol=1e-9)
    hit = ray_hit(origin, direction, kitchen.cloud())
    goal = resolve_click(hit, kitchen.cloud(), kitchen.spec)
    assert isinstance(goal, PickGoal) and goal.object_name == "teapot1"
    with pytest.raises(PlanningError, match="hits nothing"):
        ray_hit(origin, -direction, kitchen.cloud())
    with pytest.raises(PlanningError, match="outside the 320x240 image"):
        camera_ray(cam, (400, 10))


# ------------------------------------------------------------------------------------ navigation


def _wall_map() -> FloorMap:
    """A 4 m square room with a 1.6 m wall across x = 1 from y = -0.8 to 0.8."""
    wall = np.stack([np.full(81, 1.0), np.linspace(-0.8, 0.8, 81)], axis=1)
    return FloorMap(wall, [-1.0, -2.0], [3.0, 2.0], 0.04)


def test_approach_cost_eq23_values() -> None:
    cfg = NavigationConfig(approach_length=0.4, approach_weight=4.0)
    goal, heading = np.zeros(2), np.array([1.0, 0.0])
    cells = np.array([[-0.2, 0.0], [0.2, 0.0], [0.0, 0.2], [0.0, -0.39], [-1.0, 0.0], [0.5, 0.0]])
    np.testing.assert_allclose(approach_cost(cells, goal, heading, cfg), [1.0, 5.0, 3.0, 3.0, 1.0, 1.0])


def test_fast_marching_path_goes_around_the_wall_and_arrives_along_the_heading() -> None:
    floor = _wall_map()
    cfg = NavigationConfig()
    start, goal, heading = np.array([0.0, 0.0]), np.array([2.0, 0.5]), np.array([0.0, 1.0])
    path = plan_root_path(floor, start, goal, heading, radius=0.25, config=cfg)
    np.testing.assert_allclose(path[0], start) and np.testing.assert_allclose(path[-1], goal)
    dense = np.vstack([a + np.linspace(0, 1, 10)[:, None] * (b - a) for a, b in itertools.pairwise(path)])
    wall_dist = np.hypot(np.abs(dense[:, 0] - 1.0), np.maximum(np.abs(dense[:, 1]) - 0.8, 0.0))
    assert wall_dist.min() >= 0.25 - 0.03  # around the wall with the body radius
    assert np.abs(dense[:, 1]).max() > 0.8  # it did go around an end of the wall
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    assert 2.0 < length < 3.5

    def arrival(p: np.ndarray) -> float:
        near = p[np.linalg.norm(p - goal, axis=1) <= 0.4]
        d = near[-1] - near[0]
        return float(d @ heading / np.linalg.norm(d))

    plain = plan_root_path(
        floor, start, goal, heading, radius=0.25, config=NavigationConfig(approach_weight=0.0)
    )
    assert arrival(path) > 0.75 and arrival(plain) < 0.3  # Eq. 23: the last 0.4 m follow the heading


def test_fast_marching_errors() -> None:
    floor = _wall_map()
    with pytest.raises(PlanningError, match=r"root goal \[1\.0, 0\.0\] has -?0\.\d+ m clearance"):
        plan_root_path(floor, [0.0, 0.0], [1.0, 0.0], [1.0, 0.0], radius=0.25, config=NavigationConfig())
    boxed = floor.with_segments([[[0.5, -1.9], [0.5, 1.9]]])  # wall from side to side (map edge open)
    closed = boxed.with_segments([[[0.5, 1.9], [0.5, 2.0]], [[0.5, -2.0], [0.5, -1.9]]])
    with pytest.raises(PlanningError, match="no collision-free root path"):
        plan_root_path(closed, [0.0, 0.0], [2.0, 0.0], [1.0, 0.0], radius=0.25, config=NavigationConfig())


def test_a_root_start_a_little_too_close_leaves_through_clearer_cells() -> None:
    """A body that stands 3 cm closer to the wall than its radius (a robot base pushed there) walks away
    from it, its clearance never falling below the start's; 8 cm closer is more than the start slack."""
    floor = _wall_map()
    cfg = NavigationConfig()
    goal, heading = np.array([0.0, -1.2]), np.array([0.0, -1.0])
    start = np.array([0.78, 0.0])  # 0.22 m from the wall, body radius 0.25 m
    path = plan_root_path(floor, start, goal, heading, radius=0.25, config=cfg)
    np.testing.assert_allclose(path[0], start) and np.testing.assert_allclose(path[-1], goal)
    dense = np.vstack([a + np.linspace(0, 1, 10)[:, None] * (b - a) for a, b in itertools.pairwise(path)])
    clear = floor.clearance(dense)
    assert clear.min() >= floor.clearance(start[None])[0] - 0.03
    assert clear[len(clear) // 2 :].min() >= 0.25 - 0.03  # beyond the start: the full body radius
    with pytest.raises(PlanningError, match=r"root start \[0\.83, 0\.0\].*a start may have 0\.05 m less"):
        plan_root_path(floor, [0.83, 0.0], goal, heading, radius=0.25, config=cfg)
    with pytest.raises(PlanningError, match="root start"):
        plan_root_path(floor, start, goal, heading, radius=0.25, config=NavigationConfig(start_slack=0.0))
    with pytest.raises(ConfigError, match="start_slack"):
        NavigationConfig(start_slack=-0.01)


def test_stance_reaches_targets_or_says_how_far() -> None:
    floor = _wall_map()
    body = BodyConfig()
    target = np.array([1.45, 1.4, 0.3])  # low, beside the wall's end
    pose = choose_stance([StanceTarget("right", target)], floor, None, body, StanceConfig(), near=[0.0, 0.0])
    shoulder = pose.shoulder("right", body)
    assert np.linalg.norm(target - shoulder) <= body.reach_limit + 1e-9
    assert pose.position[2] < body.standing_height and pose.pitch > 0.0  # crouched and leaning
    assert floor.clearance(pose.xy[None])[0] >= body.body_radius
    with pytest.raises(PlanningError, match=r"needs \d\.\d\d m of reach \(limit 0\.72 m\)"):
        choose_stance([StanceTarget("left", np.array([1.5, 1.5, 2.6]))], floor, None, body, StanceConfig())


def test_stance_keeps_a_resting_wrist_out_of_the_scene() -> None:
    """Points around where the cheapest stance puts the left ready wrist (a counter's edge, say): with that
    wrist resting on the body, another stance is chosen whose ready wrist keeps ``wrist_clearance``."""
    floor, body, config = _wall_map(), BodyConfig(), StanceConfig(wrist_clearance=0.05)
    targets = [StanceTarget("right", np.array([1.45, 1.4, 0.3]))]
    first = choose_stance(targets, floor, None, body, config, near=[0.0, 0.0])
    wrist = first.wrist_offset("left", body.ready_offset)
    grid = np.arange(-0.02, 0.021, 0.01)
    blob = wrist + np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), axis=-1).reshape(-1, 3)
    tree = cKDTree(blob)
    resting = [("left", body.ready_offset, 0.0)]
    same = choose_stance(targets, floor, tree, body, config, near=[0.0, 0.0])  # not resting: not checked
    np.testing.assert_array_equal(same.position, first.position)
    moved = choose_stance(targets, floor, tree, body, config, near=[0.0, 0.0], resting=resting)
    assert tree.query(moved.wrist_offset("left", body.ready_offset))[0] >= config.wrist_clearance
    assert np.linalg.norm(moved.shoulder("right", body) - targets[0].point) <= body.reach_limit + 1e-9
    assert wrists_clear(first, resting, tree, config.wrist_clearance) is False
    gap = float(tree.query(moved.wrist_offset("left", body.ready_offset))[0])
    carried = [("left", body.ready_offset, gap)]  # an object that size held there: too close now
    assert wrists_clear(moved, carried, tree, config.wrist_clearance) is False
    assert wrists_clear(moved, carried, tree, 0.0) is True  # 0: not checked
    everywhere = cKDTree(
        np.array([[x, y, z] for x in range(-2, 4) for y in range(-2, 4) for z in (0.0, 1.0)])
    )
    with pytest.raises(PlanningError, match=r"a resting wrist within 1\.5 m"):
        choose_stance(targets, floor, everywhere, body, StanceConfig(wrist_clearance=1.5), resting=resting)
    with pytest.raises(ConfigError, match="wrist_clearance"):
        StanceConfig(wrist_clearance=-0.01)


def test_hip_pose_shoulders_lean_forward() -> None:
    body = BodyConfig()
    pose = HipPose(np.array([1.0, 2.0, 0.8]), math.radians(90.0), math.radians(30.0))
    left = pose.shoulder("left", body)
    expected = np.array([1.0, 2.0, 0.8]) + Rotation.from_euler("ZY", [math.pi / 2, math.pi / 6]).apply(
        [0, 0.18, 0.45]
    )
    np.testing.assert_allclose(left, expected, atol=1e-12)
    assert left[1] > 2.2 and left[0] < 1.0  # forward (+y) and to the left (-x) when facing +y
    assert pose.reachable("left", left + np.array([0.0, 0.5, 0.0]), body)
    assert not pose.reachable("left", left + np.array([0.0, 0.8, 0.0]), body)


# ---------------------------------------------------------------------------------------- hands


def test_candidate_assignments() -> None:
    both_free = candidate_assignments(HandState(), both=False, has_part=True)
    assert sorted(a.describe() for a in both_free) == [
        "cotemporal: left opens and holds, right grasps, left closes",
        "cotemporal: right opens and holds, left grasps, right closes",
        "sequential: left opens, left grasps, right closes",
        "sequential: right opens, right grasps, left closes",
    ]
    one = candidate_assignments(HandState(left="mug1"), both=False, has_part=True)
    assert [a.describe() for a in one] == [
        "sequential: right opens, right grasps, left open: no free hand to close"
    ]
    assert [a.grasp for a in candidate_assignments(HandState(), both=True, has_part=False)] == ["both"]
    assert [a.grasp for a in candidate_assignments(HandState(), False, False, preferred="left")] == ["left"]
    with pytest.raises(PlanningError, match="no free hand: left holds 'a', right holds 'b'"):
        candidate_assignments(HandState("a", "b"), both=False, has_part=False)
    with pytest.raises(PlanningError, match="needs both hands but right holds 'b'"):
        candidate_assignments(HandState(right="b"), both=True, has_part=False)
    with pytest.raises(ConfigError, match="hand='up'"):
        candidate_assignments(HandState(), False, False, preferred="up")


def test_candidate_assignments_with_the_door_hand_given() -> None:
    right_opens = candidate_assignments(HandState(), both=False, has_part=True, door="right")
    assert sorted(a.describe() for a in right_opens) == [
        "cotemporal: right opens and holds, left grasps, right closes",
        "sequential: right opens, right grasps, left closes",
    ]
    kept = candidate_assignments(HandState(), False, True, preferred="left", door="right")
    assert [a.describe() for a in kept] == ["cotemporal: right opens and holds, left grasps, right closes"]
    assert len(candidate_assignments(HandState(), False, False, door="right")) == 2  # nothing to open
    why = r"left hand cannot open the door/drawer with any grasping hand \(left holds 'mug1'\)"
    with pytest.raises(PlanningError, match=why):
        candidate_assignments(HandState(left="mug1"), both=False, has_part=True, door="left")
    with pytest.raises(ConfigError, match="door_hand='both'"):
        candidate_assignments(HandState(), False, True, door="both")


def test_hand_state_parse() -> None:
    assert HandState.parse(["left:mug1"]) == HandState(left="mug1")
    for bad in (["mug1"], ["middle:mug1"], ["left:"], ["left:a", "left:b"]):
        with pytest.raises(ConfigError, match="holding"):
            HandState.parse(bad)


def _frames(t: float, hip: list[float], left: list[float], right: list[float]) -> list[Keyframe]:
    q = [0.0, 0.0, 0.0, 1.0]
    return [
        Keyframe(t, "left_wrist", left, q, "idle", hand="left"),
        Keyframe(t, "right_wrist", right, q, "idle", hand="right"),
        Keyframe(t, "hip", hip, q, "idle"),
        Keyframe(t, "root", [hip[0], hip[1], 0.0], q, "idle"),
    ]


def test_deviation_cost_eq24_counts_arm_motion_not_walking() -> None:
    walk = Schedule(
        "w",
        tuple(
            _frames(0.0, [0, 0, 1], [0.2, 0.2, 1], [0.2, -0.2, 1])
            + _frames(2.0, [1, 0, 1], [1.2, 0.2, 1], [1.2, -0.2, 1])
        ),
    )
    assert deviation_cost(walk, 2.0) == pytest.approx(4.0)  # only w * T: the hands moved with the body
    reach = Schedule(
        "r",
        tuple(
            _frames(0.0, [0, 0, 1], [0.2, 0.2, 1], [0.2, -0.2, 1])
            + _frames(1.0, [0, 0, 1], [0.5, 0.6, 1], [0.2, -0.2, 1])
        ),
    )
    assert deviation_cost(reach, 2.0) == pytest.approx(0.5 + 2.0)  # 0.5 m of left-arm motion + 2 m/s * 1 s


def test_hand_crossing_in_the_hip_heading_frame() -> None:
    apart = Schedule("a", tuple(_frames(0.0, [0, 0, 1], [0.3, 0.2, 1], [0.3, -0.2, 1])))
    assert hand_crossing(apart) == pytest.approx(-0.4)  # the left wrist 0.4 m left of the right one
    # facing -y (hip turned -90 deg), left is +x: the left wrist at world x = 0.15 lies 0.1 m right of the
    # right one at x = 0.25
    q = Rotation.from_euler("z", -90, degrees=True).as_quat()
    crossed = Schedule(
        "c",
        (
            Keyframe(0.0, "left_wrist", [0.15, -0.3, 1], q, "hold", hand="left"),
            Keyframe(0.0, "right_wrist", [0.25, -0.3, 1], q, "reach", hand="right"),
            Keyframe(0.0, "hip", [0, 0, 1], q, "idle"),
            Keyframe(0.0, "root", [0, 0, 0], q, "idle"),
        ),
    )
    assert hand_crossing(crossed) == pytest.approx(0.1)
    with pytest.raises(ConfigError, match="max_crossing"):
        HandConfig(max_crossing=-0.1)


# ---------------------------------------------------------------------------------------- schedule


def test_schedule_validation() -> None:
    frames = _frames(0.0, [0, 0, 1], [0.2, 0.2, 1], [0.2, -0.2, 1])
    with pytest.raises(PlanningError, match="key_joint='head'"):
        Keyframe(0.0, "head", [0, 0, 0], [0, 0, 0, 1], "idle")  # type: ignore[arg-type]
    with pytest.raises(PlanningError, match="contact_event='bump'"):
        Keyframe(0.0, "hip", [0, 0, 0], [0, 0, 0, 1], "idle", "bump")  # type: ignore[arg-type]
    with pytest.raises(PlanningError, match="finite number >= 0"):
        Keyframe(-1.0, "hip", [0, 0, 0], [0, 0, 0, 1], "idle")
    later = _frames(1.0, [0, 0, 1], [0.2, 0.2, 1], [0.2, -0.2, 1])
    with pytest.raises(PlanningError, match="sorted by time"):
        Schedule("x", tuple(later + frames))
    with pytest.raises(PlanningError, match="left_wrist must be strictly increasing"):
        Schedule("x", tuple(frames + frames))
    with pytest.raises(PlanningError, match="no hip keyframe at t = 5"):
        Schedule("x", tuple(frames)).at("hip", 5.0)


# ------------------------------------------------------------------------------------ auxiliary and planner


def test_enclosing_part(kitchen: SceneWorld) -> None:
    assert enclosing_part(kitchen, "bottle2", WorldState()) == "cabinet1/door1"
    assert enclosing_part(kitchen, "mug2", WorldState()) == "drawer_unit1/drawer1"
    assert enclosing_part(kitchen, "mug2", WorldState(opened=frozenset({"drawer_unit1/drawer1"}))) is None
    assert enclosing_part(kitchen, "bottle1", WorldState()) is None


def test_door_handle_and_leaf_follow_the_hinge(kitchen: SceneWorld) -> None:
    part = kitchen.part("cabinet1/door1")
    closed, opened = kitchen.handle_at(part.name, 0.0), kitchen.handle_at(part.name, 1.0)
    r0 = np.linalg.norm((closed - part.point)[:2])
    assert np.linalg.norm((opened - part.point)[:2]) == pytest.approx(r0)
    assert (
        opened[2] == pytest.approx(closed[2]) and opened[0] < closed[0] - 0.4
    )  # swung out towards the person
    angle = math.degrees(part.open_value)
    assert angle == pytest.approx(0.9 * 110.0)
    leaf = kitchen.door_panel(part.name, 0.0)
    assert leaf[1][1] > leaf[0][1] and abs(leaf[1][0] - leaf[0][0]) < 0.05  # closed: along the front (+y)


def test_reach_planner_adapter(kitchen: SceneWorld) -> None:
    cloud = kitchen.cloud()
    start = np.array([0.3, 0.6, 1.1])
    axis = np.array([-1.0, 0.0, 0.0])
    req = PlanRequest(cloud=cloud, target="bottle1", hand="right", start_position=start, approach_axis=axis)
    result = ReachModelPlanner().plan(req)
    bottle = cloud.points[cloud.mask("bottle1")]
    contact = result.contact_position
    assert contact[0] == pytest.approx(bottle[:, 0].min() - 0.06, abs=1e-6)
    np.testing.assert_allclose(result.leave.position[0], contact)
    np.testing.assert_allclose(result.approach.position[0], start)
    np.testing.assert_allclose(result.leave.position[-1], start)  # no retreat given: back to the start
    assert result.approach.duration > 0.5 and result.leave.duration > 0.5
    with pytest.raises(PlanningError, match="no points in the cloud"):
        ReachModelPlanner().plan(PlanRequest(cloud=cloud, target="mug2", start_position=start))


def test_cloud_obstacles_distance_and_without() -> None:
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    field = CloudObstacles(pts, [1, 2], {1: "a", 2: "b"}, surface_offset=0.01)
    np.testing.assert_allclose(field.distance([[0.0, 0.5, 0.0], [0.9, 0.0, 0.0]]), [0.49, 0.09])
    assert field.nearest_name([[0.9, 0.0, 0.0]]) == ["b"]
    np.testing.assert_allclose(field.push_direction([[0.0, 0.0, 0.5]]), [[0.0, 0.0, 1.0]])
    only_a: Any = field.without(["b"])
    assert only_a.names == ("a",) and only_a.distance([[0.9, 0.0, 0.0]])[0] == pytest.approx(0.89)


def test_aside_spots_keep_a_top_down_take_out_free_without_excluding_everything(kitchen: SceneWorld) -> None:
    from hsi_planning.scheduler.auxiliary import free_spots

    state = WorldState(opened=frozenset({"drawer_unit1/drawer1"}))
    cloud = kitchen.state_cloud(state)
    start = kitchen.object_position("mug2", state)
    up = np.array([0.0, 0.0, 1.0])  # lifted out of the drawer from above
    spots = free_spots(kitchen, state, "can1", cloud, avoid=(start, up, 0.05), limit=50)
    assert spots, "a vertical take-out must not rule out every spot"
    for _, pos in spots:
        assert np.linalg.norm(pos[:2] - start[:2]) >= 0.05  # the column above the mug stays free
    front = np.array([-1.0, 0.0, 0.0])  # a horizontal take-out still excludes its strip
    strip = free_spots(kitchen, state, "can1", cloud, avoid=(start, front, 0.05), limit=50)
    assert all(not ((p[0] - start[0]) * -1.0 > -0.05 and abs(p[1] - start[1]) < 0.05) for _, p in strip)


def test_aside_spots_are_offered_nearest_first_and_spread_out(kitchen: SceneWorld) -> None:
    """The nearest spot comes first either way; the next ones keep ``spot_spread`` from every earlier one
    (a spot next to one the hand could not reach fails alike), where without spreading they crowd it."""
    from hsi_planning.scheduler.auxiliary import AuxiliaryConfig, free_spots

    state = WorldState()
    cloud = kitchen.state_cloud(state)
    here = kitchen.object_position("can1", state)
    crowded = free_spots(kitchen, state, "can1", cloud, config=AuxiliaryConfig(spot_spread=0.0), limit=8)
    spread = free_spots(kitchen, state, "can1", cloud, config=AuxiliaryConfig(spot_spread=0.08), limit=8)
    assert len(spread) == 8
    np.testing.assert_array_equal(spread[0][1], crowded[0][1])
    for k, (_, pos) in enumerate(spread):
        assert all(np.linalg.norm(pos - q) >= 0.08 - 1e-9 for _, q in spread[:k])
    gaps = [np.linalg.norm(a - b) for (_, a), (_, b) in itertools.combinations(crowded, 2)]
    assert min(gaps) < 0.08  # unspread, neighbours of the nearest spot
    dist = [float(np.linalg.norm(pos - here)) for _, pos in spread]
    assert dist == sorted(dist)
    with pytest.raises(ConfigError, match="spot_spread"):
        AuxiliaryConfig(spot_spread=-0.01)


def test_aside_spots_in_an_opened_drawer_lie_on_its_pulled_out_floor(kitchen: SceneWorld) -> None:
    from scipy.spatial import cKDTree

    from hsi_planning.scene.model import support_surfaces
    from hsi_planning.scheduler.auxiliary import AuxiliaryConfig, free_spots
    from hsi_planning.scheduler.world import label_points

    state = WorldState(opened=frozenset({"drawer_unit1/drawer1"}))
    cloud = kitchen.state_cloud(state)
    config = AuxiliaryConfig(spot_spread=0.0)  # every spot, not a spread-out few
    spots = free_spots(kitchen, state, "mug2", cloud, config=config, limit=1000)
    in_drawer = np.array([p for name, p in spots if name == "drawer_unit1/drawer1"])
    assert len(in_drawer) > 10, "the pulled-out drawer floor has room for the mug"
    unit = kitchen.spec.furniture_by_name("drawer_unit1")
    assert unit.yaw == 0.0  # opens towards -x
    front = unit.pos[0] - 0.5 * unit.size[0]
    diameter, height = kitchen.object_size("mug2")
    # on the floor as the drawer is pulled out (not where the closed drawer had it, under the counter top)
    assert in_drawer[:, 0].max() + 0.5 * diameter < front
    floor = support_surfaces(kitchen.spec)["drawer_unit1/drawer1"]
    centre = (kitchen.part_transform(floor.body, 1.0) @ floor.frame)[:3, 3]
    assert np.all(np.abs(in_drawer[:, :2] - centre[:2]) <= np.array(floor.half_extents) + 1e-9)
    pts = np.asarray(cloud.points)
    pts = pts[cKDTree(label_points(cloud, ["mug2"])).query(pts)[0] > 1e-9]  # the mug's own points moved
    for p in in_drawer:  # the column a hand puts it down through is free
        near = np.linalg.norm(pts[:, :2] - p[:2], axis=1) < 0.5 * diameter + config.spot_margin
        above = (pts[:, 2] > p[2] + 0.01) & (pts[:, 2] < p[2] + height + config.spot_headroom)
        assert not np.any(near & above)


def test_a_short_clear_move_behind_is_stepped_there_without_turning_round(kitchen: SceneWorld) -> None:
    from hsi_planning.scheduler.actions import TaskRun
    from hsi_planning.scheduler.body import HipPose
    from hsi_planning.scheduler.config import SchedulerConfig
    from hsi_planning.scheduler.timeline import Timeline
    from hsi_planning.scheduler.world import WorldState

    cfg = SchedulerConfig()
    start = HipPose.standing(np.array([0.0, 0.0]), 0.0, cfg.body)
    run = TaskRun(kitchen, None, cfg, Timeline(cfg.body, start, {}), WorldState())  # type: ignore[arg-type]
    floor = run.floor()
    stance = HipPose.standing(np.array([-0.25, 0.2]), -0.42, cfg.body)  # 32 cm behind, facing ahead
    assert floor.segment_clear(start.xy, stance.xy, cfg.body.body_radius)
    looped = plan_root_path(floor, start.xy, stance.xy, stance.heading, radius=0.25, config=cfg.navigation)
    assert np.linalg.norm(np.diff(looped, axis=0), axis=1).sum() > 0.6  # to arrive facing ahead: a loop
    run.go_to(stance, floor, "a test")
    roots = [k for k in run.timeline.keyframes if k.key_joint == "root"]
    yaws = np.unwrap([Rotation.from_quat(k.quaternion).as_euler("ZYX")[0] for k in roots])
    assert np.all(np.abs(yaws) <= 0.42 + 1e-6), yaws  # no turn beyond the stance's heading
    assert np.linalg.norm(roots[-1].position[:2] - stance.xy) < 1e-9
