"""The door or drawer while its holder has hold of the handle, where the holder's IK has put it.

:class:`~hsi_retarget.part_scene.PartPhase` puts the opened part back into the IK's scene only while it
stands open as scheduled (from the end of its opening arc to the start of its closing arc), at one
opening. In MuJoCo, though, the part goes wherever the holder's hand takes it for as long as the hand has
hold of the handle: through the opening and closing arcs, and wherever the hand drifts in between. The
rest of the robot did not see it there: in humanoid ``cabinet_bottle/reshape/2`` a sole stood in the
swinging door's way and touched its panel in MuJoCo. :attr:`~hsi_retarget.retarget.RetargetConfig.moving_part`
switches this on (by default on a floating base only: on the dual arm the reaching arm kept clear of the
opening door and missed a bottle it had reached before).

:class:`PartArcs` poses the part, on every frame from the holder's grasp of the handle
(:attr:`~PartPhase.t_grasp`) to its release (:attr:`~PartPhase.t_release`; without one, as long as the
part stands open in :class:`PartPhase`), as far open as the holder's tracked TCP had taken it by the frame
before (:meth:`PartPhase.reached` between the TCP at the grasp and there), rounded to ``step`` so that a
few posed scenes serve many frames. The holder's gripper and fingers stay exempt, as while the part stands
open.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError
from hsi_retarget.part_scene import HandleArc, PartPhase
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance

__all__ = ["PartArcs"]

F64 = NDArray[np.float64]


class PartArcs:
    """The part of ``part`` posed where its holder takes it (see the module docstring), at frame times
    ``t`` (T,) [s] of ``robot``'s tracking; ``step`` [-]: openings are rounded to multiples of it."""

    def __init__(self, part: PartPhase, t: F64, robot: RobotModel, step: float = 0.01) -> None:
        if not 0.0 < step <= 0.5:
            raise ConfigError(f"PartArcs.step must be in (0, 0.5] (a fraction of the opening), got {step}")
        self.part = part  #: the phase whose meshes and motion pose the part
        self.step = float(step)  #: [-] openings are rounded to multiples of this
        #: [s] the holder lets go of the handle (without a release keyframe: the part stands open until then)
        self.t_end = part.t_release if math.isfinite(part.t_release) else min(part.t_free, part.t_close)
        self._t = np.array(t, dtype=np.float64)
        self._robot = robot
        self._frame = robot.tcp_frames.get(part.holder) if part.holder else None
        self._grasp = int(np.searchsorted(self._t, part.t_grasp, side="right")) - 1
        self._arc: tuple[bytes, HandleArc] | None = None  # (configuration at the grasp, its TCP's arc)
        self._posed: dict[int, SceneDistance] = {}

    def holding(self, time: float) -> bool:
        """Whether the holder has hold of the handle at ``time`` [s]."""
        return self.part.t_grasp < time < self.t_end

    def at(self, i: int, qs: F64) -> tuple[SceneDistance | None, str]:
        """The scene of the part at frame ``i`` and its exempt hand, posed from the tracked configurations
        ``qs`` (T, nq) of the frames before ``i`` (``(None, '')`` while the holder does not hold it,
        without a holder TCP, meshes or motion, or before the grasp frame)."""
        part, frame = self.part, self._frame
        if frame is None or part.meshes is None or part.motion is None:
            return None, ""
        if not self.holding(float(self._t[i])) or not 0 <= self._grasp <= i - 1 < qs.shape[0]:
            return None, ""
        start = qs[self._grasp]
        if self._arc is None or self._arc[0] != start.tobytes():
            at_grasp = self._robot.fk(start, (frame,))[frame][:3, 3]
            self._arc = (start.tobytes(), HandleArc(part.motion, at_grasp))
        now = self._robot.fk(qs[i - 1], (frame,))[frame][:3, 3]
        opening = self._arc[1].nearest(now) if np.isfinite(now).all() else part.fraction
        key = round(opening / self.step)
        scene = self._posed.get(key)
        if scene is None:
            scene = self._posed[key] = part.posed(min(key * self.step, 1.0)).scene
        return scene, part.holder
