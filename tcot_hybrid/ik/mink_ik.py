"""mink backend: differential IK as a QP per step on an arm-only MuJoCo model.

Each iteration solves ``mink.solve_ik`` (TCP ``FrameTask`` + ``PostureTask`` under
``ConfigurationLimit`` with the margin, ``VelocityLimit`` at v_max * velocity_scale and, optionally, a
``CollisionAvoidanceLimit`` against the table plane) and integrates the velocity over ``step_dt_s``
(q += v dt, what ``Configuration.integrate_inplace`` does for hinge joints; done by hand so the step
can first be projected onto the limit box, which only removes QP solver tolerance).

A seed outside the limit box makes ``ConfigurationLimit`` infeasible once it is more than one velocity
step out, so such seeds are first walked inward at <= v_max per step (no QP) and solved from there.
"""
from __future__ import annotations

import warnings

import mink
import mujoco
import numpy as np
import qpsolvers
from qpsolvers.warnings import SparseConversionWarning

from tcot_hybrid.errors import RobotModelError
from tcot_hybrid.ik.base import (
    NON_FINITE,
    QP_INFEASIBLE,
    IKConfig,
    IKSolver,
    IKStepFailed,
    register_ik,
)

IK_TABLE_GEOM = "ik_table"

# OSQP's default tolerances (1e-3) give visibly different steps from daqp's exact ones; tighten them.
# (Steps are projected onto the limit box afterwards either way.)
_SOLVER_OPTIONS: dict[str, dict] = {
    "osqp": {"eps_abs": 1e-6, "eps_rel": 1e-6, "polishing": False, "verbose": False, "raise_error": False},
}


def build_ik_model(spec, *, table: bool) -> mujoco.MjModel:
    """Arm-only kinematic MuJoCo model of ``spec``: every joint not in ``spec.arm_joints`` is removed
    (its body welds at the joint's reference pose), with actuators, tendons, equalities, sensors and
    keyframes that could refer to them; arm joint ranges are set to the spec's [q_min, q_max].
    With ``table``, a plane geom ``ik_table`` is added at z = 0 that collides with everything."""
    from tcot_hybrid.robot import robot_mjspec

    ms = robot_mjspec(spec)
    for group in (ms.actuators, ms.tendons, ms.equalities, ms.sensors, ms.keys):
        for element in list(group):
            ms.delete(element)
    arm = set(spec.arm_joints)
    for joint in list(ms.joints):
        if joint.name not in arm:
            ms.delete(joint)
    for name, lo, hi in zip(spec.arm_joints, spec.q_min, spec.q_max):
        joint = ms.joint(name)
        if joint is None:
            raise RobotModelError(f"arm joint {name!r} of robot {spec.name!r} is not in its MJCF")
        joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        joint.range = [float(lo), float(hi)]
    if table:
        ms.worldbody.add_geom(
            name=IK_TABLE_GEOM,
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[0.0, 0.0, 0.01],
            contype=0x7FFFFFFF,
            conaffinity=0x7FFFFFFF,
        )
    model = ms.compile()
    if model.nq != len(spec.arm_joints) or model.nv != len(spec.arm_joints):
        raise RobotModelError(
            f"arm-only IK model of robot {spec.name!r} has nq={model.nq}, nv={model.nv}; expected "
            f"{len(spec.arm_joints)} one-DoF arm joints {list(spec.arm_joints)}"
        )
    return model


class _DisplacementCollisionLimit(mink.Limit):
    """``mink.CollisionAvoidanceLimit`` with its bound in displacement units.

    mink 1.3's QP variable is the step dq, and its other limits bound dq, but the collision bound is
    ``gain * (d - d_min) / dt``, a velocity: with step_dt_s = 0.05 it lets a geom approach 20x the
    remaining gap per step (measured: fingers 19 mm into the table). Evaluating it with dt = 1 turns
    the bound into ``gain * (d - d_min)``, a distance, as intended."""

    def __init__(self, inner: mink.CollisionAvoidanceLimit) -> None:
        self.inner = inner

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # see class docstring
        return self.inner.compute_qp_inequalities(configuration, 1.0)


