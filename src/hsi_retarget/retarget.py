"""Retargeting front: human goals (a recorded motion, a schedule, planned wrist trajectories) -> a timed
robot :class:`~hsi_retarget.joint_trajectory.JointTrajectory`.

Pipeline: source -> :class:`~hsi_retarget.mapping.HumanMotion` (:mod:`hsi_retarget.sources`) -> robot goals
(:func:`~hsi_retarget.mapping.map_to_robot`; unreachable goals flagged) -> per-frame differential IK
(:mod:`hsi_retarget.tracking`, :class:`~hsi_retarget.ik.IKSolver`; the humanoid's feet from
:func:`~hsi_retarget.humanoid_ik.plan_footsteps`; grasps the IK missed tracked again towards arm
configurations that reach them, :mod:`hsi_retarget.arm_branch`) -> time-parameterization
(:func:`~hsi_retarget.timing.time_parameterize`; stretched segments reported). The first frame is solved
to convergence from the nominal pose; every later frame takes up to ``iterations_per_frame`` steps from the
previous solution, within ``velocity_factor`` times the joint velocity limits over the source frame period
(the timing stage then enforces the true limits).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, TypeAlias, cast

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import ConfigError, RetargetError
from hsi_planning.trajectory import WristTrajectory
from hsi_retarget.arm_branch import ArmBranchConfig
from hsi_retarget.carry_correction import place_carries
from hsi_retarget.finger_room import FingerRoomConfig, make_finger_room
from hsi_retarget.grasp_depth import GraspDepthConfig, shape_grasps
from hsi_retarget.grasp_windows import GraspWindow, container_rims, grasp_windows
from hsi_retarget.grip_turn import (
    DEFAULT_OPENING,
    GripTurnConfig,
    handle_bar_axes,
    object_prims,
    turn_grips,
)
from hsi_retarget.handle_hold import HandleHold, hold_handle
from hsi_retarget.human_motion import HumanMotion
from hsi_retarget.humanoid_ik import SupportConfig
from hsi_retarget.ik import IKConfig, IKSolver
from hsi_retarget.joint_trajectory import ContactEvent, JointTrajectory
from hsi_retarget.mapping import (
    MappingConfig,
    map_to_robot,
)
from hsi_retarget.moved_target import moved_carries, shift_grasps
from hsi_retarget.part_scene import PartPhase, opened_part
from hsi_retarget.retrack import retrack_missed
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance
from hsi_retarget.smoothing import keep_clearance, smooth_joints  # noqa: F401 (smooth_joints: API)
from hsi_retarget.sources import ROTATION_CUTOFF_HZ, human_motion_from_schedule, human_motion_from_wrists
from hsi_retarget.timing import TimingConfig, time_parameterize
from hsi_retarget.tracking import tcp_errors, track

if TYPE_CHECKING:  # imported lazily: the scheduler package is heavy and not needed for recorded motion
    from hsi_planning.scheduler.schedule import Schedule

_LOG = logging.getLogger(__name__)
F64 = NDArray[np.float64]
Source: TypeAlias = "HumanMotion | Schedule | WristTrajectory | Sequence[WristTrajectory]"


@dataclass(frozen=True)
class RetargetConfig:
    """Every knob of :func:`retarget`."""

    #: Mapping; ``None``: defaults with ``anchor`` = ``world`` for plans and ``shoulder`` for recorded motion.
    mapping: MappingConfig | None = None
    ik: IKConfig = field(default_factory=IKConfig)  #: differential IK weights and margins
    timing: TimingConfig = field(default_factory=TimingConfig)  #: velocity/acceleration limit use
    support: SupportConfig = field(default_factory=SupportConfig)  #: humanoid feet and stepping
    iterations_per_frame: int = 3  #: [-] IK steps per frame after the first
    #: [rad] or [m] a frame's IK stops after a step that changed no coordinate more than this (0: never)
    settle_step: float = 1e-3
    #: [m] a frame's IK also stops after a step that leaves every TCP position error within this of the
    #: previous frame's (its first step) or improves it by less than this (a later step): the residual of
    #: the weighted tasks, which more steps would not remove; it shrinks to 0 at a contact (0: never)
    settle_position: float = 5e-4
    settle_orientation: float = 5e-3  #: [rad] the same for the TCP orientation errors
    initial_iterations: int = 200  #: [-] IK steps to converge on the first frame
    velocity_factor: float = 3.0  #: [-] per-frame step bound, multiple of v_max x frame period
    smoothing_hz: float = 8.0  #: [Hz] low-pass of the arms and the joints carrying them (smoothing); 0: none
    sample_rate: float = 60.0  #: [Hz] sampling of schedules and wrist trajectories
    #: [Hz] low-pass of a schedule's planned wrist orientations, their contact ends kept
    #: (:mod:`hsi_retarget.rotation_filter`: the learned planner's jitter); 0: as planned
    rotation_cutoff_hz: float = ROTATION_CUTOFF_HZ
    reach_tolerance: float = 0.01  #: [m] IK position residual above which a goal is reported unreached
    repair_iterations: int = 4  #: [-] extra IK steps on a frame that ends ``repair_depth`` inside a margin
    repair_depth: float = 0.005  #: [m] depth inside a collision margin that triggers the extra steps
    hip: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: hip (x [m], y [m], yaw [rad]) for wrist-only input
    #: Gripper goals around the grasps and releases of a schedule (:mod:`hsi_retarget.grasp_depth`);
    #: ``None``: the planned wrist goals as they are.
    grasp: GraspDepthConfig | None = None
    #: With ``grasp``: the gripper turned about its approach axis to grip across handle bars and the
    #: narrow side of objects (:mod:`hsi_retarget.grip_turn`; needs the scene spec).
    grip: GripTurnConfig = field(default_factory=GripTurnConfig)
    #: With ``grasp`` and a scene spec: the fingers open only as far as each free object needs, and a
    #: top-down grasp turns about its approach axis where the fingers have room
    #: (:mod:`hsi_retarget.finger_room`); ``None``: fully open, as planned.
    room: FingerRoomConfig | None = field(default_factory=FingerRoomConfig)
    #: Grasps and releases the IK missed are solved again from other arm configurations (a floating base
    #: on its footholds), and the goals tracked again pulled towards one that reaches
    #: (:mod:`hsi_retarget.arm_branch`); ``None``: off.
    arm_branch: ArmBranchConfig | None = field(default_factory=ArmBranchConfig)
    #: Carries re-aimed from the TCP pose reached at their grasp, and onto each object's placement from a
    #: schedule's record of it (:mod:`hsi_retarget.carry_correction`) [-].
    correct_carry: bool = True
    #: A grasped free object is collision geometry of its hand until its release, kept
    #: :attr:`~hsi_retarget.ik.IKConfig.held_margin` from the scene (:mod:`hsi_retarget.held_object`;
    #: needs a scene spec) [-]. ``None``: on for a floating base (the humanoid), off for a fixed one. On the
    #: humanoid's cabinet_bottle/reshape/2 the hand carrying the bottle out of the cabinet trailed its path
    #: by up to 20 cm in MuJoCo without it. On the dual arm (100 episodes, twice) it fixed such a carry
    #: (cabinet_bottle/reshape/1: the palm brushed the cabinet top) but lost as many episodes as it gained
    #: (cabinet_bottle/plain/2: the bottle never grasped); again with the part margin (2026-12-08):
    #: 86 -> 84%, +3 / -5 (drawer_mug/reshape/1 fingers against the drawer's walls).
    hold_objects: bool | None = None
    #: [m] a grasp the IK missed by more than this holds nothing (the gripper closes beside the object)
    held_reach: float = 0.05
    #: An opened door or drawer stands, as an obstacle, as far open as the holder's IK took it, not as
    #: scheduled (:meth:`~hsi_retarget.part_scene.PartPhase.reached`) [-].
    reached_part: bool = True
    #: While its holder has hold of the handle, the door or drawer is an obstacle of the rest of the robot
    #: where the holder's IK has taken it (:mod:`hsi_retarget.part_arcs`) [-]. ``None``: on for a floating
    #: base, off for a fixed one. Measured with held objects on (100 episodes per robot): the humanoid
    #: gained 6 episodes and lost 3 (a sole and the carrying hand kept off the swinging door); on the
    #: dual arm it lost cabinet_bottle/reshape/2 (the reaching arm kept clear of the opening door missed
    #: the bottle by 7.5 cm) and gained nothing.
    moving_part: bool | None = None
    #: The holder's TCP goals, while it has hold of a handle it opens, move with the part (along its arc,
    #: turning with it, sliding further open while it stands open: :mod:`hsi_retarget.handle_hold`)
    #: instead of as planned [-]. ``None``: on for a floating base, off for a fixed one (on the dual arm it
    #: lost drawer_mug/reshape/1 learned perturbed, and gained nothing, in a 100-episode run).
    hold_handle: bool | None = None

    def __post_init__(self) -> None:
        if self.iterations_per_frame < 1 or self.initial_iterations < 1 or self.repair_iterations < 0:
            raise ConfigError(
                "RetargetConfig.iterations_per_frame and initial_iterations must be >= 1, "
                "repair_iterations >= 0"
            )
        if not 0.0 <= self.settle_step < 0.05:
            raise ConfigError(f"RetargetConfig.settle_step must be in [0, 0.05), got {self.settle_step}")
        if not (self.settle_position >= 0.0 and self.settle_orientation >= 0.0):
            raise ConfigError(
                "RetargetConfig.settle_position [m] and settle_orientation [rad] must be >= 0, got "
                f"{self.settle_position}, {self.settle_orientation}"
            )
        if not 0.0 <= self.repair_depth < 0.1:
            raise ConfigError(f"RetargetConfig.repair_depth must be in [0, 0.1) m, got {self.repair_depth}")
        if not self.smoothing_hz >= 0.0:
            raise ConfigError(f"RetargetConfig.smoothing_hz must be >= 0 Hz, got {self.smoothing_hz}")
        if not self.rotation_cutoff_hz >= 0.0:
            raise ConfigError(
                f"RetargetConfig.rotation_cutoff_hz must be >= 0 Hz (0: none), got {self.rotation_cutoff_hz}"
            )
        positive = (self.velocity_factor, self.sample_rate, self.reach_tolerance, self.held_reach)
        if not all(v > 0.0 for v in positive):
            raise ConfigError(
                "RetargetConfig.velocity_factor, sample_rate [Hz], reach_tolerance [m], held_reach [m] "
                f"must be > 0, got {positive}"
            )


def _free_objects(scene: Any, motion: HumanMotion) -> list[str]:
    """Names of the free objects: the scene spec's, else the event targets that are no furniture part."""
    objects = getattr(scene, "objects", None)
    if objects is not None:
        return [str(o.name) for o in objects]
    return sorted({e.object_name for e in motion.events if e.object_name and "/" not in e.object_name})


