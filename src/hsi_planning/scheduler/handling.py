"""Grasping and placing: a stance, then the planner's segments (one hand, or two moving rigidly together).

- :func:`grasp`: the **planner's** approach (reach → grasp) and leave (take out); the carrying hands then
  move to the body's carry pose;
- :func:`place`: the planner's place approach (→ release) and withdrawal; the hands return to the ready
  pose.

A two-handed object is approached along opposite horizontal axes across the body (turned by up to ±60°
to where both insertions stay clearest); each hand plans against its own side of the object and the
carried segment is the right hand's, the left hand following it at a fixed offset.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation, Slerp

from hsi_planning.errors import PlanningError
from hsi_planning.implicit.scene_completion import ROUND_KINDS, fit_round
from hsi_planning.perception.cloud import LabelledCloud
from hsi_planning.planning import PlanRequest
from hsi_planning.scene.geometry import support_of
from hsi_planning.scene.model import support_surface
from hsi_planning.scene.objects import DEFAULTS
from hsi_planning.scheduler.actions import TaskRun
from hsi_planning.scheduler.auxiliary import FRONT_RISE, approach_axis, free_pose
from hsi_planning.scheduler.reach_planner import contact_from_points
from hsi_planning.scheduler.schedule import ContactEvent
from hsi_planning.scheduler.stance import StanceTarget
from hsi_planning.scheduler.world import WorldState, label_points
from hsi_planning.trajectory import Action, Hand, WristTrajectory

F64 = NDArray[np.float64]
_UP = np.array([0.0, 0.0, 1.0])
#: [m] room beyond the retreat's rise that a held object needs under the board above it to rise in place
_TALL_ROOM = 0.02
#: [m] how far the bottom of an object taken out from above clears the highest point of its container
_RIM_ROOM = 0.05
#: [m] points of a round object farther than this outside its fitted cylinder are a protrusion (handle).
_HANDLE_GAP = 0.01
#: [-] fraction of 10-degree sectors around a round object's fitted axis its points must cover for the
#: fitted axis to be its centre (a short arc seen past a door or a blocker fits poorly)
_ROUND_COVERAGE = 0.6


def bottom_centre(points: F64, kind: str = "") -> F64:
    """(3,) [m] bottom centre of a point set's box; for a round object class ``kind`` (mug, can, bottle, ...)
    without the points off the upright cylinder fitted to it (a mug's handle does not shift the centre), and
    on that cylinder's axis when the points go around most of it (:data:`_ROUND_COVERAGE`)."""
    centre = None
    if kind in ROUND_KINDS and len(points) >= 8:
        centre, radius = fit_round(points, DEFAULTS[kind].size[0])
        rel = points[:, :2] - centre
        body = np.linalg.norm(rel, axis=1) <= radius + _HANDLE_GAP
        if body.sum() >= 0.6 * len(points):
            points, rel = points[body], rel[body]
        bins = np.floor((np.arctan2(rel[:, 1], rel[:, 0]) + np.pi) / (2.0 * np.pi) * 36.0).astype(int)
        if np.unique(np.clip(bins, 0, 35)).size < _ROUND_COVERAGE * 36:  # a short arc: the box is safer
            centre = None
    lo, hi = points.min(axis=0), points.max(axis=0)
    out = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]])
    if centre is not None:
        out[:2] = centre
    return out


def _retimed(tr: WristTrajectory, duration: float) -> WristTrajectory:
    return dataclasses.replace(tr, t=tr.t * (duration / tr.duration))


def _follower(
    lead: WristTrajectory, hand: Hand, offsets: tuple[F64, F64], quaternions: tuple[F64, F64]
) -> WristTrajectory:
    """The other hand of a rigid two-handed carry: ``lead`` plus an offset (3,) [m] that turns about the
    vertical from ``offsets[0]`` to ``offsets[1]`` (same length when both come from one grip), and an
    orientation slerped between ``quaternions``, both with the lead's minimum-jerk time phase."""
    tau = (lead.t - lead.t[0]) / max(lead.duration, 1e-12)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    a, b = offsets
    ang_a, ang_b = math.atan2(a[1], a[0]), math.atan2(b[1], b[0])
    ang = ang_a + s * ((ang_b - ang_a + math.pi) % (2.0 * math.pi) - math.pi)
    radius = (1.0 - s) * math.hypot(a[0], a[1]) + s * math.hypot(b[0], b[1])
    offset = np.column_stack([radius * np.cos(ang), radius * np.sin(ang), (1.0 - s) * a[2] + s * b[2]])
    rot = Slerp([0.0, 1.0], Rotation.from_quat(np.vstack(quaternions)))(s)
    return WristTrajectory(
        t=lead.t,
        position=lead.position + offset,
        quaternion=np.asarray(rot.as_quat(), dtype=np.float64),
        hand=hand,
        action=lead.action,
        segment=lead.segment,
        contact_index=lead.contact_index,
        planner=lead.planner,
        object_name=lead.object_name,
    )


