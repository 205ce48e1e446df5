"""Per-frame differential inverse kinematics as a small dense QP (:mod:`hsi_retarget.qp`, DAQP).

One step solves, for the joint step ``dq`` (tangent space, the gripper fingers excluded)::

    min  sum_k w_k |J_k dq - e_k|^2 + w_post |dq - (q_post - q)|^2 + damping |dq|^2
    s.t. max(q_lower - q, -s) <= dq <= min(q_upper - q, s)       s = min(max_step, v_max dt)
         n_i^T J_i dq >= -gain (d_i - margin)                    sphere i near the scene / the other arm
         (humanoid) J_sole dq = e_sole, CoM inside the support polygon  (:mod:`hsi_retarget.humanoid_ik`)

with the tasks: both TCP poses (position weight >> orientation weight), the root goal (dual arm: planar
base x, y, yaw; humanoid: pelvis pose, its roll and pitch weighted less so that the body hinges at the
hips to reach low) and the torso lift. Position limits are velocity bounds, so a step never leaves the
limits. When the constrained QP is infeasible (e.g. a step starting inside a margin), it
is retried with the inequality rows relaxed to "do not get closer", then also with the feet's equality
rows turned into stiff tasks (a swing foot that would have to bring a thigh closer to a cabinet than it
is, or the CoM back into its polygon, cannot make the step infeasible: standing still is feasible), and
only then with every row dropped (counted in :attr:`StepInfo.fallback`).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from hsi_planning.errors import RetargetError
from hsi_retarget.candidates import CandidateCache
from hsi_retarget.collision import GROUPS, SceneLayer, collision_rows, min_gap, point_rows, robot_spheres
from hsi_retarget.culling import LinkBounds
from hsi_retarget.face_planes import FacePlanes
from hsi_retarget.held_object import HeldObject, held_rows, near_spheres
from hsi_retarget.humanoid_ik import SupportConfig, support_rows
from hsi_retarget.ik_config import IKConfig
from hsi_retarget.ik_types import IKResult, IKTargets, StepInfo
from hsi_retarget.mapping import BASE_JOINTS, LIFT_JOINT
from hsi_retarget.path_clearance import path_gaps
from hsi_retarget.qp import solve_cascade
from hsi_retarget.robots import RobotModel
from hsi_retarget.scene_distance import SceneDistance

__all__ = ["IKConfig", "IKResult", "IKSolver", "IKTargets", "StepInfo", "solve_cascade"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_WORLD_MEMO = 4  #: [-] configurations whose sphere centres :meth:`IKSolver._world` keeps


class IKSolver:
    """Differential IK of one robot (see the module docstring). Not thread-safe."""

    def __init__(
        self,
        robot: RobotModel,
        config: IKConfig | None = None,
        scene: SceneDistance | None = None,
        support: SupportConfig | None = None,
    ) -> None:
        self.robot, self.config, self.scene = robot, config or IKConfig(), scene
        self.support = support or SupportConfig()
        self._model, self._data = robot.model, robot.model.createData()
        fingers = {robot.v_index(j) for side in robot.gripper_joints.values() for j in side}
        self.act = np.array([i for i in range(robot.nv) if i not in fingers], dtype=np.int64)
        self._tcp_ids = {
            s: robot.model.getFrameId(f, pin.FrameType.BODY) for s, f in robot.tcp_frames.items()
        }
        self.spheres = robot_spheres(robot)
        pairs = self.spheres.pairs()
        #: side -> the spheres a held object of that hand keeps the self margin from (the other arm, the body)
        self._not_arm = {
            side: np.flatnonzero(self.spheres.groups != GROUPS.index(side)).astype(np.int64)
            for side in ("left", "right")
        }
        self._bounds = LinkBounds(self.spheres, pairs)
        self._pairs = pairs if self._bounds.pairs is None else self._bounds.pairs  # the very array: culled
        self._layer: SceneLayer | None = None
        self._layer_holder = ""  #: the side exempt from :attr:`_layer` ('' none)
        self._held: dict[str, HeldObject] = {}  #: side -> the object that hand holds
        #: finger spheres of each hand
        self._tips = {
            s: np.flatnonzero(self.spheres.tips & (self.spheres.groups == GROUPS.index(s)))
            for s in ("left", "right")
        }
        cfg, floating = self.config, robot.floating  # a floating base (humanoid) lags more: wider margins
        #: the (scene, finger tip, self) margins [m] of this robot
        self.margins = (
            cfg.scene_margin,
            cfg.tip_margin,
            cfg.self_margin_floating if floating else cfg.self_margin,
        )
        #: [m] finger margin added away from a contact (up to ``tip_margin_far[_floating]``)
        self._tip_span = (cfg.tip_margin_far_floating if floating else cfg.tip_margin_far) - cfg.tip_margin
        #: (S,) [m] scene margin beyond :attr:`IKConfig.scene_margin` of the body spheres (floating base)
        body = self.spheres.groups == GROUPS.index("body")
        extra = cfg.body_margin_floating if floating else 0.0
        self._body_extra = np.where(body, extra, 0.0) if extra > 0.0 and body.any() else None
        slack = self.config.candidate_slack
        self._cache = CandidateCache(slack) if slack > 0.0 else None
        planes = cfg.face_planes if cfg.face_planes is not None else floating
        self._planes = FacePlanes(self.spheres) if planes else None
        #: (S,) [m] the configured scene margin of each sphere (finger tips: ``tip_margin``)
        self._sphere_margin = np.where(self.spheres.tips, self.margins[1], self.margins[0])
        self._world_memo: dict[bytes, tuple[F64, F64]] = {}
        self._v_max = np.array(robot.v_max)
        self._jq = np.array([robot.q_index(n) for n in robot.joint_names], dtype=np.int64)
        self._jv = np.array([robot.v_index(n) for n in robot.joint_names], dtype=np.int64)
        self._posture_w = np.full(robot.nv, self.config.posture_weight)
        self._w_tcp = np.repeat([cfg.position_weight, cfg.orientation_weight], 3)  #: (6,) TCP task weights
        #: (6,) TCP weight factors at a contact, minus 1
        self._contact_gain = np.repeat([cfg.contact_position_factor, cfg.contact_orientation_factor], 3) - 1.0
        self._root_axes = np.array([1.0, 1.0, 1.0, cfg.root_tilt_factor, cfg.root_tilt_factor, 1.0])
        free = [j for j in (*BASE_JOINTS, LIFT_JOINT) if j in robot.joint_names]
        self._posture_w[[robot.v_index(j) for j in free]] = 0.0
        if robot.floating:
            self._posture_w[:6] = 0.0
            self._pelvis = robot.model.getFrameId(robot.description.links[0].name, pin.FrameType.BODY)
        arms = robot.arm_joints
        self._arm = {s: (robot.arm_q_indices(s), robot.arm_v_indices(s)) for s in arms}  # (q, v) indices
        #: side -> (n, nv) that arm's joint configuration task (:attr:`IKTargets.arm`)
        self._arm_jac = {s: np.eye(robot.nv)[iv] for s, (_, iv) in self._arm.items()}
        self._base_v = [robot.v_index(j) for j in BASE_JOINTS if j in robot.joint_names]
        self._base_q = [robot.q_index(j) for j in BASE_JOINTS if j in robot.joint_names]
        #: [rad] the base yaw's range (a holonomic base turns within it, the long way round if need be)
        self._yaw_range = (
            (float(robot.q_lower[self._base_q[2]]), float(robot.q_upper[self._base_q[2]]))
            if len(self._base_q) == 3
            else (-math.inf, math.inf)
        )
        self._lift = (
            (robot.q_index(LIFT_JOINT), robot.v_index(LIFT_JOINT))
            if LIFT_JOINT in robot.joint_names
            else None
        )
        self._base_jac = np.zeros((len(self._base_v), robot.nv))  #: (3, nv) the base x, y, yaw task
        self._base_jac[np.arange(len(self._base_v)), self._base_v] = 1.0
        self._lift_jac = np.zeros((1, robot.nv))  #: (1, nv) the torso lift task
        if self._lift is not None:
            self._lift_jac[0, self._lift[1]] = 1.0

    # ------------------------------------------------------------------------------------- tasks

    def _frame_jacobian(self, fid: int) -> F64:
        return np.asarray(pin.getFrameJacobian(self._model, self._data, fid, _LWA))

    def _pose_error(self, fid: int, goal: F64) -> F64:
        placement = self._data.oMf[fid]
        rot = np.asarray(placement.rotation)
        ep = np.asarray(goal[:3, 3]) - np.asarray(placement.translation)
        eo = pin.log3(np.asarray(goal[:3, :3]) @ rot.T)
        return np.concatenate([ep, eo])

    def _tasks(self, q: F64, targets: IKTargets) -> tuple[F64, F64]:
        """Quadratic objective (H (nv, nv), g (nv,)) of the tasks and the posture."""
        cfg, nv = self.config, self.robot.nv
        jacs: list[F64] = []
        errs: list[F64] = []
        weights: list[F64] = []
        for side, goal in targets.tcp.items():
            fid = self._tcp_ids[side]
            c = targets.contact.get(side, 0.0)
            w = self._w_tcp if c <= 0.0 else self._w_tcp * (1.0 + c * self._contact_gain)
            if side in targets.holding:
                w = w * cfg.hold_factor
            jacs.append(self._frame_jacobian(fid))
            errs.append(self._pose_error(fid, goal))
            weights.append(w)
        near = max(targets.contact.values(), default=0.0)  # the base moves less for a hand at a contact
        root_weight = cfg.root_weight * (1.0 + near * (cfg.contact_root_factor - 1.0))
        if targets.root is not None and cfg.root_weight > 0.0:
            goal = np.asarray(targets.root)
            if self.robot.floating:
                jacs.append(self._frame_jacobian(self._pelvis))
                errs.append(self._pose_error(self._pelvis, goal))
                weights.append(root_weight * self._root_axes)
            elif self._base_v:
                yaw = math.atan2(goal[1, 0], goal[0, 0])
                err = np.array([goal[0, 3], goal[1, 3], yaw]) - q[self._base_q]
                err[2] = (err[2] + math.pi) % (2 * math.pi) - math.pi
                yaw_at, lo, hi = q[self._base_q[2]], self._yaw_range[0], self._yaw_range[1]
                if not lo <= yaw_at + err[2] <= hi:  # the short way round ends past the yaw limit
                    err[2] -= math.copysign(2.0 * math.pi, err[2])
                jacs.append(self._base_jac)
                errs.append(err)
                weights.append(np.full(3, root_weight))
        for side, (goal_q, weight) in targets.arm.items():
            if weight > 0.0:
                iq = self._arm[side][0]
                jacs.append(self._arm_jac[side])
                errs.append(np.asarray(goal_q)[iq] - q[iq])
                weights.append(np.full(iq.shape[0], weight))
        if targets.lift is not None and self._lift is not None and cfg.lift_weight > 0.0:
            jacs.append(self._lift_jac)
            errs.append(np.array([targets.lift - q[self._lift[0]]]))
            weights.append(np.array([cfg.lift_weight]))
        posture = self.robot.q_home if targets.posture is None else np.asarray(targets.posture)
        diff = self._posture_w * pin.difference(self._model, q, posture)
        if jacs:
            jac = np.vstack(jacs)
            wj = jac * np.concatenate(weights)[:, None]
            hess = jac.T @ wj
            grad = -(wj.T @ np.concatenate(errs))
            # the posture acts in the null space of the tasks (no steady-state task error): its pull minus the
            # part in the tasks' row space (pinv's cut-off: J^+ J x = V V^T x). An eigendecomposition of J^T J
            # instead of the SVD was 1-2 % faster but flipped 2 humanoid benchmark episodes to failures.
            ja = jac[:, self.act]
            _, sing, vt = np.linalg.svd(ja, full_matrices=False)
            rows = vt[sing > 1e-4 * sing[0]].T
            diff_act = diff[self.act]
            diff[self.act] = diff_act - rows @ (rows.T @ diff_act)
        else:
            hess, grad = np.zeros((nv, nv)), np.zeros(nv)
        grad -= diff
        hess[np.diag_indices(nv)] += self._posture_w + cfg.damping
        return hess, grad

    # -------------------------------------------------------------------------------- collisions

    def set_part_scene(self, scene: SceneDistance | None, holder: str = "") -> None:
        """Check the robot against one more ``scene`` (e.g. an opened door or drawer) from now on, except
        the gripper and finger spheres of the ``holder`` side (the hand holding it, ``left``/``right``;
        '' none: its arm keeps clear of the part like any other); ``None`` removes it."""
        if scene is None:
            self._layer, self._layer_holder = None, ""
            return
        if holder not in ("", "left", "right"):
            raise RetargetError(f"set_part_scene: holder must be 'left', 'right' or '', got {holder!r}")
        heed = np.ones(self.spheres.radii.shape[0], dtype=bool)
        if holder:
            hand = self.spheres.tips | self.spheres.palm
            heed &= ~((self.spheres.groups == GROUPS.index(holder)) & hand)
        self._layer, self._layer_holder = (scene, heed), holder

    def hold(self, held: HeldObject) -> None:
        """From now on ``held`` moves with its hand's TCP and keeps :attr:`IKConfig.held_margin` from the
        scene (and the opened part, unless that hand holds it) (:mod:`hsi_retarget.held_object`)."""
        if held.side not in self._tcp_ids:
            valid = list(self._tcp_ids)
            raise RetargetError(f"hold: {self.robot.name} has no {held.side!r} hand; valid: {valid}")
        self._held[held.side] = held

    def release(self, side: str | None = None) -> None:
        """The hand ``side`` lets go of what it holds (``None``: both)."""
        if side is None:
            self._held.clear()
        else:
            self._held.pop(side, None)

    @property
    def held(self) -> dict[str, HeldObject]:
        """side -> the object that hand holds (a copy)."""
        return dict(self._held)

    def _held_rows(self, targets: IKTargets, q: F64) -> tuple[F64, F64]:
        """Rows A (k, nv) and lower bounds (k,) keeping the held objects off the scene and off the robot's
        other arm and body (:func:`~hsi_retarget.held_object.near_spheres`, at the self-collision margin)."""
        cfg, nv = self.config, self.robot.nv
        blocks, lows = [np.zeros((0, nv))], [np.zeros(0)]
        centers = self._world(q, posed=True)[1]
        for side, held in self._held.items():
            closeness = targets.contact.get(side, 0.0)
            if closeness >= 1.0:  # resting on its support at the grasp or the release
                continue
            layers = [] if self.scene is None else [self.scene]
            if self._layer is not None and self._layer_holder != side:
                layers.append(self._layer[0])
            fid = self._tcp_ids[side]
            tcp, jac = np.asarray(self._data.oMf[fid].homogeneous), self._frame_jacobian(fid)
            rows, low = held_rows(
                held,
                tcp,
                jac,
                layers,
                margin=cfg.held_margin * (1.0 - closeness),
                activation=cfg.activation_distance,
                gain=cfg.collision_gain,
                max_rows=cfg.max_held_rows,
            )
            blocks.append(rows)
            lows.append(low)
            others = self._not_arm[side]
            points, idx, normal, gap = near_spheres(
                held,
                tcp,
                centers[others],
                self.spheres.radii[others],
                margin=self.margins[2],
                activation=cfg.activation_distance,
                max_rows=cfg.max_held_rows,
            )
            if gap.size:
                lever = points - tcp[:3, 3]
                own = normal @ jac[:3] + np.cross(lever, normal) @ jac[3:]
                theirs = point_rows(
                    self._model, self._data, self.spheres, centers, idx=others[idx], dirs=-normal
                )
                blocks.append(own + theirs)
                lows.append(-cfg.collision_gain * gap)
        return np.vstack(blocks), np.concatenate(lows)

    def _extra_margin(self, targets: IKTargets) -> F64 | None:
        """(S,) [m] scene margins beyond the configured ones: the fingers' for ``targets``' contact
        closeness (beyond :attr:`IKConfig.tip_margin`, up to ``tip_margin_far`` or on a floating robot
        ``tip_margin_far_floating``), a floating robot's body spheres'
        (:attr:`IKConfig.body_margin_floating`); ``None``: none."""
        if self._tip_span <= 0.0 and self._body_extra is None:
            return None
        extra = np.zeros(self.spheres.radii.shape[0]) if self._body_extra is None else self._body_extra.copy()
        if self._tip_span > 0.0:
            for side, tips in self._tips.items():
                extra[tips] = self._tip_span * (1.0 - targets.contact.get(side, 0.0))
        return extra

    def _collision_rows(
        self, q: F64, extra: F64 | None = None, inside: list[tuple[I64, F64, F64]] | None = None
    ) -> tuple[F64, F64, float]:
        """Rows A (k, nv) and lower bounds (k,) of the closest sphere pairs; smallest clearance - margin
        (``extra`` (S,) [m]: more scene margin per sphere; ``inside``: see
        :func:`~hsi_retarget.collision.collision_rows`)."""
        cfg = self.config
        pairs, margins = self._checked()
        return collision_rows(
            self._model,
            self._data,
            self.spheres,
            pairs,
            self.scene,
            margins=margins,
            activation=cfg.activation_distance,
            gain=cfg.collision_gain,
            max_rows=cfg.max_collision_rows,
            bounds=self._bounds,
            extra=self._layer,
            cache=self._cache,
            extra_margin=extra,
            world=self._world(q, posed=True),
            inside=inside,
        )

    # ------------------------------------------------------------------------------------ solving

    def step(
        self, q: F64, targets: IKTargets, dt: float | None = None, q_start: F64 | None = None
    ) -> tuple[F64, StepInfo]:
        """One QP step from ``q`` (nq,); ``dt`` [s] adds the velocity limits
        ``|q + dq - q_start| <= v_max dt`` on the 1-DoF joints (``q_start``: the frame's first configuration,
        default ``q``)."""
        robot, cfg, act = self.robot, self.config, self.act
        q = np.asarray(q, dtype=np.float64)
        pin.computeJointJacobians(self._model, self._data, q)
        pin.updateFramePlacements(self._model, self._data)
        hess, grad = self._tasks(q, targets)
        lower, upper = np.full(robot.nv, -cfg.max_step), np.full(robot.nv, cfg.max_step)
        idx_q, idx_v = self._jq, self._jv
        lo_q, hi_q = robot.q_lower[idx_q], robot.q_upper[idx_q]
        if dt is not None:
            start = q[idx_q] if q_start is None else np.asarray(q_start)[idx_q]
            reach = self._v_max[idx_v] * dt
            lo_q, hi_q = np.maximum(lo_q, start - reach), np.minimum(hi_q, start + reach)
        lower[idx_v] = np.maximum(lower[idx_v], lo_q - q[idx_q])
        upper[idx_v] = np.minimum(upper[idx_v], hi_q - q[idx_q])
        upper = np.maximum(upper, lower)
        extra = self._extra_margin(targets)
        inside: list[tuple[I64, F64, F64]] = []  # filled by collision_rows when asked (face planes)
        rows, row_lo, min_slack = self._collision_rows(q, extra, None if self._planes is None else inside)
        if self._planes is not None:
            centers = self._world(q, posed=True)[1]
            margin = self._sphere_margin + extra if extra is not None else self._sphere_margin
            more, more_lo = self._planes.rows(self._model, self._data, centers, margin, cfg.collision_gain)
            rows, row_lo = np.vstack([rows, more]), np.concatenate([row_lo, more_lo])
            self._planes.remember(centers, margin, *inside[0])
        if self._held:
            more, more_lo = self._held_rows(targets, q)
            rows, row_lo = np.vstack([rows, more]), np.concatenate([row_lo, more_lo])
        row_hi = np.full(row_lo.shape, np.inf)
        if robot.floating and targets.feet:
            eq_a, eq_b, in_a, in_lo, h_add, g_add = support_rows(
                self._model, self._data, q, targets, self.support
            )
            hess += h_add
            grad += g_add
            rows = np.vstack([rows, eq_a, in_a])
            row_lo = np.concatenate([row_lo, eq_b, in_lo])
            row_hi = np.concatenate([row_hi, eq_b, np.full(in_lo.shape, np.inf)])
        n_coll = int(min(rows.shape[0], cfg.max_collision_rows))
        dq_act, ok, level = solve_cascade(
            hess[np.ix_(act, act)], grad[act], rows[:, act], (row_lo, row_hi), (lower[act], upper[act])
        )
        dq = np.zeros(robot.nv)
        if ok:
            dq[act] = np.clip(dq_act, lower[act], upper[act])
        info = StepInfo(bool(ok), level, n_coll, float(min_slack))
        return robot.integrate(q, dq), info

    def _checked(self) -> tuple[NDArray[np.int64], tuple[float, float, float]]:
        """The sphere pairs checked for self-collision (none without :attr:`IKConfig.self_collision`) and
        the (scene, finger tip, self) margins [m]."""
        cfg = self.config
        pairs = self._pairs if cfg.self_collision else np.zeros((0, 2), dtype=np.int64)
        return pairs, self.margins

    def _world(self, q: F64, *, posed: bool = False) -> tuple[F64, F64]:
        """(F, 3) link bounding centres and (S, 3) sphere centres [m] at ``q`` (nq,), read-only, from the
        last few configurations asked for (an IK step, its clearance checks and the next step share one
        configuration). ``posed``: ``self._data`` already holds the frame placements of ``q``."""
        key = np.asarray(q, dtype=np.float64).tobytes()
        hit = self._world_memo.get(key)
        if hit is None:
            if not posed:
                pin.framesForwardKinematics(self._model, self._data, np.asarray(q, dtype=np.float64))
            hit = self._bounds.world(self._data, self.spheres)
            for a in hit:
                a.flags.writeable = False
            if len(self._world_memo) >= _WORLD_MEMO:
                self._world_memo.pop(next(iter(self._world_memo)))
            self._world_memo[key] = hit
        return hit

    def sphere_centers(self, q: F64) -> F64:
        """(S, 3) [m] world centres of :attr:`spheres` at ``q`` (nq,)."""
        return np.array(self._world(q)[1])

    def clearance(self, q: F64, within: float | None = None) -> float:
        """[m] smallest sphere clearance minus its margin (scene and self) at ``q``; ``inf`` when every pair
        is farther than ``within`` [m] (default: the activation distance) beyond its margin (a smaller
        ``within`` measures fewer pairs: cheaper when only a cut into the margins matters)."""
        cfg = self.config
        reach = cfg.activation_distance if within is None else float(within)
        pairs, margins = self._checked()
        links, centers = self._world(q)
        gap = min_gap(
            self.spheres,
            centers,
            pairs,
            self.scene,
            margins,
            activation=reach,
            bounds=self._bounds,
            links=links,
            extra=self._layer,
            cache=self._cache,
        )
        return gap if gap < reach else math.inf

    def clearances(self, qs: F64, within: float | None = None) -> F64:
        """(N,) [m] :meth:`clearance` of each configuration of ``qs`` (N, nq), the same numbers, culled for
        all at once (:mod:`hsi_retarget.path_clearance`)."""
        cfg = self.config
        reach = cfg.activation_distance if within is None else float(within)
        qs = np.asarray(qs, dtype=np.float64).reshape(-1, self.robot.nq)
        centers = np.empty((qs.shape[0], self.spheres.radii.shape[0], 3))
        links = np.empty((qs.shape[0], self._bounds.radii.shape[0], 3))
        for i, q in enumerate(qs):
            pin.framesForwardKinematics(self._model, self._data, q)
            links[i], centers[i] = self._bounds.world(self._data, self.spheres)
        pairs, margins = self._checked()
        return path_gaps(
            self.spheres,
            centers,
            links,
            pairs,
            self.scene,
            margins=margins,
            reach=reach,
            bounds=self._bounds,
            extra=self._layer,
        )

    def clearance_bound(self, q_from: F64, q_to: F64, clearance_from: float) -> float:
        """[m] a lower bound of :meth:`clearance` at ``q_to`` (nq,) from its value ``clearance_from`` [m]
        at ``q_from`` (nq,): no sphere moved farther than the largest centre displacement, and a gap
        between two spheres closes by at most twice that (distances are 1-Lipschitz)."""
        moved = float(np.linalg.norm(self._world(q_to)[1] - self._world(q_from)[1], axis=1).max())
        return clearance_from - 2.0 * moved

    def errors(self, q: F64, targets: IKTargets) -> tuple[dict[str, float], dict[str, float]]:
        """TCP position [m] and orientation [rad] errors per side with a goal."""
        pin.framesForwardKinematics(self._model, self._data, np.asarray(q, dtype=np.float64))
        pos, ori = {}, {}
        for side, goal in targets.tcp.items():
            err = self._pose_error(self._tcp_ids[side], np.asarray(goal))
            pos[side], ori[side] = float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:]))
        return pos, ori

    def solve(
        self,
        q0: F64,
        targets: IKTargets,
        iterations: int | None = None,
        dt: float | None = None,
        stall: tuple[int, float] | None = None,
        *,
        give_up: float | None = None,
    ) -> IKResult:
        """Step from ``q0`` until the TCP errors are within tolerance, the steps stall, or ``iterations``.
        ``stall`` = (steps n, progress [m]): also stop once the largest TCP position error is less than
        ``progress`` below what it was n steps before (stuck against a constraint, or close enough); only
        with TCP goals. ``give_up`` [m] (with ``stall``): also stop once that error, falling on at its rate
        over those n steps, would still be above ``give_up`` at the step limit (it cannot get there)."""
        cfg = self.config
        q = np.array(q0, dtype=np.float64)
        fallbacks, done, it = 0, False, 0
        worst: list[float] = []  # the largest TCP position error after each step
        stall = stall if targets.tcp else None  # without TCP goals there is no error to watch
        limit = iterations or cfg.iterations
        for step in range(1, limit + 1):
            it = step
            q_new, info = self.step(q, targets, dt)
            fallbacks += int(info.fallback > 0)
            moved = float(np.max(np.abs(pin.difference(self._model, q, q_new))))
            q = q_new
            pos, ori = self.errors(q, targets)
            done = bool(pos) and all(
                pos[s] <= cfg.position_tolerance and ori[s] <= cfg.orientation_tolerance for s in pos
            )
            if done or moved < 1e-7:
                break
            if stall is not None:
                worst.append(max(pos.values()))
                if len(worst) > stall[0]:
                    fell = worst[-1 - stall[0]] - worst[-1]  # [m] over the last n steps
                    if fell < stall[1]:
                        break
                    if give_up is not None and worst[-1] - fell / stall[0] * (limit - step) > give_up:
                        break
        pos, ori = self.errors(q, targets)
        return IKResult(q, pos, ori, it, done, fallbacks)
