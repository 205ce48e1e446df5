"""The differential IK's goals of one frame and its outcomes (:class:`~hsi_retarget.ik.IKSolver`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class IKTargets:
    """Goals of one IK frame (world frame, [m]).

    Attributes:
        tcp: side -> (4, 4) TCP goal pose (sides without a goal are free, held by the posture task).
        root: (4, 4) base floor pose (dual arm) or pelvis pose (humanoid); ``None``: free.
        lift: [m] torso lift goal; ``None``: free.
        feet: side -> (4, 4) sole poses held exactly (humanoid).
        support: feet on the floor whose soles form the CoM support polygon.
        com: (2,) [m] soft CoM goal (humanoid weight shift), ``None``: none.
        posture: (nq,) posture configuration; ``None``: the robot's home.
        contact: side -> [0..1] closeness of its TCP goal to a contact (scales its task weights up).
        holding: sides holding an opened door's or drawer's handle (their TCP weights scaled up more).
        arm: side -> ((nq,) configuration, weight [1/rad^2]): a task pulling that arm's joints towards
            the configuration's (e.g. an arm configuration found to reach a grasp,
            :mod:`hsi_retarget.arm_branch`); unlike the posture, it competes with the other tasks.
    """

    tcp: dict[str, F64] = field(default_factory=dict)
    root: F64 | None = None
    lift: float | None = None
    feet: dict[str, F64] = field(default_factory=dict)
    support: tuple[str, ...] = ("left", "right")
    com: F64 | None = None
    posture: F64 | None = None
    contact: dict[str, float] = field(default_factory=dict)
    holding: tuple[str, ...] = ()
    arm: dict[str, tuple[F64, float]] = field(default_factory=dict)


@dataclass(frozen=True)
class StepInfo:
    """Outcome of one step: QP status, fallback level (0: full, 1: relaxed rows, 2: relaxed rows and soft
    feet, 3: no rows), rows used."""

    success: bool
    fallback: int
    collision_rows: int
    min_clearance: float  #: [m] smallest sphere clearance minus its margin at the step start (inf: none)


@dataclass(frozen=True)
class IKResult:
    """Outcome of :meth:`~hsi_retarget.ik.IKSolver.solve`: configuration, residuals per side, iterations,
    convergence."""

    q: F64
    position_error: dict[str, float]  #: [m]
    orientation_error: dict[str, float]  #: [rad]
    iterations: int
    converged: bool
    fallbacks: int
