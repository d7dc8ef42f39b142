"""Arm-only view of a MuJoCo simulation: the one way controllers see the robot.

``MujocoArmDynamics`` resolves the arm's joint, dof and actuator indices once and, after each
``mujoco.mj_step1``, copies the arm block of the state and dynamics into preallocated arrays:

    t    [s]          simulation time of the tick
    q    [rad]        (n,) arm joint positions
    qd   [rad/s]      (n,) arm joint velocities
    M    [kg m^2]     (n, n) arm block of the joint-space inertia (``mj_fullM``, includes armature)
    bias [Nm]         (n,) arm part of ``qfrc_bias`` = Coriolis/centrifugal + gravity
    passive [Nm]      (n,) arm part of ``qfrc_passive`` (joint damping/springs acting on the arm)
    bias_net [Nm]     (n,) bias - passive: the torque that cancels gravity, Coriolis and passive forces

The end-effector Jacobian and pose are computed lazily, at most once per tick. The scene may hold
other dofs (free objects, gripper fingers): only the arm's dofs are read. The arrays are owned by
this object and overwritten by the next ``update()``; copy what you keep. They are read-only views:
controllers must not write into them, nor touch ``MjData`` themselves.

Loop contract (per control tick): ``mj_step1`` → ``update()`` → controller → safety →
``write_ctrl(tau)`` → ``mj_step2`` → (substeps - 1) × ``mj_step``. ``ee_jacobian()``/``ee_pose()``
refer to the kinematics of the last ``mj_step1`` and are valid until the next ``mj_step2``.
"""
from __future__ import annotations

import mujoco
import numpy as np

from tcot_hybrid.errors import RobotModelError

_HINGE_OR_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


