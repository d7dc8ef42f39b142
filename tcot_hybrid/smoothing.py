"""Jerk-limited joint-space smoothing with Ruckig, one state-to-state segment at a time.

The smoother turns sparse joint targets (IK solutions of lifted waypoints) into a reference
``q, qd, qdd`` sampled at ``ctrl_dt``. Each :meth:`JointSmoother.set_target` computes a new
time-optimal, time-synchronised Ruckig segment from the *current reference state* (so retargeting
mid-motion is continuous in position, velocity and acceleration); :meth:`JointSmoother.step` then
samples it with ``Trajectory.at_time``, which is cheap.

Ruckig's ``intermediate_positions`` are never used: the pip build sends them to a cloud service.

A segment is a short chain of Ruckig trajectories ("phases"):

1. ``brake`` (only if the current velocity/acceleration exceeds the planning limits, e.g. after a
   push or a reset from a fast measured state): velocity-control interface to zero velocity, using
   the robot's full acceleration/jerk limits so it stops as soon as possible;
2. ``move``: position interface to the target (position-control, synchronisation on);
3. ``stop`` (only if the target velocity is non-zero): velocity interface back to rest, so that the
   reference always ends at rest and "hold at the end" never jumps.

Every input is validated here before Ruckig sees it (:class:`TrajectoryError` naming the field,
joint index and value); Ruckig's own ``validate_input`` and result codes are checked as well, and a
segment whose position extrema leave ``[q_min, q_max]`` is refused. Refused calls leave the
smoother's reference unchanged. :meth:`JointSmoother.brake` is the fault fallback and never refuses
a finite state.
"""
from __future__ import annotations

import math
import numbers
import time
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import numpy as np
import ruckig

from tcot_hybrid.config import require_in_range, require_positive
from tcot_hybrid.errors import TrajectoryError

# Ruckig's sampled states can exceed a bound by rounding only; anything larger is a real excursion.
_LIMIT_TOL = 1e-10


@dataclass(frozen=True, kw_only=True)
class SmoothingConfig:
    """Ruckig planning limits and the start-state check.

    velocity_scale:      fraction of the robot's v_max used for planning, in (0, 1]. Turn down for
                         slower, more trackable motion; up for faster motion (harder to track).
    acceleration_scale:  fraction of a_max used for planning, in (0, 1]. Turn down for gentler starts
                         and stops (smaller torques), up for snappier motion.
    jerk_scale:          fraction of j_max used for planning, in (0, 1]. Turn down for smoother
                         torque profiles (less excitation of a light wrist), up for shorter segments.
    start_tolerance_rad: largest |q_reference - q_measured| accepted by ``check_start`` [rad]
                         (MoveIt uses 0.01). Turn down to refuse plans sooner when tracking is poor;
                         up if a stiff contact keeps the arm slightly off its reference.
    torque_fraction:     with a torque model (the scene's inverse dynamics): the share of each joint's
                         tau_max a planned move may ask for; a move that asks more is slowed down (its
                         limits scaled as a time stretch) until it fits, the rest of tau_max is left to
                         feedback. Down: slower moves, more margin; up: faster, nearer saturation. Why:
                         robosuite's air drag on the Panda gripper asks joint 7 for 13 N m of its 12 at
                         1.3 rad/s (docs/reliability.md, "Findings and fixes"). None: no torque check.
    """

    velocity_scale: float = 0.5
    acceleration_scale: float = 0.5
    jerk_scale: float = 0.5
    start_tolerance_rad: float = 0.01
    torque_fraction: float | None = 0.8

    def __post_init__(self) -> None:
        for name in ("velocity_scale", "acceleration_scale", "jerk_scale"):
            require_in_range(name, getattr(self, name), 0.0, 1.0, low_closed=False,
                             meaning="a fraction of the robot's limit")
        require_positive("start_tolerance_rad", self.start_tolerance_rad)
        if self.torque_fraction is not None:
            require_in_range("torque_fraction", self.torque_fraction, 0.0, 1.0, low_closed=False,
                             meaning="a share of tau_max, or None")


class JointReference(NamedTuple):
    """Reference state for the joint controller at one control tick."""

    q: np.ndarray  # joint positions [rad]
    qd: np.ndarray  # joint velocities [rad/s]
    qdd: np.ndarray  # joint accelerations [rad/s^2]


