"""Inverse kinematics: TCP pose -> arm joint configuration, two backends behind one interface.

    ik = make_ik("mink", load_robot_spec("panda"), IKConfig())
    result = ik.solve(IKTarget(pos=np.array([0.5, 0.0, 0.2]), rot=R_down), seed=q_previous)

Backends register themselves with ``@register_ik``; adding one = one new module imported below.
"""
from tcot_hybrid.ik.base import (
    CONVERGED,
    MAX_ITERS,
    NON_FINITE,
    QP_INFEASIBLE,
    STATUSES,
    IKConfig,
    IKResult,
    IKSolver,
    IKStepFailed,
    IKTarget,
    list_ik,
    make_ik,
    register_ik,
    rotation_angle,
)
from tcot_hybrid.ik import mink_ik as _mink_ik  # noqa: F401  (registers "mink")
from tcot_hybrid.ik import pinocchio_ik as _pinocchio_ik  # noqa: F401  (registers "pinocchio")
from tcot_hybrid.ik.mink_ik import MinkIK
from tcot_hybrid.ik.pinocchio_ik import PinocchioIK

__all__ = [
    "CONVERGED",
    "MAX_ITERS",
    "NON_FINITE",
    "QP_INFEASIBLE",
    "STATUSES",
    "IKConfig",
    "IKResult",
    "IKSolver",
    "IKStepFailed",
    "IKTarget",
    "MinkIK",
    "PinocchioIK",
    "list_ik",
    "make_ik",
    "register_ik",
    "rotation_angle",
]
