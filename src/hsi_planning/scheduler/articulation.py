"""Opening and closing doors and drawers: the handle moves along the door's arc (or the drawer's slide) in
``door_steps`` keyframes while the body takes, for each, a stance that reaches the handle and stays clear
of the door leaf swept between the previous and the current angle (the person steps back as a door swings
towards them), each one straight clear step from the previous. Closing retraces the opening's stances
in reverse (or new ones for the other hand). A hand may keep holding an opened part (co-temporal).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import PlanningError
from hsi_planning.scene.furniture import opening_direction
from hsi_planning.scheduler.actions import TaskRun
from hsi_planning.scheduler.body import HipPose, wrist_quaternion
from hsi_planning.scheduler.navigation import FloorMap
from hsi_planning.scheduler.schedule import ContactEvent
from hsi_planning.scheduler.stance import StanceTarget, choose_stance
from hsi_planning.trajectory import Hand

F64 = NDArray[np.float64]


def _handle_quat(run: TaskRun, part: str, fraction: float) -> F64:
    info = run.world.part(part)
    inward = -opening_direction(run.world.spec.furniture_by_name(info.furniture))
    rot = run.world.part_transform(part, fraction)[:3, :3]
    return wrist_quaternion(rot @ inward)


def _arc_floor(run: TaskRun, part: str, f0: float, f1: float) -> FloorMap:
    """Floor map while ``part`` moves from ``f0`` to ``f1``: a door's leaf swept between the two
    angles (on the map without the door), a drawer pulled out."""
    if run.world.part(part).kind == "slide":
        return run.floor(state=run.state.with_opened(part, True))
    sweep = np.linspace(f0, f1, 4)
    return run.floor([run.world.door_panel(part, f) for f in sweep], state=run.state.with_opened(part, False))


def _arc_stances(run: TaskRun, part: str, hand: Hand, steps: int) -> list[HipPose]:
    """Stances for the handle at opening fractions 0, 1/steps, ..., 1: each clear of the leaf's sweep
    from the previous fraction and one straight clear step from the previous stance. The search starts
    near the current root, then near earlier arcs of this part, then near the start position."""
    anchors = [run.timeline.hip.xy, *(v[0].xy for k, v in run.arcs.items() if k[0] == part)]
    anchors.append(np.asarray(run.config.start_xy, dtype=np.float64))
    errors: list[str] = []
    for anchor in anchors:
        try:
            return _arc_from(run, part, hand, steps, anchor)
        except PlanningError as exc:
            errors.append(str(exc))
    raise PlanningError(errors[0])


def _arc_from(run: TaskRun, part: str, hand: Hand, steps: int, anchor: F64) -> list[HipPose]:
    info = run.world.part(part)
    fractions = np.linspace(0.0, 1.0, steps + 1)
    holds = run.holds(exclude=(hand,))
    tree, body = run.tree(), run.config.body
    out: list[HipPose] = []
    for k, f in enumerate(fractions):
        floor = _arc_floor(run, part, float(fractions[max(k - 1, 0)]), float(fractions[max(k, 1)]))
        near = out[-1].xy if out else anchor

        def clear_step(pose: HipPose, floor: FloorMap = floor, near: F64 = near) -> bool:
            return floor.segment_clear(near, pose.xy, body.body_radius)

        targets = [StanceTarget(hand, run.world.handle_at(part, float(f))), *holds]
        try:
            out.append(
                choose_stance(
                    targets,
                    floor,
                    tree,
                    body,
                    run.config.stance,
                    near=near,
                    accept=clear_step if out else None,
                )
            )
        except PlanningError as exc:
            thing = "door" if info.kind == "hinge" else "drawer"
            raise PlanningError(
                f"moving {part} with the {hand} hand: no stance at {f:.0%} of its opening while the "
                f"{thing} moves: {exc}"
            ) from exc
    return out


def _arc(
    run: TaskRun, part: str, hand: Hand, fractions: Sequence[float], *, stances: Sequence[HipPose], verb: str
) -> None:
    """Move the held handle through ``fractions``, the body through the matching ``stances``."""
    tl = run.timeline
    for k in range(1, len(fractions)):
        handle = run.world.handle_at(part, fractions[k])
        duration = max(
            run.move_time(tl.position(hand), handle, run.config.door_speed),
            run._posture_time(tl.hip, stances[k]),
        )
        event: ContactEvent = ("pull" if verb == "open" else "push") if k == 1 else ""
        tl.move(
            duration,
            verb,
            hip=stances[k],
            wrists={hand: (handle, _handle_quat(run, part, fractions[k]))},
            acting={hand: (verb, event, part)},
        )


def _take_handle(run: TaskRun, part: str, hand: Hand, fraction: float, stance: HipPose) -> None:
    """Go to ``stance`` and grasp the handle of ``part`` opened to ``fraction``."""
    tl = run.timeline
    if tl.wrists[hand].contact != part:
        run.go_to(stance, run.floor(), f"the handle of {part}")
        handle = run.world.handle_at(part, fraction)
        tl.move(
            run.move_time(tl.position(hand), handle),
            "reach",
            wrists={hand: (handle, _handle_quat(run, part, fraction))},
            acting={hand: ("reach", "grasp", part)},
        )
        tl.wrists[hand].contact = part
    else:
        run.go_to(stance, run.floor(), f"closing {part}")


def _let_go(run: TaskRun, hand: Hand, part: str) -> None:
    tl = run.timeline
    tl.hold(run.config.release_time, "release", {hand: ("release", "release", part)})
    tl.wrists[hand].contact = ""
    tl.attach([hand], tl.attach_time([hand], run.config.hand_speed, run.config.min_move_time), "idle")


def _steps(run: TaskRun, part: str) -> int:
    return run.config.door_steps if run.world.part(part).kind == "hinge" else 2


def open_part(run: TaskRun, part: str, hand: Hand, hold: bool) -> None:
    """Open ``part`` with ``hand``; keep holding it when ``hold`` (co-temporal)."""
    steps = _steps(run, part)
    stances = _arc_stances(run, part, hand, steps)
    _take_handle(run, part, hand, 0.0, stances[0])
    _arc(run, part, hand, np.linspace(0.0, 1.0, steps + 1).tolist(), stances=stances, verb="open")
    run.arcs[(part, hand)] = stances
    run.state = run.state.with_opened(part, True)
    run.timeline.step(f"open {part} with the {hand} hand" + (" and hold it" if hold else ""))
    if not hold:
        _let_go(run, hand, part)


def close_part(run: TaskRun, part: str, hand: Hand) -> None:
    """Close ``part`` with ``hand``: the opening's stances in reverse (the hand's own, or new ones)."""
    steps = _steps(run, part)
    stances = run.arcs.get((part, hand)) or _arc_stances(run, part, hand, steps)
    back = stances[::-1]
    _take_handle(run, part, hand, 1.0, back[0])
    _arc(run, part, hand, np.linspace(1.0, 0.0, steps + 1).tolist(), stances=back, verb="close")
    run.state = run.state.with_opened(part, False)
    run.timeline.step(f"close {part} with the {hand} hand")
    _let_go(run, hand, part)
