"""casadi backend: every waypoint of a plan solved jointly with IPOPT (whole-plan IK).

The per-waypoint backends (mink, pinocchio) solve one waypoint at a time, each seeded from the last:
a plan can walk the arm into a joint-limit corner that a later waypoint cannot leave. This backend
sees the whole plan. For waypoints i = 1..N with TCP targets (p_i, R_i), starting from q_0:

    minimise   travel_weight * sum_i |q_i - q_{i-1}|^2 + posture_weight * sum_i |q_i - q_posture|^2
    subject to fk_pos(q_i) = p_i, fk_rot(q_i) = R_i               (orientation = "hard"; "soft": a cost)
               lower <= q_i <= upper                              (limits minus limit_margin_rad)
               z of the TCP and of every moving joint origin >= support_z + min_height_m

Forward kinematics is a casadi expression generated from the reduced arm-only Pinocchio model that
the pinocchio backend loads (``build_pinocchio_model``), joint by joint from its joint placements,
joint axes and the TCP frame placement, so any robot that loads there works here. (The ``pin`` wheel
on PyPI ships without ``pinocchio.casadi``: stack-of-tasks/pinocchio#2759.) IPOPT gets exact
derivatives from the expression graph.

IPOPT's return status is always checked, and so is the answer: the targets, the limits and the height
bound are re-evaluated numerically on the returned configurations. When the first solve (from the
configured warm start) fails either check, the same problem is solved from the other kind of warm start
(the per-waypoint chain and "every waypoint at the start configuration" lead to different arm branches),
and then a last solve minimises the tolerance-normalised pose errors under the same limits and height
bound: if it meets every target, its configurations are used; otherwise the plan is reported
infeasible, naming the waypoints that cannot be met and how far off the closest configuration stays.
Returned configurations are always finite and inside the limit box.
"""
from __future__ import annotations

import math
import time
from collections import OrderedDict
from typing import NamedTuple

import casadi as ca
import numpy as np

from tcot_hybrid.errors import IKError, RobotModelError
from tcot_hybrid.ik.base import (
    CONVERGED,
    INFEASIBLE,
    MAX_ITERS,
    NON_FINITE,
    ROT_ORTHO_TOL,
    IKConfig,
    IKResult,
    IKSolver,
    make_ik,
    register_ik,
    rotation_angle,
)

# IPOPT statuses that claim a solution (the answer is still checked numerically).
_IPOPT_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
_IPOPT_ITER_LIMIT = ("Maximum_Iterations_Exceeded", "Maximum_CpuTime_Exceeded", "Maximum_WallTime_Exceeded")
# Numerical slack of the re-check: IPOPT meets constraints to ~1e-9; this only absorbs round-off.
_CHECK_SLACK = 1e-6
# A joint this close to the limit box counts as limiting the solution [rad].
_LIMIT_ACTIVE_RAD = 1e-4
# A target farther than this multiple of the arm's reach from the base is refused as out of range.
_RANGE_FACTOR = 10.0
# At most this many (plan length, formulation) solvers are kept.
_SOLVER_CACHE = 16

_REVOLUTE_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}
_PRISMATIC_AXES = {"JointModelPX": (1.0, 0.0, 0.0), "JointModelPY": (0.0, 1.0, 0.0), "JointModelPZ": (0.0, 0.0, 1.0)}


# -- forward kinematics as a casadi expression --------------------------------------------------------


def _axis_rotation(axis: np.ndarray, angle) -> ca.SX:
    """Rotation by ``angle`` about the unit ``axis`` (Rodrigues; exact zeros stay zeros)."""
    x, y, z = (float(a) for a in axis)
    c, s = ca.cos(angle), ca.sin(angle)
    K = ca.SX(np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]))
    aaT = ca.SX(np.outer(axis, axis))
    return c * ca.SX.eye(3) + s * K + (1.0 - c) * aaT