def _human_motion(
    source: Source, cfg: RetargetConfig, scene: Any = None, moved: Mapping[str, Any] | None = None
) -> tuple[HumanMotion, list[dict[str, Any]], list[GraspWindow], list[dict[str, Any]]]:
    """The human goals of ``source`` (a schedule's with gripper goals around its grasps when
    ``cfg.grasp`` is set, turned to grip across, :mod:`hsi_retarget.grip_turn`, the grasps of ``moved``
    objects re-aimed, :mod:`hsi_retarget.moved_target`), the grasps turned, the grasp windows (empty
    unless shaped) and the grasps re-aimed."""
    is_schedule = hasattr(source, "keyframes") and hasattr(source, "segments")
    if moved and (cfg.grasp is None or not is_schedule):
        raise RetargetError(
            "moved objects are re-aimed in a schedule's grasps: give a Schedule and config.grasp"
        )
    if isinstance(source, HumanMotion):
        return source, [], [], []
    if hasattr(source, "keyframes") and hasattr(source, "segments"):  # a Schedule
        schedule = cast("Schedule", source)
        motion = human_motion_from_schedule(schedule, cfg.sample_rate, cfg.rotation_cutoff_hz)
        turns: list[dict[str, Any]] = []
        windows: list[GraspWindow] = []
        shifted: list[dict[str, Any]] = []
        if cfg.grasp is not None:
            windows = grasp_windows(schedule, _free_objects(scene, motion), cfg.grasp, container_rims(scene))
            if hasattr(scene, "furniture"):  # a scene spec: its handle bars and object shapes
                bars, prims = handle_bar_axes(scene), object_prims(scene)
                motion, turns = turn_grips(motion, windows, bars, prims, cfg.grip)
            if moved:
                motion, shifted = shift_grasps(motion, windows, moved)
            motion = shape_grasps(motion, windows, cfg.grasp)
        return motion, turns, windows, shifted
    segments = [source] if isinstance(source, WristTrajectory) else list(source)
    if not all(isinstance(s, WristTrajectory) for s in segments):
        raise RetargetError("retarget() takes a HumanMotion, a Schedule or WristTrajectory segments")
    return human_motion_from_wrists(segments, cfg.hip, rate=cfg.sample_rate), [], [], []


