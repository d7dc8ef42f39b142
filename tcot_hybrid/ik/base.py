"""IK interface shared by every backend: config, target/result types, input checks, limit box.

Every backend takes a TCP target pose in the world frame and a seed configuration (the previous
solution) and returns an :class:`IKResult` with a status; it never returns None and never raises for
ordinary non-convergence. What every backend guarantees (checked in ``tests/test_ik.py``):

- the returned ``q`` is finite;
- it lies inside ``[q_min + limit_margin_rad, q_max - limit_margin_rad]``, or, when the seed was
  outside that box, no farther out than the seed (the seed is walked inward at <= v_max per step);
- every iteration moves each joint by at most ``v_max * velocity_scale * step_dt_s`` (the iterative
  backends mink and pinocchio; casadi solves for the configuration directly, always inside the box,
  and Ruckig bounds the speed of the motion toward it).

Backends with ``solves_plans = True`` (casadi) also solve a whole plan at once: ``solve_plan``.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, NamedTuple

import numpy as np

from tcot_hybrid.config import (
    require_bool,
    require_choice,
    require_finite,
    require_in_range,
    require_int,
    require_nonnegative,
    require_positive,
)
from tcot_hybrid.errors import ConfigError, IKError, unknown_name

if TYPE_CHECKING:
    from tcot_hybrid.robot import RobotSpec

# Statuses every backend reports (IKResult.status).
CONVERGED = "converged"
MAX_ITERS = "max_iters"
QP_INFEASIBLE = "qp_infeasible"
NON_FINITE = "non_finite"
INFEASIBLE = "infeasible"  # whole-plan solve: some waypoint cannot be met within the tolerances
STATUSES: tuple[str, ...] = (CONVERGED, MAX_ITERS, QP_INFEASIBLE, NON_FINITE, INFEASIBLE)

POSTURE_TARGETS: tuple[str, ...] = ("home", "seed")

# A target rotation may deviate this much from orthonormal (max |R^T R - I| entry) before it is refused.
ROT_ORTHO_TOL = 1e-6


def _qp_solvers() -> list[str]:
    import qpsolvers

    return list(qpsolvers.available_solvers)


WARM_STARTS: tuple[str, ...] = ("current", "pinocchio", "mink")
ORIENTATION_MODES: tuple[str, ...] = ("hard", "soft")


@dataclass(frozen=True, kw_only=True)
class CasadiConfig:
    """Whole-plan IK (backend ``casadi``): every waypoint of a plan solved jointly with IPOPT.

    Minimise  travel_weight * sum_i |q_i - q_{i-1}|^2 + posture_weight * sum_i |q_i - q_posture|^2
    subject to: TCP position of waypoint i = its target (hard); TCP rotation within ``rot_tol_rad``
    of its target (``orientation = "hard"``) or ``orientation_weight * angle^2`` added to the cost
    (``"soft"``); joints inside the limits minus ``limit_margin_rad`` (hard, the same box as the other
    backends); TCP and every moving joint origin at least ``min_height_m`` above the support surface.
    q_0 is the configuration the plan starts from; q_posture follows ``posture_target``.

    travel_weight:      [1/rad^2] weight of joint travel between consecutive waypoints. Up: shorter,
                        more consistent motions (one arm branch for the whole plan); 0: posture only.
    posture_weight:     [1/rad^2] weight of the pull toward the posture target. Up: elbow stays near
                        home; down: less travel. Keep it well below travel_weight.
    orientation:        "hard" (rotation error <= rot_tol_rad is a constraint) or "soft" (a cost with
                        orientation_weight; a waypoint then counts as met on its position alone).
    orientation_weight: [1/rad^2] weight of the squared rotation error with orientation = "soft". Up:
                        closer to the target rotation; down: more slack for reach.
    min_height_m:       [m] the TCP and every moving joint origin stay at least this far above the
                        support surface (hard). Up: more clearance, low grasps become infeasible; down:
                        lets the hand reach lower.
    support_z_m:        [m] height of the support surface (table top) in the IK frame; ``solve_plan``
                        may override it per plan.
    max_iters:          IPOPT iterations per solve (a plan takes one solve, two when the first fails).
                        Up: fewer plans given up; down: bounded solve time.
    tol:                [-] IPOPT's convergence tolerance (scaled KKT error). Down: more accurate optimum
                        of the cost (the targets are constraints either way), more iterations.
    warm_start:         first initial guess: "current" (every waypoint at the start configuration),
                        "pinocchio" or "mink" (that backend's per-waypoint solutions, chained). When the
                        solve from it fails, the other kind is tried once ("current" <-> the chain): they
                        reach different arm branches and each solves plans the other does not.
    max_waypoints:      largest plan accepted (bounds the NLP size and memory).
    max_time_s:         [s] wall-clock cap per IPOPT solve; None = none (runs stay reproducible: only
                        max_iters bounds the work).
    """

    travel_weight: float = 1.0
    posture_weight: float = 0.01
    orientation: str = "hard"
    orientation_weight: float = 100.0
    min_height_m: float = 0.0
    support_z_m: float = 0.0
    max_iters: int = 200
    tol: float = 1e-8
    warm_start: str = "pinocchio"
    max_waypoints: int = 256
    max_time_s: float | None = None

    def __post_init__(self) -> None:
        p = "ik_params.casadi."
        for name in ("travel_weight", "posture_weight"):
            require_nonnegative(p + name, getattr(self, name))
        if self.travel_weight + self.posture_weight <= 0.0:
            raise ConfigError(f"{p}travel_weight + {p}posture_weight must be > 0 (got {self.travel_weight} and "
                              f"{self.posture_weight}): the cost needs at least one of them")
        require_choice(p + "orientation", self.orientation, ORIENTATION_MODES)
        require_positive(p + "orientation_weight", self.orientation_weight)
        for name in ("min_height_m", "support_z_m"):
            require_finite(p + name, getattr(self, name))
            if abs(getattr(self, name)) > 10.0:
                raise ConfigError(f"{p}{name} must be within +-10 m, got {getattr(self, name)!r}")
        require_int(p + "max_iters", self.max_iters, minimum=1)
        require_positive(p + "tol", self.tol)
        require_choice(p + "warm_start", self.warm_start, WARM_STARTS)
        require_int(p + "max_waypoints", self.max_waypoints, minimum=1)
        if self.max_time_s is not None:
            require_positive(p + "max_time_s (or null: no cap)", self.max_time_s)


@dataclass(frozen=True, kw_only=True)
class IKConfig:
    """Settings shared by the IK backends.

    max_iters:         iterations per solve. Up: more far targets converge, worst-case time grows;
                       down: bounded latency (a nearby seed needs < 10).
    pos_tol_m:         converged when the TCP position error is <= this [m]. Down: more accurate, more
                       iterations.
    rot_tol_rad:       ... and the TCP rotation error is <= this [rad].
    damping:           Levenberg-Marquardt damping added to the normal equations [-] (> 0). Up: steadier
                       near singularities and with far targets (1e-3 let mink cycle on 1-3% of panda
                       waypoint walks, 1e-2 converged on all); down: fewer iterations per solve.
    posture_cost:      weight of the pull toward the posture target (``posture_target``) [1/rad, residual
                       weight, enters squared next to ``damping``]. Used only while the TCP is farther than
                       10x the tolerances from the target, so it shapes the approach but cannot bias the
                       result (a permanent pull of 1e-2 left up to 8 mm error 1.2 rad from home). Up:
                       keeps the panda's redundant elbow nearer the posture; down: lets far targets
                       converge (3e-2 halved convergence from home to random poses; 1e-2 and 3e-3 measured
                       the same).
    posture_target:    "home" (spec.home_q: the same target gives the same elbow wherever the walk came
                       from) or "seed" (stay close to the previous solution).
    orientation_cost:  weight of rotation error [1/rad] against position error [1/m]. Up: orientation is
                       met first; 0 ignores orientation (the rotation error is still reported).
    step_dt_s:         integration step of the differential IK [s]; each iteration moves a joint by at
                       most v_max * velocity_scale * step_dt_s. Up: fewer iterations for far targets;
                       down: smaller, more local steps (0.02 doubled the solve time for no gain).
    solver:            QP solver used by the mink backend (one of qpsolvers' installed solvers).
                       daqp is exact and ~5x faster than osqp on these small dense QPs.
    velocity_scale:    fraction (0, 1] of the robot's v_max allowed per IK step. Down: more cautious
                       steps (with the same step_dt_s).
    limit_margin_rad:  keep this far inside the joint limits [rad]. Up: more clearance for tracking
                       overshoot; down: more reachable workspace.
    collision_avoidance: mink only; keep the hand/finger collision geoms (the subtree of the last arm
                       joint's body) above the table (z = 0 plane). The limit is linearised per step, so
                       the clearance is approached within ~2 mm. Targets that need the fingers lower
                       than that do not converge. Off by default: grasps at z ~ 0.02 need the fingertips
                       near the table.
    table_clearance_m: hand/finger distance to keep from the table with collision_avoidance [m].
    casadi:            settings of the whole-plan backend (:class:`CasadiConfig`); the fields above that
                       it uses: pos_tol_m, rot_tol_rad, posture_target, limit_margin_rad.
    """

    max_iters: int = 200
    pos_tol_m: float = 1e-3
    rot_tol_rad: float = 1e-2
    damping: float = 1e-2
    posture_cost: float = 1e-2
    posture_target: str = "home"
    orientation_cost: float = 1.0
    step_dt_s: float = 0.05
    solver: str = "daqp"
    velocity_scale: float = 1.0
    limit_margin_rad: float = 0.02
    collision_avoidance: bool = False
    table_clearance_m: float = 0.005
    casadi: CasadiConfig = field(default_factory=CasadiConfig)

    def __post_init__(self) -> None:
        require_int("max_iters", self.max_iters, minimum=1)
        for name in ("pos_tol_m", "rot_tol_rad", "damping", "step_dt_s"):
            require_positive(name, getattr(self, name))
        for name in ("posture_cost", "orientation_cost", "limit_margin_rad", "table_clearance_m"):
            require_nonnegative(name, getattr(self, name))
        require_in_range("velocity_scale", self.velocity_scale, 0.0, 1.0, low_closed=False)
        require_choice("posture_target", self.posture_target, POSTURE_TARGETS)
        require_choice("solver", self.solver, _qp_solvers())
        require_bool("collision_avoidance", self.collision_avoidance)
        if not isinstance(self.casadi, CasadiConfig):
            raise ConfigError(f"casadi must be a CasadiConfig (ik_params.casadi.*), got {self.casadi!r}")


class IKTarget(NamedTuple):
    """TCP target pose in the world frame."""

    pos: np.ndarray  # (3,) [m] world
    rot: np.ndarray  # (3, 3) rotation matrix, TCP axes in world coordinates


class IKResult(NamedTuple):
    """Outcome of one solve. ``q`` is always finite and within the limit box (see module docstring).

    status: one of STATUSES. ``converged`` means both tolerances were met at ``q``.
    iters: iterations taken (QP/CLIK steps plus inward recovery steps from a seed outside the limits).
    pos_err: TCP position error at ``q`` [m]; rot_err: rotation error angle at ``q`` [rad].
    limit_active: a joint position limit (with margin) shaped the solution during this solve.
    """

    q: np.ndarray
    converged: bool
    status: str
    iters: int
    pos_err: float
    rot_err: float
    limit_active: bool = False


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices [rad], accurate near 0 and near pi."""
    M = R_a.T @ R_b
    s = 0.5 * np.sqrt((M[2, 1] - M[1, 2]) ** 2 + (M[0, 2] - M[2, 0]) ** 2 + (M[1, 0] - M[0, 1]) ** 2)
    c = 0.5 * (np.trace(M) - 1.0)
    return float(np.arctan2(s, c))


def joint_bounds(spec: RobotSpec, cfg: IKConfig) -> tuple[np.ndarray, np.ndarray]:
    """The joint range IK may use: the robot's limits minus ``cfg.limit_margin_rad`` [rad]. ConfigError when the
    margin leaves a joint no range or puts the home pose outside (checked before a run builds anything)."""
    q_min = np.asarray(spec.q_min, dtype=float)
    q_max = np.asarray(spec.q_max, dtype=float)
    lower, upper = q_min + cfg.limit_margin_rad, q_max - cfg.limit_margin_rad
    if np.any(lower >= upper):
        bad = [spec.arm_joints[i] for i in np.flatnonzero(lower >= upper)]
        raise ConfigError(
            f"limit_margin_rad = {cfg.limit_margin_rad} leaves no range for joints {bad} of robot "
            f"{spec.name!r}; use a margin below half the smallest joint range "
            f"({0.5 * float(np.min(q_max - q_min)):.4g} rad)"
        )
    home = np.asarray(spec.home_q, dtype=float)
    if np.any(home < lower) or np.any(home > upper):
        raise ConfigError(
            f"home_q {home.tolist()} of robot {spec.name!r} is not inside its joint limits minus "
            f"limit_margin_rad = {cfg.limit_margin_rad}; lower the margin"
        )
    return lower, upper


class IKStepFailed(Exception):
    """Raised by a backend's :meth:`IKSolver._step` when no step can be taken; ``status`` (one of STATUSES)
    ends the solve with that status."""

    def __init__(self, status: str) -> None:
        super().__init__(status)
        self.status = status


class IKSolver(ABC):
    """One IK backend. :meth:`solve` validates the inputs; the iteration loop (:meth:`_solve`) is shared.

    A backend implements :meth:`_tcp_at` (forward kinematics) and :meth:`_step` (one differential-IK
    step), and may override :meth:`_begin` (per-solve setup, e.g. setting task targets). The loop checks
    convergence, walks a seed outside the limit box inward, refuses non-finite steps, projects every step
    into the velocity/position box and counts iterations, identically for every backend.

    Attributes available to subclasses (all per arm joint, in spec order):
    ``lower``/``upper``: limit box with margin [rad]; ``max_step``: largest |dq| per iteration [rad].
    """

    name: ClassVar[str]
    supports_collision_avoidance: ClassVar[bool] = False
    solves_plans: ClassVar[bool] = False  # has solve_plan(): all waypoints of a plan at once

    def __init__(self, spec: RobotSpec, config: IKConfig | None = None) -> None:
        self.spec = spec
        self.config = IKConfig() if config is None else config
        if not isinstance(self.config, IKConfig):
            raise ConfigError(f"config must be an IKConfig, got {type(self.config).__name__}")
        check_ik_options(type(self), self.config)
        cfg = self.config
        self.dof = int(spec.dof)
        self.lower, self.upper = joint_bounds(spec, cfg)
        self.max_step = np.asarray(spec.v_max, dtype=float) * cfg.velocity_scale * cfg.step_dt_s
        self.home_q = np.asarray(spec.home_q, dtype=float)

    # -- public API ---------------------------------------------------------------------------------

    def solve(self, target: IKTarget, seed: np.ndarray) -> IKResult:
        """Solve for a TCP pose ``target`` starting from ``seed`` (the previous solution) [rad].

        Raises IKError only for unusable input (non-finite values, wrong shapes, a non-rotation
        ``target.rot``); everything else is reported through ``IKResult.status``.
        """
        pos, rot = self._check_target(target)
        q = self._check_seed(seed)
        return self._solve(pos, rot, q)

    def tcp_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: TCP position [m] (3,) and rotation (3, 3) at arm configuration ``q`` [rad], in the
        world frame of :meth:`_tcp_at` (the robot's base frame, where targets are solved). Raises IKError for a
        ``q`` of the wrong shape or not finite."""
        pos, rot = self._tcp_at(self._check_seed(q, "q"))
        return pos.copy(), rot.copy()

    def _solve(self, pos: np.ndarray, rot: np.ndarray, seed: np.ndarray) -> IKResult:
        """The iteration loop on validated inputs (``seed`` is a private float copy)."""
        cfg = self.config
        self._begin(pos, rot, seed)
        q = seed
        status, iters, limit_active = MAX_ITERS, 0, False
        for it in range(cfg.max_iters + 1):
            pos_err, rot_err = self.errors(*self._tcp_at(q), pos, rot)
            if self.is_converged(pos_err, rot_err):
                status = CONVERGED
                break
            if it == cfg.max_iters:
                break
            if self.outside_box(q):
                # Walk a seed outside the limits inward at <= v_max before solving (mink's ConfigurationLimit,
                # for one, is infeasible when q is farther outside than one velocity step).
                q = self.recovery_step(q)
                limit_active = True
            else:
                try:
                    dq, at_limit = self._step(q, pos, rot, pos_err, rot_err)
                except IKStepFailed as exc:
                    status = exc.status
                    break
                if not np.all(np.isfinite(dq)):
                    status = NON_FINITE
                    break
                # Solver tolerance can leave a step a hair outside the velocity/position box: project.
                lo, hi = self.step_bounds(q)
                dq = np.clip(dq, lo, hi)
                limit_active |= at_limit
                q = q + dq
            iters += 1
        return IKResult(q.copy(), status == CONVERGED, status, iters, pos_err, rot_err, limit_active)

    def _begin(self, pos: np.ndarray, rot: np.ndarray, seed: np.ndarray) -> None:
        """Per-solve setup before the first iteration (default: nothing)."""

    @abstractmethod
    def _tcp_at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """TCP position [m] (3,) and rotation (3, 3) in the world frame at arm configuration ``q`` [rad]."""

    @abstractmethod
    def _step(self, q: np.ndarray, pos: np.ndarray, rot: np.ndarray, pos_err: float,
              rot_err: float) -> tuple[np.ndarray, bool]:
        """One step from ``q`` (inside the box, :meth:`_tcp_at` just evaluated there) toward the target
        (``pos``, ``rot``): (dq [rad] in spec joint order, whether a position limit shaped it). Raise
        :class:`IKStepFailed` when no step can be taken (e.g. QP infeasible)."""

    # -- helpers for backends -----------------------------------------------------------------------

    def posture_for(self, seed: np.ndarray) -> np.ndarray:
        """Posture target for this solve: home or the seed (clamped into the box) [rad]."""
        if self.config.posture_target == "home":
            return self.home_q
        return np.clip(seed, self.lower, self.upper)

    def posture_active(self, pos_err: float, rot_err: float) -> bool:
        """The posture pull is used only farther than 10x the tolerances from the target: it shapes the
        approach (elbow), while the last steps are solved without it, so it cannot bias the result
        (a posture far from the solution otherwise leaves a residual TCP error)."""
        far_rot = rot_err > 10.0 * self.config.rot_tol_rad and self.config.orientation_cost > 0.0
        return pos_err > 10.0 * self.config.pos_tol_m or far_rot

    def outside_box(self, q: np.ndarray) -> bool:
        return bool(np.any(q < self.lower) or np.any(q > self.upper))

    def recovery_step(self, q: np.ndarray) -> np.ndarray:
        """One inward step for a configuration outside the box: joints outside move toward the box by
        at most ``max_step``; joints inside stay. Never moves a joint outward."""
        target = np.clip(q, self.lower, self.upper)
        return q + np.clip(target - q, -self.max_step, self.max_step)

    def step_bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-joint bounds on dq for one step from q inside the box: position box and velocity."""
        lo = np.maximum(self.lower - q, -self.max_step)
        hi = np.minimum(self.upper - q, self.max_step)
        return np.minimum(lo, 0.0), np.maximum(hi, 0.0)

    def errors(self, p: np.ndarray, R: np.ndarray, pos: np.ndarray, rot: np.ndarray) -> tuple[float, float]:
        """(position error [m], rotation error [rad]) of TCP pose (p, R) against the target."""
        # hypot does not overflow for absurd (1e300 m) but finite targets, where norm() returns inf.
        return math.hypot(*(p - pos)), rotation_angle(R, rot)

    def is_converged(self, pos_err: float, rot_err: float) -> bool:
        # orientation_cost == 0 means orientation is not part of the task, so it cannot block convergence.
        rot_ok = rot_err <= self.config.rot_tol_rad or self.config.orientation_cost == 0.0
        return pos_err <= self.config.pos_tol_m and rot_ok

    # -- input checks -------------------------------------------------------------------------------

    def _check_target(self, target: IKTarget) -> tuple[np.ndarray, np.ndarray]:
        try:
            pos = np.array(target.pos, dtype=float)
            rot = np.array(target.rot, dtype=float)
        except (AttributeError, TypeError, ValueError) as exc:
            raise IKError(f"target must be an IKTarget(pos (3,) [m], rot (3, 3)), got {target!r}") from exc
        if pos.shape != (3,):
            raise IKError(f"target.pos must have shape (3,), got shape {pos.shape}: {pos!r}")
        if rot.shape != (3, 3):
            raise IKError(f"target.rot must have shape (3, 3), got shape {rot.shape}: {rot!r}")
        if not np.all(np.isfinite(pos)):
            raise IKError(f"target.pos must be finite, got {pos.tolist()}")
        if not np.all(np.isfinite(rot)):
            raise IKError(f"target.rot must be finite, got {rot.tolist()}")
        ortho = float(np.max(np.abs(rot.T @ rot - np.eye(3))))
        if not ortho <= ROT_ORTHO_TOL or np.linalg.det(rot) <= 0.0:
            raise IKError(
                f"target.rot must be a rotation matrix (|R^T R - I| <= {ROT_ORTHO_TOL}, det = +1), "
                f"got {rot.tolist()} (orthonormality error {ortho:.3g}, det {np.linalg.det(rot):.6g})"
            )
        return pos, rot

    def _check_seed(self, seed: np.ndarray, name: str = "seed") -> np.ndarray:
        try:
            q = np.array(seed, dtype=float)
        except (TypeError, ValueError) as exc:
            raise IKError(f"{name} must be a numeric array of shape ({self.dof},), got {seed!r}") from exc
        if q.shape != (self.dof,):
            raise IKError(f"{name} must have shape ({self.dof},) for robot {self.spec.name!r}, got shape {q.shape}")
        if not np.all(np.isfinite(q)):
            raise IKError(f"{name} must be finite, got {q.tolist()}")
        return q


# -- registry -------------------------------------------------------------------------------------

_REGISTRY: dict[str, type[IKSolver]] = {}


def register_ik(cls: type[IKSolver]) -> type[IKSolver]:
    """Class decorator: make a backend available to :func:`make_ik` under ``cls.name``."""
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise ConfigError(f"IK backend name {cls.name!r} is registered twice")
    _REGISTRY[cls.name] = cls
    return cls


def list_ik() -> list[str]:
    """Names of the registered IK backends."""
    return sorted(_REGISTRY)


def ik_backend(name: str) -> type[IKSolver]:
    """The registered IK backend class ``name``; an unknown name is refused listing the valid ones."""
    cls = _REGISTRY.get(name) if isinstance(name, str) else None
    if cls is None:
        raise ConfigError(unknown_name("ik backend", name, _REGISTRY))  # names the run-config field `ik`
    return cls


def check_ik_options(backend: type[IKSolver], config: IKConfig) -> None:
    """Refuse options ``backend`` does not implement (the run checks this before building anything)."""
    if config.collision_avoidance and not backend.supports_collision_avoidance:
        able = sorted(n for n, c in _REGISTRY.items() if c.supports_collision_avoidance)
        raise ConfigError(f"ik_params.collision_avoidance = True is only implemented by the IK backends {able}, "
                          f"not by {backend.name!r}; choose one of those or set ik_params.collision_avoidance = false")


def make_ik(name: str, spec: RobotSpec, config: IKConfig | None = None) -> IKSolver:
    """Build the IK backend ``name`` ("mink" | "pinocchio" | "casadi") for robot ``spec``."""
    return ik_backend(name)(spec, config)