class CasadiChain:
    """The kinematic chain of a :class:`~tcot_hybrid.robot.PinocchioRobot`'s reduced (arm-only) model as
    casadi functions of the arm joints in spec order.

    fk:      q (dof,) -> (TCP position (3,) [m], TCP rotation (3, 3)), both in the model's base frame.
    heights: q -> z of the TCP and of every joint origin that moves with q [m] (the height bound).
    reach_m: an upper bound on the TCP's distance from the first joint's origin [m].
    """

    def __init__(self, robot) -> None:
        model, spec = robot.model, robot.spec
        dof = int(spec.dof)
        if model.nq != dof or model.nv != dof:
            raise RobotModelError(f"casadi FK needs the reduced arm-only model of robot {spec.name!r} with "
                                  f"nq = nv = {dof}; got nq={model.nq}, nv={model.nv}")
        q = ca.SX.sym("q", dof)
        # Pinocchio q index k holds spec joint i where arm_q_idx[i] = k.
        q_pin = [None] * dof
        for i, k in enumerate(np.asarray(robot.arm_q_idx, dtype=int)):
            q_pin[int(k)] = q[i]
        R_of: list[ca.SX] = [ca.SX.eye(3)]
        p_of: list[ca.SX] = [ca.SX.zeros(3, 1)]
        origins: list[ca.SX] = []
        reach_to = [0.0]  # distance bound from joint 1's origin to joint j's origin
        for j in range(1, model.njoints):
            jm = model.joints[j]
            kind = jm.shortname()
            if jm.nq != 1 or jm.nv != 1:
                raise RobotModelError(f"casadi FK supports 1-DoF joints only; joint {model.names[j]!r} of robot "
                                      f"{spec.name!r} is a {kind} with nq={jm.nq}")
            qj = q_pin[jm.idx_q]
            parent = int(model.parents[j])
            M = model.jointPlacements[j]
            R_par, p_par = R_of[parent], p_of[parent]
            R_pl = R_par @ ca.SX(M.rotation)
            p_pl = p_par + R_par @ ca.SX(M.translation)
            if kind in _REVOLUTE_AXES or kind == "JointModelRevoluteUnaligned":
                axis = np.asarray(_REVOLUTE_AXES[kind] if kind in _REVOLUTE_AXES else jm.extract().axis, dtype=float)
                R_j, p_j = R_pl @ _axis_rotation(axis / np.linalg.norm(axis), qj), p_pl
            elif kind in _PRISMATIC_AXES or kind == "JointModelPrismaticUnaligned":
                axis = np.asarray(_PRISMATIC_AXES[kind] if kind in _PRISMATIC_AXES else jm.extract().axis, dtype=float)
                R_j, p_j = R_pl, p_pl + R_pl @ ca.SX(axis / np.linalg.norm(axis)) * qj
            else:
                raise RobotModelError(f"casadi FK does not support joint {model.names[j]!r} of robot {spec.name!r} "
                                      f"(type {kind}); supported: revolute and prismatic 1-DoF joints")
            R_of.append(R_j)
            p_of.append(p_j)
            # Reach bound: link lengths from joint 1's origin on, plus a prismatic joint's stroke.
            link = float(np.linalg.norm(M.translation)) if parent != 0 else 0.0
            if kind.startswith("JointModelP"):
                i_spec = list(np.asarray(robot.arm_q_idx, dtype=int)).index(jm.idx_q)
                link += float(max(abs(spec.q_min[i_spec]), abs(spec.q_max[i_spec])))
            reach_to.append(reach_to[parent] + link)
            origins.append(p_j)
        frame = model.frames[robot.tcp_frame_id]
        fj = int(frame.parentJoint)
        R_tcp = R_of[fj] @ ca.SX(frame.placement.rotation)
        p_tcp = p_of[fj] + R_of[fj] @ ca.SX(frame.placement.translation)
        moving = [o[2] for o in origins if ca.depends_on(o[2], q)]
        self.dof = dof
        self.fk = ca.Function("fk", [q], [p_tcp, R_tcp], ["q"], ["p", "R"])
        self.heights = ca.Function("heights", [q], [ca.vertcat(p_tcp[2], *moving)], ["q"], ["z"])
        self.n_heights = 1 + len(moving)
        self.base_m = np.asarray(model.jointPlacements[1].translation, dtype=float)
        self.reach_m = reach_to[fj] + float(np.linalg.norm(frame.placement.translation))

    def pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Numeric TCP pose at q [m], rotation matrix."""
        p, R = self.fk(q)
        return np.asarray(p, dtype=float).reshape(3), np.asarray(R, dtype=float)


def casadi_chain(spec) -> CasadiChain:
    """The casadi chain of robot ``spec`` (from the same reduced Pinocchio model the pinocchio backend loads)."""
    from tcot_hybrid.robot import build_pinocchio_model

    return CasadiChain(build_pinocchio_model(spec, lock_gripper=True))


# -- results ------------------------------------------------------------------------------------------


class PlanIKResult(NamedTuple):
    """Outcome of one whole-plan solve. ``q`` is always finite and inside the limit box.

    q:             (N, dof) joint configuration per waypoint [rad].
    status:        "converged" (every waypoint met), "infeasible" (some cannot be met: see ``offending``),
                   "max_iters" or "non_finite" (the solver gave up; errors are those of ``q``).
    solver_status: IPOPT's return status of the last solve.
    iters:         IPOPT iterations over all solves.
    pos_err:       (N,) TCP position error per waypoint at ``q`` [m].
    rot_err:       (N,) TCP rotation error per waypoint at ``q`` [rad].
    height_margin: (N,) lowest checked point (TCP, moving joint origins) above support_z + min_height_m
                   [m]; >= 0 when the height bound holds.
    offending:     waypoint indices whose targets are not met (empty when converged), worst first.
    limit_active:  (N,) a joint sits at the limit box (with margin) at that waypoint.
    solve_time_s:  wall time of the whole call [s].
    fallback:      the first solve (from the configured warm start) failed and a later one produced ``q``.
    """

    q: np.ndarray
    status: str
    solver_status: str
    iters: int
    pos_err: np.ndarray
    rot_err: np.ndarray
    height_margin: np.ndarray
    offending: tuple[int, ...]
    limit_active: np.ndarray
    solve_time_s: float
    fallback: bool

    @property
    def converged(self) -> bool:
        return self.status == CONVERGED

    @property
    def worst(self) -> int | None:
        """The waypoint farthest from its target (None when every waypoint is met)."""
        return self.offending[0] if self.offending else None


# -- the backend --------------------------------------------------------------------------------------


@register_ik
class CasadiIK(IKSolver):
    """Whole-plan IK with casadi + IPOPT (``solve_plan``); ``solve`` is the one-waypoint plan."""

    name = "casadi"
    solves_plans = True

    def __init__(self, spec, config: IKConfig | None = None) -> None:
        super().__init__(spec, config)
        self.chain = casadi_chain(spec)
        self._solvers: OrderedDict[tuple[int, str], tuple[ca.Function, np.ndarray, np.ndarray]] = OrderedDict()
        # Warm starts in the order tried: the configured one, then the other kind (the per-waypoint chain and
        # "every waypoint at the start configuration" reach different arm branches; each solves plans the other
        # does not: docs/ik-plans). A per-waypoint chain uses the configured backend, or pinocchio.
        first = self.config.casadi.warm_start
        chain_backend = first if first != "current" else "pinocchio"
        self._chain_ik = make_ik(chain_backend, spec, self.config)
        self._warm_starts = (first, "current" if first != "current" else "pinocchio")
        # 1 + 2 cos(rot_tol): trace(R_target^T R) above this <=> rotation error <= rot_tol_rad.
        self._trace_min = 1.0 + 2.0 * math.cos(min(self.config.rot_tol_rad, math.pi))

    # -- public API ---------------------------------------------------------------------------------

    def solve_plan(self, positions, rotations, q_start, *, support_z: float | None = None) -> PlanIKResult:
        """Solve every waypoint of a plan at once.

        positions: (N, 3) TCP target positions in the IK (robot base) frame [m].
        rotations: (N, 3, 3) TCP target rotations, TCP axes in IK-frame coordinates.
        q_start:   (dof,) configuration the plan starts from (the travel cost's q_0; also the warm start) [rad].
        support_z: height of the support surface in the IK frame [m]; default ``config.casadi.support_z_m``.

        Raises IKError for unusable input (non-finite values, wrong shapes, a non-rotation, a target out
        of range, more than ``max_waypoints`` waypoints); everything else is reported in the result.
        """
        P, R = self._check_plan(positions, rotations)
        q0 = self._check_seed(q_start)
        zs = self.config.casadi.support_z_m if support_z is None else support_z
        try:
            zs = float(zs)
        except (TypeError, ValueError) as exc:
            raise IKError(f"support_z must be a number [m], got {support_z!r}") from exc
        if not math.isfinite(zs) or abs(zs) > 10.0:
            raise IKError(f"support_z must be finite and within +-10 m, got {support_z!r}")
        return self._solve_plan(P, R, q0, zs)

    def _solve(self, pos: np.ndarray, rot: np.ndarray, seed: np.ndarray) -> IKResult:
        """One waypoint as a plan of one (replaces the shared differential-IK iteration loop)."""
        self._check_range(pos[None, :])
        r = self._solve_plan(pos[None, :], rot[None, :, :], seed, self.config.casadi.support_z_m)
        status = r.status
        return IKResult(r.q[0].copy(), status == CONVERGED, status, r.iters, float(r.pos_err[0]),
                        float(r.rot_err[0]), bool(r.limit_active[0]))

    def _tcp_at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.chain.pose(q)

    def _step(self, q, pos, rot, pos_err, rot_err):
        """Not used: this backend solves for the configurations directly (``_solve`` replaces the loop)."""
        raise NotImplementedError("the casadi backend has no differential-IK step; it solves whole plans")

    # -- input checks -------------------------------------------------------------------------------

    def _check_plan(self, positions, rotations) -> tuple[np.ndarray, np.ndarray]:
        try:
            P = np.array(positions, dtype=float)
            R = np.array(rotations, dtype=float)
        except (TypeError, ValueError) as exc:
            raise IKError(f"positions must be an (N, 3) and rotations an (N, 3, 3) numeric array, got "
                          f"{positions!r} and {rotations!r}") from exc
        if P.ndim != 2 or P.shape[1:] != (3,) or P.shape[0] < 1:
            raise IKError(f"positions must have shape (N, 3) with N >= 1, got shape {P.shape}")
        n = P.shape[0]
        if R.shape != (n, 3, 3):
            raise IKError(f"rotations must have shape ({n}, 3, 3) (one per waypoint), got shape {R.shape}")
        cap = self.config.casadi.max_waypoints
        if n > cap:
            raise IKError(f"plan has {n} waypoints; ik_params.casadi.max_waypoints = {cap}")
        bad = np.flatnonzero(~np.all(np.isfinite(P), axis=1))
        if bad.size:
            raise IKError(f"positions must be finite; waypoint {int(bad[0])} is {P[bad[0]].tolist()}")
        bad = np.flatnonzero(~np.all(np.isfinite(R), axis=(1, 2)))
        if bad.size:
            raise IKError(f"rotations must be finite; waypoint {int(bad[0])} is {R[bad[0]].tolist()}")
        ortho = np.max(np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)), axis=(1, 2))
        det = np.linalg.det(R)
        bad = np.flatnonzero(~(ortho <= ROT_ORTHO_TOL) | (det <= 0.0))
        if bad.size:
            i = int(bad[0])
            raise IKError(f"rotations[{i}] must be a rotation matrix (|R^T R - I| <= {ROT_ORTHO_TOL}, det = +1), "
                          f"got {R[i].tolist()} (orthonormality error {ortho[i]:.3g}, det {det[i]:.6g})")
        self._check_range(P)
        return P, R

    def _check_range(self, P: np.ndarray) -> None:
        """Refuse targets absurdly far from the base (> 10x the arm's reach): a unit or frame mistake, not a plan."""
        limit = _RANGE_FACTOR * self.chain.reach_m
        with np.errstate(over="ignore"):  # a 1e300 m target: inf, refused below
            dist = np.linalg.norm(P - self.chain.base_m, axis=1)
        bad = np.flatnonzero(~(dist <= limit))
        if bad.size:
            i = int(bad[0])
            raise IKError(f"target position of waypoint {i}, {P[i].tolist()} m, is {dist[i]:.4g} m from the base of "
                          f"robot {self.spec.name!r}; out of range (its reach is {self.chain.reach_m:.3f} m; targets "
                          f"beyond {limit:.3g} m are refused as a unit or frame mistake)")

    # -- NLP ----------------------------------------------------------------------------------------

    def _solver(self, n: int, kind: str) -> tuple[ca.Function, np.ndarray, np.ndarray]:
        """IPOPT solver for plans of n waypoints; kind "plan" (the cost above, targets hard) or "closest"
        (minimise the tolerance-normalised pose errors, limits and heights still hard)."""
        key = (n, kind)
        if key in self._solvers:
            self._solvers.move_to_end(key)
            return self._solvers[key]
        X = ca.MX.sym("q", self.dof, n)
        q0, q_post, zs = ca.MX.sym("q0", self.dof), ca.MX.sym("q_post", self.dof), ca.MX.sym("support_z")
        P, Rt = ca.MX.sym("p", 3, n), ca.MX.sym("R", 9, n)  # rotation columns stacked (column-major)
        # One waypoint's cost and constraints as an SX function, mapped over the plan: building the NLP then
        # costs the same for every plan length (an expanded graph took 0.4-1.3 s for a 34-waypoint plan).
        wp, lbg1, ubg1 = self._waypoint_function(kind)
        cost, G = wp.map(n)(X, ca.horzcat(q0, X[:, :-1]), P, Rt, ca.repmat(q_post, 1, n), ca.repmat(zs, 1, n))
        nlp = {"x": ca.vec(X), "p": ca.vertcat(q0, q_post, zs, ca.vec(P), ca.vec(Rt)), "f": ca.sum2(cost),
               "g": ca.vec(G)}
        lbg, ubg = np.tile(lbg1, n), np.tile(ubg1, n)
        cc = self.config.casadi
        ipopt = {"max_iter": cc.max_iters, "tol": cc.tol, "print_level": 0, "sb": "yes",
                 "constr_viol_tol": 1e-9, "acceptable_constr_viol_tol": 1e-9, "mu_strategy": "adaptive"}
        if cc.max_time_s is not None:
            ipopt["max_wall_time"] = float(cc.max_time_s)
        solver = ca.nlpsol(f"plan_ik_{kind}_{n}", "ipopt", nlp, {"ipopt": ipopt, "print_time": False,
                                                                  "error_on_fail": False})
        self._solvers[key] = (solver, lbg, ubg)
        while len(self._solvers) > _SOLVER_CACHE:
            self._solvers.popitem(last=False)
        return self._solvers[key]

    def _waypoint_function(self, kind: str) -> tuple[ca.Function, np.ndarray, np.ndarray]:
        """(cost, constraints) of one waypoint as a function of (q_i, q_{i-1}, p_i, R_i, q_posture, support_z),
        with the constraints' lower and upper bounds."""
        cfg, cc, dof = self.config, self.config.casadi, self.dof
        qi, prev, q_post = ca.SX.sym("q", dof), ca.SX.sym("q_prev", dof), ca.SX.sym("q_post", dof)
        p_t, R_t, zs = ca.SX.sym("p", 3), ca.SX.sym("R", 9), ca.SX.sym("support_z")
        p, R = self.chain.fk(qi)
        Rt = ca.reshape(R_t, 3, 3)
        tr = ca.trace(Rt.T @ R)  # 1 + 2 cos(angle)
        soft_rot = cc.orientation == "soft"
        g, lbg, ubg = [], [], []
        if kind == "plan":
            f = cc.travel_weight * ca.sumsqr(qi - prev) + cc.posture_weight * ca.sumsqr(qi - q_post)
            g.append(p - p_t)
            lbg += [0.0] * 3
            ubg += [0.0] * 3
            if soft_rot:
                f += cc.orientation_weight * (3.0 - tr)  # 2 (1 - cos a) ~ a^2 [rad^2]
            else:
                # Rotation met exactly: vee(E - E^T) / 2 = sin(a) * axis = 0 with E = R_target^T R; that also
                # holds at a = pi, which the trace bound (a <= rot_tol_rad, inactive at a = 0) excludes.
                E = Rt.T @ R
                g += [ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]) / 2, tr]
                lbg += [0.0, 0.0, 0.0, self._trace_min]
                ubg += [0.0, 0.0, 0.0, np.inf]
        else:  # "closest": pose errors in units of the tolerances; a whisper of travel keeps it well posed
            f = ca.sumsqr(p - p_t) / cfg.pos_tol_m**2 + 1e-6 * ca.sumsqr(qi - prev)
            if not soft_rot:
                f += (3.0 - tr) / (3.0 - self._trace_min)  # 2 (1 - cos a) / 2 (1 - cos rot_tol)
        g.append(self.chain.heights(qi) - zs)
        lbg += [cc.min_height_m] * self.chain.n_heights
        ubg += [np.inf] * self.chain.n_heights
        fn = ca.Function(f"waypoint_{kind}", [qi, prev, p_t, R_t, q_post, zs], [f, ca.vertcat(*g)])
        return fn, np.array(lbg, dtype=float), np.array(ubg, dtype=float)

    def _warm_start(self, kind: str, P: np.ndarray, R: np.ndarray, q0: np.ndarray) -> np.ndarray:
        """Initial guess: every waypoint at the (clipped) start configuration, or the per-waypoint chain."""
        if kind == "current":
            return np.tile(np.clip(q0, self.lower, self.upper), (len(P), 1))
        out, q = np.empty((len(P), self.dof)), q0
        for i in range(len(P)):
            q = self._chain_ik._solve(P[i], R[i], q.copy()).q
            out[i] = q
        return np.clip(out, self.lower, self.upper)

    def _run(self, built, X0: np.ndarray, params: np.ndarray) -> tuple[np.ndarray | None, str, int]:
        """One IPOPT solve: (configurations or None on an evaluation error, return status, iterations)."""
        solver, lbg, ubg = built
        n = X0.shape[0]
        try:
            sol = solver(x0=X0.reshape(-1), p=params, lbx=np.tile(self.lower, n), ubx=np.tile(self.upper, n),
                         lbg=lbg, ubg=ubg)
        except RuntimeError as exc:  # evaluation errors (NaN in a derivative) surface here
            return None, "error: " + str(exc).splitlines()[0][:200], 0
        stats = solver.stats()
        x = np.asarray(sol["x"], dtype=float).reshape(n, self.dof)
        return x, str(stats.get("return_status", "unknown")), int(stats.get("iter_count", 0))

    def _evaluate(self, X: np.ndarray, P: np.ndarray, R: np.ndarray, zs: float):
        """Numeric re-check of configurations X: (pos_err, rot_err, height_margin, limit_active, met)."""
        cfg, cc = self.config, self.config.casadi
        n = len(X)
        pos_err, rot_err, margin = np.empty(n), np.empty(n), np.empty(n)
        for i in range(n):
            p, Rq = self.chain.pose(X[i])
            pos_err[i] = math.hypot(*(p - P[i]))
            rot_err[i] = rotation_angle(Rq, R[i])
            margin[i] = float(np.min(np.asarray(self.chain.heights(X[i])))) - zs - cc.min_height_m
        rot_ok = rot_err <= cfg.rot_tol_rad + _CHECK_SLACK if cc.orientation == "hard" else np.ones(n, bool)
        met = (pos_err <= cfg.pos_tol_m) & rot_ok & (margin >= -_CHECK_SLACK)
        limit_active = np.any((X - self.lower <= _LIMIT_ACTIVE_RAD) | (self.upper - X <= _LIMIT_ACTIVE_RAD), axis=1)
        return pos_err, rot_err, margin, limit_active, met

    def _solve_plan(self, P: np.ndarray, R: np.ndarray, q0: np.ndarray, zs: float) -> PlanIKResult:
        t0 = time.perf_counter()
        n = len(P)
        q_post = self.posture_for(q0)
        params = np.concatenate([q0, q_post, [zs], P.reshape(-1),
                                 np.transpose(R, (0, 2, 1)).reshape(-1)])  # each rotation column-major
        iters_total = 0
        tried: list[tuple[np.ndarray, str]] = []
        attempts = [("plan", kind) for kind in self._warm_starts] + [("closest", None)]
        for attempt, (formulation, warm) in enumerate(attempts):
            if warm is not None:
                start = self._warm_start(warm, P, R, q0)
                tried.append((start, "warm_start"))
            else:  # the pose-error solve starts from the best configurations so far
                start = min(tried, key=lambda t: self._rank(self._evaluate(t[0], P, R, zs)))[0]
            X, status, iters = self._run(self._solver(n, formulation), start, params)
            iters_total += iters
            if X is None or not np.all(np.isfinite(X)):
                tried.append((start, status if X is None else "non_finite"))
                continue
            X = np.clip(X, self.lower, self.upper)  # IPOPT honours the bounds; this removes round-off only
            tried.append((X, status))
            pos_err, rot_err, margin, limit_active, met = self._evaluate(X, P, R, zs)
            if np.all(met):  # IPOPT's status alone is never trusted: the answer was re-checked above
                return PlanIKResult(X, CONVERGED, status, iters_total, pos_err, rot_err, margin, (),
                                    limit_active, time.perf_counter() - t0, attempt > 0)
        # Neither solve met every target: report the closest configurations found.
        best = None
        for X, _ in tried:
            ev = self._evaluate(X, P, R, zs)
            score = self._rank(ev)
            if best is None or score < best[0]:
                best = (score, X, ev)
        _, X, (pos_err, rot_err, margin, limit_active, met) = best
        closest_status = tried[-1][1]
        if np.all(met):  # only the warm start met every target (both solves failed from it)
            return PlanIKResult(X, CONVERGED, closest_status, iters_total, pos_err, rot_err, margin, (),
                                limit_active, time.perf_counter() - t0, True)
        if closest_status in _IPOPT_ITER_LIMIT:
            status = MAX_ITERS
        elif closest_status == "non_finite" or closest_status.startswith("error"):
            status = NON_FINITE
        else:
            status = INFEASIBLE
        badness = self._badness(pos_err, rot_err, margin)
        offending = tuple(int(i) for i in sorted(np.flatnonzero(~met), key=lambda i: -badness[i]))
        return PlanIKResult(X, status, closest_status, iters_total, pos_err, rot_err, margin, offending,
                            limit_active, time.perf_counter() - t0, True)

    def _rank(self, ev) -> tuple[bool, float]:
        """Order of candidate configurations: within the height bound first, then the smallest total miss."""
        return bool(np.any(ev[2] < -_CHECK_SLACK)), float(np.sum(self._badness(*ev[:3])))

    def _badness(self, pos_err, rot_err, margin) -> np.ndarray:
        """Per-waypoint distance from meeting the target, in tolerances (0 = met)."""
        cfg = self.config
        b = np.maximum(pos_err / cfg.pos_tol_m - 1.0, 0.0) + np.maximum(-margin / cfg.pos_tol_m, 0.0)
        if self.config.casadi.orientation == "hard":
            b = b + np.maximum(rot_err / cfg.rot_tol_rad - 1.0, 0.0)
        return b