def _object_meshes(scene: Any, motion: HumanMotion) -> dict[str, Any] | None:
    """Free object name -> its world mesh at rest, of a scene spec (``None`` without one)."""
    if not (hasattr(scene, "objects") and hasattr(scene, "furniture")):
        return None
    from hsi_planning.scene import scene_meshes

    meshes = scene_meshes(scene)
    return {n: meshes[n] for n in _free_objects(scene, motion) if n in meshes}


def _scene(scene: Any, motion: HumanMotion, source: Any) -> SceneDistance | None:
    """A distance query for ``scene`` (spec or ready), without what the task touches: the objects of the
    grasp/release events and every object or part a schedule keyframe names (doors and drawers move)."""
    if scene is None or isinstance(scene, SceneDistance):
        return scene
    touched = {e.object_name for e in motion.events if e.object_name}
    touched |= {str(k.object_name) for k in getattr(source, "keyframes", ()) if k.object_name}
    return SceneDistance.from_spec(scene, exclude=sorted(touched))


def _part_phase(source: Any, scene: Any, motion: HumanMotion, padding: float) -> PartPhase | None:
    """The opened part of a schedule in a scene spec (:func:`~hsi_retarget.part_scene.opened_part`)."""
    if not (hasattr(source, "keyframes") and hasattr(scene, "furniture") and hasattr(scene, "objects")):
        return None
    targets = tuple(sorted({e.object_name for e in motion.events if e.object_name}))
    return opened_part(cast("Schedule", source), scene, exclude=targets, padding=padding)