def _side_of(cloud: LabelledCloud, obj: str, axis: F64, share: float = 0.35) -> LabelledCloud:
    """``cloud`` with only the part of ``obj`` facing ``axis`` (3,): its points within ``share`` of its
    extent from its face along ``axis`` (the rest of ``obj`` dropped)."""
    names = cloud.label_names or {}
    ids = [k for k, v in names.items() if v == obj]
    mine = np.isin(cloud.labels, ids)
    along = cloud.points @ axis
    top, bottom = float(along[mine].max()), float(along[mine].min())
    drop = mine & (along < top - share * (top - bottom))
    return cloud.select(~drop)


def _axes(
    run: TaskRun, axis: F64, pts: F64, hands: tuple[Hand, ...], *, cloud: LabelledCloud, obj: str
) -> dict[Hand, F64]:
    """Approach axes: ``axis`` for one hand; for two, opposite horizontal axes across the body's
    forward direction, turned by up to ±60° to where both hands' insertions stay clearest."""
    if len(hands) == 1:
        return {hands[0]: axis}
    fwd = pts.mean(axis=0)[:2] - run.timeline.hip.xy
    if abs(axis[2]) < 0.9:
        fwd = -axis[:2]
    base = math.atan2(float(fwd[1]), float(fwd[0])) + 0.5 * math.pi
    names = cloud.label_names or {}
    own = [k for k, v in names.items() if v == obj]
    tree = cKDTree(cloud.points[~np.isin(cloud.labels, own)])
    palm, need = run.config.auxiliary.palm_offset, run.config.auxiliary.hand_radius + 0.03
    best: tuple[float, dict[Hand, F64]] = (-math.inf, {})
    for turn in (0.0, 30.0, -30.0, 60.0, -60.0):
        angle = base + math.radians(turn)
        left = np.array([math.cos(angle), math.sin(angle), 0.0])
        axes: dict[Hand, F64] = {"left": left, "right": -left}
        clear = math.inf
        for a in axes.values():
            contact = contact_from_points(pts, a, palm)[0]
            tail = contact + np.linspace(0.0, 0.15, 6)[:, None] * a
            clear = min(clear, float(tree.query(tail, k=1)[0].min()))
        if clear >= need:
            return axes
        if clear > best[0]:
            best = (clear, axes)
    return best[1]


def _retreats(
    run: TaskRun,
    contacts: dict[Hand, F64],
    axis: F64,
    support_name: str,
    *,
    held: F64 | None = None,
    cloud: LabelledCloud | None = None,
) -> dict[Hand, F64]:
    """Free wrist poses after a front or top access: out of the opening by ``retreat_clearance`` beyond
    the wrist, slightly raised. Taking out an object that cannot rise that much under the board above
    it (``held``: its points (M, 3) [m]; headroom below the rise + ``_TALL_ROOM``), beyond the deepest of
    its points instead: a tall bottle reaches deeper into the shelf than the wrist holding it by its near
    side, and only clears the board once all of it is out. Taken out from above, the object rises at
    least until its bottom is ``_RIM_ROOM`` above the highest point of its container in ``cloud`` (a
    drawer's front panel reaches higher than its walls): the hands carry it back over that rim."""
    c = run.config
    if len(contacts) == 2:
        towards = run.timeline.hip.position - np.mean(list(contacts.values()), axis=0)
        towards[2] = 0.0
        towards /= max(float(np.linalg.norm(towards)), 1e-9)
        return {h: p + c.lift_height * 2.0 * _UP + 0.15 * towards for h, p in contacts.items()}
    support = support_surface(run.world.spec, support_name)
    front = support.frame[:3, 3] + support.half_extents[0] * support.opening
    rise = c.retreat_clearance + 0.1  # [m] above the contact, of a top access
    if abs(axis[2]) > 0.9 and cloud is not None and held is not None and len(held):
        rim = label_points(cloud, [support.body])
        if len(rim):
            rise = max(rise, float(rim[:, 2].max()) + _RIM_ROOM - float(held[:, 2].min()))
    deepest = 0.0  # [m] how far behind the front the held object reaches when it cannot rise in place
    if (
        held is not None
        and len(held)
        and support.top_z + support.ceiling - float(held[:, 2].max()) < FRONT_RISE + _TALL_ROOM
    ):
        deepest = float(((front - held) @ axis).max())
    out = {}
    for h, p in contacts.items():
        if abs(axis[2]) > 0.9:
            out[h] = free_pose(p, axis, rise)
        else:
            depth = max(0.0, float((front - p) @ axis), deepest)
            out[h] = free_pose(p, axis, depth + c.retreat_clearance)
    return out


