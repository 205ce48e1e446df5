"""The human-reach model: human-like timing and shape, exact endpoints, determinism, collisions."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.signal import find_peaks

from hsi_planning.config import from_mapping
from hsi_planning.demos import ObstacleField, ReachModelConfig, ReachRequest, box_mesh, generate_reach
from hsi_planning.errors import ConfigError, PlanningError, SceneError
from hsi_planning.metrics.kinematics import (
    max_path_deviation_ratio,
    normalized_peak_speed_time,
    speed_curvature_exponent,
)
from hsi_planning.trajectory import WristTrajectory

Q_START = np.array([0.0, 0.0, 0.0, 1.0])
Q_CONTACT = np.array([0.0, np.sin(0.4), 0.0, np.cos(0.4)])  # 0.8 rad pitch
HIGH_REACH = {  # grabHighR-like: ~1 m up and forward with the right hand
    "start_position": [0.10, -0.25, 0.90],
    "start_quaternion": Q_START,
    "contact_position": [0.45, -0.30, 1.85],
    "contact_quaternion": Q_CONTACT,
}


def _reach(seed: int, **overrides: object) -> WristTrajectory:
    kwargs = {**HIGH_REACH, **overrides}
    return generate_reach(ReachRequest(**kwargs), None, ReachModelConfig(), np.random.default_rng(seed))  # type: ignore[arg-type]


def _movement(traj: WristTrajectory) -> slice:
    """Samples moving at >= 5 % of peak speed (the reach onset/contact convention used for HDM05)."""
    v = traj.speed()
    moving = np.flatnonzero(v >= 0.05 * v.max())
    return slice(int(moving[0]), int(moving[-1]) + 1)


def _peak_time(traj: WristTrajectory) -> float:
    sl = _movement(traj)
    return normalized_peak_speed_time(traj.position[sl], traj.t[sl])


def _chord_distance(traj: WristTrajectory) -> np.ndarray:
    a, b = traj.position[0], traj.position[-1]
    axis = (b - a) / np.linalg.norm(b - a)
    rel = traj.position - a
    return np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1)


def test_grasp_speed_is_bell_shaped_with_early_peak() -> None:
    peaks = []
    for seed in range(6):
        traj = _reach(seed)
        v = traj.speed()
        assert v[0] < 0.05 * v.max() and v[-1] < 0.05 * v.max()
        significant, _ = find_peaks(v, prominence=0.1 * v.max())
        assert len(significant) == 1, f"seed {seed}: speed has {len(significant)} peaks"
        peaks.append(_peak_time(traj))
    assert 0.2 <= float(np.median(peaks)) <= 0.4
    assert max(peaks) < 0.5


def test_place_peaks_later_than_grasp() -> None:
    grasp = [_peak_time(_reach(s)) for s in range(4)]
    place = [_peak_time(_reach(s, action="place")) for s in range(4)]
    assert float(np.median(place)) > float(np.median(grasp)) + 0.03
    assert 0.25 <= float(np.median(place)) <= 0.6


def test_paths_are_curved_not_straight() -> None:
    ratios = [max_path_deviation_ratio(_reach(seed).position) for seed in range(8)]
    assert float(np.median(ratios)) >= 0.05
    assert max(ratios) <= 0.2
    # the bulge bends elbow-out / upward for the right hand, i.e. not towards +y (the body's left)
    traj = _reach(0)
    mid = traj.position[np.argmax(_chord_distance(traj))]
    chord_mid = 0.5 * (traj.position[0] + traj.position[-1])
    assert (mid - chord_mid)[1] < 0.02
    # the left hand mirrors it: same reach mirrored in y bulges the other way
    mirror = np.array([1.0, -1.0, 1.0])
    left = _reach(
        0,
        hand="left",
        start_position=np.multiply(HIGH_REACH["start_position"], mirror),
        contact_position=np.multiply(HIGH_REACH["contact_position"], mirror),
    )
    left_mid = left.position[np.argmax(_chord_distance(left))]
    assert (left_mid - 0.5 * (left.position[0] + left.position[-1]))[1] > -0.02
    assert (left_mid - 0.5 * (left.position[0] + left.position[-1]))[1] == pytest.approx(
        -(mid - chord_mid)[1], abs=0.03
    )


def test_speed_curvature_exponent_is_human_like() -> None:
    betas = [speed_curvature_exponent(t.position, t.t) for t in (_reach(seed) for seed in range(5))]
    assert -0.6 <= float(np.median(betas)) <= -0.25


def test_endpoints_exact_and_quaternions_unit() -> None:
    for segment, first, last in (("approach", 0, -1), ("leave", -1, 0)):
        traj = _reach(3, segment=segment)
        assert np.allclose(traj.position[first], HIGH_REACH["start_position"], atol=1e-3)
        assert np.allclose(traj.position[last], HIGH_REACH["contact_position"], atol=1e-3)
        assert traj.contact_index == (len(traj.t) - 1 if segment == "approach" else 0)
        norms = np.linalg.norm(traj.quaternion, axis=1)
        assert np.allclose(norms, 1.0, atol=1e-9)
        assert abs(np.dot(traj.quaternion[first], Q_START)) > 1 - 1e-9
        assert abs(np.dot(traj.quaternion[last], Q_CONTACT)) > 1 - 1e-9
        assert np.allclose(np.diff(traj.t), 1.0 / 120.0)
        assert traj.planner == "human_reach_model"


def test_rotation_happens_mid_reach() -> None:
    traj = _reach(1)
    angle = 2 * np.arccos(np.clip(np.abs(traj.quaternion @ Q_CONTACT), 0, 1))
    total = angle[0]
    tau = traj.t / traj.t[-1]
    done_early = total - angle[np.searchsorted(tau, 0.2)]
    done_mid = angle[np.searchsorted(tau, 0.3)] - angle[np.searchsorted(tau, 0.7)]
    assert done_mid > 0.5 * total > done_early


def test_same_seed_same_trajectory_and_variability_mid_reach() -> None:
    a, b = _reach(7), _reach(7)
    assert np.array_equal(a.position, b.position) and np.array_equal(a.quaternion, b.quaternion)
    samples = []
    for seed in range(12):
        traj = _reach(seed)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(traj.position, axis=0), axis=1))])
        u = np.array([0.02, 0.5, 0.98]) * arc[-1]
        samples.append([np.interp(u, arc, traj.position[:, k]) for k in range(3)])
    spread = np.linalg.norm(
        np.std(np.asarray(samples), axis=0), axis=0
    )  # (3,) at 2 %, 50 %, 98 % of the path
    assert spread[1] > 0.02
    assert spread[1] > 3 * spread[0] and spread[1] > 3 * spread[2]


def test_duration_scales_with_distance() -> None:
    def movement_time(traj: WristTrajectory) -> float:
        sl = _movement(traj)
        return float(traj.t[sl][-1] - traj.t[sl][0])

    near = [movement_time(_reach(s, contact_position=[0.30, -0.25, 1.10])) for s in range(4)]
    far = [movement_time(_reach(s)) for s in range(4)]  # ~1 m: HDM05 grabHighR takes 0.85-1.1 s
    assert 0.8 <= float(np.median(far)) <= 1.15
    assert float(np.median(near)) < float(np.median(far)) - 0.1


def test_collision_free_against_box_near_the_chord() -> None:
    start, contact = np.array([0.0, 0.0, 1.0]), np.array([0.8, 0.0, 1.0])
    box = box_mesh([0.4, 0.0, 0.98], [0.16, 0.16, 0.16])  # straddles the straight line
    field = ObstacleField({"box": box})
    chord = np.linspace(start, contact, 50)
    assert field.distance(chord).min() < 0.0  # a straight reach would go through it
    config = ReachModelConfig()
    for seed in range(4):
        request = ReachRequest(start, Q_START, contact, Q_CONTACT)
        traj = generate_reach(request, field, config, np.random.default_rng(seed))
        assert field.distance(traj.position).min() >= config.hand_radius - 2e-3
        assert np.allclose(traj.position[-1], contact, atol=1e-3)


def test_contact_inside_obstacle_raises() -> None:
    field = ObstacleField({"cabinet": box_mesh([0.6, 0.0, 1.0], [0.3, 0.4, 0.4])})
    request = ReachRequest([0.0, 0.0, 1.0], Q_START, [0.6, 0.0, 1.0], Q_CONTACT)
    with pytest.raises(PlanningError, match="inside obstacle 'cabinet'"):
        generate_reach(request, field, ReachModelConfig(), np.random.default_rng(0))


def test_enclosed_target_raises_after_attempts() -> None:
    walls = [
        box_mesh(c, s)
        for c, s in (
            ([0.6, 0.0, 0.8], [0.4, 0.4, 0.02]),
            ([0.6, 0.0, 1.2], [0.4, 0.4, 0.02]),
            ([0.4, 0.0, 1.0], [0.02, 0.4, 0.4]),
            ([0.8, 0.0, 1.0], [0.02, 0.4, 0.4]),
            ([0.6, 0.2, 1.0], [0.4, 0.02, 0.4]),
            ([0.6, -0.2, 1.0], [0.4, 0.02, 0.4]),
        )
    ]
    field = ObstacleField({"cage": trimesh.util.concatenate(walls)})
    request = ReachRequest([0.0, 0.0, 1.0], Q_START, [0.6, 0.0, 1.0], Q_CONTACT)
    config = from_mapping(ReachModelConfig, {"max_attempts": 3, "bend_iterations": 4})
    with pytest.raises(PlanningError, match="no collision-free reach found in 3 attempts"):
        generate_reach(request, field, config, np.random.default_rng(0))


def test_insertion_along_the_opening_axis_slows_inside() -> None:
    # a shelf compartment opening towards -x: the hand enters along +x
    board_low = box_mesh([0.85, 0.0, 1.00], [0.30, 0.50, 0.02])
    board_high = box_mesh([0.85, 0.0, 1.30], [0.30, 0.50, 0.02])
    back = box_mesh([1.01, 0.0, 1.15], [0.02, 0.50, 0.32])
    field = ObstacleField({"shelf": trimesh.util.concatenate([board_low, board_high, back])})
    contact = np.array([0.88, 0.0, 1.10])
    axis = np.array([1.0, 0.0, 0.0])
    request = ReachRequest(
        [0.1, -0.25, 0.85], Q_START, contact, Q_CONTACT, approach_axis=axis, object_name="can1"
    )
    traj = generate_reach(request, field, ReachModelConfig(), np.random.default_rng(2))
    inside = traj.position[:, 0] > contact[0] - 0.11
    direction = traj.position[-1] - traj.position[inside][0]
    assert np.dot(direction / np.linalg.norm(direction), axis) > 0.99
    v = traj.speed()
    assert v[inside].max() < 0.45 * v.max()
    assert field.distance(traj.position).min() > 0.0


def test_carrying_out_lifts_and_keeps_more_clearance() -> None:
    contact = np.array([0.8, 0.0, 1.06])
    axis = np.array([1.0, 0.0, 0.0])
    board = box_mesh([0.85, 0.0, 1.00], [0.30, 0.50, 0.02])
    field = ObstacleField({"board": board})
    request = ReachRequest(
        [0.2, -0.3, 1.0],
        Q_START,
        contact,
        Q_CONTACT,
        approach_axis=axis,
        action="grasp",
        segment="leave",
        carried_radius=0.05,
    )
    traj = generate_reach(request, field, ReachModelConfig(), np.random.default_rng(0))
    assert traj.contact_index == 0 and traj.meta["carrying"] and traj.meta["clearance"] == pytest.approx(0.07)
    # the first 3 cm of motion are a lift (upward), before moving out along -axis
    moved = np.linalg.norm(traj.position - contact, axis=1)
    k = int(np.searchsorted(moved, 0.03))
    assert traj.position[k, 2] - contact[2] > 0.025
    assert abs(traj.position[k, 0] - contact[0]) < 0.01


def test_obstacle_field_signed_distance() -> None:
    field = ObstacleField(
        {"a": box_mesh([0, 0, 0], [0.2, 0.2, 0.2]), "b": box_mesh([1, 0, 0], [0.2, 0.2, 0.2])}
    )
    d = field.distance(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.3], [0.95, 0.0, 0.0], [0.5, 0.0, 0.0]]))
    assert np.allclose(d, [-0.1, 0.2, -0.05, 0.4], atol=1e-5)
    assert field.nearest_name(np.array([[0.8, 0.0, 0.0]])) == ["b"]
    assert field.without(["b"]).names == ("a",)
    assert np.isinf(ObstacleField.empty().distance(np.zeros((2, 3)))).all()
    with pytest.raises(SceneError):
        field.distance(np.zeros((3, 2)))


def test_config_and_request_validation() -> None:
    with pytest.raises(ConfigError, match="hand_radius"):
        ReachModelConfig(hand_radius=0.0)
    with pytest.raises(ConfigError, match="unknown parameter"):
        from_mapping(ReachModelConfig, {"hand_size": 0.1})
    with pytest.raises(PlanningError, match="hand"):
        ReachRequest([0, 0, 0], Q_START, [1, 0, 0], Q_START, hand="middle")  # type: ignore[arg-type]
    with pytest.raises(PlanningError, match="approach_axis"):
        ReachRequest([0, 0, 0], Q_START, [1, 0, 0], Q_START, approach_axis=[0, 0, 0])
    with pytest.raises(PlanningError, match="quaternion"):
        ReachRequest([0, 0, 0], [0, 0, 0, 0], [1, 0, 0], Q_START)
    with pytest.raises(PlanningError, match="apart"):
        generate_reach(ReachRequest([0, 0, 0], Q_START, [0, 0, 0.001], Q_START), None)
