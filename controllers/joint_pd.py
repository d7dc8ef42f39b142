"""Decentralised joint PD + bias (gravity/Coriolis) compensation.

    tau = I_eff (kp e + kd de [+ qdd_ref]) + bias,    e = q_ref - q,  de = qd_ref - qd

``I_eff = 1 / diag(M^-1)`` is each joint's effective inertia, so the acceleration-level gains of the
robot spec fit the heavy shoulder and the light wrist alike (plain Nm/rad gains ring on the wrist;
diag(M) scaling over-drives the coupled wrist modes 13x on the Panda). Unlike computed torque it
ignores the coupling terms of M: cheaper to reason about, a little more lag.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tcot_hybrid.controllers import register
from tcot_hybrid.controllers.base import bias_attr, STATUS_OK, Controller, JointGainsConfig, effective_joint_inertia, resolve_joint_gains


@dataclass(frozen=True, kw_only=True)
class JointPDConfig(JointGainsConfig):
    """Joint PD gains (acceleration-level, default = robot spec) and feedforward.

    inertia_feedforward: add I_eff * qdd_ref [Nm]; on = less lag on accelerating references, off = pure PD.
    """

    inertia_feedforward: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.inertia_feedforward, bool):
            from tcot_hybrid.errors import ConfigError

            raise ConfigError(f"inertia_feedforward must be a bool, got {self.inertia_feedforward!r}")


@register
class JointPD(Controller):
    name = "joint_pd"
    Config = JointPDConfig

    def __init__(self, spec, *, ctrl_dt: float, config: JointPDConfig) -> None:
        super().__init__(spec, ctrl_dt=ctrl_dt, config=config)
        self.kp, self.kd = resolve_joint_gains(config, spec, ctrl_dt)
        self._bias = bias_attr(config)
        self._ff = config.inertia_feedforward

    def _compute(self, dyn, reference, preview):
        M = dyn.M
        fb = effective_joint_inertia(M) * (self.kp * (reference.q - dyn.q) + self.kd * (reference.qd - dyn.qd))
        if self._ff:
            fb += M @ reference.qdd
        return fb + getattr(dyn, self._bias), STATUS_OK, "", 0.0
