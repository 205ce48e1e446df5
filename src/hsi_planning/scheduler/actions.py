"""The state of a schedule being built (:class:`TaskRun`): world state, timeline, the floor map and
torso-clearance points of the current state, stances, and walking.

:meth:`TaskRun.go_to` stands up if crouched, walks the fast-marching root path (Eq. 23) — or side-steps
in one move while a hand holds a door — then turns and takes the stance's posture. The actions that use
it live in :mod:`.articulation` (doors, drawers) and :mod:`.handling` (grasp, place).
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from hsi_planning.planning import Planner
from hsi_planning.scheduler.body import HipPose
from hsi_planning.scheduler.config import SchedulerConfig
from hsi_planning.scheduler.navigation import FloorMap, plan_root_path, resample_path
from hsi_planning.scheduler.stance import StanceTarget, choose_stance
from hsi_planning.scheduler.timeline import Timeline
from hsi_planning.scheduler.world import SceneWorld, WorldState
from hsi_planning.trajectory import Hand

_LOG = logging.getLogger(__name__)
F64 = NDArray[np.float64]
_UP = np.array([0.0, 0.0, 1.0])


@dataclass
class TaskRun:
    """The state of one schedule being built: world state, timeline, held objects' shapes."""

    world: SceneWorld
    planner: Planner
    config: SchedulerConfig
    timeline: Timeline
    state: WorldState
    shapes: dict[str, F64] = field(default_factory=dict)  #: held object -> points relative to its bottom
    #: (part, hand) -> the stances along its opening
    arcs: dict[tuple[str, str], list[HipPose]] = field(default_factory=dict)
    #: two-handed object -> (approach axes, contacts relative to its bottom centre [m]) of its grip
    grips: dict[str, tuple[dict[Hand, F64], dict[Hand, F64]]] = field(default_factory=dict)

    # ------------------------------------------------------------------------------ geometry

    def floor(self, segments: Sequence[F64] = (), state: WorldState | None = None) -> FloorMap:
        cloud = self.world.state_cloud(state or self.state)
        keep = [self.timeline.hip.xy, np.asarray(self.config.start_xy, dtype=np.float64)]
        base = FloorMap.from_points(cloud.points, self.config.navigation, keep)
        walls = self.world.wall_segments() if self.config.walls_behind else []
        extra = [*walls, *segments]
        return base.with_segments(extra) if extra else base

    def tree(self) -> cKDTree:
        cloud = self.world.state_cloud(self.state)
        names = cloud.label_names or {}
        floor = [k for k, v in names.items() if v == "floor"]
        return cKDTree(cloud.points[~np.isin(cloud.labels, floor)])

    def holds(self, exclude: Sequence[Hand] = ()) -> list[StanceTarget]:
        """Wrists fixed on a furniture part (holding a door) that the next stance must still reach."""
        return [
            StanceTarget(h, self.timeline.position(h))
            for h, w in self.timeline.wrists.items()
            if w.contact and w.mode == "world" and h not in exclude
        ]

    def stance(self, targets: list[StanceTarget], floor: FloorMap, step: bool = False) -> HipPose:
        """The stance for ``targets``; ``step``: reachable by one straight clear step from the root."""
        here, radius = self.timeline.hip.xy, self.config.body.body_radius

        def clear_step(pose: HipPose) -> bool:
            return floor.segment_clear(here, pose.xy, radius)

        body, wrists = self.config.body, self.timeline.wrists
        resting = [  # a carried object's size is room the wrist needs besides its own
            (h, body.carry_offset, self._size(w.holding))
            if w.mode == "carry"
            else (h, body.ready_offset, 0.0)
            for h, w in wrists.items()
            if w.mode == "ready" or (w.mode == "carry" and w.carry_local is None)
        ]
        return choose_stance(
            targets,
            floor,
            self.tree(),
            body,
            self.config.stance,
            near=here,
            accept=clear_step if step else None,
            resting=resting,
        )

    def _size(self, obj: str) -> float:
        """[m] the largest extent of held ``obj``'s points (0 when its shape is unknown)."""
        shape = self.shapes.get(obj)
        return float(np.ptp(shape, axis=0).max()) if shape is not None and len(shape) else 0.0

    def move_time(self, a: F64, b: F64, speed: float | None = None) -> float:
        dist = float(np.linalg.norm(np.asarray(b) - np.asarray(a)))
        return max(self.config.min_move_time, dist / (speed or self.config.hand_speed))

    # ------------------------------------------------------------------------------ navigation

    def go_to(self, stance: HipPose, floor: FloorMap, why: str) -> None:
        """Walk (fast marching, Eq. 23) to ``stance`` and take its heading and posture."""
        tl, nav, body = self.timeline, self.config.navigation, self.config.body
        start = tl.hip
        holding_part = any(w.contact and w.mode == "world" for w in tl.wrists.values())
        if holding_part and floor.segment_clear(start.xy, stance.xy, body.body_radius):
            # a side step while a hand keeps holding a door: one move, the hand stays on the handle
            if np.linalg.norm(stance.xy - start.xy) > 0.02:
                tl.step(f"step to ({stance.xy[0]:.2f}, {stance.xy[1]:.2f}) m for {why}, still holding")
        elif np.linalg.norm(stance.xy - start.xy) > 0.02:
            if np.linalg.norm(stance.xy - start.xy) < nav.side_step_length and floor.segment_clear(
                start.xy, stance.xy, body.body_radius
            ):  # a few steps straight there (the fast-marching path may loop round to arrive facing ahead)
                path = np.vstack([start.xy, stance.xy])
            else:
                path = plan_root_path(
                    floor, start.xy, stance.xy, stance.heading, radius=body.body_radius, config=nav
                )
            if abs(start.position[2] - body.standing_height) > 1e-6 or abs(start.pitch) > 1e-6:
                up = HipPose.standing(start.xy, start.yaw, body)
                tl.move_hip(up, self._posture_time(start, up), "navigate")
            points = resample_path(path, nav.keyframe_spacing)
            short = _length(path) < nav.side_step_length
            for i, (a, b) in enumerate(itertools.pairwise(points)):
                if short:  # a few side/back steps: turn gradually towards the stance's heading
                    yaw = tl.hip.yaw + _wrap(stance.yaw - tl.hip.yaw) / (len(points) - 1 - i)
                else:
                    yaw = math.atan2(float(b[1] - a[1]), float(b[0] - a[0]))
                turn = abs(_wrap(yaw - tl.hip.yaw)) / nav.turn_speed
                tl.move_hip(
                    HipPose.standing(b, yaw, body),
                    float(np.linalg.norm(b - a)) / nav.walk_speed + turn,
                    "navigate",
                )
            tl.step(
                f"navigate to ({stance.xy[0]:.2f}, {stance.xy[1]:.2f}) m for {why}, "
                f"path {_length(path):.2f} m"
            )
        if (
            np.linalg.norm(stance.position - tl.hip.position) > 1e-6
            or abs(_wrap(stance.yaw - tl.hip.yaw)) > 1e-6
            or abs(stance.pitch - tl.hip.pitch) > 1e-6
        ):
            tl.move_hip(stance, self._posture_time(tl.hip, stance), "navigate")

    def _posture_time(self, a: HipPose, b: HipPose) -> float:
        c, nav = self.config, self.config.navigation
        return float(
            max(
                c.min_move_time,
                abs(b.position[2] - a.position[2]) / c.posture_speed,
                abs(_wrap(b.yaw - a.yaw)) / nav.turn_speed,
                float(np.linalg.norm(b.xy - a.xy)) / nav.walk_speed,
            )
        )


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _length(path: F64) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
