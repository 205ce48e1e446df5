"""Human palm contacts -> gripper grasps: TCP goals around the grasps and releases of a schedule.

The planners place a grasp's wrist ``palm_offset`` [m] beyond the object's box along the approach axis
(the palm touches the object; :func:`hsi_planning.scheduler.reach_planner.contact_from_points`), and the
retargeter maps the wrist onto the robot's TCP one to one (``MappingConfig(anchor="world")``). A parallel
gripper has to close *around* the object and holds it rigidly, so around every grasp and release
(:class:`~hsi_retarget.grasp_windows.GraspWindow`, from :func:`~hsi_retarget.grasp_windows.grasp_windows`)
:func:`shape_grasps` rewrites the wrist goals of a :class:`~hsi_retarget.human_motion.HumanMotion`:

- **depth**: while a free object is held the TCP goal is ``offset = palm_offset + grasp_depth`` further
  along the planned wrist's x axis (the approach direction; the TCP's z axis): the planned grasp point,
  which the held object follows as the planner checked it. The depth ramps in over the approach and out
  over the withdrawal. Door and drawer handles get no depth (their goals are the handle bar itself).
- **straight final approach**: from where the planned wrist is ``standoff`` [m] from the contact (at least
  ``straight_min_s`` before it; before a grasp at least ``grasp_straight`` of the approach) the TCP goes
  in a straight line along the contact's approach axis into the grasp pose, in the contact orientation
  (a release starts ``place_height`` higher, so the object comes down onto its support); before that the
  planned path is shifted smoothly onto the line's start and the orientation turns smoothly to the
  contact one. A learned wrist path may come in low and from the side, or wobble in orientation near the
  object: a gripper then pushes the object away instead of closing around it.
- **straight first retreat**: the mirror image after a grasp (rising ``lift`` [m], so the object leaves
  its support) and after a release, then back onto the planned path.
- **carried orientation**: between the grasp and the release of a free object the gripper turns smoothly
  from the grasp orientation to the release orientation, both relative to the body's heading (hip yaw),
  instead of following the planned wrist rotations (a rigidly held object would swing with them; held
  fixed in the world while the body turns, it would wind the wrist up into the arm).

Times are unchanged: the shaping only moves the goals. Everything is a function of the motion samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from hsi_planning.errors import ConfigError
from hsi_retarget.easing import ease
from hsi_retarget.grasp_windows import GraspWindow
from hsi_retarget.human_motion import HumanMotion

__all__ = ["GraspDepthConfig", "shape_grasps"]

F64 = NDArray[np.float64]
_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class GraspDepthConfig:
    """How the gripper's TCP goals differ from the planned wrist goals around grasps and releases."""

    #: Wrist distance beyond the object's box used by the planners (scheduler ``palm_offset``) [m].
    palm_offset: float = 0.06
    #: Depth of the TCP inside the object's box past its near face [m].
    grasp_depth: float = 0.03
    #: Approach / withdrawal window of a grasp or release without a planned segment [s].
    ramp_s: float = 0.5
    #: Length of the straight final approach and first retreat along the approach axis; 0 = none [m].
    standoff: float = 0.08
    #: Its length for a top-down approach (within 30 deg of straight down) or placement; at least
    #: ``standoff``: the gripper comes down from above the walls of an open drawer or box [m].
    top_standoff: float = 0.2
    #: Shortest straight part (at most 60 % of its approach or withdrawal) [s].
    straight_min_s: float = 0.3
    #: Shortest straight part of a grasp approach as a share of the approach (at most 0.6) [-].
    grasp_straight: float = 0.4
    #: Rise of the first retreat after an object grasp (the object leaves its support) [m].
    lift: float = 0.02
    #: Height above the release pose where the straight final approach of a release starts [m].
    place_height: float = 0.04
    #: Height above a container's rim (:attr:`GraspWindow.rim`, an open drawer's walls) where the straight
    #: top-down approach into a grasp in it starts and its first retreat ends: the fingers below the TCP
    #: clear the rim instead of catching on it [m].
    rim_clearance: float = 0.08
    #: A carried object turns smoothly from its grasp to its release orientation (else: planned) [-].
    hold_orientation: bool = True

    def __post_init__(self) -> None:
        for name in (
            "palm_offset",
            "grasp_depth",
            "standoff",
            "top_standoff",
            "lift",
            "place_height",
            "rim_clearance",
        ):
            if not 0.0 <= getattr(self, name) <= 0.3:
                raise ConfigError(f"GraspDepthConfig.{name} must be in [0, 0.3] m, got {getattr(self, name)}")
        if not 0.0 <= self.grasp_straight <= 0.6:
            raise ConfigError(
                f"GraspDepthConfig.grasp_straight must be in [0, 0.6], got {self.grasp_straight}"
            )
        if not (self.ramp_s > 0.0 and self.straight_min_s >= 0.0):
            raise ConfigError(
                f"GraspDepthConfig: ramp_s > 0 s and straight_min_s >= 0 s, got {self.ramp_s}, "
                f"{self.straight_min_s}"
            )

    @property
    def offset(self) -> float:
        """[m] full TCP offset along the wrist's x axis while an object is grasped."""
        return self.palm_offset + self.grasp_depth


