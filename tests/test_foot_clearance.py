"""Footholds clear of a swinging door: the region the kitchen cabinet's door sweeps, a sole in it moved out
by the least offset, the footstep plan's targets kept clear, and bad settings refused."""

from __future__ import annotations

import numpy as np
import pytest
from test_part_scene import DOOR, DRAWER, _phase

from hsi_planning.errors import ConfigError
from hsi_retarget.foot_clearance import dodge, part_sweep, sole_clearance, sole_points
from hsi_retarget.humanoid_ik import SupportConfig, plan_footsteps
from hsi_retarget.robots import RobotModel


def _sole(x: float, y: float, yaw: float = 0.0) -> np.ndarray:
    pose = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    pose[:2, :2] = [[c, -s], [s, c]]
    pose[:2, 3] = (x, y)
    return pose


def test_the_sweep_holds_the_door_at_every_opening_and_nothing_without_a_part() -> None:
    phase = _phase(DOOR)
    sweep = part_sweep(phase)
    assert sweep is not None and part_sweep(None) is None
    assert phase.meshes is not None and phase.motion is not None
    for fraction in (0.0, 1.0):  # the closed and the scheduled opening are in it exactly
        mesh = phase.meshes[DOOR].copy()
        mesh.apply_transform(phase.motion(fraction))
        dist, _ = sweep.query(np.asarray(mesh.vertices))
        assert np.abs(dist).max() < 1e-4
    for fraction in (0.02, 0.35, 0.7, 0.98):  # between the sampled openings: within about 1 cm
        mesh = phase.meshes[DOOR].copy()
        mesh.apply_transform(phase.motion(fraction))
        dist, _ = sweep.query(np.asarray(mesh.vertices))
        assert np.abs(dist).max() < 0.015


def test_a_sole_in_the_door_arc_moves_out_by_the_least_offset() -> None:
    cfg = SupportConfig()
    sweep = part_sweep(_phase(DOOR))
    assert sweep is not None
    inside = _sole(0.11, -0.558)  # on the rim of the arc, 0.65 m from the hinge
    assert sole_clearance(inside, sweep, cfg) < 0.0
    moved, offset = dodge(inside, sweep, cfg)
    assert 0.0 < offset <= cfg.max_dodge
    assert offset / cfg.dodge_step == pytest.approx(round(offset / cfg.dodge_step))
    assert sole_clearance(moved, sweep, cfg) >= cfg.keep_out_clearance
    assert np.linalg.norm(moved[:2, 3] - inside[:2, 3]) == pytest.approx(offset)
    np.testing.assert_array_equal(moved[:3, :3], inside[:3, :3])  # only slid on the floor
    assert moved[2, 3] == inside[2, 3]
    # no offset one ring smaller clears it: the least one
    smaller = offset - cfg.dodge_step
    if smaller > 0.0:
        for a in np.linspace(0.0, 2 * np.pi, 16, endpoint=False):
            probe = inside.copy()
            probe[:2, 3] += smaller * np.array([np.cos(a), np.sin(a)])
            assert sole_clearance(probe, sweep, cfg) < cfg.keep_out_clearance


def test_a_clear_sole_or_no_keep_out_leaves_the_sole_where_it_is() -> None:
    cfg = SupportConfig()
    sweep = part_sweep(_phase(DOOR))
    clear = _sole(0.0, 0.0)
    assert sole_clearance(clear, sweep, cfg) > cfg.keep_out_clearance  # type: ignore[arg-type]
    for keep_out in (sweep, None):
        pose, offset = dodge(clear, keep_out, cfg)
        assert offset == 0.0 and np.array_equal(pose, clear)
    inside = _sole(0.11, -0.558)
    pose, offset = dodge(inside, sweep, SupportConfig(max_dodge=0.0))  # moving switched off
    assert offset == 0.0 and np.array_equal(pose, inside)
    high = part_sweep(_phase(DRAWER))  # a drawer slides 0.57 m above the floor: never in a foot's way
    assert high is not None
    under = _sole(0.6, -1.3)
    assert dodge(under, high, cfg)[1] == 0.0


def test_sole_points_span_the_foot_box() -> None:
    cfg = SupportConfig()
    pts = sole_points(_sole(1.0, 2.0, np.pi / 2), cfg)
    assert pts.shape == (18, 3)
    # turned 90 deg: the sole's length lies along world y
    np.testing.assert_allclose(pts[:, 1].max() - pts[:, 1].min(), 2 * cfg.foot_half_length)
    np.testing.assert_allclose(pts[:, 0].max() - pts[:, 0].min(), 2 * cfg.foot_half_width)
    assert pts[:, 2].min() > 0.0 and pts[:, 2].max() == pytest.approx(0.05)


def test_the_footstep_plan_lands_its_steps_clear_of_the_door() -> None:
    robot = RobotModel("humanoid")
    cfg = SupportConfig()
    sweep = part_sweep(_phase(DOOR))
    assert sweep is not None
    t = np.linspace(0.0, 3.0, 181)
    pelvis = np.repeat(np.eye(4)[None], t.shape[0], axis=0)
    pelvis[:, 2, 3] = robot.q_home[2]
    # the pelvis walks from the open floor to just in front of the door's arc, facing it (-y)
    start, end = np.array([0.05, 0.1]), np.array([0.05, -0.45])
    u = np.clip(t / 1.5, 0.0, 1.0)[:, None]
    pelvis[:, :2, 3] = (1 - u) * start + u * end
    pelvis[:, :2, :2] = [[0.0, 1.0], [-1.0, 0.0]]
    plain = plan_footsteps(robot, t, pelvis, cfg)
    kept = plan_footsteps(robot, t, pelvis, cfg, keep_out=sweep)
    gaps = [sole_clearance(plain.feet[s][-1], sweep, cfg) for s in ("left", "right")]
    assert min(gaps) < cfg.keep_out_clearance  # the nominal stance stands in the door's way
    for side in ("left", "right"):
        assert sole_clearance(kept.feet[side][-1], sweep, cfg) >= cfg.keep_out_clearance - 1e-9
    assert any(float(s["dodge_m"]) > 0.0 for s in kept.steps)
    assert all(float(s["dodge_m"]) == 0.0 for s in plain.steps)


@pytest.mark.parametrize(
    "field, value",
    [("keep_out_clearance", -0.01), ("max_dodge", -0.1), ("dodge_step", 0.0), ("max_step_yaw", 0.0)],
)
def test_bad_foot_clearance_settings_are_refused(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=field):
        SupportConfig(**{field: value})
