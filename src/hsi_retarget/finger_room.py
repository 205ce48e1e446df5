"""Room for the fingers at the grasp of a free object: the gripper's turn about its approach axis and
how far its fingers open.

A parallel gripper approaching an object fully open needs its whole stroke on both sides of the object
(14 cm for the dual arm's gripper). In a crowded drawer or between close neighbours there is no such room
along the planned finger axis, and the per-frame IK then stops the gripper above the object at its
collision margins: the grasp is missed. :func:`make_finger_room` changes the robot's goals around every
free-object grasp (:class:`~hsi_retarget.grasp_windows.GraspWindow`, after the mapping):

- **aperture**: the fingers open only ``clearance`` [m] wider than the object on each side (half its extent
  along the finger axis), capped at the stroke. :attr:`RobotGoals.finger` carries the opening per finger
  joint; the IK's finger spheres and the executed trajectory follow it.
- **turn** (top-down grasps only, approach within ``top_down_deg`` of straight down, where any turn about
  the vertical is an equally good grip): the gripper turns about its approach axis to the angle, on a
  ``step_deg`` grid in [-90, 90) deg, whose hand spheres (palm, wrist and fingers at that aperture) keep
  their IK margins to the scene at the grasp pose and at the release pose; of those the smallest turn;
  where none does, the one with the most room if it gains ``min_gain`` [m]. The object must still fit
  between the open fingers. The scene is the IK's (the touched objects left out) plus an opened drawer or
  door with what rides in it (:mod:`hsi_retarget.part_scene`).

Both ease in over the grasp's approach and out after the release like the grip turn
(:func:`~hsi_retarget.grip_turn.turn_weight`). Times are unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hsi_planning.errors import ConfigError
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.grip_turn import grip_phases, object_width, turn_weight
from hsi_retarget.mapping import RobotGoals

if TYPE_CHECKING:
    from hsi_retarget.ik import IKSolver
    from hsi_retarget.part_scene import PartPhase

__all__ = ["FingerRoomConfig", "make_finger_room"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class FingerRoomConfig:
    """How the gripper makes room for its fingers at a free-object grasp."""

    aperture: bool = True  #: [-] open the fingers only as far as the object needs (else the full stroke)
    turn: bool = True  #: [-] turn top-down grasps about the approach axis for room
    clearance: float = 0.015  #: [m] free space between each open finger and the object
    step_deg: float = 15.0  #: [deg] turn resolution over [-90, 90)
    top_down_deg: float = 30.0  #: [deg] largest tilt of the approach axis from straight down that may turn
    min_gain: float = 0.005  #: [m] least room a turn must gain where no turn keeps every margin
    turn_s: float = 1.0  #: [s] shortest easing of the turn and aperture before a grasp / after a release

    def __post_init__(self) -> None:
        if not 0.0 <= self.clearance <= 0.05:
            raise ConfigError(f"FingerRoomConfig.clearance must be in [0, 0.05] m, got {self.clearance}")
        if not 1.0 <= self.step_deg <= 90.0:
            raise ConfigError(f"FingerRoomConfig.step_deg must be in [1, 90] deg, got {self.step_deg}")
        if not 0.0 <= self.top_down_deg <= 90.0:
            raise ConfigError(
                f"FingerRoomConfig.top_down_deg must be in [0, 90] deg, got {self.top_down_deg}"
            )
        if not (self.min_gain >= 0.0 and 0.0 < self.turn_s <= 10.0):
            raise ConfigError(
                f"FingerRoomConfig: min_gain >= 0 m and turn_s in (0, 10] s, got {self.min_gain}, "
                f"{self.turn_s}"
            )


class _Hand:
    """The IK spheres of one hand (from the wrist joint outwards) in its TCP frame, per finger opening."""

    def __init__(self, solver: IKSolver, side: str) -> None:
        robot = solver.robot
        self.robot, self.side = robot, side
        model = robot.model
        self.tcp = model.getFrameId(robot.tcp_frames[side], pin.FrameType.BODY)
        self.fingers = [robot.q_index(j) for j in robot.gripper_joints[side]]
        joints = {int(model.frames[self.tcp].parentJoint)}
        joints |= {int(model.getJointId(j)) for j in robot.gripper_joints[side]}
        spheres = solver.spheres
        parents = np.array([int(model.frames[int(f)].parentJoint) for f in spheres.frame_ids])
        self.index = np.flatnonzero(np.isin(parents, sorted(joints)))
        cfg = solver.config
        self.radii = spheres.radii[self.index]
        self.margin = np.where(spheres.tips[self.index], cfg.tip_margin, cfg.scene_margin)
        self.stroke = float(robot.q_upper[self.fingers[0]])
        self._solver = solver

    def local(self, opening: float) -> F64:
        """(K, 3) [m] sphere centres in the TCP frame with each finger ``opening`` [m] from the mid-plane."""
        q = np.array(self.robot.q_home)
        q[self.fingers] = opening
        world = self._solver.sphere_centers(q)[self.index]
        frame = self.robot.tcp_frames[self.side]
        placement = self.robot.fk(q, (frame,))[frame]
        return np.asarray((world - placement[:3, 3]) @ placement[:3, :3])


def _room(hand: _Hand, local: F64, poses: Sequence[tuple[F64, Sequence[Any]]], angle: float) -> float:
    """[m] smallest sphere distance minus radius and margin over ``poses`` ((4, 4) TCP pose, scenes)
    with the gripper turned by ``angle`` [rad] about its z axis."""
    turn = Rotation.from_euler("z", angle).as_matrix()
    room = math.inf
    for pose, scenes in poses:
        world = local @ (pose[:3, :3] @ turn).T + pose[:3, 3]
        for scene in scenes:
            dist, _ = scene.query(world)
            room = min(room, float(np.min(dist - hand.radii - hand.margin)))
    return room


def _choose(rooms: F64, angles: F64, min_gain: float) -> int:
    """Index of the chosen turn: the smallest with room >= 0, else the roomiest if it gains ``min_gain``."""
    zero = int(np.argmin(np.abs(angles)))
    ok = np.flatnonzero(rooms >= 0.0)
    if ok.size:
        return int(ok[np.argmin(np.abs(angles[ok]))])
    best = int(np.argmax(rooms))
    return best if rooms[best] >= rooms[zero] + min_gain else zero


def make_finger_room(
    goals: RobotGoals,
    windows: Sequence[GraspWindow],
    objects: Mapping[str, Sequence[Any]],
    solver: IKSolver,
    *,
    part: PartPhase | None = None,
    config: FingerRoomConfig | None = None,
) -> tuple[RobotGoals, list[dict[str, Any]]]:
    """A copy of ``goals`` with room for the fingers at every free-object grasp (see the module docstring)
    and one record per grasp (``hand``, ``target``, ``time_s`` [s], ``turn_deg`` [deg], ``aperture_m``
    [m] per finger, ``room_m`` [m] before and after the turn; ``None`` where not searched or the object
    does not fit).

    ``objects``: free object name -> world primitives (:func:`~hsi_retarget.grip_turn.object_prims`);
    ``solver``: the IK solver (its robot, spheres, margins and scene); ``part``: an opened door or drawer.
    """
    cfg = config if config is not None else FingerRoomConfig()
    t = goals.t
    tcp = {s: np.array(v) for s, v in goals.tcp.items()}
    finger = {s: np.array(v) for s, v in goals.finger.items()}
    records: list[dict[str, Any]] = []
    angles = np.radians(np.arange(-90.0, 90.0 - 1e-9, cfg.step_deg))
    for side in list(tcp):
        if side not in solver.robot.gripper_joints:
            continue
        hand = _Hand(solver, side)
        opening = finger.setdefault(side, np.full(t.shape[0], np.nan))
        for grasp, release, span in grip_phases(windows, side):
            if not grasp.free or grasp.target not in objects:
                continue
            prims = objects[grasp.target]
            k = int(np.clip(np.searchsorted(t, grasp.time - 1e-9), 0, t.shape[0] - 1))
            pose = tcp[side][k]
            weight = turn_weight(t, grasp, release, span, cfg.turn_s)
            top_down = -float(pose[2, 2]) >= math.cos(math.radians(cfg.top_down_deg))
            searched = angles if cfg.turn and top_down else np.zeros(1)
            openings = np.array([_opening(prims, pose, float(a), hand.stroke, cfg) for a in searched])
            best = 0
            rooms = np.full(searched.shape[0], math.nan)
            if searched.shape[0] > 1:
                poses = [(pose, _scenes(solver, part, side, grasp.time))]
                if release is not None:
                    j = int(np.clip(np.searchsorted(t, release.time - 1e-9), 0, t.shape[0] - 1))
                    poses.append((tcp[side][j], _scenes(solver, part, side, release.time)))
                locals_: dict[float, F64] = {}
                for n, (a, w) in enumerate(zip(searched, openings, strict=True)):
                    if np.isfinite(w):
                        local = locals_.setdefault(float(w), hand.local(float(w)))
                        rooms[n] = _room(hand, local, poses, float(a))
                rooms = np.where(np.isfinite(rooms), rooms, -np.inf)
                best = _choose(rooms, searched, cfg.min_gain)
                if abs(searched[best]) > 1e-9:
                    turn = Rotation.from_rotvec(np.outer(weight * searched[best], [0.0, 0.0, 1.0]))
                    tcp[side][:, :3, :3] = tcp[side][:, :3, :3] @ turn.as_matrix()
            zero = int(np.argmin(np.abs(searched)))
            aperture = float(openings[best]) if np.isfinite(openings[best]) else hand.stroke
            records.append(
                {
                    "hand": side,
                    "target": grasp.target,
                    "time_s": grasp.time,
                    "turn_deg": float(np.degrees(searched[best])),
                    "aperture_m": aperture,
                    "room_m": [_finite(rooms[zero]), _finite(rooms[best])],
                }
            )
            if aperture < hand.stroke:
                base = np.where(np.isfinite(opening), opening, hand.stroke)
                opening[:] = np.where(weight > 0.0, base + weight * (aperture - base), opening)
    return replace(goals, tcp=tcp, finger=finger), records


def _opening(prims: Sequence[Any], pose: F64, angle: float, stroke: float, cfg: FingerRoomConfig) -> float:
    """[m] finger opening from the mid-plane for the object between the fingers after a turn by ``angle``
    [rad] about the TCP's z axis (``pose`` (4, 4)): half its extent plus the clearance (the full ``stroke``
    without ``cfg.aperture``); ``nan`` when it does not fit (less than half the clearance to spare)."""
    axis = math.cos(angle) * pose[:3, 1] - math.sin(angle) * pose[:3, 0]
    half = 0.5 * object_width(prims, np.asarray(axis))
    if half + 0.5 * cfg.clearance > stroke:
        return math.nan
    return min(half + cfg.clearance, stroke) if cfg.aperture else stroke


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _scenes(solver: IKSolver, part: PartPhase | None, side: str, time: float) -> list[Any]:
    """The distance queries the hand ``side`` keeps its margins to at ``time`` [s]."""
    scenes: list[Any] = [] if solver.scene is None else [solver.scene]
    if part is not None:
        scene, holder = part.at(time)
        if scene is not None and holder != side:
            scenes.append(scene)
    return scenes