def _readonly(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


def _as_slice(idx: np.ndarray) -> slice | None:
    """A slice equal to ``idx`` when it is contiguous and increasing (cheap views), else None."""
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return None


class MujocoArmDynamics:
    """Arm state, inertia and bias of a robot inside a (possibly larger) MuJoCo scene.

    ``spec`` is a ``tcot_hybrid.robot.RobotSpec`` (only ``arm_joints``, ``arm_actuators``, ``ee_site``
    and ``tau_max`` are used). Raises ``RobotModelError`` when a name is missing, a joint is not a
    1-dof hinge/slide, or an arm actuator is not a unit-gain torque motor on its joint (MuJoCo would
    otherwise scale or clamp the commanded torque silently).
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, spec, *,
                 T_base_world: np.ndarray | None = None) -> None:
        """``T_base_world`` (4x4, default identity) maps the scene's world frame into the robot's base frame,
        the frame ``ee_pose``/``ee_jacobian`` report in (the frame Pinocchio's model of the robot lives in;
        LIBERO's robot sits at e.g. (-0.66, 0, 0.912) in its world)."""
        self.model = model
        self.data = data
        self.spec = spec
        T = np.eye(4) if T_base_world is None else np.asarray(T_base_world, dtype=float)
        self._R_bw, self._p_bw = T[:3, :3].copy(), T[:3, 3].copy()
        self._base_is_world = bool(np.array_equal(T, np.eye(4)))
        joints = tuple(spec.arm_joints)
        actuators = tuple(spec.arm_actuators)
        if len(joints) != len(actuators) or not joints:
            raise RobotModelError(
                f"robot {spec.name!r}: need one arm actuator per arm joint, got {len(joints)} joints "
                f"and {len(actuators)} actuators"
            )
        n = len(joints)
        self.n = n
        jids = np.array([self._id(mujoco.mjtObj.mjOBJ_JOINT, "joint", j) for j in joints])
        for name, jid in zip(joints, jids):
            if int(model.jnt_type[jid]) not in _HINGE_OR_SLIDE:
                raise RobotModelError(f"arm joint {name!r} must be a hinge or slide joint, got type "
                                      f"{mujoco.mjtJoint(int(model.jnt_type[jid])).name}")
        aids = np.array([self._id(mujoco.mjtObj.mjOBJ_ACTUATOR, "actuator", a) for a in actuators])
        tau_max = np.asarray(spec.tau_max, dtype=float)
        for k, (name, aid) in enumerate(zip(actuators, aids)):
            self._check_motor(name, int(aid), int(jids[k]), joints[k], float(tau_max[k]))
        self.joint_ids = jids
        self.qpos_adr = model.jnt_qposadr[jids].astype(np.intp)
        self.dof_adr = model.jnt_dofadr[jids].astype(np.intp)
        self.actuator_ids = aids.astype(np.intp)
        self.ee_site_id = self._id(mujoco.mjtObj.mjOBJ_SITE, "site", spec.ee_site)

        # Cached views into MjData (its buffers never move) so update() does no name or index work.
        self._qsl = _as_slice(self.qpos_adr)
        self._dsl = _as_slice(self.dof_adr)
        self._asl = _as_slice(self.actuator_ids)
        self._qpos_all = data.qpos
        self._qvel_all = data.qvel
        self._bias_all = data.qfrc_bias
        self._passive_all = data.qfrc_passive
        self._ctrl_all = data.ctrl
        nv = model.nv
        self._M_full = np.zeros((nv, nv))
        self._jacp = np.zeros((3, nv))
        self._jacr = np.zeros((3, nv))
        if self._dsl is not None:
            self._M_arm_view = self._M_full[self._dsl, self._dsl]
            self._bias_view = self._bias_all[self._dsl]
            self._passive_view = self._passive_all[self._dsl]
            self._qvel_view = self._qvel_all[self._dsl]
        if self._qsl is not None:
            self._qpos_view = self._qpos_all[self._qsl]
        if self._asl is not None:
            self._ctrl_view = self._ctrl_all[self._asl]
        self._ix = np.ix_(self.dof_adr, self.dof_adr)

        self._q = np.zeros(n)
        self._qd = np.zeros(n)
        self._M = np.zeros((n, n))
        self._bias = np.zeros(n)
        self._passive = np.zeros(n)
        self._bias_net = np.zeros(n)
        self._J = np.zeros((6, n))
        self._pos = np.zeros(3)
        self._rot = np.zeros((3, 3))
        self.q = _readonly(self._q)
        self.qd = _readonly(self._qd)
        self.M = _readonly(self._M)
        self.bias = _readonly(self._bias)
        self.passive = _readonly(self._passive)
        self.bias_net = _readonly(self._bias_net)
        self._J_ro = _readonly(self._J)
        self._pos_ro = _readonly(self._pos)
        self._rot_ro = _readonly(self._rot)
        self.t = 0.0
        self.tick = 0  # number of update() calls; lazy caches are keyed on it
        self._jac_tick = -1
        self._pose_tick = -1

    @property
    def dof(self) -> int:
        """Number of arm joints (same as ``spec.dof``)."""
        return self.n

    # -- construction helpers -------------------------------------------------------------------
    def _id(self, obj, kind: str, name: str) -> int:
        i = mujoco.mj_name2id(self.model, obj, name)
        if i < 0:
            raise RobotModelError(f"robot {self.spec.name!r}: {kind} {name!r} not found in the MuJoCo model")
        return i

    def _check_motor(self, name: str, aid: int, jid: int, joint: str, tau_max: float) -> None:
        m = self.model
        if int(m.actuator_trntype[aid]) != int(mujoco.mjtTrn.mjTRN_JOINT) or int(m.actuator_trnid[aid, 0]) != jid:
            raise RobotModelError(f"actuator {name!r} must drive joint {joint!r} directly")
        gear = float(m.actuator_gear[aid, 0])
        gain = float(m.actuator_gainprm[aid, 0])
        if (int(m.actuator_dyntype[aid]) != int(mujoco.mjtDyn.mjDYN_NONE)
                or int(m.actuator_gaintype[aid]) != int(mujoco.mjtGain.mjGAIN_FIXED)
                or int(m.actuator_biastype[aid]) != int(mujoco.mjtBias.mjBIAS_NONE)
                or gear != 1.0 or gain != 1.0):
            raise RobotModelError(
                f"actuator {name!r} must be a torque motor (no dynamics, fixed gain 1, no bias, gear 1), "
                f"got gear {gear}, gain {gain}"
            )
        # MuJoCo clamps ctrl and actuator force silently: both ranges must admit the full tau_max.
        if m.actuator_ctrllimited[aid]:
            lo, hi = m.actuator_ctrlrange[aid]
            if lo > -tau_max or hi < tau_max:
                raise RobotModelError(f"actuator {name!r} ctrlrange [{lo}, {hi}] is narrower than "
                                      f"tau_max {tau_max} Nm; MuJoCo would clamp silently")
        if m.actuator_forcelimited[aid]:
            lo, hi = m.actuator_forcerange[aid]
            if lo > -tau_max or hi < tau_max:
                raise RobotModelError(f"actuator {name!r} forcerange [{lo}, {hi}] is narrower than "
                                      f"tau_max {tau_max} Nm; MuJoCo would clamp silently")

    # -- per tick -------------------------------------------------------------------------------
    def update(self) -> None:
        """Copy the arm state and dynamics of the current ``MjData`` (call right after ``mj_step1``)."""
        mujoco.mj_fullM(self.model, self.data, self._M_full)
        if self._dsl is not None:
            np.copyto(self._qd, self._qvel_view)
            np.copyto(self._bias, self._bias_view)
            np.copyto(self._passive, self._passive_view)
            np.copyto(self._M, self._M_arm_view)
        else:
            np.take(self._qvel_all, self.dof_adr, out=self._qd)
            np.take(self._bias_all, self.dof_adr, out=self._bias)
            np.take(self._passive_all, self.dof_adr, out=self._passive)
            np.copyto(self._M, self._M_full[self._ix])
        np.subtract(self._bias, self._passive, out=self._bias_net)
        if self._qsl is not None:
            np.copyto(self._q, self._qpos_view)
        else:
            np.take(self._qpos_all, self.qpos_adr, out=self._q)
        self.t = self.data.time
        self.tick += 1

    def ee_jacobian(self) -> np.ndarray:
        """(6, n) base-frame Jacobian of the TCP site: rows 0-2 linear [m/rad], 3-5 angular [rad/rad]."""
        if self._jac_tick != self.tick:
            mujoco.mj_jacSite(self.model, self.data, self._jacp, self._jacr, self.ee_site_id)
            if self._dsl is not None:
                self._J[:3] = self._jacp[:, self._dsl]
                self._J[3:] = self._jacr[:, self._dsl]
            else:
                self._J[:3] = self._jacp[:, self.dof_adr]
                self._J[3:] = self._jacr[:, self.dof_adr]
            if not self._base_is_world:
                self._J[:3] = self._R_bw @ self._J[:3]
                self._J[3:] = self._R_bw @ self._J[3:]
            self._jac_tick = self.tick
        return self._J_ro

    def ee_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """TCP position [m] (3,) and rotation matrix (3, 3) in the robot's base frame (= world in the workcell)."""
        if self._pose_tick != self.tick:
            sid = self.ee_site_id
            self._pos[:] = self.data.site_xpos[sid]
            self._rot.ravel()[:] = self.data.site_xmat[sid]
            if not self._base_is_world:
                self._pos[:] = self._R_bw @ self._pos + self._p_bw
                self._rot[:] = self._R_bw @ self._rot
            self._pose_tick = self.tick
        return self._pos_ro, self._rot_ro

    def inverse_torques(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """(N, n) arm torques [Nm] that (N, n) arm states (q, qd, qdd) ask for: M(q) qdd + bias(q, qd) - passive(q, qd),
        armature included, from MuJoCo's own model of the scene (gravity, rotor armature, and the passive forces the
        controller feeds forward: damping, springs and the fluid drag of a scene with air, e.g. robosuite's
        density 1.2, where the Panda gripper's 10 g finger tips with 0.01 kg m^2 inertia act as 2.4 m boxes). On a
        scratch ``MjData``: everything but the arm stays where it is now and at rest; no contacts."""
        m = self.model
        if getattr(self, "_scratch", None) is None:
            self._scratch = mujoco.MjData(m)
            self._rne = np.zeros(m.nv)
        d = self._scratch
        q, qd, qdd = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (q, qd, qdd))
        out = np.empty((q.shape[0], self.n))
        d.qpos[:] = self.data.qpos
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        armature = m.dof_armature[self.dof_adr]
        for k in range(q.shape[0]):
            d.qpos[self.qpos_adr] = q[k]
            d.qvel[self.dof_adr] = qd[k]
            d.qacc[self.dof_adr] = qdd[k]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            mujoco.mj_tendon(m, d)
            mujoco.mj_transmission(m, d)
            mujoco.mj_comVel(m, d)
            mujoco.mj_passive(m, d)
            mujoco.mj_rne(m, d, 1, self._rne)
            out[k] = self._rne[self.dof_adr] + armature * qdd[k] - d.qfrc_passive[self.dof_adr]
        return out

    def write_ctrl(self, tau: np.ndarray) -> None:
        """Write arm torques [Nm] into ``MjData.ctrl`` (for the simulation loop, not for controllers)."""
        if self._asl is not None:
            np.copyto(self._ctrl_view, tau)
        else:
            self._ctrl_all[self.actuator_ids] = tau