class SegmentInfo(NamedTuple):
    """What a planning call produced.

    duration_s:          time from now until the target state is reached [s] (brake included)
    total_s:             time until the reference is at rest (adds the stop phase when the target
                         velocity is non-zero) [s]
    brake_s:             length of the leading brake phase, 0 if none was needed [s]
    synchronized:        False when time synchronisation had to be dropped to stay within [q_min, q_max]
    result:              Ruckig result name of the last calculation ("Working" = success)
    compute_s:           wall time spent computing the segment [s]
    limit_excursion_rad: largest excursion beyond [q_min, q_max] along the segment [rad]; always 0 for
                         set_target (refused otherwise), may be > 0 for brake() from a bad state
    time_stretch:        set_target: how many times slower than the planning limits allow the move was made,
                         as asked (``slower``) and, with a torque model, so its torques fit (1 = not slowed)
    torque_ratio:        the move's largest |tau| / (torque_fraction * tau_max) over its samples and joints
                         (at most 1 unless even the slowest allowed stretch did not fit); 0 without a model
    """

    duration_s: float
    total_s: float
    brake_s: float
    synchronized: bool
    result: str
    compute_s: float
    limit_excursion_rad: float
    time_stretch: float = 1.0
    torque_ratio: float = 0.0


class _Phase(NamedTuple):
    trajectory: Any  # ruckig.Trajectory
    t0: float  # start time within the segment [s]
    duration: float  # [s]
    end: JointReference  # exact end state (Ruckig's at_time(duration) is off by rounding)
    velocity_interface: bool  # position_extrema are wrong for these (see _position_bounds)


def _position_bounds(phase: _Phase) -> list[tuple[float, float]]:
    """Per-joint (min, max) position over a phase [rad], computed here from the jerk-constant pieces (brake
    pre-profile + 7-step profile): extrema lie at piece ends or where the (quadratic) velocity crosses zero.

    Ruckig's ``position_extrema`` is not used: with the velocity interface it includes an unset final position
    (0.0), and with the position interface (ruckig 0.19.4) it is short for moves that start while moving: it
    missed the overshoot of one toward a joint limit (it reported 3.705 rad; the trajectory reached 3.768, past
    joint 6's 3.7525), so a commanded reference went past the limit (docs/reliability.md, "Findings and fixes").
    """
    bounds = []
    for prof in phase.trajectory.profiles[0]:
        pieces = []
        brake = prof.brake
        for k in range(2):
            if brake.t[k] > 0:
                pieces.append((brake.t[k], brake.p[k], brake.v[k], brake.a[k], brake.j[k]))
        for k in range(7):
            if prof.t[k] > 0:
                pieces.append((prof.t[k], prof.p[k], prof.v[k], prof.a[k], prof.j[k]))
        values = [prof.p[0] if not pieces else pieces[0][1], prof.p[7]]
        for dt, p0, v0, a0, j in pieces:
            taus = [dt]
            if j != 0.0:
                disc = a0 * a0 - 2.0 * j * v0
                if disc >= 0.0:
                    r = math.sqrt(disc)
                    taus += [(-a0 + r) / j, (-a0 - r) / j]
            elif a0 != 0.0:
                taus.append(-v0 / a0)
            for tau in taus:
                if 0.0 <= tau <= dt:
                    values.append(p0 + tau * (v0 + tau * (a0 / 2.0 + tau * j / 6.0)))
        bounds.append((min(values), max(values)))
    return bounds