@register_ik
class MinkIK(IKSolver):
    """Differential IK with mink (QP per step, solver ``config.solver``)."""

    name = "mink"
    supports_collision_avoidance = True

    def __init__(self, spec, config: IKConfig | None = None) -> None:
        super().__init__(spec, config)
        cfg = self.config
        self.model = build_ik_model(spec, table=cfg.collision_avoidance)
        model = self.model
        # qpos index of each arm joint in spec order (tree order can differ from spec order).
        self._qidx = np.array([model.jnt_qposadr[model.joint(n).id] for n in spec.arm_joints])
        if sorted(self._qidx.tolist()) != list(range(self.dof)):
            raise RobotModelError(f"arm joints {list(spec.arm_joints)} do not map one-to-one onto qpos")
        self._site_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, spec.ee_site)
        if self._site_id < 0:
            raise RobotModelError(f"ee_site {spec.ee_site!r} of robot {spec.name!r} is not in its MJCF")

        self.configuration = mink.Configuration(model)
        self.frame_task = mink.FrameTask(
            frame_name=spec.ee_site,
            frame_type="site",
            position_cost=1.0,
            orientation_cost=cfg.orientation_cost,
            gain=1.0,
        )
        self.posture_task: mink.PostureTask | None = None
        self._tasks_near: list[mink.Task] = [self.frame_task]  # close to the target: no posture bias
        self._tasks_far = self._tasks_near
        if cfg.posture_cost > 0.0:
            self.posture_task = mink.PostureTask(model, cost=cfg.posture_cost)
            self._tasks_far = [self.frame_task, self.posture_task]

        v_limit = np.asarray(spec.v_max, dtype=float) * cfg.velocity_scale
        self.limits: list[mink.Limit] = [
            mink.ConfigurationLimit(model, min_distance_from_limits=cfg.limit_margin_rad),
            mink.VelocityLimit(model, {n: float(v) for n, v in zip(spec.arm_joints, v_limit)}),
        ]
        self._config_gain = self.limits[0].gain
        if cfg.collision_avoidance:
            hand = self.hand_geoms()
            # Detect early enough that one maximal step cannot skip past the clearance.
            reach = float(np.sum(self.max_step)) * 1.0  # [m] crude bound: |dp| <= sum|dq_i| * 1 m lever
            self.collision_limit = mink.CollisionAvoidanceLimit(
                model,
                [(hand, [IK_TABLE_GEOM])],
                minimum_distance_from_collisions=cfg.table_clearance_m,
                collision_detection_distance=cfg.table_clearance_m + reach,
            )
            self.limits.append(_DisplacementCollisionLimit(self.collision_limit))
        self._solver_options = _SOLVER_OPTIONS.get(cfg.solver, {})

    def hand_geoms(self) -> list[int]:
        """Collision geoms in the subtree of the last arm joint's body (wrist, hand, fingers)."""
        model = self.model
        wrist_body = int(model.jnt_bodyid[model.joint(self.spec.arm_joints[-1]).id])
        geoms = [
            g
            for g in mink.get_subtree_geom_ids(model, wrist_body)
            if model.geom_contype[g] or model.geom_conaffinity[g]
        ]
        if not geoms:
            raise RobotModelError(
                f"collision_avoidance needs collision geoms (contype/conaffinity != 0) on the hand of "
                f"robot {self.spec.name!r}; found none below body {model.body(wrist_body).name!r}"
            )
        return geoms

    def _to_model(self, q: np.ndarray) -> np.ndarray:
        q_model = np.empty(self.dof)
        q_model[self._qidx] = q
        return q_model

    def _tcp(self) -> tuple[np.ndarray, np.ndarray]:
        data = self.configuration.data
        return data.site_xpos[self._site_id].copy(), data.site_xmat[self._site_id].reshape(3, 3).copy()

    def _begin(self, pos: np.ndarray, rot: np.ndarray, seed: np.ndarray) -> None:
        self.frame_task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3.from_matrix(rot), pos))
        if self.posture_task is not None:
            self.posture_task.set_target(self._to_model(self.posture_for(seed)))

    def _tcp_at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.configuration.update(self._to_model(q))
        return self._tcp()

    def _step(self, q: np.ndarray, pos: np.ndarray, rot: np.ndarray, pos_err: float,
              rot_err: float) -> tuple[np.ndarray, bool]:
        cfg = self.config
        dt = cfg.step_dt_s
        try:
            # Absurd (1e300 m) targets overflow inside mink; the result is checked for finiteness.
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                # qpsolvers warns on every dense->sparse conversion for osqp; nothing to act on.
                warnings.simplefilter("ignore", SparseConversionWarning)
                v = mink.solve_ik(
                    self.configuration,
                    self._tasks_far if self.posture_active(pos_err, rot_err) else self._tasks_near,
                    dt,
                    cfg.solver,
                    damping=cfg.damping,
                    limits=self.limits,
                    **self._solver_options,
                )
        except (mink.NoSolutionFound, qpsolvers.QPError):
            raise IKStepFailed(QP_INFEASIBLE) from None
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            # Overflowing error terms (absurdly far targets) reach the solver as inf/NaN.
            raise IKStepFailed(NON_FINITE) from None
        dq = v[self._qidx] * dt
        if not np.all(np.isfinite(dq)):
            raise IKStepFailed(NON_FINITE)
        dq = np.clip(dq, *self.step_bounds(q))
        # ConfigurationLimit lets a joint cover at most `gain` of its distance to the limit.
        gain = self._config_gain
        at_limit = (dq >= gain * (self.upper - q) - 1e-9) | (dq <= gain * (self.lower - q) + 1e-9)
        return dq, bool(np.any(at_limit))