def _between(t: F64, t0: float, t1: float) -> NDArray[np.bool_]:
    return np.asarray((t >= t0 - 1e-9) & (t <= t1 + 1e-9))


@dataclass(frozen=True)
class _Contact:
    """Where a window's straight part meets the contact: orientation, axis, TCP goal, split time, length."""

    rot: F64  #: (3, 3) contact orientation
    axis: F64  #: (3,) approach axis (the wrist's x)
    goal: F64  #: (3,) [m] TCP goal at the contact
    split: float  #: [s] start of the straight approach / end of the straight retreat
    length: float  #: [m] length of the straight part


class _Hand:
    """Per-sample goal edits of one hand: orientation target and its weight, depth, path shifts, lines."""

    def __init__(self, motion: HumanMotion, side: str, cfg: GraspDepthConfig) -> None:
        t, rotation = motion.t, motion.wrist_rotation[side]
        n = t.shape[0]
        self.t, self.p, self.r, self.cfg = t, motion.wrist_position[side], rotation, cfg
        self.heading = Rotation.from_euler("z", motion.hip_yaw[:, None])  #: (T,) the body's heading
        self.target = np.array(rotation)  #: (T, 3, 3) orientation the goal turns to
        self.weight = np.zeros(n)  #: (T,) share of ``target`` in the goal orientation
        self.depth = np.zeros(n)  #: (T,) [m] TCP offset along the planned wrist x axis
        self.line = np.full((n, 3), np.nan)  #: (T, 3) [m] straight-line goals (NaN: none)
        self.own_axis = np.zeros(n, dtype=bool)  #: (T,) depth along the goal's x axis, not the planned one
        self.near = np.zeros(n)  #: (T,) [0..1] closeness to a contact (:attr:`HumanMotion.contact`)
        self.shifts: list[tuple[NDArray[np.bool_], F64, int, F64]] = []  #: (samples, weight, anchor, goal)

    def index(self, time: float) -> int:
        return int(np.clip(np.searchsorted(self.t, time - 1e-9), 0, self.t.shape[0] - 1))

    def contact(self, w: GraspWindow, before: bool) -> _Contact:
        """The contact of ``w`` and the split of its approach (``before``) or withdrawal: where the planned
        wrist is ``standoff`` from the contact (the last such time before it, the first after it), kept
        ``straight_min_s`` (a grasp approach: ``grasp_straight`` of its span) from the contact and 30 % of
        the segment from its far end."""
        cfg, t = self.cfg, self.t
        i = self.index(w.time)
        rot = self.r[i]
        goal = self.p[i] + (cfg.offset if w.free else 0.0) * rot[:, 0]
        t0, t1 = w.before if before else w.after
        span = max(t1 - t0, 1e-9)
        inside = _between(t, t0, t1)
        dist = np.linalg.norm(self.p[inside] - self.p[i], axis=1)
        top = w.free and float(rot[2, 0]) < -np.cos(np.radians(30.0))  # approach straight down
        standoff = max(cfg.top_standoff, cfg.standoff) if top and cfg.standoff > 0.0 else cfg.standoff
        if top and cfg.standoff > 0.0:  # down from above the rim of an open container
            standoff = max(standoff, w.rim + cfg.rim_clearance - float(goal[2]))
        length = float(min(standoff, dist.max(initial=0.0)))
        far = t[inside][dist >= standoff - 1e-9]
        straight = min(cfg.straight_min_s, 0.6 * span)
        if before and w.kind == "grasp":  # a gripper needs a longer straight approach than a human hand
            straight = min(max(straight, cfg.grasp_straight * span), 0.6 * span)
        if before:
            split = float(far.max()) if far.size else t0 + 0.3 * span
            split = float(np.clip(split, t0 + 0.3 * span, t1 - straight))
        else:
            split = float(far.min()) if far.size else t1 - 0.3 * span
            split = float(np.clip(split, t0 + straight, t1 - 0.3 * span))
        return _Contact(rot, rot[:, 0], goal, split, length)

    def orientation(self) -> F64:
        """(T, 3, 3) goal orientations: the planned ones turned by ``weight`` towards ``target``."""
        planned = Rotation.from_matrix(self.r)
        turn = (planned.inv() * Rotation.from_matrix(self.target)).as_rotvec() * self.weight[:, None]
        return np.asarray((planned * Rotation.from_rotvec(turn)).as_matrix())

    def positions(self) -> F64:
        """(T, 3) [m] TCP goals: the planned grasp point (the wrist moved by ``depth`` along its planned x
        axis, which a held object follows as planned; along the goal's own x axis on the way to a grasp),
        shifted onto the straight parts, and the lines."""
        own_x = self.orientation()[:, :, 0]
        axis = np.where(self.own_axis[:, None], own_x, self.r[:, :, 0])
        nominal = self.p + self.depth[:, None] * axis
        out = np.array(nominal)
        for mask, weight, anchor, goal in self.shifts:
            # the anchor's nominal goal by the axis rule of the shifted samples (the goal's own x axis or
            # the planned one), so that the shifted path meets ``goal`` without a jump
            ref_axis = own_x[anchor] if self.own_axis[mask].any() else self.r[anchor, :, 0]
            ref = self.p[anchor] + self.depth[anchor] * ref_axis
            out[mask] += weight[:, None] * (goal - ref)
        lined = np.isfinite(self.line[:, 0])
        out[lined] = self.line[lined]
        return out


