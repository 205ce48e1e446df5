"""Weights, limits and margins of the differential IK (:class:`~hsi_retarget.ik.IKSolver`)."""

from __future__ import annotations

from dataclasses import dataclass

from hsi_planning.errors import ConfigError


@dataclass(frozen=True)
class IKConfig:
    """Weights, limits and margins of :class:`~hsi_retarget.ik.IKSolver`."""

    position_weight: float = 1.0  #: [1/m^2] TCP position task
    orientation_weight: float = 0.01  #: [1/rad^2] TCP orientation task (position weight >> this)
    root_weight: float = 1.0  #: [1/m^2 or 1/rad^2] base / pelvis goal task
    lift_weight: float = 0.05  #: [1/m^2] torso lift goal task
    posture_weight: float = 1e-3  #: [1/rad^2] pull of the arm (and waist/leg) joints to the posture
    #: [-] TCP position / orientation weight factors at a contact (:attr:`IKTargets.contact` = 1; scaled
    #: linearly in between): the hand at a grasp wins over the other hand, the posture and the torso lift
    contact_position_factor: float = 10.0
    contact_orientation_factor: float = 30.0
    contact_root_factor: float = 1.5  #: [-] root goal weight factor there (the base follows less)
    #: [-] factor on ``root_weight`` for a floating base's roll and pitch (the pelvis goal is level):
    #: below 1 the pelvis tilts over the hips where the hands reach low and far
    root_tilt_factor: float = 0.1
    #: [-] TCP weight factor (on top of the contact factors) of a hand holding an opened door's or drawer's
    #: handle (:attr:`IKTargets.holding`): the part follows that hand, a near-closed chain
    hold_factor: float = 10.0
    damping: float = 1e-4  #: [1/rad^2] Levenberg-Marquardt damping of every step
    max_step: float = 0.05  #: [rad] or [m] largest change of one joint in one step (trust region)
    iterations: int = 200  #: [-] step limit of :meth:`~hsi_retarget.ik.IKSolver.solve`
    position_tolerance: float = 1e-4  #: [m] convergence of :meth:`~hsi_retarget.ik.IKSolver.solve`
    orientation_tolerance: float = 1e-3  #: [rad] convergence of :meth:`~hsi_retarget.ik.IKSolver.solve`
    scene_margin: float = 0.02  #: [m] clearance kept between robot spheres and the scene
    tip_margin: float = 0.005  #: [m] clearance kept between finger spheres and the scene at a contact
    #: [m] that clearance away from contacts (:attr:`IKTargets.contact` 0; linear in between): the fingers
    #: pass furniture edges with room for the execution's tracking error, and close in only at a grasp
    tip_margin_far: float = 0.015
    #: [m] that clearance on a floating-base robot (the humanoid), whose hands lag their command by 2-4 cm
    #: in MuJoCo
    tip_margin_far_floating: float = 0.035
    self_margin: float = 0.015  #: [m] clearance kept between the arms and between an arm and the body
    #: [m] more clearance from an opened door or drawer (and what rides in it) than from the rest of the
    #: scene: it stands where the holder's hand put it, off by that hand's tracking error. Without it, in
    #: dual-arm ``drawer_can/reshape/1`` a finger reaching into the drawer passed its front 7 mm off in
    #: the plan (tip margin 5 mm), the held drawer crept 1.5 mm towards it and the hand lagged 2.4 mm
    part_margin: float = 0.005
    #: [m] that clearance on a floating-base robot (the humanoid): its margins are wider already
    #: (``tip_margin_far_floating``) and its part is posed where the holder's IK took it on every frame
    #: (:mod:`hsi_retarget.part_arcs`); at 5 mm its reaches into drawers and cabinets missed (humanoid
    #: benchmark 83 -> 77%; four of the five episodes re-run at 0 succeeded again)
    part_margin_floating: float = 0.0
    #: [m] that clearance on a floating-base robot (the humanoid): its arms lag their command by 2-4 cm in
    #: MuJoCo while the pelvis and waist lean under them, and at 1.5 cm a forearm and the other upper arm,
    #: planned apart, met in the simulation (humanoid benchmark: collision-free 59 -> 66% at 3.5 cm)
    self_margin_floating: float = 0.035
    #: [m] more scene margin for a floating-base robot's body spheres (torso, pelvis, head, thighs): they
    #: lag their command by 2-3 cm in MuJoCo too (a head planned 2.7 cm from a shelf touched it)
    body_margin_floating: float = 0.02
    #: [m] beyond the margin: farther pairs get no constraint row. A row binds only when one step would
    #: close ``collision_gain`` of the gap, but a first frame's solve takes large steps: at 0.10 m (6 %
    #: faster, the same trajectories to 2e-7 rad on 6 benchmark cases) a perturbed episode's re-plan
    #: missed its grasp.
    activation_distance: float = 0.15
    collision_gain: float = 0.5  #: [-] fraction of the gap to the margin one step may close
    max_collision_rows: int = 24  #: [-] closest pairs constrained per step
    self_collision: bool = True  #: [-] constrain left/right arm and arm/body spheres
    #: [m] clearance kept between a held object's surface points and the scene
    #: (:mod:`hsi_retarget.held_object`), shrinking with the hand's contact closeness (none at the grasp
    #: and the release)
    held_margin: float = 0.01
    max_held_rows: int = 6  #: [-] closest points of one held object constrained per step
    #: [m] extra reach of the culled collision candidates, reused until a sphere moved half of it
    #: (:mod:`hsi_retarget.candidates`; the same rows, cheaper); 0: culled anew at every query
    candidate_slack: float = 0.05
    #: [-] also hold each sphere off the face plane it was inside its margin of at the step before
    #: (:mod:`hsi_retarget.face_planes`: no chatter between two faces at a furniture edge); ``None``: on
    #: for a floating base (measured there: a humanoid's head under a shelf board), off on a fixed one
    face_planes: bool | None = None

    def __post_init__(self) -> None:
        positive = ("position_weight", "orientation_weight", "max_step", "position_tolerance")
        factors = (
            self.contact_position_factor,
            self.contact_orientation_factor,
            self.contact_root_factor,
            self.hold_factor,
        )
        if not all(f >= 1.0 for f in factors):
            raise ConfigError(
                f"IKConfig.contact_*_factor (position, orientation, root), hold_factor: >= 1, got {factors}"
            )
        for name in (*positive, "orientation_tolerance", "activation_distance"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"IKConfig.{name} must be > 0, got {getattr(self, name)}")
        for name in (
            "root_weight",
            "root_tilt_factor",
            "lift_weight",
            "posture_weight",
            "damping",
            "tip_margin",
            "tip_margin_far",
            "tip_margin_far_floating",
            "scene_margin",
            "self_margin",
            "self_margin_floating",
            "body_margin_floating",
            "part_margin",
            "part_margin_floating",
            "held_margin",
            "candidate_slack",
        ):
            if not getattr(self, name) >= 0.0:
                raise ConfigError(f"IKConfig.{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 < self.collision_gain <= 1.0:
            raise ConfigError(f"IKConfig.collision_gain must be in (0, 1], got {self.collision_gain}")
        if min(self.tip_margin_far, self.tip_margin_far_floating) < self.tip_margin:
            raise ConfigError(
                f"IKConfig.tip_margin_far and tip_margin_far_floating [m] must be >= tip_margin "
                f"{self.tip_margin}, got {self.tip_margin_far} and {self.tip_margin_far_floating}"
            )
        if self.iterations < 1 or self.max_collision_rows < 0 or self.max_held_rows < 0:
            raise ConfigError("IKConfig.iterations must be >= 1, max_collision_rows and max_held_rows >= 0")
