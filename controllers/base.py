"""Controller interface shared by every low-level torque controller.

A controller turns the measured arm state (a :class:`tcot_hybrid.dynamics.MujocoArmDynamics`, updated
after ``mj_step1``) and a joint reference into arm torques [Nm]:

    cmd = controller.compute(dyn, reference, preview=None)   # -> Command(tau, status, detail, solve_time_s)

``reference`` is anything with ``.q [rad]``, ``.qd [rad/s]``, ``.qdd [rad/s^2]`` arrays of shape (n,)
(e.g. ``tcot_hybrid.smoothing.JointReference`` from the Ruckig smoother) for the current tick.

``preview`` (optional, only read by controllers with ``preview_horizon > 0``, i.e. MPC): future
reference positions, shape (H, n) [rad], row ``k`` = reference position at ``t + (k + 1) * ctrl_dt``
(exactly what ``JointSmoother.preview(controller.preview_horizon)`` returns right after ``step()``).
The simulation loop passes it as ``compute(dyn, ref, preview=smoother.preview(c.preview_horizon))``
when ``c.preview_horizon > 0``; without it MPC extrapolates the reference (see ``controllers/mpc.py``).

Bumpless switching: ``reset(dyn, last_tau)`` activates a controller mid-motion. It clears the
controller's internal state (it starts from the measured state) and fades out the difference
between ``last_tau`` (the torque applied on the previous tick) and its own command: the first tick
returns exactly ``last_tau``, then the offset shrinks linearly to zero over
``max(blend_time_s, |offset|_max / blend_rate_nm_per_ms)``. Pass ``last_tau=None`` on a cold start
(episode start): no blending.

Joint gains are acceleration-level, like the robot spec's ``kp`` [1/s^2] and ``kd`` [1/s]:
``tau = inertia * (kp e + kd de) + ...``, so one set of gains suits the heavy shoulder and the light
wrist alike.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np
from scipy.linalg import lapack

from tcot_hybrid.config import require_positive
from tcot_hybrid.errors import ConfigError, ControllerError

# Sampled-data stability limits for acceleration-level gains with torque held over ctrl_dt
# (double integrator under zero-order hold): sqrt(kp) * ctrl_dt and kd * ctrl_dt beyond these leave
# little damping margin (kd * ctrl_dt = 2 is the stability edge).
MAX_OMEGA_DT = 0.5
MAX_KD_DT = 1.0

STATUS_OK = "ok"
STATUS_BLENDING = "blending"   # nominal command plus a fading offset after reset(dyn, last_tau)
STATUS_FALLBACK = "fallback"   # the controller could not compute its law and holds position instead


class ReferenceLike(Protocol):
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


class Command(NamedTuple):
    """One controller output.

    tau:          (n,) arm torques [Nm], before the safety layer (may exceed tau_max; safety saturates
                  and reports it). A fresh array each tick.
    status:       ``"ok"``, ``"blending"`` (bumpless switch in progress) or ``"fallback"`` (the law
                  failed, e.g. MPC solver status / timeout / non-finite, and a PD position hold was
                  returned instead).
    detail:       why, for ``"fallback"`` (solver status name, timing); a note for an accepted but
                  degraded result (MPC: ``"osqp status solved_inaccurate"``); empty otherwise.
    solve_time_s: time spent in an optimiser this tick [s] (0 for closed-form laws).
    """

    tau: np.ndarray
    status: str = STATUS_OK
    detail: str = ""
    solve_time_s: float = 0.0


@dataclass(frozen=True, kw_only=True)
class ControllerConfig:
    """Settings every controller has (bumpless switching).

    blend_time_s:        shortest time over which a newly activated controller fades out the torque
                         difference to the previous command [s]. Longer = gentler switch, but the new
                         controller takes over later.
    blend_rate_nm_per_ms: fastest fade of that difference [Nm/ms] per joint; a large difference
                         blends for longer. Lower = gentler switch. Must stay below the 1 Nm/ms
                         bumpless requirement minus the torque change of the motion itself.
    """

    blend_time_s: float = 0.05
    blend_rate_nm_per_ms: float = 0.5

    def __post_init__(self) -> None:
        require_positive("blend_time_s", self.blend_time_s)
        require_positive("blend_rate_nm_per_ms", self.blend_rate_nm_per_ms)


@dataclass(frozen=True, kw_only=True)
class JointGainsConfig(ControllerConfig):
    """Acceleration-level joint gains, defaulting to the robot spec's.

    kp:       per-joint stiffness [1/s^2] (n values) or None = the robot spec's ``kp``. Higher = stiffer,
              less lag; must keep sqrt(kp * kp_scale) * ctrl_dt <= 0.5.
    kd:       per-joint damping [1/s] or None = the robot spec's ``kd`` (critical: 2 sqrt(kp)). Higher =
              less overshoot, noisier; must keep kd * kd_scale * ctrl_dt <= 1.
    kp_scale: multiplies kp [-]; turn up for stiffer tracking, down if it rings.
    kd_scale: multiplies kd [-]; turn up for more damping, down if it chatters.
    compensate_passive: also cancel the model's passive joint forces (MuJoCo ``qfrc_passive``: joint
              damping) [on/off]. On = tracks like the ideal law; off = treat them as unmodelled
              friction (measured: 5 mrad peak lag instead of 0.4 on a 0.3 rad / 1 s Panda move).
    """

    kp: tuple[float, ...] | None = None
    kd: tuple[float, ...] | None = None
    kp_scale: float = 1.0
    kd_scale: float = 1.0
    compensate_passive: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("kp", "kd"):
            value = getattr(self, name)
            if value is not None:
                require_positive(name, value)
                object.__setattr__(self, name, tuple(float(v) for v in np.atleast_1d(value)))
        require_positive("kp_scale", self.kp_scale)
        require_positive("kd_scale", self.kd_scale)
        if not isinstance(self.compensate_passive, bool):
            raise ConfigError(f"compensate_passive must be a bool, got {self.compensate_passive!r}")


def resolve_joint_gains(cfg: JointGainsConfig, spec: Any, ctrl_dt: float, *, prefix: str = "") -> tuple[np.ndarray, np.ndarray]:
    """kp [1/s^2], kd [1/s] per joint from ``cfg`` and the spec; ConfigError if unstable at ``ctrl_dt``."""
    n = spec.dof
    gains = []
    for name, scale, default in (("kp", cfg.kp_scale, spec.kp), ("kd", cfg.kd_scale, spec.kd)):
        raw = getattr(cfg, name)
        arr = np.asarray(default if raw is None else raw, dtype=float)
        if arr.shape != (n,):
            raise ConfigError(f"{prefix}{name} needs {n} values (one per arm joint), got {arr.shape}: {raw!r}")
        gains.append(arr * scale)
    kp, kd = gains
    check_gain_stability(kp, kd, ctrl_dt, kp_field=f"{prefix}kp", kd_field=f"{prefix}kd")
    for a in gains:
        a.flags.writeable = False
    return kp, kd


def check_gain_stability(kp: np.ndarray, kd: np.ndarray, ctrl_dt: float, *, kp_field: str, kd_field: str) -> None:
    """ConfigError naming the field, joint and value when a gain is too high for sampling at ctrl_dt."""
    w_dt = np.sqrt(np.asarray(kp, dtype=float)) * ctrl_dt
    d_dt = np.asarray(kd, dtype=float) * ctrl_dt
    if np.any(w_dt > MAX_OMEGA_DT):
        i = int(np.argmax(w_dt))
        raise ConfigError(f"{kp_field} (after scaling) = {float(np.ravel(kp)[i]):.4g} 1/s^2 at joint {i} gives "
                          f"sqrt(kp) * ctrl_dt = {w_dt.flat[i]:.3g} > {MAX_OMEGA_DT} with ctrl_dt = {ctrl_dt} s; "
                          "lower the gain or ctrl_dt")
    if np.any(d_dt > MAX_KD_DT):
        i = int(np.argmax(d_dt))
        raise ConfigError(f"{kd_field} (after scaling) = {float(np.ravel(kd)[i]):.4g} 1/s at joint {i} gives "
                          f"kd * ctrl_dt = {d_dt.flat[i]:.3g} > {MAX_KD_DT} with ctrl_dt = {ctrl_dt} s; "
                          "lower the gain or ctrl_dt")


# Raw LAPACK: numpy.linalg costs ~5 us of Python overhead per call on 7x7 matrices, these ~1 us.
_potrf = lapack.dpotrf
_potrs = lapack.dpotrs
_posv = lapack.dposv
_EYES: dict[int, np.ndarray] = {}


def cholesky(M: np.ndarray) -> np.ndarray | None:
    """Upper Cholesky factor U (M = U^T U) of an SPD matrix, or None when M is not positive definite."""
    U, info = _potrf(M)
    return U if info == 0 else None


def cho_solve(U: np.ndarray, B: np.ndarray) -> np.ndarray:
    """M^-1 B given the factor from :func:`cholesky` (B may be a vector or a matrix)."""
    return _potrs(U, B)[0]


def spd_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A^-1 b for SPD A; NaNs when A is not positive definite (the caller's finiteness check catches it)."""
    _, x, info = _posv(A, b)
    return x if info == 0 else np.full(np.shape(b), np.nan)