def _approach(hand: _Hand, w: GraspWindow, held: bool) -> None:
    """Straight final approach into the contact of ``w`` with the blend onto it before."""
    cfg, t = hand.cfg, hand.t
    c = hand.contact(w, before=True)
    start, end = w.before
    up = cfg.place_height * _UP if w.kind == "release" and w.free else np.zeros(3)
    pre = c.goal - c.length * c.axis + up
    blend = _between(t, start, c.split)
    line = _between(t, c.split, end) & ~blend
    sigma = ease((t[blend] - start) / max(c.split - start, 1e-9))
    if not held:  # a carried object's orientation is set by the carry
        hand.target[blend] = c.rot
        hand.weight[blend] = np.maximum(hand.weight[blend], sigma)
    if w.free:
        hand.depth[blend] = cfg.offset if held else cfg.offset * sigma
        hand.depth[line] = cfg.offset
        hand.own_axis[blend] = not held
    hand.target[line], hand.weight[line] = c.rot, 1.0
    hand.near[blend] = np.maximum(hand.near[blend], sigma)
    hand.near[line] = 1.0
    if cfg.standoff > 0.0:
        hand.shifts.append((blend, sigma, hand.index(c.split), pre))
        u = ease((t[line] - c.split) / max(end - c.split, 1e-9))
        hand.line[line] = pre + u[:, None] * (c.goal - pre)


