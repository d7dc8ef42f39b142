"""Joint-space model predictive control with OSQP (sparse QP, warm-started, structure fixed at setup).

Model: the feedback-linearised arm, one double integrator per joint, tau = M v + bias, with the
decision variables the joint accelerations v at H nodes. Node 0 lasts one control tick (it is the
command applied now); the others last ``node_ticks`` ticks, so the horizon spans
``ctrl_dt * (1 + (H - 1) * node_ticks)`` whatever ctrl_dt is (default ~0.1 s).

Per joint i, with node times t_k and position/velocity predictions q_k = f_k + Phi v, qd_k = g_k + Psi v:

    min  sum_k  w_p,i (q_k - r_k)^2 + w_v,i (qd_k - rd_k)^2 + v_k^2      (+ terminal weight on k = H)
         + limit_weight (s_p,i^2 + s_v,i^2)
    s.t. q_min + margin <= q_k - s_p,i <= q_max - margin                 (soft: one slack per joint)
         -v_max <= qd_k - s_v,i <= v_max                                  (soft)
         -torque_margin tau_max <= M v_k + bias <= torque_margin tau_max  (hard, first torque_nodes
                                                                          nodes, M and bias of this tick)

The weights come from the acceleration-level gains (default: robot spec): w_p = kp^2,
w_v = kd^2 - 2 kp, the LQR weights whose infinite-horizon optimum is the PD law kp e + kd de. The
slack s shifts the whole predicted path of a joint back inside its limits; its weight is set
relative to the tracking weight of that joint (``limit_weight`` x w_p x H), so a reference beyond a
limit moves the plan past it by only ~1/limit_weight of the excess. The QP is always feasible (the
torque box admits some v; position and velocity are soft).

References: ``preview`` rows are the reference positions at t + (k+1) ctrl_dt (``preview_horizon``
rows; shorter previews hold their last row, i.e. the trajectory ends there). Without a preview the
reference is extrapolated at constant velocity from (q_ref, qd_ref). Velocity references at the
nodes are finite differences of the positions.

Every tick checks the inputs, the OSQP status (``solved``; ``solved_inaccurate`` only when the torque
stays within tau_max, noted in ``Command.detail``), the wall time against
``time_limit_fraction * ctrl_dt`` and the finiteness of the torque; any failure returns a PD hold of
the position measured when the failure started (``Command.status == "fallback"``, reason in
``detail``) and MPC is retried next tick (transitions are blended like a controller switch).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp

from tcot_hybrid.config import require_int, require_nonnegative, require_positive
from tcot_hybrid.controllers import register
from tcot_hybrid.controllers.base import (
    STATUS_FALLBACK,
    STATUS_OK,
    Controller,
    JointGainsConfig,
    bias_attr,
    pd_hold_torque,
    resolve_joint_gains,
)
from tcot_hybrid.errors import ConfigError, ControllerError

_SOLVED = int(osqp.SolverStatus.OSQP_SOLVED)
_ACCEPTED = (_SOLVED, int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE))
_STATUS_NAMES = {int(s): s.name.removeprefix("OSQP_").lower() for s in osqp.SolverStatus}


@dataclass(frozen=True, kw_only=True)
class MPCConfig(JointGainsConfig):
    """MPC settings. ``kp``/``kd``/scales (default spec) set the tracking weights and the fallback hold.

    horizon:             number of nodes H [-]; longer = anticipates limits earlier, slower solve.
    torque_nodes:        leading nodes carrying the torque constraint [-] (M and bias of this tick are
                         only accurate near it). More = torque-aware further ahead, slower refactorisation.
    node_ticks:          control ticks per node after the first [-]; None = round(0.01 s / ctrl_dt),
                         at least 1. Larger = longer horizon at the same cost, coarser plan.
    terminal_weight:     multiplies w_p and w_v on the last node [-]; higher = firmer arrival.
    torque_margin:       fraction of tau_max the plan may use [-]; lower leaves room for OSQP's
                         tolerance before the safety layer has to saturate.
    position_margin_rad: distance kept from q_min/q_max [rad]; higher = more conservative.
    limit_weight:        weight of the limit slacks relative to the joint's summed tracking weight [-];
                         higher = harder position/velocity limits, worse conditioning (more iterations).
    max_iter:            OSQP iteration cap [-]; reaching it is a failure (fallback).
    eps:                 OSQP absolute and relative tolerance [-]; lower = more accurate, slower.
    time_limit_fraction: wall-clock solve budget as a fraction of ctrl_dt [-]; exceeding it is a
                         failure (fallback). Lower = stricter real-time behaviour. None = no wall-clock
                         deadline (only ``max_iter``): runs then replay bit-identically whatever the
                         machine load, which a wall-clock deadline cannot promise (measured on 2 shared
                         cores: median solve 0.15 ms, p99 0.3 ms, load spikes up to ~6 ms).
    """

    horizon: int = 10
    torque_nodes: int = 3
    node_ticks: int | None = None
    terminal_weight: float = 5.0
    torque_margin: float = 0.97
    position_margin_rad: float = 0.005
    limit_weight: float = 100.0
    max_iter: int = 200
    eps: float = 1e-3
    time_limit_fraction: float | None = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        require_int("horizon", self.horizon, minimum=2)
        require_int("torque_nodes", self.torque_nodes, minimum=1)
        if self.torque_nodes > self.horizon:
            raise ConfigError(f"torque_nodes = {self.torque_nodes} must be <= horizon = {self.horizon}")
        if self.node_ticks is not None:
            require_int("node_ticks", self.node_ticks, minimum=1)
        require_positive("terminal_weight", self.terminal_weight)
        require_positive("torque_margin", self.torque_margin)
        if self.torque_margin > 1.0:
            raise ConfigError(f"torque_margin must be in (0, 1], got {self.torque_margin!r}")
        require_nonnegative("position_margin_rad", self.position_margin_rad)
        require_positive("limit_weight", self.limit_weight)
        require_int("max_iter", self.max_iter, minimum=1)
        require_positive("eps", self.eps)
        if self.time_limit_fraction is not None:
            require_positive("time_limit_fraction", self.time_limit_fraction)


@register
class JointMPC(Controller):
    name = "mpc"
    Config = MPCConfig

    def __init__(self, spec, *, ctrl_dt: float, config: MPCConfig) -> None:
        super().__init__(spec, ctrl_dt=ctrl_dt, config=config)
        n, H = self.n, config.horizon
        self.kp, self.kd = resolve_joint_gains(config, spec, ctrl_dt)
        self._bias = bias_attr(config)
        s = config.node_ticks if config.node_ticks is not None else max(1, round(0.01 / ctrl_dt))
        self.node_ticks = s
        self.horizon = H
        self.preview_horizon = 1 + (H - 1) * s
        frac = config.time_limit_fraction
        self.time_limit_s = float("inf") if frac is None else frac * ctrl_dt
        # Node k (1..H) is at t_k; its reference is preview row rows[k-1].
        dts = np.array([ctrl_dt] + [s * ctrl_dt] * (H - 1))
        t_start = np.concatenate([[0.0], np.cumsum(dts)[:-1]])
        self._t = np.cumsum(dts)
        self._rows = np.array([(k - 1) * s for k in range(1, H + 1)])
        phi = np.zeros((H, H))
        psi = np.zeros((H, H))
        for k in range(1, H + 1):
            for j in range(k):
                phi[k - 1, j] = dts[j] * (self._t[k - 1] - t_start[j] - dts[j] / 2)
                psi[k - 1, j] = dts[j]
        self._phi, self._psi = phi, psi
        t_ext = np.concatenate([[0.0], self._t])
        den = np.empty(H)
        den[:-1] = t_ext[2:] - t_ext[:-2]
        den[-1] = t_ext[-1] - t_ext[-2]
        self._inv_den = 1.0 / den

        # Each term weighted by the time it stands for, so the sum approximates the continuous LQR
        # cost whatever the node spacing; normalised by the node interval.
        node_w = dts / dts[-1]
        node_w_end = node_w.copy()
        node_w_end[-1] *= config.terminal_weight
        self._w_p = (self.kp**2)[:, None] * node_w_end[None, :]                       # (n, H)
        self._w_v = np.maximum(self.kd**2 - 2 * self.kp, 0.0)[:, None] * node_w_end[None, :]
        blocks = [phi.T @ (self._w_p[i][:, None] * phi) + psi.T @ (self._w_v[i][:, None] * psi) + np.diag(node_w)
                  for i in range(n)]
        # Slacks [s_p (n), s_v (n)], weighted against each joint's summed tracking weights.
        w_sp = config.limit_weight * self._w_p.sum(axis=1)
        w_sv = config.limit_weight * np.maximum(self._w_v.sum(axis=1), 1.0)
        P = sp.block_diag(blocks + [sp.diags(np.concatenate([w_sp, w_sv]))], format="csc")
        P = sp.triu(P, format="csc")

        # Constraint matrix: [pos rows (n*H); vel rows (n*H); torque rows (n*torque_nodes)], joint-major.
        # M's entries sit at fixed CSC positions (found by tagging) so each tick rewrites only them.
        nv = n * H
        self._nx = nv + 2 * n
        rows, cols, vals = [], [], []
        for i in range(n):
            for k in range(H):
                r = i * H + k
                for j in range(k + 1):
                    rows += [r, nv + r]
                    cols += [i * H + j, i * H + j]
                    vals += [phi[k, j], psi[k, j]]
                rows += [r, nv + r]
                cols += [nv + i, nv + n + i]
                vals += [-1.0, -1.0]
        n_rows0 = 2 * nv
        m_tags = []
        Ht = self._torque_nodes = config.torque_nodes
        for i in range(n):
            for k in range(Ht):
                for j in range(n):
                    rows.append(n_rows0 + i * Ht + k)
                    cols.append(j * H + k)
                    vals.append(1.0)
                    m_tags.append((i, j))
        nnz_fixed = len(vals) - len(m_tags)
        tags = np.arange(1, len(vals) + 1, dtype=float)
        A_tag = sp.csc_matrix((tags, (rows, cols)), shape=(n_rows0 + n * Ht, self._nx))
        order = A_tag.data.astype(int) - 1            # CSC position -> original entry
        vals_arr = np.array(vals)
        self._A_data = vals_arr[order].copy()
        pos_of = np.empty_like(order)
        pos_of[order] = np.arange(order.size)
        m_pos = pos_of[nnz_fixed:]                    # CSC positions of the M entries, in m_tags order
        self._m_pos = m_pos
        self._m_flat = np.array([i * n + j for i, j in m_tags])  # index into M.ravel()
        A = sp.csc_matrix((self._A_data.copy(), A_tag.indices, A_tag.indptr), shape=A_tag.shape)

        self._q_vec = np.zeros(self._nx)
        self._l = np.zeros(n_rows0 + n * Ht)
        self._u = np.zeros(n_rows0 + n * Ht)
        self._trq = n_rows0
        self._q_lo = (spec.q_min + config.position_margin_rad)[:, None]
        self._q_hi = (spec.q_max - config.position_margin_rad)[:, None]
        self._v_max = spec.v_max[:, None]
        self._tau_max = np.asarray(spec.tau_max, dtype=float)
        self._tau_lim = config.torque_margin * self._tau_max
        self._idx0 = np.arange(n) * H
        self._prob = osqp.OSQP()
        self._prob.setup(P, self._q_vec, A, -np.ones(self._l.size), np.ones(self._l.size), verbose=False,
                         eps_abs=config.eps, eps_rel=config.eps, max_iter=config.max_iter,
                         time_limit=min(self.time_limit_s, 1e10), warm_starting=True, polishing=False,
                         check_termination=5)
        raw = getattr(self._prob, "_solver", None)
        needed = ("update_data_vec", "update_data_mat", "solve", "info", "solution")
        self._raw = raw if raw is not None and all(hasattr(raw, a) for a in needed) else None
        self._fallback = False
        self._q_hold = np.zeros(n)
        self.last_solve_status = "none"
        self.last_iterations = 0

    # -- internals ------------------------------------------------------------------------------
    def _reset_state(self, dyn) -> None:
        self._fallback = False
        self._prob.warm_start(x=np.zeros(self._nx), y=np.zeros(self._l.size))

    def _references(self, reference, preview) -> tuple[np.ndarray, np.ndarray]:
        """Positions (n, H) [rad] and velocities (n, H) [rad/s] at the nodes."""
        if preview is None:
            R = reference.q[:, None] + reference.qd[:, None] * self._t[None, :]
        else:
            pv = np.asarray(preview, dtype=float)
            if pv.ndim != 2 or pv.shape[1] != self.n or pv.shape[0] < 1:
                raise ControllerError(f"MPC preview must have shape (rows >= 1, {self.n}), got {pv.shape}")
            R = pv[np.minimum(self._rows, pv.shape[0] - 1)].T
        ext = np.concatenate([reference.q[:, None], R], axis=1)   # (n, H+1): node 0..H
        RD = np.empty_like(R)
        RD[:, :-1] = ext[:, 2:] - ext[:, :-2]
        RD[:, -1] = ext[:, -1] - ext[:, -2]
        RD *= self._inv_den
        return R, RD

    def _solve_qp(self, dyn, R, RD) -> tuple[int, np.ndarray]:
        """Update the QP for this tick and solve it. Returns (OSQP status value, x)."""
        q0, qd0, M, bias = dyn.q, dyn.qd, dyn.M, getattr(dyn, self._bias)
        n, H, nv = self.n, self.horizon, self.n * self.horizon
        F = q0[:, None] + qd0[:, None] * self._t[None, :]
        lin = (self._w_p * (F - R)) @ self._phi + (self._w_v * (qd0[:, None] - RD)) @ self._psi
        self._q_vec[:nv] = lin.ravel()
        l, u = self._l, self._u
        l[:nv] = (self._q_lo - F).ravel()
        u[:nv] = (self._q_hi - F).ravel()
        l[nv:2 * nv] = (-self._v_max - qd0[:, None]).repeat(H, axis=1).ravel()
        u[nv:2 * nv] = (self._v_max - qd0[:, None]).repeat(H, axis=1).ravel()
        l[self._trq:] = np.repeat(-self._tau_lim - bias, self._torque_nodes)
        u[self._trq:] = np.repeat(self._tau_lim - bias, self._torque_nodes)
        self._A_data[self._m_pos] = M.ravel()[self._m_flat]
        if self._raw is not None:
            # The low-level solver skips ~35 us/tick of wrapper bookkeeping (derivative caches).
            raw = self._raw
            raw.update_data_vec(q=self._q_vec, l=l, u=u)
            raw.update_data_mat(P_x=None, P_i=None, A_x=self._A_data, A_i=None)
            raw.solve()
            info = raw.info
            self.last_iterations = int(info.iter)
            return int(info.status_val), raw.solution.x
        self._prob.update(q=self._q_vec, l=l, u=u, Ax=self._A_data)
        res = self._prob.solve(raise_error=False)
        self.last_iterations = int(res.info.iter)
        return int(res.info.status_val), res.x

    def _compute(self, dyn, reference, preview):
        start = time.perf_counter()
        reason = ""
        if not (np.all(np.isfinite(reference.q)) and np.all(np.isfinite(reference.qd))
                and np.all(np.isfinite(dyn.M)) and np.all(np.isfinite(getattr(dyn, self._bias)))
                and np.all(np.isfinite(dyn.q)) and np.all(np.isfinite(dyn.qd))):
            reason = "non-finite reference or state"
        else:
            R, RD = self._references(reference, preview)
            if not np.all(np.isfinite(R)):
                reason = "non-finite preview"
        tau = None
        if not reason:
            status, x = self._solve_qp(dyn, R, RD)
            self.last_solve_status = _STATUS_NAMES.get(status, str(status))
            elapsed = time.perf_counter() - start
            if status not in _ACCEPTED:
                reason = f"osqp status {self.last_solve_status}"
            elif elapsed > self.time_limit_s:
                reason = f"timeout {elapsed * 1e3:.2f} ms > {self.time_limit_s * 1e3:.2f} ms"
            else:
                tau = dyn.M @ x[self._idx0] + getattr(dyn, self._bias)
                if not np.all(np.isfinite(tau)):
                    reason = "non-finite solution"
                    tau = None
                elif status != _SOLVED:
                    # Inaccurate (tolerance x10): usable only if the torque box, the hard constraint, holds.
                    if np.any(np.abs(tau) > self._tau_max):
                        reason = f"osqp status {self.last_solve_status} beyond tau_max"
                        tau = None
        solve_time = time.perf_counter() - start
        if tau is not None:
            if self._fallback:
                self._fallback = False
                self._blend_from_last_output()
            detail = "" if status == _SOLVED else f"osqp status {self.last_solve_status}"
            return tau, STATUS_OK, detail, solve_time
        # Fallback: PD hold of the position measured when the failure started.
        if not self._fallback:
            self._fallback = True
            self._q_hold = np.array(dyn.q) if np.all(np.isfinite(dyn.q)) else self._q_hold
            self._blend_from_last_output()
            self._prob.warm_start(x=np.zeros(self._nx), y=np.zeros(self._l.size))
        return pd_hold_torque(dyn, self._q_hold, self.kp, self.kd, getattr(dyn, self._bias)), STATUS_FALLBACK, reason, solve_time
