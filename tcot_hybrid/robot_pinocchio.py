"""The Pinocchio model of a robot, built from the same MJCF as the simulation and checked against MuJoCo
(forward kinematics, mass matrix, bias forces): what the Pinocchio IK and the model-based controllers use.
Split out of :mod:`tcot_hybrid.robot` (the spec and its MuJoCo model), which re-exports these names."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from tcot_hybrid.robot import RobotIndices, RobotSpec, _compile, _err, mj_robot_indices


@dataclass(frozen=True, kw_only=True, eq=False)
class PinocchioRobot:
    """Pinocchio model of a robot, built from the same MJCF as the simulation.

    model:         pinocchio.Model; position/velocity/effort limits of the arm joints are the spec's.
    tcp_frame_id:  frame id of ``spec.ee_site``.
    joint_names:   joint names in Pinocchio q order (one coordinate each; all joints are 1-DoF).
    arm_q_idx:     Pinocchio q (= v) indices of the arm joints, in spec order.
    mj_qpos_idx:   for each Pinocchio q index, the qpos address in the robot's own MjModel;
                   identity for a serial chain (checked), so ``q_pin = qpos[mj_qpos_idx]``.
    mj_dof_idx:    the same for velocities / generalized forces.
    gripper_locked: True for the reduced arm-only model (gripper joints fixed at ``gripper_q``).
    gripper_q:     gripper joint positions the reduced model is locked at [m or rad]; empty if not locked.
    """

    spec: RobotSpec
    model: Any
    tcp_frame_id: int
    joint_names: tuple[str, ...]
    arm_q_idx: np.ndarray
    mj_qpos_idx: np.ndarray
    mj_dof_idx: np.ndarray
    gripper_locked: bool
    gripper_q: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def nq(self) -> int:
        return int(self.model.nq)


def build_pinocchio_model(
    spec: RobotSpec, *, lock_gripper: bool = False, gripper_q: np.ndarray | None = None,
    check: bool = True,
) -> PinocchioRobot:
    """Load ``spec.mjcf_path`` with ``pinocchio.buildModelFromMJCF``.

    lock_gripper: build the reduced arm-only model for IK (gripper joints fixed at ``gripper_q``,
                  default: the MJCF's qpos0 of each gripper joint); q then has ``spec.dof`` entries
                  in spec order.
    check:        compare TCP pose and mass matrix with MuJoCo at home and at one more configuration
                  and raise RobotModelError above 1e-6 (catches Pinocchio MJCF parser gaps).
    """
    import pinocchio as pin

    r = spec.name
    try:
        full = pin.buildModelFromMJCF(str(spec.mjcf_path))
    except Exception as exc:  # pin raises plain RuntimeError/ValueError for parser problems
        raise _err(r, "mjcf", f"Pinocchio cannot load {str(spec.mjcf_path)!r}: {exc}") from exc
    m = _compile(r, spec.mjcf_path)
    idx = mj_robot_indices(spec, m)

    names = tuple(full.names[1:])
    jids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]
    if any(j < 0 for j in jids) or any(full.joints[i].nq != 1 for i in range(1, full.njoints)):
        raise _err(r, "mjcf", f"Pinocchio joints {list(names)} do not map 1:1 onto MuJoCo 1-DoF joints")
    if full.nq != m.nq or full.nv != m.nv:
        raise _err(r, "mjcf", f"Pinocchio nq/nv {full.nq}/{full.nv} != MuJoCo {m.nq}/{m.nv}; the robot MJCF "
                              "must hold only the robot (no free bodies)")
    mj_qpos = np.array([m.jnt_qposadr[j] for j in jids], dtype=int)
    mj_dof = np.array([m.jnt_dofadr[j] for j in jids], dtype=int)
    # Our code assumes a plain serial chain where both orders coincide; say so loudly if not.
    if not (np.array_equal(mj_qpos, np.arange(m.nq)) and np.array_equal(mj_dof, np.arange(m.nv))):
        raise _err(r, "mjcf", f"MuJoCo qpos order {mj_qpos.tolist()} differs from Pinocchio joint order {list(names)}")

    # Armature is imported by pin >= 3.x MJCF parser; set it explicitly so M matches MuJoCo anyway.
    full.armature = np.asarray(m.dof_armature[mj_dof], dtype=float).copy()
    arm_pin = np.array([names.index(j) for j in spec.arm_joints], dtype=int)
    _apply_spec_limits(full, arm_pin, spec)
    if not full.existFrame(spec.ee_site):
        raise _err(r, "ee_site", f"Pinocchio model has no frame {spec.ee_site!r}")

    grip_pin = np.array([names.index(j) for j in spec.gripper_joints], dtype=int)
    if gripper_q is None:
        gq = np.array([m.qpos0[idx.gripper_qpos[i]] for i in range(len(grip_pin))], dtype=float)
    else:
        gq = np.asarray(gripper_q, dtype=float)
        if gq.shape != grip_pin.shape or not np.all(np.isfinite(gq)):
            raise _err(r, "gripper_q", f"needs {grip_pin.size} finite values, got {gripper_q!r}")

    if lock_gripper:
        q_ref = pin.neutral(full)
        q_ref[grip_pin] = gq
        q_ref[arm_pin] = spec.home_q
        model = pin.buildReducedModel(full, [int(i) + 1 for i in grip_pin], q_ref)
        out_names = tuple(model.names[1:])
        if out_names != spec.arm_joints:
            raise _err(r, "arm_joints", f"reduced Pinocchio model joints {list(out_names)} are not in spec "
                                        f"order {list(spec.arm_joints)}; list arm joints base to tip")
        mj_q_out, mj_v_out = mj_qpos[arm_pin], mj_dof[arm_pin]
        _apply_spec_limits(model, np.arange(spec.dof), spec)  # buildReducedModel mangles lower limits
        gq.flags.writeable = False
    else:
        model, out_names = full, names
        mj_q_out, mj_v_out = mj_qpos, mj_dof
        gq = np.zeros(0)
    arm_idx = np.array([out_names.index(j) for j in spec.arm_joints], dtype=int)
    for a in (arm_idx, mj_q_out, mj_v_out):
        a.flags.writeable = False
    robot = PinocchioRobot(
        spec=spec, model=model, tcp_frame_id=int(model.getFrameId(spec.ee_site)), joint_names=out_names,
        arm_q_idx=arm_idx, mj_qpos_idx=mj_q_out, mj_dof_idx=mj_v_out, gripper_locked=lock_gripper, gripper_q=gq,
    )
    if check:
        _check_against_mujoco(robot, m, idx)
    return robot


def _apply_spec_limits(model: Any, arm_idx: np.ndarray, spec: RobotSpec) -> None:
    """Arm joint position/velocity/effort limits of the Pinocchio model := the spec's."""
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    vel, eff = model.velocityLimit.copy(), model.effortLimit.copy()
    lower[arm_idx], upper[arm_idx] = spec.q_min, spec.q_max
    vel[arm_idx], eff[arm_idx] = spec.v_max, spec.tau_max
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper
    model.velocityLimit, model.effortLimit = vel, eff
    # pin 4 also keeps lower/upper velocity and effort limits; its MJCF parser leaves the lower ones
    # at +inf and buildReducedModel copies the upper ones into them: mirror them explicitly.
    for name, val in (("lowerVelocityLimit", -vel), ("upperVelocityLimit", vel),
                      ("lowerEffortLimit", -eff), ("upperEffortLimit", eff)):
        if hasattr(model, name):
            setattr(model, name, val.copy())


def mj_full_mass_matrix(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    """Dense joint-space mass matrix M(q) [kg m^2 | kg] incl. armature, after mj_forward / mj_crb."""
    M = np.zeros((m.nv, m.nv))
    if hasattr(d, "qM"):  # mujoco < 4: mj_fullM(m, dst, qM)
        mujoco.mj_fullM(m, M, d.qM)
    else:  # mujoco >= 4: mj_fullM(m, d, dst)
        mujoco.mj_fullM(m, d, M)
    return M


def _check_against_mujoco(robot: PinocchioRobot, m: mujoco.MjModel, idx: RobotIndices, tol: float = 1e-6) -> None:
    import pinocchio as pin

    spec, pm = robot.spec, robot.model
    pdata, d = pm.createData(), mujoco.MjData(m)
    for t in (0.0, 0.37):  # home and a point toward the limits (generic, not symmetric)
        q_arm = spec.home_q + t * (spec.q_max - spec.home_q) * np.linspace(1.0, -1.0, spec.dof)
        d.qpos[:] = m.qpos0
        d.qpos[idx.arm_qpos] = q_arm
        if robot.gripper_locked:
            d.qpos[idx.gripper_qpos] = robot.gripper_q
        mujoco.mj_forward(m, d)
        q = d.qpos[robot.mj_qpos_idx].copy()
        pin.framesForwardKinematics(pm, pdata, q)
        T = pdata.oMf[robot.tcp_frame_id]
        pos_err = np.abs(T.translation - d.site_xpos[idx.ee_site]).max()
        rot_err = np.abs(T.rotation - d.site_xmat[idx.ee_site].reshape(3, 3)).max()
        if pos_err > tol or rot_err > tol:
            raise _err(spec.name, "ee_site", f"Pinocchio and MuJoCo disagree on the TCP pose (pos {pos_err:.3g} m, "
                                             f"rot {rot_err:.3g}); keep the site directly in a body with a joint")
        if not robot.gripper_locked:
            M_mj = mj_full_mass_matrix(m, d)
            M_pin = pin.crba(pm, pdata, q)
            M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
            M_err = np.abs(M_pin - M_mj[np.ix_(robot.mj_dof_idx, robot.mj_dof_idx)]).max()
            if M_err > tol:
                raise _err(spec.name, "mjcf", f"Pinocchio and MuJoCo mass matrices differ by {M_err:.3g}; "
                                              "give every body an explicit <inertial>")