def _retreat(hand: _Hand, w: GraspWindow, held: bool) -> None:
    """Hold at the contact of ``w``, a straight first retreat, then the blend back onto the plan."""
    cfg, t = hand.cfg, hand.t
    c = hand.contact(w, before=False)
    start, end = w.after
    up = cfg.lift * _UP if w.kind == "grasp" and w.free else np.zeros(3)
    post = c.goal - c.length * c.axis + up
    still = _between(t, w.time, c.split)
    blend = _between(t, c.split, end) & ~still
    sigma = 1.0 - ease((t[blend] - c.split) / max(end - c.split, 1e-9))
    hand.target[still], hand.weight[still] = c.rot, 1.0
    hand.near[still] = 1.0
    hand.near[blend] = np.maximum(hand.near[blend], sigma)
    if not held:
        hand.target[blend] = c.rot
        hand.weight[blend] = np.maximum(hand.weight[blend], sigma)
    if w.free:
        hand.depth[still] = cfg.offset
        hand.depth[blend] = cfg.offset if held else cfg.offset * sigma
    if cfg.standoff > 0.0:
        hold = _between(t, w.time, start)
        hand.line[hold] = c.goal
        line = still & ~hold
        u = ease((t[line] - start) / max(c.split - start, 1e-9))
        hand.line[line] = c.goal + u[:, None] * (post - c.goal)
        hand.shifts.append((blend, sigma, hand.index(c.split), post))


def _carry(hand: _Hand, grasp: GraspWindow, release: GraspWindow | None) -> None:
    """Depth (and with ``hold_orientation`` the smoothly turning orientation) while an object is held."""
    cfg, t = hand.cfg, hand.t
    t1 = release.time if release is not None else float(t[-1])
    span = _between(t, grasp.time, t1)
    hand.depth[span] = cfg.offset
    if not cfg.hold_orientation:
        return
    picked = hand.contact(grasp, before=False)
    hand.weight[span] = 1.0
    if release is None:
        relative = hand.heading[hand.index(grasp.time)].inv() * Rotation.from_matrix(picked.rot)
        hand.target[span] = (hand.heading[span] * relative).as_matrix()
        return
    placed = hand.contact(release, before=True)
    a = min(picked.split, t1)
    b = max(min(placed.split, t1), a)
    ends = [
        hand.heading[hand.index(w.time)].inv() * Rotation.from_matrix(c.rot)
        for w, c in ((grasp, picked), (release, placed))
    ]
    slerp = Slerp([0.0, 1.0], Rotation.concatenate(ends))  # relative to the heading: turns with the body
    relative = slerp(ease((t[span] - a) / max(b - a, 1e-9)))
    hand.target[span] = (hand.heading[span] * relative).as_matrix()


def shape_grasps(
    motion: HumanMotion, windows: Sequence[GraspWindow], config: GraspDepthConfig | None = None
) -> HumanMotion:
    """A copy of ``motion`` whose wrist goals around ``windows`` are gripper goals (see the module
    docstring), with :attr:`HumanMotion.contact` set around them; samples away from every window are
    unchanged."""
    cfg = config if config is not None else GraspDepthConfig()
    positions = dict(motion.wrist_position)
    rotations = dict(motion.wrist_rotation)
    contact = dict(motion.contact)
    for side in motion.wrist_position:
        own = sorted((w for w in windows if w.hand == side), key=lambda w: w.time)
        if not own:
            continue
        hand = _Hand(motion, side, cfg)
        for i, w in enumerate(own):
            nxt = next((v for v in own[i + 1 :] if v.target == w.target and v.kind == "release"), None)
            if w.kind == "grasp" and w.free:
                _carry(hand, w, nxt)
            elif w.kind == "grasp":  # a door or drawer held: its handle moves along a fixed path
                hand.near[_between(hand.t, w.time, nxt.time if nxt is not None else w.time)] = 1.0
        for w in own:
            carried = w.free and cfg.hold_orientation
            if w.kind == "grasp" or w.free:
                _approach(hand, w, carried and w.kind == "release")
            if w.kind == "release" or w.free:
                _retreat(hand, w, carried and w.kind == "grasp")
        rotations[side] = hand.orientation()
        positions[side] = hand.positions()
        contact[side] = np.maximum(hand.near, contact.get(side, 0.0))
    return replace(motion, wrist_position=positions, wrist_rotation=rotations, contact=contact)