def _runs(mask: NDArray[np.bool_], t: F64, values: F64, side: str) -> list[dict[str, Any]]:
    padded = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    out = []
    for a, b in zip(np.flatnonzero(padded == 1), np.flatnonzero(padded == -1) - 1, strict=True):
        out.append(
            {
                "side": side,
                "t_start": float(t[a]),
                "t_end": float(t[b]),
                "max_error_m": float(values[a : b + 1].max()),
            }
        )
    return out


def retarget(
    source: Source,
    robot: RobotModel | str,
    scene: Any = None,
    config: RetargetConfig | None = None,
    *,
    moved: Mapping[str, Any] | None = None,
) -> JointTrajectory:
    """Retarget human goals onto ``robot`` (see the module docstring).

    Args:
        source: a :class:`HumanMotion` (e.g. :func:`~hsi_retarget.sources.human_motion_from_mocap`), a
            :class:`Schedule`, or planned :class:`WristTrajectory` segments.
        robot: a :class:`RobotModel` or a robot name (``dual_ur5e``/``dual_arm``, ``humanoid``).
        scene: a scene spec (its meshes become collision margins; objects named in the events are left
            out; its objects are the free ones of ``config.grasp``), a :class:`SceneDistance`, or ``None``
            (no scene margins).
        config: :class:`RetargetConfig`.
        moved: object name -> (3,) [m] its displacement since a Schedule ``source`` was planned: its grasps
            re-aimed there (:mod:`hsi_retarget.moved_target`; needs ``config.grasp``).

    Returns:
        The timed trajectory; ``meta`` reports the mapping (scale, anchor), unreachable goals (per-sample
        ``reachable`` flags and intervals), IK residuals, the IK rate [frames/s], and the time scaling.
    """
    cfg = config or RetargetConfig()
    model = robot if isinstance(robot, RobotModel) else RobotModel(robot)
    if cfg.grip.opening == 0.0:  # the robot's gripper decides which grasps turn across
        fingers = next(iter(model.gripper_joints.values()), ())
        opening = float(sum(model.q_upper[model.q_index(j)] for j in fingers))
        cfg = replace(cfg, grip=replace(cfg.grip, opening=opening or DEFAULT_OPENING))
    motion, handle_turns, windows, shifted = _human_motion(source, cfg, scene, moved)
    mapping = cfg.mapping or MappingConfig(anchor="shoulder" if motion.shoulder_position else "world")
    t0 = time.perf_counter()
    goals = map_to_robot(motion, model, mapping)
    t_map = time.perf_counter() - t0
    solver = IKSolver(model, cfg.ik, _scene(scene, motion, source), cfg.support)
    padding = cfg.ik.part_margin_floating if model.floating else cfg.ik.part_margin
    part = _part_phase(source, scene, motion, padding)
    handles: list[HandleHold] = []
    handle_holds: list[dict[str, Any]] = []
    if cfg.hold_handle if cfg.hold_handle is not None else model.floating:
        goals, handles, handle_holds = hold_handle(goals, motion.events, part)
    finger_room: list[dict[str, Any]] = []
    if cfg.room is not None and windows and hasattr(scene, "objects"):
        goals, finger_room = make_finger_room(
            goals, windows, object_prims(scene), solver, part=part, config=cfg.room
        )
    placed: list[dict[str, Any]] = []
    carry_records = getattr(source, "info", {}).get("carries", []) if cfg.correct_carry else []
    if moved and carry_records:  # a moved object is grasped where it is now
        carry_records = moved_carries(carry_records, moved)
    if carry_records:  # the planned goals may not hold each object at its release as at its grasp
        goals, placed = place_carries(goals, motion.events, carry_records)
    t1 = time.perf_counter()
    carried = motion.events if cfg.correct_carry else ()  # re-aimed from the reached grasp poses
    retrack = bool(windows)
    hold = cfg.hold_objects if cfg.hold_objects is not None else model.floating
    objects = _object_meshes(scene, motion) if hold else None
    qs, pos_track, _, diag = track(
        goals, model, solver, cfg, part=part, events=carried, trace=retrack, objects=objects, handles=handles
    )
    if retrack:  # grasps the IK missed: tracked again from arm configurations
        qs, diag = retrack_missed(
            goals,
            model,
            solver,
            cfg,
            (qs, pos_track, diag),
            part=part,
            events=carried,
            windows=windows,
            objects=objects,
            handles=handles,
        )
    goals = diag.pop("goals", goals)
    diag.pop("part", None)  # the posed part: its opening is diag["part_fraction"]
    layers = diag.pop("layers", None)  # the part scene each frame heeded
    qs, diag["smoothing_restored_frames"] = keep_clearance(
        solver, model, goals.t, qs, cfg.smoothing_hz, layers=layers
    )
    pos_err, ori_err = tcp_errors(model, goals, qs)
    t_ik = time.perf_counter() - t1
    vq, aq = np.full(model.nq, np.inf), np.full(model.nq, np.inf)
    for name in model.joint_names:
        vq[model.q_index(name)] = model.v_max[model.v_index(name)]
        aq[model.q_index(name)] = model.a_max[model.v_index(name)]
    timing = time_parameterize(goals.t, qs, vq, aq, config=cfg.timing)
    warp = np.interp
    events = tuple(
        ContactEvent(float(warp(e.time, goals.t, timing.t)), e.hand, e.kind, e.object_name)
        for e in motion.events
    )
    n = goals.t.shape[0]
    tracking: dict[str, Any] = {}
    unreached: list[dict[str, Any]] = []
    for s in goals.tcp:
        act = goals.active[s]
        pe, oe = pos_err[s][act], ori_err[s][act]
        tracking[s] = {
            "max_position_error_m": float(pe.max()) if pe.size else 0.0,
            "rms_position_error_m": float(np.sqrt(np.mean(pe**2))) if pe.size else 0.0,
            "max_orientation_error_deg": float(np.degrees(oe.max())) if oe.size else 0.0,
        }
        unreached += _runs(
            act & (np.nan_to_num(pos_err[s]) > cfg.reach_tolerance), goals.t, np.nan_to_num(pos_err[s]), s
        )
    meta: dict[str, Any] = {
        "source": motion.source,
        "anchor": mapping.anchor,
        "scale": goals.scale,
        "frames": n,
        "source_rate_hz": float((n - 1) / (goals.t[-1] - goals.t[0])) if n > 1 else 0.0,
        "ik_time_s": t_ik,
        "ik_rate_fps": n / t_ik if t_ik > 0 else float("inf"),
        "mapping_time_s": t_map,
        "reachable": {s: goals.reachable[s].tolist() for s in goals.tcp},
        "unreachable": goals.unreachable_intervals(),
        "ik_unreached": unreached,
        "tracking": tracking,
        "goal_position": {s: goals.tcp[s][:, :3, 3] for s in goals.tcp},
        "goal_time": goals.t,
        "time_scaling": timing.summary(goals.t),
        "handle_turns": handle_turns,
        "handle_holds": handle_holds,
        "moved_grasps": shifted,
        "finger_room": finger_room,
        "carry_placements": placed,
        **diag,
    }
    if np.isfinite(goals.lift).any():
        il = model.q_index("torso_lift_joint")
        saturated = (goals.lift <= model.q_lower[il] + 1e-9) | (goals.lift >= model.q_upper[il] - 1e-9)
        meta["lift_saturated_fraction"] = float(np.mean(saturated))
    if meta["unreachable"]:
        _LOG.warning(
            "%d unreachable goal interval(s) for %s: %s",
            len(meta["unreachable"]),
            model.name,
            meta["unreachable"][:3],
        )
    return JointTrajectory(
        robot=model.name,
        t=timing.t - timing.t[0],
        q=qs,
        joint_names=model.joint_names,
        events=events,
        meta=meta,
        floating_index=0 if model.floating else -1,
    )