def _vector(field: str, value: object, dof: int) -> np.ndarray:
    """``value`` as a finite float vector of length ``dof``; TrajectoryError naming field/joint/value otherwise."""
    if value is None or isinstance(value, (str, bytes)):
        raise TrajectoryError(f"{field} must be a numeric vector of {dof} joint values, got {value!r}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TrajectoryError(f"{field} must be a numeric vector of {dof} joint values, got {value!r}") from exc
    if arr.ndim != 1 or arr.shape[0] != dof:
        raise TrajectoryError(f"{field} must have shape ({dof},) (one value per joint), got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        j = int(bad[0])
        raise TrajectoryError(f"{field}[{j}] = {arr[j]} is not finite (joint {j})")
    return arr


def _frozen(arr: np.ndarray) -> np.ndarray:
    out = np.array(arr, dtype=float)
    out.setflags(write=False)
    return out


class JointSmoother:
    """Online, jerk-limited joint reference generator (Ruckig, offline calculate + ``at_time``).

    Limits are per joint, SI units: q_min/q_max [rad], v_max [rad/s], a_max [rad/s^2],
    j_max [rad/s^3]. The planning limits are these times the config's scales; braking uses the full
    a_max/j_max. ``ctrl_dt`` [s] is the sampling period of :meth:`step`.
    """

    def __init__(
        self,
        *,
        q_min: np.ndarray,
        q_max: np.ndarray,
        v_max: np.ndarray,
        a_max: np.ndarray,
        j_max: np.ndarray,
        ctrl_dt: float,
        config: SmoothingConfig = SmoothingConfig(),
        tau_max: np.ndarray | None = None,
        torques: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None,
    ) -> None:
        if not isinstance(config, SmoothingConfig):
            raise TrajectoryError(f"config must be a SmoothingConfig, got {type(config).__name__}")
        try:
            arr = np.asarray(q_min, dtype=float)
        except (TypeError, ValueError) as exc:
            raise TrajectoryError(f"q_min must be a numeric vector, got {q_min!r}") from exc
        if arr.ndim != 1 or arr.shape[0] < 1:
            raise TrajectoryError(f"q_min must be a 1-D vector with one value per joint, got shape {arr.shape}")
        dof = int(arr.shape[0])
        self.q_min = _frozen(_vector("q_min", q_min, dof))
        self.q_max = _frozen(_vector("q_max", q_max, dof))
        bad = np.flatnonzero(~(self.q_min < self.q_max))
        if bad.size:
            j = int(bad[0])
            raise TrajectoryError(f"joint {j}: need q_min < q_max, got q_min = {self.q_min[j]}, q_max = {self.q_max[j]} [rad]")
        limits = {}
        for name, value, unit in (("v_max", v_max, "rad/s"), ("a_max", a_max, "rad/s^2"), ("j_max", j_max, "rad/s^3")):
            vec = _vector(name, value, dof)
            bad = np.flatnonzero(~(vec > 0))
            if bad.size:
                j = int(bad[0])
                raise TrajectoryError(f"{name}[{j}] = {vec[j]} must be > 0 [{unit}] (joint {j})")
            limits[name] = _frozen(vec)
        self.v_max, self.a_max, self.j_max = limits["v_max"], limits["a_max"], limits["j_max"]
        if isinstance(ctrl_dt, bool) or not isinstance(ctrl_dt, (int, float, np.floating, np.integer)) or not (
            math.isfinite(ctrl_dt) and ctrl_dt > 0
        ):
            raise TrajectoryError(f"ctrl_dt must be a finite number > 0 [s], got {ctrl_dt!r}")
        self.dof = dof
        self.ctrl_dt = float(ctrl_dt)
        self.config = config
        self.v_plan = _frozen(self.v_max * config.velocity_scale)
        self.a_plan = _frozen(self.a_max * config.acceleration_scale)
        self.j_plan = _frozen(self.j_max * config.jerk_scale)
        # torque model: torques(q, qd, qdd) -> (N, dof) [Nm] for (N, dof) states (the scene's inverse dynamics)
        self._torques = torques if config.torque_fraction is not None else None
        if self._torques is not None:
            if tau_max is None:
                raise TrajectoryError("a torque model needs tau_max (one torque limit per joint [N m])")
            tau = _vector("tau_max", tau_max, dof)
            bad = np.flatnonzero(~(tau > 0))
            if bad.size:
                raise TrajectoryError(f"tau_max[{int(bad[0])}] = {tau[bad[0]]} must be > 0 [N m]")
            self._tau_budget = _frozen(tau * config.torque_fraction)
        self._otg = ruckig.Ruckig(dof)
        self._phases: list[_Phase] = []
        self._rest: JointReference | None = None  # state held when no phase is active
        self._tick = 0  # ticks since the segment started; time = tick * ctrl_dt (no drift)

    @classmethod
    def from_spec(cls, spec: Any, *, ctrl_dt: float, config: SmoothingConfig = SmoothingConfig(),
                  torques: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None) -> JointSmoother:
        """Smoother for a robot spec (anything with q_min, q_max, v_max, a_max, j_max and tau_max arrays);
        ``torques`` is the scene's inverse dynamics (e.g. ``MujocoArmDynamics.inverse_torques``)."""
        return cls(q_min=spec.q_min, q_max=spec.q_max, v_max=spec.v_max, a_max=spec.a_max, j_max=spec.j_max,
                   ctrl_dt=ctrl_dt, config=config, tau_max=spec.tau_max, torques=torques)

    # -- state ------------------------------------------------------------------------------------------

    @property
    def _time(self) -> float:
        return self._tick * self.ctrl_dt

    @property
    def _total(self) -> float:
        return self._phases[-1].t0 + self._phases[-1].duration if self._phases else 0.0

    @property
    def done(self) -> bool:
        """True once the reference is at rest at the end of the last segment (or nothing was planned)."""
        return self._time >= self._total

    @property
    def time_remaining(self) -> float:
        """Time until the reference is at rest [s]."""
        return max(0.0, self._total - self._time)

    @property
    def reference(self) -> JointReference:
        """The current reference state (what the last step() returned, or the reset state)."""
        return self._sample(self._time)

    def _require_started(self) -> None:
        if self._rest is None:
            raise TrajectoryError("JointSmoother has no state yet: call reset(q_measured) first")

    def _sample(self, t: float) -> JointReference:
        self._require_started()
        for phase in self._phases:
            if t < phase.t0 + phase.duration:
                q, qd, qdd = phase.trajectory.at_time(max(0.0, t - phase.t0))
                return JointReference(np.array(q), np.array(qd), np.array(qdd))
        end = self._phases[-1].end if self._phases else self._rest
        return JointReference(end.q.copy(), end.qd.copy(), end.qdd.copy())

    # -- Ruckig -----------------------------------------------------------------------------------------

    def _input(self, state: JointReference, v: np.ndarray, a: np.ndarray, j: np.ndarray) -> Any:
        inp = ruckig.InputParameter(self.dof)
        inp.current_position = state.q.tolist()
        inp.current_velocity = state.qd.tolist()
        inp.current_acceleration = state.qdd.tolist()
        inp.max_velocity = v.tolist()
        inp.max_acceleration = a.tolist()
        inp.max_jerk = j.tolist()
        return inp

    def _calculate(self, inp: Any, what: str) -> tuple[Any, str]:
        try:
            if not self._otg.validate_input(inp, False, True):
                raise TrajectoryError(f"Ruckig validate_input refused the {what} input")
            trajectory = ruckig.Trajectory(self.dof)
            result = self._otg.calculate(inp, trajectory)
        except ruckig.RuckigError as exc:
            raise TrajectoryError(f"Ruckig refused the {what} segment: {str(exc).strip()}") from exc
        except ValueError as exc:
            # The pip binding has no enum member for some codes (e.g. -101 ErrorTrajectoryDuration:
            # duration > 7.6e3 s, limits far too small) and raises "-101 is not a valid Result".
            raise TrajectoryError(f"Ruckig failed on the {what} segment with result code: {exc}") from exc
        if result != ruckig.Result.Working:
            raise TrajectoryError(f"Ruckig could not compute the {what} segment: result {result.name}")
        if not math.isfinite(trajectory.duration) or trajectory.duration < 0:
            raise TrajectoryError(f"Ruckig returned a {what} segment of invalid duration {trajectory.duration}")
        return trajectory, result.name

    def _stop_phase(self, state: JointReference, t0: float, *, a: np.ndarray, j: np.ndarray, what: str) -> tuple[_Phase, str]:
        """Velocity-interface trajectory from ``state`` to rest, each joint as fast as ``a``/``j`` allow."""
        inp = self._input(state, np.maximum(self.v_max, np.abs(state.qd)), a, j)
        inp.control_interface = ruckig.ControlInterface.Velocity
        inp.synchronization = ruckig.Synchronization.No
        inp.target_velocity = [0.0] * self.dof
        inp.target_acceleration = [0.0] * self.dof
        trajectory, name = self._calculate(inp, what)
        q_end, _, _ = trajectory.at_time(trajectory.duration)
        zero = np.zeros(self.dof)
        return _Phase(trajectory, t0, trajectory.duration, JointReference(np.array(q_end), zero, zero.copy()), True), name

    def _excursion(self, phases: list[_Phase]) -> tuple[float, int, float]:
        """Largest excursion beyond [q_min, q_max] over ``phases``: (amount [rad], joint, extreme value)."""
        worst = (0.0, -1, 0.0)
        for phase in phases:
            for j, (lo, hi) in enumerate(_position_bounds(phase)):
                over, under = hi - self.q_max[j], self.q_min[j] - lo
                if over > worst[0]:
                    worst = (over, j, hi)
                if under > worst[0]:
                    worst = (under, j, lo)
        return worst

    def _refuse_excursion(self, phases: list[_Phase], what: str) -> None:
        amount, j, value = self._excursion(phases)
        if amount > _LIMIT_TOL:
            raise TrajectoryError(
                f"{what}: joint {j} would reach {value:.6g} rad, outside [q_min, q_max] = "
                f"[{self.q_min[j]:.6g}, {self.q_max[j]:.6g}] rad (by {amount:.3g} rad); "
                f"the current state cannot be stopped inside the limits — call brake()"
            )

    def _check_state(self, q: object, qd: object, qdd: object, *, within_limits: bool) -> JointReference:
        qv = _vector("q", q, self.dof)
        qdv = np.zeros(self.dof) if qd is None else _vector("qd", qd, self.dof)
        qddv = np.zeros(self.dof) if qdd is None else _vector("qdd", qdd, self.dof)
        if within_limits:
            bad = np.flatnonzero((qv < self.q_min) | (qv > self.q_max))
            if bad.size:
                j = int(bad[0])
                raise TrajectoryError(
                    f"q[{j}] = {qv[j]:.6g} rad is outside [q_min, q_max] = [{self.q_min[j]:.6g}, {self.q_max[j]:.6g}] "
                    f"(joint {j}); use brake(q, qd) to stop from an out-of-limit state"
                )
        return JointReference(qv, qdv, qddv)

    def _beyond_plan(self, state: JointReference) -> bool:
        return bool(
            np.any(np.abs(state.qd) > self.v_plan * (1 + 1e-12)) or np.any(np.abs(state.qdd) > self.a_plan * (1 + 1e-12))
        )

    def _install(self, phases: list[_Phase], rest: JointReference) -> None:
        self._phases = phases
        self._rest = rest
        self._tick = 0

    # -- public API -------------------------------------------------------------------------------------

    def reset(self, q: np.ndarray, qd: np.ndarray | None = None, qdd: np.ndarray | None = None) -> SegmentInfo:
        """Start from a measured state (velocity/acceleration zero unless given).

        q must lie within [q_min, q_max]. A moving state is brought to rest (planning limits, or the
        full limits if it already exceeds the planning limits); the stop must stay within the
        position limits. Raises TrajectoryError and leaves the smoother unchanged otherwise.
        """
        state = self._check_state(q, qd, qdd, within_limits=True)
        start = time.perf_counter()
        if not np.any(state.qd) and not np.any(state.qdd):
            self._install([], state)
            return SegmentInfo(0.0, 0.0, 0.0, True, "Working", time.perf_counter() - start, 0.0)
        fast = self._beyond_plan(state)
        a, j = (self.a_max, self.j_max) if fast else (self.a_plan, self.j_plan)
        phase, name = self._stop_phase(state, 0.0, a=a, j=j, what="reset stop")
        self._refuse_excursion([phase], "reset")
        self._install([phase], state)
        return SegmentInfo(phase.duration, phase.duration, phase.duration, True, name, time.perf_counter() - start, 0.0)

    def set_target(self, q_target: np.ndarray, qd_target: np.ndarray | None = None, *, slower: float = 1.0
                   ) -> SegmentInfo:
        """Retarget online: a new segment from the current reference state to ``q_target`` [rad].

        ``qd_target`` [rad/s] (default zero) must be within the planning velocity limits; the
        reference then comes to rest after passing the target. ``slower`` (>= 1): the move planned that many times
        slower (the planning limits scaled v / k, a / k^2, j / k^3), e.g. a guarded move that must not strike what it
        meets. Raises TrajectoryError (reference unchanged) for invalid input, Ruckig errors, or segments that would
        leave [q_min, q_max].
        """
        if isinstance(slower, bool) or not isinstance(slower, numbers.Real) or not 1.0 <= slower < math.inf:
            raise TrajectoryError(f"slower must be a finite number >= 1 (how many times slower a move is planned), "
                                  f"got {slower!r}")
        self._require_started()
        target = _vector("q_target", q_target, self.dof)
        bad = np.flatnonzero((target < self.q_min) | (target > self.q_max))
        if bad.size:
            j = int(bad[0])
            raise TrajectoryError(
                f"q_target[{j}] = {target[j]:.6g} rad is outside [q_min, q_max] = "
                f"[{self.q_min[j]:.6g}, {self.q_max[j]:.6g}] (joint {j})"
            )
        target_v = np.zeros(self.dof) if qd_target is None else _vector("qd_target", qd_target, self.dof)
        bad = np.flatnonzero(np.abs(target_v) > self.v_plan)
        if bad.size:
            j = int(bad[0])
            raise TrajectoryError(
                f"qd_target[{j}] = {target_v[j]:.6g} rad/s exceeds the planning velocity limit "
                f"{self.v_plan[j]:.6g} rad/s (joint {j})"
            )
        start = time.perf_counter()
        state = self.reference
        phases: list[_Phase] = []
        t0 = 0.0
        if self._beyond_plan(state):
            brake, _ = self._stop_phase(state, 0.0, a=self.a_max, j=self.j_max, what="pre-brake")
            self._refuse_excursion([brake], "set_target pre-brake")
            phases.append(brake)
            state, t0 = brake.end, brake.duration
        brake_s = t0

        candidate, move, synchronized, name = self._move(phases, t0, state, target, target_v, slower)
        stretch, ratio = slower, 0.0
        if self._torques is not None:
            ratio = self._torque_ratio(move)
            while ratio > 1.0 and stretch < self.MAX_TIME_STRETCH:
                # a k-times slower move asks 1/k^2 of the inertial and drag torques (gravity stays): stretch by the
                # square root of the excess, and again while it does not fit
                stretch = min(self.MAX_TIME_STRETCH, stretch * math.sqrt(ratio) * 1.02)
                try:
                    candidate, move, synchronized, name = self._move(phases, t0, state, target, target_v, stretch)
                except TrajectoryError:
                    break  # keep the last move that was computed (a stretched one Ruckig refused, e.g. too slow)
                ratio = self._torque_ratio(move)
        self._install(candidate, candidate[-1].end)
        duration = t0 + move.duration
        return SegmentInfo(duration, candidate[-1].t0 + candidate[-1].duration, brake_s, synchronized, name,
                           time.perf_counter() - start, 0.0, stretch, ratio)

    # A move is slowed at most this many times for its torques (joints whose gravity load alone exceeds the budget
    # cannot be helped by slowing down; the safety layer saturates them as before).
    MAX_TIME_STRETCH = 4.0
    TORQUE_SAMPLE_S = 0.02  # spacing of the samples a move's torques are checked at [s]
    MAX_TORQUE_SAMPLES = 48

    def _move(self, phases: list[_Phase], t0: float, state: JointReference, target: np.ndarray, target_v: np.ndarray,
              stretch: float) -> tuple[list[_Phase], _Phase, bool, str]:
        """The move (and stop) phases after ``phases`` with the planning limits scaled as a ``stretch``-times slower
        motion (v / k, a / k^2, j / k^3); refused (TrajectoryError) when they would leave [q_min, q_max]."""
        k = stretch
        inp = self._input(state, self.v_plan / k, self.a_plan / k**2, self.j_plan / k**3)
        inp.target_position = target.tolist()
        inp.target_velocity = target_v.tolist()
        inp.target_acceleration = [0.0] * self.dof
        inp.synchronization = ruckig.Synchronization.Time
        synchronized = True
        for attempt in ("synchronised", "unsynchronised"):
            trajectory, name = self._calculate(inp, "move")
            move = _Phase(trajectory, t0, trajectory.duration, JointReference(target.copy(), target_v.copy(), np.zeros(self.dof)), False)
            candidate = [*phases, move]
            if np.any(target_v):
                stop, name = self._stop_phase(move.end, t0 + move.duration, a=self.a_plan / k**2,
                                              j=self.j_plan / k**3, what="stop")
                candidate.append(stop)
            if self._excursion(candidate)[0] <= _LIMIT_TOL or attempt == "unsynchronised":
                break
            # Synchronising slows joints down and can make one swing past its limit; each joint alone
            # does not overshoot a target inside the limits unless it must brake.
            inp.synchronization = ruckig.Synchronization.No
            synchronized = False
        self._refuse_excursion(candidate, "set_target")
        return candidate, move, synchronized, name

    def _torque_ratio(self, move: _Phase) -> float:
        """Largest |tau| / budget over the move's samples (every TORQUE_SAMPLE_S, ends included) and joints."""
        n = int(min(self.MAX_TORQUE_SAMPLES, max(2, math.ceil(move.duration / self.TORQUE_SAMPLE_S) + 1)))
        states = [move.trajectory.at_time(t) for t in np.linspace(0.0, move.duration, n)]
        q, qd, qdd = (np.array([s[i] for s in states]) for i in range(3))
        tau = np.asarray(self._torques(q, qd, qdd), dtype=float)
        if tau.shape != q.shape or not np.isfinite(tau).all():
            raise TrajectoryError(f"the torque model returned {tau.shape} (finite: {bool(np.isfinite(tau).all())}) "
                                  f"for {q.shape} states; expected finite torques of that shape")
        return float((np.abs(tau) / self._tau_budget).max())

    def brake(self, q: np.ndarray | None = None, qd: np.ndarray | None = None, qdd: np.ndarray | None = None) -> SegmentInfo:
        """Fault fallback: stop at zero velocity as fast as the full a_max/j_max allow, then hold.

        Brakes from the current reference state, or from a measured state if ``q`` is given (then
        ``qd``/``qdd`` default to zero). Never refuses a finite state of the right size, even outside
        the position limits; ``limit_excursion_rad`` reports how far beyond them the stop goes.
        """
        if q is None:
            if qd is not None or qdd is not None:
                raise TrajectoryError("brake(): give q together with qd/qdd, or no state at all")
            state = self.reference
        else:
            state = self._check_state(q, qd, qdd, within_limits=False)
        start = time.perf_counter()
        phase, name = self._stop_phase(state, 0.0, a=self.a_max, j=self.j_max, what="brake")
        excursion = self._excursion([phase])[0]
        # A state already outside the limits counts too.
        excursion = max(excursion, float(np.max(np.maximum(state.q - self.q_max, self.q_min - state.q))))
        self._install([phase], phase.end)
        return SegmentInfo(phase.duration, phase.duration, phase.duration, False, name, time.perf_counter() - start, max(0.0, excursion))

    def step(self) -> JointReference:
        """Advance ``ctrl_dt`` along the segment and return the reference there; holds at the end."""
        self._require_started()
        if not self.done:
            self._tick += 1
        return self._sample(self._time)

    def preview(self, n: int) -> np.ndarray:
        """The next ``n`` reference positions (what ``n`` calls of step() would return), shape (n, dof) [rad]."""
        self._require_started()
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise TrajectoryError(f"preview length n must be an integer >= 0, got {n!r}")
        out = np.empty((int(n), self.dof))
        for i in range(int(n)):
            out[i] = self._sample((self._tick + i + 1) * self.ctrl_dt).q
        return out

    def check_start(self, q_measured: np.ndarray) -> None:
        """Refuse (TrajectoryError) if the reference is farther than start_tolerance_rad from ``q_measured``."""
        qm = _vector("q_measured", q_measured, self.dof)
        diff = np.abs(self.reference.q - qm)
        j = int(np.argmax(diff))
        if diff[j] > self.config.start_tolerance_rad:
            raise TrajectoryError(
                f"reference does not start at the measured state: joint {j} differs by {diff[j]:.4g} rad "
                f"(reference {self.reference.q[j]:.6g}, measured {qm[j]:.6g}); allowed "
                f"start_tolerance_rad = {self.config.start_tolerance_rad}"
            )
