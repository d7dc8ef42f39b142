"""Computed torque (inverse dynamics) control in joint space.

    tau = M(q) (qdd_ref + kp e + kd de) + bias(q, qd),    e = q_ref - q,  de = qd_ref - qd

With the exact model the error obeys e'' + kd e' + kp e = 0 for every joint, decoupled; the gains are
the robot spec's acceleration-level kp [1/s^2] and kd [1/s]. ``M`` and ``bias`` come from MuJoCo
(``MujocoArmDynamics``, already computed by ``mj_step1``, so this costs one 7x7 mat-vec, ~4 us per
tick); ``model = "pinocchio"`` computes M acc + bias with Pinocchio's RNEA instead (what a real
controller with only the robot model would do; ~2 us more).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tcot_hybrid.config import require_choice
from tcot_hybrid.controllers import register
from tcot_hybrid.controllers.base import STATUS_OK, Controller, JointGainsConfig, bias_attr, resolve_joint_gains


@dataclass(frozen=True, kw_only=True)
class ComputedTorqueConfig(JointGainsConfig):
    """Computed-torque gains (acceleration-level, default = robot spec) and dynamics source.

    model: "mujoco" (M and bias of the simulation, incl. armature and the gripper's weight; cheapest)
           or "pinocchio" (recomputed from the robot MJCF with the gripper locked at its MJCF qpos0;
           models a real controller that only has the URDF/MJCF).
    """

    model: str = "mujoco"

    def __post_init__(self) -> None:
        super().__post_init__()
        require_choice("model", self.model, ("mujoco", "pinocchio"))


@register
class ComputedTorque(Controller):
    name = "computed_torque"
    Config = ComputedTorqueConfig

    def __init__(self, spec, *, ctrl_dt: float, config: ComputedTorqueConfig) -> None:
        super().__init__(spec, ctrl_dt=ctrl_dt, config=config)
        self.kp, self.kd = resolve_joint_gains(config, spec, ctrl_dt)
        self._bias = bias_attr(config)
        self._pin = None
        if config.model == "pinocchio":
            import pinocchio as pin

            from tcot_hybrid.robot import build_pinocchio_model

            robot = build_pinocchio_model(spec, lock_gripper=True)
            self._pin = pin
            self._pin_model = robot.model
            self._pin_data = robot.model.createData()

    def _compute(self, dyn, reference, preview):
        acc = reference.qdd + self.kp * (reference.q - dyn.q) + self.kd * (reference.qd - dyn.qd)
        if self._pin is None:
            return dyn.M @ acc + getattr(dyn, self._bias), STATUS_OK, "", 0.0
        # RNEA gives M acc + bias in one pass.
        tau = self._pin.rnea(self._pin_model, self._pin_data, dyn.q, dyn.qd, acc)
        if self._bias == "bias_net":
            return tau - dyn.passive, STATUS_OK, "", 0.0
        return np.array(tau), STATUS_OK, "", 0.0
