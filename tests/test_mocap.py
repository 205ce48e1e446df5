"""ASF/AMC/BVH loaders, forward kinematics, reach segmentation and HDM05 statistics on real clips."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hsi_planning.config import from_mapping
from hsi_planning.errors import ConfigError, MotionDataError
from hsi_planning.mocap import (
    ReachConfig,
    forward_kinematics,
    hdm05_clips,
    hdm05_reach_stats,
    hip_trajectory,
    load_amc,
    load_asf,
    load_bvh,
    median_stats,
    save_bvh,
    segment_reaches,
    wrist_rotations,
    wrist_trajectory,
)

ACTORS = ("bd", "bk", "dg")
INCH_OVER_045 = 0.0254 / 0.45


def _clip(hdm05_dir: Path, actor: str, action: str) -> Path:
    return sorted(hdm05_dir.glob(f"HDM_{actor}_{action}_*_120.amc"))[0]


# ---------------------------------------------------------------- hand-written files with known FK

TINY_ASF = """# two-bone test skeleton
:version 1.10
:name TEST
:units
  mass 1.0
  length 1.0
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name upper
     direction 1 0 0
     length 10
     axis 0 0 90  XYZ
    dof rx
  end
  begin
     id 2
     name lower
     direction 0 1 0
     length 5
     axis 0 0 0  XYZ
    dof rx ry rz
  end
:hierarchy
  begin
    root upper
    upper lower
  end