def _plan(
    run: TaskRun,
    obj: str,
    hands: tuple[Hand, ...],
    action: Action,
    *,
    axes: dict[Hand, F64],
    retreats: dict[Hand, F64],
    cloud: LabelledCloud,
) -> tuple[dict[Hand, WristTrajectory], ...]:
    """The planner's approach and leave per hand. Two hands: each plans against its own side of the
    object (the rest of the object left out, so the planner sees the part that hand holds); the carried
    segment (grasp: leave, place: approach) is the right hand's, the left hand moving rigidly with it."""
    tl = run.timeline
    results = {}
    for h in hands:
        request = PlanRequest(
            cloud=cloud if len(hands) == 1 else _side_of(cloud, obj, axes[h]),
            target=obj,
            hand=h,
            action=action,
            start_position=tl.position(h),
            start_quaternion=tl.quaternion(h),
            approach_axis=axes[h],
            retreat_position=retreats[h],
        )
        results[h] = run.planner.plan(request)
    approaches = {h: r.approach for h, r in results.items()}
    leaves = {h: r.leave for h, r in results.items()}
    if len(hands) == 2:
        free, carried = (approaches, leaves) if action == "grasp" else (leaves, approaches)
        longest = max(tr.duration for tr in free.values())
        free = {h: _retimed(tr, longest) for h, tr in free.items()}
        lead, left = carried["right"], carried["left"]
        grip = left.position[left.contact_index] - lead.position[lead.contact_index]
        grip_q = left.quaternion[left.contact_index]
        if action == "grasp":  # taking out: the grip's offset throughout
            follower = _follower(lead, "left", (grip, grip), (grip_q, grip_q))
        else:  # carrying to the place: from the hands' offset now to the grip's at the contact
            now = tl.position("left") - tl.position("right")
            follower = _follower(lead, "left", (now, grip), (tl.quaternion("left"), grip_q))
        carried = {"right": lead, "left": follower}
        approaches, leaves = (free, carried) if action == "grasp" else (carried, free)
    return approaches, leaves


def grasp(run: TaskRun, obj: str, hands: tuple[Hand, ...]) -> None:
    """Reach, grasp and take out ``obj`` with ``hands`` (planned segments)."""
    tl, c = run.timeline, run.config
    cloud = run.world.state_cloud(run.state, complete=run.world.neighbours(obj))
    pts = label_points(cloud, [obj])
    if len(pts) == 0:
        raise PlanningError(f"{obj!r} is not visible in the cloud of the current state; it cannot be grasped")
    support = support_of(run.world.spec, obj)
    axis = approach_axis(run.world, support)
    axes = _axes(run, axis, pts, hands, cloud=cloud, obj=obj)
    contacts = {h: contact_from_points(pts, a, c.auxiliary.palm_offset)[0] for h, a in axes.items()}
    retreats = _retreats(run, contacts, axis, support.name, held=pts, cloud=cloud)
    targets = [StanceTarget(h, p) for h in hands for p in (contacts[h], retreats[h])]
    floor = run.floor()
    stance = run.stance([*targets, *run.holds()], floor)
    run.go_to(stance, floor, f"grasping {obj}")
    approaches, leaves = _plan(run, obj, hands, "grasp", axes=axes, retreats=retreats, cloud=cloud)
    label = "both hands" if len(hands) == 2 else f"the {hands[0]} hand"
    tl.step(f"reach and grasp {obj} with {label}")
    tl.planned(approaches, "reach", "reach", "grasp", obj)
    tl.hold(c.grasp_time, "grasp", {h: ("grasp", "", obj) for h in hands})
    kind = run.world.spec.object_by_name(obj).kind
    bottom = bottom_centre(pts, kind)
    run.shapes[obj] = pts - bottom
    tl.carries.append({"object": obj, "hands": list(hands), "grasp": [float(v) for v in bottom]})
    run.state = run.state.with_held(obj, True)
    for h in hands:
        tl.wrists[h].holding = obj
    tl.planned(leaves, "take_out", "take_out", "", obj)
    tl.step(f"take {obj} out")
    if len(hands) == 1 and abs(axis[2]) > 0.9 and support.body in run.world.parts:
        _carry_over_rim(run, hands[0])
    if len(hands) == 2:  # carry the object in front of the body, the hands keeping their grip
        run.grips[obj] = (axes, {h: approaches[h].position[-1] - bottom_centre(pts, kind) for h in hands})
        mid = 0.5 * (tl.position("left") + tl.position("right"))
        yaw = tl.hip.yaw
        unturn = np.array(
            [[math.cos(yaw), math.sin(yaw), 0.0], [-math.sin(yaw), math.cos(yaw), 0.0], [0, 0, 1]]
        )
        centre = np.array([c.body.carry_offset[0], 0.0, c.body.carry_offset[2]])
        for h in hands:
            tl.wrists[h].carry_local = centre + unturn @ (tl.position(h) - mid)
    tl.attach(hands, tl.attach_time(hands, c.hand_speed, c.min_move_time), "carry")


