"""Operational-space control of the TCP (position + orientation) with a joint-space posture task.

The Cartesian reference is the forward kinematics of the joint reference (Pinocchio, arm-only model
with the gripper locked: ~2 us per tick; a second MuJoCo kinematics + Jacobian pass measured ~9 us):

    x_ref = FK(q_ref),   xd_ref = J(q_ref) qd_ref

Law (J = world-frame TCP Jacobian, Lambda = (J M^-1 J^T + lambda I)^-1):

    a0  = qdd_ref + kp_posture e_q + kd_posture de_q                      joint posture task [rad/s^2]
    r   = K_x e_x + D_x (xd_ref - J qd) - J (kp_posture e_q + kd_posture de_q)
    tau = M a0 + bias + J^T Lambda r

i.e. computed torque in joint space whose task-space part is replaced by a Cartesian PD: the TCP
error obeys e_x'' + D_x e_x' + K_x e_x = 0 (up to J-dot terms that cancel between reference and
state to first order), the posture task acts in the dynamically consistent null space.
e_x = (p_ref - p, 1/2 vee(R_ref R^T - R R_ref^T)) [m, rad].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tcot_hybrid.config import require_positive
from tcot_hybrid.controllers import register
from tcot_hybrid.controllers.base import (
    STATUS_OK,
    Controller,
    JointGainsConfig,
    bias_attr,
    check_gain_stability,
    cho_solve,
    cholesky,
    resolve_joint_gains,
    spd_solve,
)


@dataclass(frozen=True, kw_only=True)
class OSCConfig(JointGainsConfig):
    """OSC gains. ``kp``/``kd``/``kp_scale``/``kd_scale`` are the null-space posture gains (default spec).

    pos_kp: TCP position stiffness [1/s^2]; None = median of the spec's kp. Higher = stiffer TCP.
    pos_kd: TCP position damping [1/s]; None = median of the spec's kd. Higher = less overshoot.
    rot_kp: TCP orientation stiffness [1/s^2]; None = median of the spec's kp.
    rot_kd: TCP orientation damping [1/s]; None = median of the spec's kd.
    singularity_damping: lambda added to J M^-1 J^T [1/kg, 1/(kg m^2)]; higher = tamer near
        singularities, softer task tracking there. Must stay small against its eigenvalues (~0.5-20).
    """

    pos_kp: float | None = None
    pos_kd: float | None = None
    rot_kp: float | None = None
    rot_kd: float | None = None
    singularity_damping: float = 1e-3

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("pos_kp", "pos_kd", "rot_kp", "rot_kd"):
            if getattr(self, name) is not None:
                require_positive(name, getattr(self, name))
        require_positive("singularity_damping", self.singularity_damping)


@register
class OperationalSpace(Controller):
    name = "osc"
    Config = OSCConfig

    def __init__(self, spec, *, ctrl_dt: float, config: OSCConfig) -> None:
        super().__init__(spec, ctrl_dt=ctrl_dt, config=config)
        import pinocchio as pin

        from tcot_hybrid.robot import build_pinocchio_model

        self.kp, self.kd = resolve_joint_gains(config, spec, ctrl_dt, prefix="posture ")
        self._bias = bias_attr(config)
        kp_med, kd_med = float(np.median(spec.kp)), float(np.median(spec.kd))
        pick = lambda v, d: d if v is None else float(v)  # noqa: E731
        self.task_kp = np.array([pick(config.pos_kp, kp_med)] * 3 + [pick(config.rot_kp, kp_med)] * 3)
        self.task_kd = np.array([pick(config.pos_kd, kd_med)] * 3 + [pick(config.rot_kd, kd_med)] * 3)
        check_gain_stability(self.task_kp, self.task_kd, ctrl_dt, kp_field="pos_kp/rot_kp", kd_field="pos_kd/rot_kd")
        robot = build_pinocchio_model(spec, lock_gripper=True)
        self._pin = pin
        self._pm = robot.model
        self._pd = robot.model.createData()
        self._fid = robot.tcp_frame_id
        self._lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        self._lam = np.eye(6) * config.singularity_damping
        self._e = np.zeros(6)

    def reference_pose(self, q_ref: np.ndarray, qd_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """TCP position [m], rotation (3, 3) and twist (6,) [m/s, rad/s] of the joint reference (world frame)."""
        pin = self._pin
        pin.forwardKinematics(self._pm, self._pd, q_ref, qd_ref)
        T = pin.updateFramePlacement(self._pm, self._pd, self._fid)
        twist = pin.getFrameVelocity(self._pm, self._pd, self._fid, self._lwa).vector
        return T.translation, T.rotation, twist

    def _compute(self, dyn, reference, preview):
        p_ref, R_ref, xd_ref = self.reference_pose(reference.q, reference.qd)
        J = dyn.ee_jacobian()
        p, R = dyn.ee_pose()
        M = dyn.M
        e = self._e
        e[:3] = p_ref - p
        Re = R_ref @ R.T
        e[3] = 0.5 * (Re[2, 1] - Re[1, 2])
        e[4] = 0.5 * (Re[0, 2] - Re[2, 0])
        e[5] = 0.5 * (Re[1, 0] - Re[0, 1])
        joint_fb = self.kp * (reference.q - dyn.q) + self.kd * (reference.qd - dyn.qd)
        r = self.task_kp * e + self.task_kd * (xd_ref - J @ dyn.qd) - J @ joint_fb
        U = cholesky(M)
        if U is None:  # not SPD: a broken state; NaN lets the safety layer hold position
            return np.full(self.n, np.nan), STATUS_OK, "", 0.0
        f = spd_solve(J @ cho_solve(U, J.T) + self._lam, r)
        tau = M @ (reference.qdd + joint_fb) + getattr(dyn, self._bias) + J.T @ f
        return tau, STATUS_OK, "", 0.0
