"""Inverse kinematics: TCP pose -> arm joint configuration, three backends behind one interface.

    ik = make_ik("mink", load_robot_spec("panda"), IKConfig())
    result = ik.solve(IKTarget(pos=np.array([0.5, 0.0, 0.2]), rot=R_down), seed=q_previous)

The casadi backend also solves a whole plan at once (``CasadiIK.solve_plan``; ``IKSolver.solves_plans``).

Backends register themselves with ``@register_ik``; adding one = one new module imported below.
"""
from tcot_hybrid.ik.base import (
    CONVERGED,
    INFEASIBLE,
    MAX_ITERS,
    NON_FINITE,
    QP_INFEASIBLE,
    STATUSES,
    CasadiConfig,
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
from tcot_hybrid.ik import casadi_ik as _casadi_ik  # noqa: F401  (registers "casadi")
from tcot_hybrid.ik.casadi_ik import CasadiIK, PlanIKResult
from tcot_hybrid.ik.mink_ik import MinkIK
from tcot_hybrid.ik.pinocchio_ik import PinocchioIK

__all__ = [
    "CONVERGED",
    "INFEASIBLE",
    "MAX_ITERS",
    "NON_FINITE",
    "QP_INFEASIBLE",
    "STATUSES",
    "CasadiConfig",
    "CasadiIK",
    "IKConfig",
    "IKResult",
    "IKSolver",
    "IKStepFailed",
    "IKTarget",
    "MinkIK",
    "PinocchioIK",
    "PlanIKResult",
    "list_ik",
    "make_ik",
    "register_ik",
    "rotation_angle",
]