def effective_joint_inertia(M: np.ndarray) -> np.ndarray:
    """1 / diag(M^-1) [kg m^2]: the inertia each joint feels when the others are free.

    Scaling decentralised PD gains by this (instead of diag(M)) keeps the coupled closed loop within
    ~2.4x of the design bandwidth on the Panda (diag(M) reaches 13x on the light wrist: unstable at
    ctrl_dt = 10 ms). NaNs when M is not positive definite.
    """
    n = M.shape[0]
    U = cholesky(M)
    if U is None:
        return np.full(n, np.nan)
    eye = _EYES.get(n)
    if eye is None:
        eye = _EYES[n] = np.eye(n)
    return 1.0 / np.diagonal(cho_solve(U, eye))


class Controller(ABC):
    """Base of every controller. Subclasses set ``name``, ``Config`` and implement ``_compute``.

    Construct through :func:`tcot_hybrid.controllers.make_controller`. ``preview_horizon`` is the
    number of future reference rows ``compute`` reads from ``preview`` (0: it ignores it).
    """

    name: ClassVar[str]
    Config: ClassVar[type[ControllerConfig]] = ControllerConfig
    preview_horizon: int = 0

    def __init__(self, spec: Any, *, ctrl_dt: float, config: ControllerConfig) -> None:
        require_positive("ctrl_dt", ctrl_dt)
        if not isinstance(config, self.Config):
            raise ConfigError(f"controller {self.name!r} needs a {self.Config.__name__}, got {type(config).__name__}")
        self.spec = spec
        self.ctrl_dt = float(ctrl_dt)
        self.config = config
        self.n = int(spec.dof)
        self._pending_blend: np.ndarray | None = None
        self._offset = np.zeros(self.n)
        self._blend_k = 0
        self._blend_n = 0
        self._last_out: np.ndarray | None = None

    # -- public API -----------------------------------------------------------------------------
    def reset(self, dyn: Any, last_tau: np.ndarray | None = None) -> None:
        """Activate: forget internal state, start from ``dyn``'s measured state, blend from ``last_tau`` [Nm]."""
        self._blend_k = self._blend_n = 0
        self._pending_blend = None
        self._last_out = None
        if last_tau is not None:
            last = np.array(last_tau, dtype=float)
            if last.shape != (self.n,):
                raise ControllerError(f"last_tau must have shape ({self.n},), got {last.shape}")
            # Blending toward a non-finite torque would propagate it; start clean instead.
            if np.all(np.isfinite(last)):
                self._pending_blend = last
        self._reset_state(dyn)

    def compute(self, dyn: Any, reference: ReferenceLike, preview: np.ndarray | None = None) -> Command:
        """Torque command for this tick (see the module docstring for the arguments)."""
        tau, status, detail, solve_time = self._compute(dyn, reference, preview)
        if self._pending_blend is not None:
            self._start_blend(self._pending_blend, tau)
            self._pending_blend = None
        if self._blend_k < self._blend_n:
            tau = tau + self._offset * (1.0 - self._blend_k / self._blend_n)
            self._blend_k += 1
            if status == STATUS_OK:
                status = STATUS_BLENDING
        self._last_out = tau
        return Command(tau, status, detail, solve_time)

    @property
    def blending(self) -> bool:
        """True while a bumpless-switch offset is still being faded out."""
        return self._pending_blend is not None or self._blend_k < self._blend_n

    # -- for subclasses -------------------------------------------------------------------------
    @abstractmethod
    def _compute(self, dyn: Any, reference: ReferenceLike, preview: np.ndarray | None) -> tuple[np.ndarray, str, str, float]:
        """Return (tau [Nm], status, detail, solve_time_s) without blending."""

    def _reset_state(self, dyn: Any) -> None:
        """Clear internal state (integrators, warm starts, fallback latches). Default: nothing."""

    def _blend_from_last_output(self) -> None:
        """Blend from this controller's own previous output (e.g. when MPC enters or leaves fallback)."""
        if self._last_out is not None and np.all(np.isfinite(self._last_out)):
            self._pending_blend = self._last_out

    def _start_blend(self, last_tau: np.ndarray, tau: np.ndarray) -> None:
        offset = last_tau - tau
        if not np.all(np.isfinite(offset)):
            self._blend_k = self._blend_n = 0
            return
        cfg = self.config
        rate_per_tick = cfg.blend_rate_nm_per_ms * 1e3 * self.ctrl_dt  # [Nm per tick]
        n_time = math.ceil(cfg.blend_time_s / self.ctrl_dt - 1e-9)
        n_rate = math.ceil(float(np.max(np.abs(offset))) / rate_per_tick - 1e-9)
        self._offset = offset
        self._blend_k = 0
        self._blend_n = max(n_time, n_rate, 1)


def bias_attr(cfg: Any) -> str:
    """Name of the ``MujocoArmDynamics`` array a controller adds: ``bias_net`` or ``bias``."""
    return "bias_net" if getattr(cfg, "compensate_passive", True) else "bias"


def pd_hold_torque(dyn: Any, q_hold: np.ndarray, kp: np.ndarray, kd: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """Position hold: tau = M (kp (q_hold - q) - kd qd) + bias [Nm] (decoupled, critically damped with the
    spec gains: a joint moving at v stops within ~v / (e sqrt(kp))). Non-finite M → bias only (the
    caller checks the finiteness of the result)."""
    M = dyn.M
    if not np.all(np.isfinite(M)):
        return np.array(bias, dtype=float)
    return M @ (kp * (q_hold - dyn.q) - kd * dyn.qd) + bias
