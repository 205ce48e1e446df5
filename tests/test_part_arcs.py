"""The door or drawer as an obstacle wherever its holder's IK has taken it (hsi_retarget.part_arcs)."""

from __future__ import annotations

import numpy as np
import pytest
from test_part_scene import DRAWER, _phase, _pulled_drawer

from hsi_planning.errors import ConfigError
from hsi_planning.scene_paths import load_scene
from hsi_planning.scheduler.world import SceneWorld
from hsi_retarget.part_arcs import PartArcs
from hsi_retarget.retarget import RetargetConfig
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance
from hsi_retarget.tracking import track


def test_the_drawer_is_posed_where_the_tracked_hand_has_pulled_it_while_the_hand_holds_it() -> None:
    robot, phase, goals, solver = _pulled_drawer()  # held 1-4.8 s, pulled to 0.6 of its travel by 2 s
    qs = track(goals, robot, solver, RetargetConfig(), part=phase)[0]
    arcs = PartArcs(phase, goals.t, robot)
    world = SceneWorld(load_scene("kitchen"))
    t = goals.t
    assert arcs.at(int(np.argmax(t >= 0.5)), qs) == (None, "")  # before the grasp: not held
    assert arcs.at(int(np.argmax(t >= 4.9)), qs) == (None, "")  # let go
    for time, fraction in ((1.5, 0.3), (3.0, 0.6)):  # half way through the pull, then standing
        i = int(np.argmax(t >= time))
        scene, holder = arcs.at(i, qs)
        assert scene is not None and holder == "right"
        handle = world.handle_at(DRAWER, fraction)[None]
        assert abs(float(scene.query(handle)[0][0])) < 0.02  # the handle is where the hand took it
        farther = world.handle_at(DRAWER, fraction + 0.2)[None]
        assert float(scene.query(farther)[0][0]) > 0.03  # not as far as scheduled
    i = int(np.argmax(t >= 3.0))
    assert arcs.at(i, qs)[0] is arcs.at(i + 1, qs)[0]  # the same rounded opening: the same scene


def test_the_moving_part_is_posed_anew_when_on_and_stands_still_by_default_on_a_fixed_base() -> None:
    robot, phase, goals, solver = _pulled_drawer()
    seen: list[object] = []
    set_scene = solver.set_part_scene

    def spy(scene: SceneDistance | None, holder: str = "") -> None:
        seen.append(scene)
        set_scene(scene, holder)

    solver.set_part_scene = spy  # type: ignore[method-assign]
    track(goals, robot, solver, RetargetConfig(moving_part=True), part=phase)
    moving = {id(s) for s in seen if s is not None}
    seen.clear()
    track(goals, robot, solver, RetargetConfig(), part=phase)  # default: off on a fixed base
    standing = {id(s) for s in seen if s is not None}
    assert len(standing) == 1  # the part standing open, one pose
    assert len(moving) > 5  # posed anew as the hand pulls it


def test_a_bad_rounding_step_is_refused() -> None:
    with pytest.raises(ConfigError, match="step"):
        PartArcs(_phase(DRAWER), np.arange(10) / 24.0, RobotModel("dual_ur5e"), step=0.0)


def test_the_tracking_lists_the_part_scene_each_frame_heeded() -> None:
    robot, phase, goals, solver = _pulled_drawer()  # held 1-4.8 s, pulled to 0.6 of its travel by 2 s
    seen: list[tuple[float | None, str]] = []
    set_scene = solver.set_part_scene

    def spy(scene: SceneDistance | None, holder: str = "") -> None:
        seen.append((_probe(scene), holder))
        set_scene(scene, holder)

    for moving in (False, True):
        seen.clear()
        solver.set_part_scene = spy  # type: ignore[method-assign]
        cfg = RetargetConfig(moving_part=moving)
        _, _, _, diag = track(goals, robot, solver, cfg, part=phase, trace=True)
        del solver.set_part_scene
        layers = diag["layers"]
        assert len(layers) == goals.t.shape[0]
        assert layers[0] == (None, "")  # before the opening
        heeded = _runs([(_probe(s), h) for s, h in layers])
        assert heeded[1:] == _runs(seen) and seen[-1] == (None, "")  # the same, and cleared at the end
        held = [h for s, h in layers if s is not None]
        assert held and set(held) == {"right"}  # the holder's hand is exempt while the part is a layer
        assert len(heeded) > (5 if moving else 2)  # posed anew as the hand pulls it, or standing open
        k = int(np.argmax(goals.t >= 3.0))  # a second pass from a frame on: the frames before as traced
        again = track(goals, robot, solver, cfg, part=phase, resume=(k, diag["trace"]))[3]["layers"]
        assert all(a is b for (a, _), (b, _) in zip(again[:k], layers[:k], strict=True))
        assert [(_probe(s), h) for s, h in again] == [(_probe(s), h) for s, h in layers]


def _runs(values: list[tuple[float | None, str]]) -> list[tuple[float | None, str]]:
    return [v for k, v in enumerate(values) if k == 0 or values[k - 1] != v]


def _probe(scene: SceneDistance | None) -> float | None:
    """[m] the distance of a point in front of the drawer unit to ``scene``, rounded to 0.1 mm."""
    if scene is None:
        return None
    return round(float(scene.query(np.array([[0.5, -0.3, 0.75]]))[0][0]), 4)
