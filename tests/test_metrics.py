"""Kinematic, smoothness and DTW metrics on analytic signals with known values."""

from __future__ import annotations

import numpy as np
import pytest

from hsi_planning.errors import MotionDataError
from hsi_planning.metrics import (
    curvature,
    dimensionless_jerk,
    dtw_distance,
    integrated_squared_jerk,
    log_dimensionless_jerk,
    max_path_deviation_ratio,
    mean_acceleration,
    normalized_peak_speed_time,
    normalized_trajectory,
    path_length,
    rms_curvature,
    sparc,
    speed_curvature_exponent,
    speed_profile,
)

FS = 120.0


def min_jerk(duration: float = 1.0, fs: float = FS, delta=(0.6, 0.3, 0.2)) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, duration + 0.5 / fs, 1.0 / fs)
    tau = t / duration
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    return np.outer(s, delta), t


def test_min_jerk_reach_timing_shape_and_length() -> None:
    pos, t = min_jerk()
    assert normalized_peak_speed_time(pos, t) == pytest.approx(0.5, abs=1.0 / FS)
    assert max_path_deviation_ratio(pos) < 1e-12
    assert path_length(pos) == pytest.approx(np.linalg.norm([0.6, 0.3, 0.2]), rel=1e-9)
    v = speed_profile(pos, t)
    assert v.max() == pytest.approx(1.875 * np.linalg.norm([0.6, 0.3, 0.2]), rel=1e-3)  # 1.875 D/T


def test_integrated_squared_jerk_of_min_jerk_is_720_d2_over_t5() -> None:
    pos, t = min_jerk(duration=0.8, fs=1000.0, delta=(0.5, 0.0, 0.0))
    # Finite differences lose ~1 % at the ends, where minimum-jerk jerk is largest.
    assert integrated_squared_jerk(pos, t) == pytest.approx(720 * 0.5**2 / 0.8**5, rel=0.02)


def test_sparc_min_jerk_value_and_invariances() -> None:
    pos, t = min_jerk()
    v = speed_profile(pos, t)
    # Published algorithm (fc 10 Hz, threshold 0.05, pad 4): −1.40 for one minimum-jerk submovement.
    assert sparc(v, FS) == pytest.approx(-1.40, abs=0.01)
    assert sparc(3.0 * v, FS) == pytest.approx(sparc(v, FS), abs=1e-9)  # amplitude invariant
    pos2, t2 = min_jerk(duration=2.0)
    assert sparc(speed_profile(pos2, t2), FS) == pytest.approx(sparc(v, FS), abs=0.01)  # duration invariant
    two = np.concatenate([v, v])  # two submovements: less smooth
    assert sparc(two, FS) < sparc(v, FS) - 0.3


def test_ldlj_min_jerk_matches_analytic_value() -> None:
    pos, t = min_jerk()
    expected = -np.log(720 / 1.875**2)  # −ln 204.8 ≈ −5.322
    assert log_dimensionless_jerk(speed_profile(pos, t), FS) == pytest.approx(expected, abs=0.01)
    assert log_dimensionless_jerk(pos, FS) == pytest.approx(expected, abs=0.01)
    assert dimensionless_jerk(pos, FS) == pytest.approx(204.8, rel=0.01)
    two = np.concatenate([pos, pos[-1] + pos[1:]])
    assert log_dimensionless_jerk(two, FS) < expected - 0.5


def test_two_thirds_power_law_ellipse_gives_minus_one_third() -> None:
    # Harmonic motion on an ellipse obeys v = k κ^(−1/3) exactly.
    t = np.linspace(0.0, 2.0, 241)
    w = 2 * np.pi / 2.0
    pos = np.stack([0.3 * np.cos(w * t), 0.1 * np.sin(w * t), 0.05 * np.sin(w * t)], axis=1)
    assert speed_curvature_exponent(pos, t) == pytest.approx(-1.0 / 3.0, abs=0.02)


def test_constant_speed_wobble_is_not_a_power_law() -> None:
    # Constant speed along a path with varying curvature: β ≈ 0.
    rng = np.random.default_rng(0)
    s = np.linspace(0.0, 1.0, 400)
    theta = 2.0 * np.sin(2 * np.pi * s) + rng.normal(0.0, 1e-9, s.shape)
    ds = 1.0 / 399
    pos2 = np.cumsum(np.stack([np.cos(theta), np.sin(theta)], axis=1) * ds, axis=0)
    pos = np.concatenate([pos2, np.zeros((400, 1))], axis=1)
    assert abs(speed_curvature_exponent(pos, s)) < 0.05


