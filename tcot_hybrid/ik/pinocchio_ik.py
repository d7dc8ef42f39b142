"""Pinocchio backend: damped least-squares CLIK on the reduced arm-only model.

Per iteration, with the SE(3) log error ``e`` of the TCP frame and its Jacobian ``J_e``:

    (J_e^T W^2 J_e + (damping + posture_cost^2) I) dq = -J_e^T W^2 e + posture_cost^2 (q_posture - q)

(``W`` weighs rotation by ``orientation_cost``). This is the same objective mink's QP minimises, so
``damping`` and ``posture_cost`` mean the same in both backends. The step is then scaled uniformly so
no joint exceeds v_max * velocity_scale * step_dt_s (direction kept), and joints that would leave the
limit box are clamped at its edge and removed from the solve, which is repeated for the remaining
joints (a small active-set projection); ``IKResult.limit_active`` records that it happened.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from tcot_hybrid.errors import RobotModelError
from tcot_hybrid.ik.base import (
    NON_FINITE,
    IKConfig,
    IKSolver,
    IKStepFailed,
    register_ik,
)


@register_ik
class PinocchioIK(IKSolver):
    """Damped least-squares CLIK with Pinocchio (no QP; ``config.solver`` is not used)."""

    name = "pinocchio"

    def __init__(self, spec, config: IKConfig | None = None) -> None:
        super().__init__(spec, config)
        from tcot_hybrid.robot import build_pinocchio_model

        robot = build_pinocchio_model(spec, lock_gripper=True)
        self.robot = robot
        self.model: pin.Model = robot.model
        self.data: pin.Data = self.model.createData()
        if self.model.nq != self.dof or self.model.nv != self.dof:
            raise RobotModelError(
                f"reduced Pinocchio model of robot {spec.name!r} has nq={self.model.nq}, nv={self.model.nv}; "
                f"expected the {self.dof} arm joints {list(spec.arm_joints)}"
            )
        # Pinocchio q index of each arm joint, in spec order.
        self._qidx = np.asarray(robot.arm_q_idx, dtype=int)
        if sorted(self._qidx.tolist()) != list(range(self.dof)):
            raise RobotModelError(f"arm joints {list(spec.arm_joints)} do not map one-to-one onto Pinocchio q")
        self._frame_id = int(robot.tcp_frame_id)
        cfg = self.config
        # Squared task weights: position rows 1, rotation rows orientation_cost^2.
        self._w2 = np.array([1.0, 1.0, 1.0] + [cfg.orientation_cost**2] * 3)

    def _to_model(self, q: np.ndarray) -> np.ndarray:
        q_model = np.empty(self.dof)
        q_model[self._qidx] = q
        return q_model

    def _gauss_newton_step(
        self, J_e: np.ndarray, err: np.ndarray, q: np.ndarray, q_post: np.ndarray, *, posture: bool
    ) -> tuple[np.ndarray, bool]:
        """One regularised Gauss-Newton step in spec joint order, within velocity and position box.
        Returns (dq, a position limit clamped a joint)."""
        cfg = self.config
        c2 = cfg.posture_cost**2 if posture else 0.0
        JtW = J_e.T * self._w2  # (n, 6)
        H = JtW @ J_e + (cfg.damping + c2) * np.eye(self.dof)
        g = -JtW @ err + c2 * (q_post - q)
        pos_lo, pos_hi = self.lower - q, self.upper - q  # q is inside the box here
        free = np.ones(self.dof, dtype=bool)
        dq = np.zeros(self.dof)
        clamped = False
        for _ in range(self.dof):
            # Solve for the free joints with the clamped ones fixed at their edge.
            f = free
            rhs = g[f] - H[np.ix_(f, ~f)] @ dq[~f]
            dq[f] = np.linalg.solve(H[np.ix_(f, f)], rhs)
            # Uniform velocity scaling keeps the direction of the free part.
            ratio = np.max(np.abs(dq[f]) / self.max_step[f])
            if ratio > 1.0:
                dq[f] /= ratio
            out = f & ((dq < pos_lo) | (dq > pos_hi))
            if not np.any(out):
                break
            dq[out] = np.clip(dq[out], pos_lo[out], pos_hi[out])
            free = free & ~out
            clamped = True
            if not np.any(free):
                break
        return dq, clamped

    def _begin(self, pos: np.ndarray, rot: np.ndarray, seed: np.ndarray) -> None:
        self._oMdes = pin.SE3(rot, pos)
        self._q_post = self.posture_for(seed)

    def _tcp_at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._q_model = self._to_model(q)
        pin.forwardKinematics(self.model, self.data, self._q_model)
        self._oMf = pin.updateFramePlacement(self.model, self.data, self._frame_id)
        return self._oMf.translation, self._oMf.rotation

    def _step(self, q: np.ndarray, pos: np.ndarray, rot: np.ndarray, pos_err: float,
              rot_err: float) -> tuple[np.ndarray, bool]:
        with np.errstate(all="ignore"):
            fMd = self._oMf.actInv(self._oMdes)
            err = pin.log6(fMd).vector
            J = pin.computeFrameJacobian(self.model, self.data, self._q_model, self._frame_id, pin.ReferenceFrame.LOCAL)
            J_e = -pin.Jlog6(fMd.inverse()) @ J[:, self._qidx]
            if not (np.all(np.isfinite(err)) and np.all(np.isfinite(J_e))):
                raise IKStepFailed(NON_FINITE)
            try:
                posture = self.posture_active(pos_err, rot_err)
                return self._gauss_newton_step(J_e, err, q, self._q_post, posture=posture)
            except np.linalg.LinAlgError:
                raise IKStepFailed(NON_FINITE) from None