def _carry_over_rim(run: TaskRun, hand: Hand) -> None:
    """The hand that took an object up out of a drawer carries it level to above its carry pose, then
    lowers it there: straight to the carry pose it would drag the object back down through the drawer's
    front panel, which it was lifted over."""
    tl, c = run.timeline, run.config
    here, carry = tl.position(hand), tl.attached(hand)
    if here[2] <= carry[2]:
        return
    over = np.array([carry[0], carry[1], here[2]])
    duration = max(c.min_move_time, float(np.linalg.norm(over - here)) / c.hand_speed)
    acting: dict[Hand, tuple[str, ContactEvent, str]] = {hand: ("carry", "", tl.wrists[hand].holding)}
    tl.move(duration, "carry", wrists={hand: (over, tl.quaternion(hand))}, acting=acting)


def place(run: TaskRun, obj: str, hands: tuple[Hand, ...], position: F64, support_name: str) -> None:
    """Put the held ``obj`` down with its bottom centre at ``position`` (3,) [m] on ``support_name``."""
    tl, c = run.timeline, run.config
    placed = run.shapes[obj] + position
    cloud = run.world.state_cloud(run.state, inject={obj: placed})
    axis = approach_axis(run.world, support_surface(run.world.spec, support_name))
    if len(hands) == 2 and obj in run.grips:  # put it down as it was gripped (same world orientation)
        axes, rel = run.grips[obj]
        contacts = {h: position + rel[h] for h in hands}
    else:
        axes = _axes(run, axis, placed, hands, cloud=cloud, obj=obj)
        contacts = {h: contact_from_points(placed, a, c.auxiliary.palm_offset)[0] for h, a in axes.items()}
    retreats = _retreats(run, contacts, axis, support_name)
    floor = run.floor()
    targets = [StanceTarget(h, p) for h in hands for p in (contacts[h], retreats[h])]
    stance = run.stance([*targets, *run.holds()], floor)
    run.go_to(stance, floor, f"placing {obj}")
    approaches, leaves = _plan(run, obj, hands, "place", axes=axes, retreats=retreats, cloud=cloud)
    tl.step(f"place {obj} on {support_name} at {np.round(position, 2).tolist()}")
    tl.planned(approaches, "place", "place", "release", obj)
    for h in hands:
        tl.wrists[h].holding = ""
        tl.wrists[h].carry_local = None
    run.grips.pop(obj, None)
    tl.hold(c.release_time, "release", {h: ("release", "", obj) for h in hands})
    open_carries = [k for k in tl.carries if k["object"] == obj and "place" not in k]
    if open_carries:
        open_carries[-1]["place"] = [float(v) for v in position]
    base = run.world.object_position(obj, WorldState(opened=run.state.opened))
    run.state = run.state.with_held(obj, False).with_moved(obj, position - base)
    run.shapes.pop(obj, None)
    tl.planned(leaves, "withdraw", "release", "", obj)
    tl.attach(hands, tl.attach_time(hands, c.hand_speed, c.min_move_time), "idle")