def test_curvature_of_circle_is_inverse_radius() -> None:
    r = 0.25
    t = np.linspace(0.0, 1.0, 400)
    pos = np.stack([r * np.cos(2 * np.pi * t), r * np.sin(2 * np.pi * t), 0.0 * t], axis=1)
    kappa = curvature(pos, t)
    assert np.allclose(kappa[2:-2], 1.0 / r, rtol=1e-3)
    assert rms_curvature(pos, t) == pytest.approx(1.0 / r, rel=1e-2)
    assert np.allclose(curvature(pos[:, :2], t)[2:-2], 1.0 / r, rtol=1e-3)  # 2D input
    v = 2 * np.pi * r
    assert mean_acceleration(pos, t) == pytest.approx(v**2 / r, rel=0.01)


def test_curvature_of_a_line_is_zero_and_stationary_is_nan() -> None:
    pos, t = min_jerk()
    kappa = curvature(pos, t)
    moving = speed_profile(pos, t) > 0.01 * speed_profile(pos, t).max()
    assert np.max(kappa[moving]) < 1e-6
    still = np.concatenate([np.repeat(pos[:1], 3, axis=0), pos])
    assert np.isnan(curvature(still, np.arange(still.shape[0]) / FS)[0])  # zero speed: undefined


def test_dtw_identity_symmetry_and_time_warp() -> None:
    u = np.linspace(0.0, 3.0, 100)
    a = np.stack([np.sin(u), np.cos(u), u / 3], axis=1)
    warp = 3.0 * np.linspace(0.0, 1.0, 160) ** 1.7
    b = np.stack([np.sin(warp), np.cos(warp), warp / 3], axis=1)
    assert dtw_distance(a, a) == 0.0
    assert dtw_distance(a, b) == pytest.approx(dtw_distance(b, a), abs=1e-12)
    assert dtw_distance(a, b) < 0.01
    line = np.stack([u, 0 * u, 0 * u], axis=1)
    shifted = line + np.array([0.0, 0.2, 0.0])  # offset across a straight line: no warp does better
    assert dtw_distance(line, shifted) == pytest.approx(0.2, abs=1e-9)


def test_dtw_small_exact_cases() -> None:
    assert dtw_distance(np.array([[0.0], [1.0], [2.0]]), np.array([[0.0], [1.0], [1.0], [2.0]])) == 0.0
    assert dtw_distance(np.array([[0.0]]), np.array([[1.0]]), normalized=False) == 1.0
    # [0, 2] vs [1]: both pairs cost 1, total 2, path length 2.
    assert dtw_distance(np.array([[0.0], [2.0]]), np.array([[1.0]]), normalized=False) == 2.0
    with pytest.raises(MotionDataError, match="same dimension"):
        dtw_distance(np.zeros((3, 2)), np.zeros((3, 3)))


def test_normalized_trajectory_is_invariant_to_pose_and_scale() -> None:
    rng = np.random.default_rng(1)
    s = np.linspace(0.0, 1.0, 80)
    path = np.stack([s, 0.2 * np.sin(np.pi * s), 0.05 * np.sin(2 * np.pi * s)], axis=1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    moved = 2.5 * path @ q.T + np.array([1.0, -2.0, 0.5])
    n1 = normalized_trajectory(path, n=50)
    n2 = normalized_trajectory(moved, n=50)
    assert n1.shape == (50, 3)
    assert np.allclose(n1, n2, atol=1e-9)
    assert np.allclose(n1[0], 0.0) and np.allclose(n1[-1], [1.0, 0.0, 0.0], atol=1e-12)
    same = normalized_trajectory(moved, n=80)  # the input's own samples
    k = int(np.argmax(np.linalg.norm(same[:, 1:], axis=1)))
    assert same[k, 1] > 0.1 and abs(same[k, 2]) < 1e-9  # max deviation in the x–y plane, at +y
    arc = normalized_trajectory(path, n=50, by="arc")
    steps = np.linalg.norm(np.diff(arc, axis=0), axis=1)
    assert np.ptp(steps) / steps.mean() < 0.05  # uniform in arc length


def test_metric_input_errors() -> None:
    pos, t = min_jerk()
    with pytest.raises(MotionDataError, match="samples"):
        curvature(pos, t[:-1])
    with pytest.raises(MotionDataError, match="strictly increasing"):
        speed_profile(pos, t[::-1].copy())
    loop = np.concatenate([pos, pos[::-1]])
    with pytest.raises(MotionDataError, match="chord"):
        max_path_deviation_ratio(loop)
    with pytest.raises(MotionDataError, match="fc"):
        sparc(np.ones(10), FS, fc=-1.0)