"""

TINY_AMC = """:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 0 0 0
upper 0
lower 0 0 0
2
root 1 2 3 0 0 0
upper 90
lower 0 0 0
"""


def test_acclaim_fk_uses_c_m_cinv(tmp_path: Path) -> None:
    (tmp_path / "t.asf").write_text(TINY_ASF)
    (tmp_path / "t.amc").write_text(TINY_AMC)
    skel = load_asf(tmp_path / "t.asf")
    assert skel.length_unit_m == pytest.approx(0.0254)
    fk = forward_kinematics(skel, load_amc(tmp_path / "t.amc", skel))
    inch = 0.0254
    root_src = np.array([1.0, 2.0, 3.0]) * inch
    # Frame 1, rest: upper tip at root + 10 x; lower tip 5 y further (source y-up frame).
    # World z-up: (x, y, z)_world = (z, x, y)_source.
    to_world = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]])
    assert np.allclose(fk.positions["root"][0], to_world @ root_src)
    assert np.allclose(fk.positions["upper"][0], to_world @ (root_src + np.array([10 * inch, 0, 0])))
    assert np.allclose(fk.positions["lower"][0], to_world @ (root_src + np.array([10 * inch, 5 * inch, 0])))
    # Frame 2: rx = 90° about the bone's local x, which C = Rz(90°) maps to the source y axis:
    # L = C·Rx(90°)·C⁻¹ = Ry(90°) takes x → −z and leaves y.
    assert np.allclose(
        fk.positions["upper"][1], to_world @ (root_src + np.array([0, 0, -10 * inch])), atol=1e-12
    )
    assert np.allclose(
        fk.positions["lower"][1], to_world @ (root_src + np.array([0, 5 * inch, -10 * inch])), atol=1e-12
    )
    # The bone frame's orientation: world · L · C.
    ry90 = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    rz90 = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert np.allclose(fk.rotations["upper"][1], to_world @ ry90 @ rz90, atol=1e-12)


TINY_BVH = """HIERARCHY
ROOT hip
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT j1
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT j2
    {
      OFFSET 0 20 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 5 0
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.01
0 0 0 0 0 0 0 0 0 0 0 0
1 2 3 90 0 0 0 90 0 90 90 0
"""


def test_bvh_three_joint_chain_matches_analytic_fk(tmp_path: Path) -> None:
    path = tmp_path / "chain.bvh"
    path.write_text(TINY_BVH)
    skel, motion = load_bvh(path)  # centimetres
    assert skel.convention == "bvh" and motion.fps == pytest.approx(100.0) and motion.n_frames == 2
    fk = forward_kinematics(skel, motion)
    to_world = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]]) * 0.01
    rest = {"hip": [0, 0, 0], "j1": [0, 10, 0], "j2": [0, 30, 0], "j2_end": [0, 35, 0]}
    for name, p in rest.items():
        assert np.allclose(fk.positions[name][0], to_world @ p)
    # Frame 2: root at (1,2,3), R0 = Rz90; j1 adds Rx90; j2 has Z=90 then X=90 read as R = Rz·Rx.
    # j1 = p0 + Rz90 (0,10,0) = (−9,2,3); j2 = j1 + Rz90·Rx90 (0,20,0) = (−9,2,23);
    # end = j2 + Rz90·Rx90·Rz90·Rx90 (0,5,0) = j2 + (5,0,0) = (−4,2,23).
    expected = {"hip": [1, 2, 3], "j1": [-9, 2, 3], "j2": [-9, 2, 23], "j2_end": [-4, 2, 23]}
    for name, p in expected.items():
        assert np.allclose(fk.positions[name][1], to_world @ p, atol=1e-12), name


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        ("0 0 0 0 0 0 0 0 0 0 0\n", r"chain\.bvh:24: frame has 11 values"),
        ("0 0 0 0 0 0 0 0 0 0 0 x\n", r"chain\.bvh:24: not a number"),
    ],
)
def test_bvh_malformed_frame_names_file_and_line(tmp_path: Path, bad: str, match: str) -> None:
    path = tmp_path / "chain.bvh"
    path.write_text(TINY_BVH.replace("0 0 0 0 0 0 0 0 0 0 0 0\n", bad))
    with pytest.raises(MotionDataError, match=match):
        load_bvh(path)


def test_bvh_structure_errors(tmp_path: Path) -> None:
    path = tmp_path / "x.bvh"
    path.write_text(TINY_BVH.split("MOTION", maxsplit=1)[0])
    with pytest.raises(MotionDataError, match="missing MOTION"):
        load_bvh(path)
    path.write_text(
        TINY_BVH.replace("Zrotation Xrotation Yrotation\n      End", "Zrotation Xrot Yrotation\n      End")
    )
    with pytest.raises(MotionDataError, match=r"x\.bvh:13: unknown channel"):
        load_bvh(path)
    path.write_text(TINY_BVH.replace("Frames: 2", "Frames: 3"))
    with pytest.raises(MotionDataError, match="'Frames: 3' but 2 frame lines"):
        load_bvh(path)


def test_asf_amc_malformed_inputs_name_file_and_line(tmp_path: Path) -> None:
    asf = tmp_path / "t.asf"
    asf.write_text(TINY_ASF)
    skel = load_asf(asf)
    amc = tmp_path / "t.amc"
    amc.write_text(TINY_AMC.replace("upper 90", "upper 90 1"))
    with pytest.raises(MotionDataError, match=r"t\.amc:9: bone 'upper' needs 1 values \(rx\), got 2"):
        load_amc(amc, skel)
    amc.write_text(TINY_AMC.replace("lower 0 0 0\n2", "elbow 0 0 0\n2"))
    with pytest.raises(MotionDataError, match=r"t\.amc:6: unknown bone 'elbow'"):
        load_amc(amc, skel)
    amc.write_text(TINY_AMC.replace("upper 90\n", ""))
    with pytest.raises(MotionDataError, match=r"t\.amc:7: frame has missing bone\(s\) \['upper'\]"):
        load_amc(amc, skel)
    amc.write_text(TINY_AMC.replace("\n2\n", "\n3\n"))
    with pytest.raises(MotionDataError, match=r"t\.amc:7: frame number 3 out of sequence \(expected 2\)"):
        load_amc(amc, skel)
    amc.write_text(TINY_AMC)
    assert load_amc(amc, skel, fps=60.0).fps == 60.0
    asf.write_text(TINY_ASF.split(":hierarchy", maxsplit=1)[0])
    with pytest.raises(MotionDataError, match="missing :hierarchy"):
        load_asf(asf)
    asf.write_text(TINY_ASF.replace("    upper lower", "    upper lower hand"))
    with pytest.raises(MotionDataError, match="unknown bone 'hand'"):
        load_asf(asf)
    asf.write_text(TINY_ASF.replace("direction 0 1 0", "direction 0 1"))
    with pytest.raises(MotionDataError, match=r"t\.asf:25: expected 3 numbers"):
        load_asf(asf)


# ---------------------------------------------------------------- real HDM05 clips


def test_hdm05_skeleton_units_and_structure(hdm05_dir: Path) -> None:
    skel = load_asf(hdm05_dir / "HDM_bd.asf")
    assert len(skel.joints) == 31 and skel.joints[0].name == "root"
    assert skel.length_unit_m == pytest.approx(INCH_OVER_045)
    femur = float(np.linalg.norm(skel.joint("rfemur").offset))
    assert femur == pytest.approx(7.43932 * INCH_OVER_045)
    assert 0.35 < femur < 0.5  # a human thigh [m]
    assert skel.joint("rhumerus").dofs == ("rx", "ry", "rz")
    with pytest.raises(MotionDataError, match="no joint 'tail'"):
        skel.joint("tail")


@pytest.mark.parametrize("actor", ACTORS)
def test_hdm05_standing_heights_and_handedness(hdm05_dir: Path, actor: str) -> None:
    skel = load_asf(hdm05_dir / f"HDM_{actor}.asf")
    fk = forward_kinematics(skel, load_amc(_clip(hdm05_dir, actor, "grabHighR"), skel))
    p = fk.positions
    floor = min(p["ltoes"][:, 2].min(), p["rtoes"][:, 2].min())
    assert abs(floor) < 0.1  # the capture floor is z = 0
    head = float(np.median(p["head"][:, 2])) - floor
    assert 1.5 < head < 1.9
    assert 0.85 < float(np.median(hip_trajectory(fk)[:, 2])) < 1.2
    # Not mirrored: forward (toes) × left (left hip − right hip) points up.
    fwd = (p["ltoes"] - p["lfoot"] + p["rtoes"] - p["rfoot"])[0]
    left = (p["lhipjoint"] - p["rhipjoint"])[0]
    assert np.cross(fwd, left)[2] > 0
    rot = fk.rotations["rhumerus"]
    assert np.allclose(rot @ np.swapaxes(rot, 1, 2), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(rot), 1.0)
    wrist = wrist_trajectory(fk)
    wrist[:] = 0.0  # a copy: the FK result is untouched
    assert np.all(fk.positions["rwrist"][:, 2] > 0.3)
    assert wrist_rotations(fk).shape == (fk.n_frames, 3, 3)


def test_segmentation_finds_one_reach_per_hdm05_clip(hdm05_dir: Path) -> None:
    skeletons = {a: load_asf(hdm05_dir / f"HDM_{a}.asf") for a in ACTORS}
    clips = hdm05_clips(hdm05_dir)
    assert len(clips) == 34
    for clip in clips:
        actor = clip.name.split("_")[1]
        fk = forward_kinematics(skeletons[actor], load_amc(clip, skeletons[actor]))
        wrist = wrist_trajectory(fk, "right")
        reaches = segment_reaches(wrist, fk.fps)
        assert len(reaches) == 1, clip.name
        r = reaches[0]
        assert r.onset <= r.peak < r.contact <= r.withdrawal_start < r.end
        contact_z = wrist[r.contact, 2]
        if "grabHighR" in clip.name:
            assert wrist[:, 2].max() > 1.4, clip.name
            assert contact_z > 1.4, clip.name
        else:
            assert contact_z < 0.35, clip.name
        assert 0.6 < r.approach_distance < 1.8


def test_segmentation_on_synthetic_reaches() -> None:
    fps = 120.0
    rng = np.random.default_rng(3)

    def move(a: np.ndarray, b: np.ndarray, seconds: float) -> np.ndarray:
        tau = np.linspace(0.0, 1.0, int(seconds * fps))[:, None]
        return a + (b - a) * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)

    home, shelf, table = np.array([0.3, -0.2, 1.0]), np.array([0.7, -0.3, 1.6]), np.array([0.6, 0.2, 0.8])
    rest = np.repeat(home[None], int(0.5 * fps), axis=0)
    one = np.concatenate(
        [rest, move(home, shelf, 1.0), np.repeat(shelf[None], 60, 0), move(shelf, home, 1.0), rest]
    )
    one += rng.normal(0.0, 5e-4, one.shape)  # 0.5 mm marker noise
    reaches = segment_reaches(one, fps)
    assert len(reaches) == 1
    r = reaches[0]
    assert r.onset / fps == pytest.approx(0.5, abs=0.12)
    assert r.contact / fps == pytest.approx(1.5, abs=0.12)
    assert r.peak / fps == pytest.approx(1.0, abs=0.03)
    assert r.withdrawal_start / fps == pytest.approx(2.0, abs=0.12)
    assert r.end / fps == pytest.approx(3.0, abs=0.12) and not r.end_truncated
    assert r.approach_distance == pytest.approx(np.linalg.norm(shelf - home), abs=0.02)
    two = np.concatenate(
        [one, move(home, table, 0.8), np.repeat(table[None], 60, 0), move(table, home, 0.8), rest]
    )
    assert len(segment_reaches(two, fps)) == 2
    assert segment_reaches(np.repeat(home[None], 200, 0), fps) == []
    wiggle = np.concatenate([rest, move(home, home + 0.05, 0.5), rest])  # 9 cm: not a reach
    assert segment_reaches(wiggle, fps) == []


def test_reach_config_validation() -> None:
    assert from_mapping(ReachConfig, {"cutoff_hz": 8}).cutoff_hz == 8.0
    with pytest.raises(ConfigError, match="onset_fraction"):
        ReachConfig(onset_fraction=1.5)
    with pytest.raises(ConfigError, match="unknown parameter"):
        from_mapping(ReachConfig, {"cutoff": 8.0})


def test_bvh_round_trip_of_hdm05_clip_within_1mm(hdm05_dir: Path, tmp_path: Path) -> None:
    skel = load_asf(hdm05_dir / "HDM_bk.asf")
    motion = load_amc(_clip(hdm05_dir, "bk", "grabHighR"), skel)
    fk = forward_kinematics(skel, motion)
    out = tmp_path / "clip.bvh"
    save_bvh(out, skel, motion)
    skel2, motion2 = load_bvh(out)
    assert motion2.fps == pytest.approx(120.0) and motion2.n_frames == motion.n_frames
    fk2 = forward_kinematics(skel2, motion2)
    children: dict[str, list[str]] = {}
    for j in skel.joints:
        if j.parent is not None:
            children.setdefault(j.parent, []).append(j.name)
    worst = 0.0
    for j in skel.joints:
        # An Acclaim bone end is the next BVH joint (or the End Site of a leaf bone).
        other = (
            "root" if j.parent is None else (children[j.name][0] if j.name in children else f"{j.name}_end")
        )
        worst = max(worst, float(np.max(np.abs(fk.positions[j.name] - fk2.positions[other]))))
    assert worst < 1e-3
    # The reach helpers find the same anatomical wrist in both conventions.
    assert np.allclose(wrist_trajectory(fk), wrist_trajectory(fk2), atol=1e-3)
    assert np.allclose(hip_trajectory(fk), hip_trajectory(fk2), atol=1e-3)


@pytest.fixture(scope="module")
def hdm05_stats(hdm05_dir: Path) -> list[dict[str, Any]]:
    return hdm05_reach_stats(hdm05_dir)


def test_hdm05_reach_stats_match_reference_facts(hdm05_stats: list[dict[str, Any]]) -> None:
    assert len(hdm05_stats) == 34
    assert {r["actor"] for r in hdm05_stats} == set(ACTORS)
    grab = next(m for m in median_stats(hdm05_stats, group_by=("action",)) if m["action"] == "grabHighR")
    # DESIGN.md: ≈ 0.9–1 s over ≈ 1 m, peak 2.3–2.6 m/s at ≈ 30 %, deviation 9–13 %, β ≈ −0.4.
    assert 0.8 < grab["duration"] < 1.1
    assert 0.8 < grab["distance"] < 1.2
    assert 2.0 < grab["peak_speed"] < 2.8
    assert 0.2 < grab["peak_time_ratio"] < 0.4
    assert 0.05 < grab["max_deviation_ratio"] < 0.16
    assert -0.6 < grab["speed_curvature_exponent"] < -0.3
    assert -2.0 < grab["sparc"] < -1.3  # less smooth than minimum jerk (−1.40)
    assert grab["ldlj"] < -5.32
    per_actor = median_stats(hdm05_stats, complete_only=True)
    assert {m["actor"] for m in per_actor if m["action"] == "grabHighR"} == set(ACTORS)
    for row in hdm05_stats:
        assert (row["contact_height"] > 1.4) == (row["action"] == "grabHighR")
