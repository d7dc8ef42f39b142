"""Safety layer between the controller and the simulator.

Per control tick, ``SafetyLayer.filter(cmd, dyn, reference)``:

1. refuses a torque command that is non-finite or has the wrong shape, a reference (q, qd, qdd)
   that is non-finite or has the wrong shape, and a non-finite measured state: fault → hold position with a PD hold on the last safe
   measured q (``tau = M (kp (q_safe - q) - kd qd) + bias_net``, robot-spec gains); if even that
   is non-finite, gravity/bias only; if that is non-finite too, zero torque;
2. saturates torques beyond ``tau_max`` — never silently: the tick's result says ``"saturated"``,
   carries the events, and the counters record it;
3. watches the measured state: joint position beyond [q_min, q_max] and speed beyond v_max are
   recorded (it cannot undo them; the smoother and controller keep inside).

Events are ``SafetyEvent(t, kind, joint, value, limit)``. Faults are recorded every tick they occur;
saturation and limit events are recorded when a joint *enters* the condition (the per-tick counters
count every tick), so a long saturation does not flood the log. The stored log is capped at
``max_events``; ``events_dropped`` counts the rest. The nominal path allocates one output array and
does a handful of vector operations (~5 us).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from tcot_hybrid.config import require_int, require_nonnegative, require_positive
from tcot_hybrid.controllers.base import pd_hold_torque

STATUS_OK = "ok"
STATUS_SATURATED = "saturated"
STATUS_FAULT = "fault"

# Event kinds.
NONFINITE_TORQUE = "nonfinite_torque"
BAD_TORQUE_SHAPE = "bad_torque_shape"
NONFINITE_REFERENCE = "nonfinite_reference"
BAD_REFERENCE_SHAPE = "bad_reference_shape"
TORQUE_SATURATED = "torque_saturated"
POSITION_LIMIT = "position_limit"
VELOCITY_LIMIT = "velocity_limit"
NONFINITE_STATE = "nonfinite_state"  # measured q or qd non-finite (the simulation diverged)
HOLD_NONFINITE = "hold_nonfinite"  # even the PD hold was non-finite: bias-only or zero torque applied


class SafetyEvent(NamedTuple):
    """One safety event. ``value`` and ``limit`` are in the unit of the kind ([Nm], [rad], [rad/s])."""

    t: float      # simulation time [s]
    kind: str     # one of the kinds above
    joint: str    # arm joint name ("" when not joint-specific)
    value: float  # offending value (NaN/inf for non-finite faults)
    limit: float  # the limit it broke (NaN when not applicable)


class SafeCommand(NamedTuple):
    """Torque to apply this tick and what the layer did to get it.

    tau:       (n,) torques [Nm], always finite and within +-tau_max (a fresh array).
    status:    "ok", "saturated" (some joint clipped to tau_max) or "fault" (command, reference or
               measured state refused, holding position).
    max_ratio: max |tau_cmd| / tau_max of the controller's command this tick [-] (NaN if non-finite).
    events:    events recorded this tick (empty tuple in the nominal path).
    """

    tau: np.ndarray
    status: str
    max_ratio: float
    events: tuple[SafetyEvent, ...]


@dataclass(frozen=True, kw_only=True)
class SafetyConfig:
    """Safety layer settings.

    hold_kp_scale:          multiplies the robot spec's kp [1/s^2] for the fault position hold [-];
                            higher = stiffer hold.
    hold_kd_scale:          multiplies the spec's kd [1/s] for the hold [-]; higher = more damping.
    position_tolerance_rad: how far beyond q_min/q_max a joint may be before an event [rad]; 0 = strict.
    velocity_tolerance:     fraction above v_max tolerated before an event [-]; 0 = strict.
    max_events:             events kept in memory [-]; the rest are only counted.
    """

    hold_kp_scale: float = 1.0
    hold_kd_scale: float = 1.0
    position_tolerance_rad: float = 0.0
    velocity_tolerance: float = 0.0
    max_events: int = 10_000

    def __post_init__(self) -> None:
        require_positive("hold_kp_scale", self.hold_kp_scale)
        require_positive("hold_kd_scale", self.hold_kd_scale)
        require_nonnegative("position_tolerance_rad", self.position_tolerance_rad)
        require_nonnegative("velocity_tolerance", self.velocity_tolerance)
        require_int("max_events", self.max_events, minimum=0)


def _finite_exact(*arrays: np.ndarray) -> bool:
    with np.errstate(all="ignore"):
        return all(bool(np.isfinite(a).all()) for a in arrays)


def _json_float(x: float) -> float | str:
    return x if math.isfinite(x) else str(x)


class SafetyLayer:
    """Checks and saturates arm torques; see the module docstring. ``spec`` is a ``RobotSpec``."""

    def __init__(self, spec: Any, config: SafetyConfig | None = None) -> None:
        self.spec = spec
        self.config = config if config is not None else SafetyConfig()
        cfg = self.config
        n = spec.dof
        self.n = n
        self.joint_names = tuple(spec.arm_joints)
        self._shape = (n,)
        self._tau_max = np.asarray(spec.tau_max, dtype=float).copy()
        self._inv_tau_max = 1.0 / self._tau_max
        self._q_lo = np.asarray(spec.q_min, dtype=float) - cfg.position_tolerance_rad
        self._q_hi = np.asarray(spec.q_max, dtype=float) + cfg.position_tolerance_rad
        self._v_lim = np.asarray(spec.v_max, dtype=float) * (1.0 + cfg.velocity_tolerance)
        self._inv_v_lim = 1.0 / self._v_lim
        self._hold_kp = np.asarray(spec.kp, dtype=float) * cfg.hold_kp_scale
        self._hold_kd = np.asarray(spec.kd, dtype=float) * cfg.hold_kd_scale
        self._buf = np.empty(n)
        self._ones = np.ones(n)
        self.reset()

    def reset(self) -> None:
        """Forget counters, events and the last safe position (new episode)."""
        n = self.n
        self._q_safe: np.ndarray | None = None
        self._sat_active = np.zeros(n, dtype=bool)
        self._pos_active = np.zeros(n, dtype=bool)
        self._vel_active = np.zeros(n, dtype=bool)
        self._any_sat = self._any_pos = self._any_vel = False
        self.events: list[SafetyEvent] = []
        self.events_dropped = 0
        self.ticks = 0
        self.faults = 0
        self.saturations = 0
        self.saturations_per_joint = np.zeros(n, dtype=int)
        self.position_violations = 0
        self.velocity_violations = 0
        self.max_torque_ratio = 0.0
        self.max_position_violation_rad = 0.0
        self.max_velocity_ratio = 0.0

    @property
    def q_safe(self) -> np.ndarray | None:
        """Last measured position [rad] of a tick without fault (the fault hold target)."""
        return self._q_safe

    # -- per tick -------------------------------------------------------------------------------
    def filter(self, cmd: Any, dyn: Any, reference: Any) -> SafeCommand:
        """Check ``cmd`` (a Command or a torque array [Nm]) against ``dyn``'s state and ``reference``."""
        tau = getattr(cmd, "tau", cmd)
        rq, rqd, rqdd = getattr(reference, "q", None), getattr(reference, "qd", None), getattr(reference, "qdd", None)
        shp = self._shape
        tau_ok = type(tau) is np.ndarray and tau.shape == shp and tau.dtype.kind == "f"
        ref_ok = (type(rq) is np.ndarray and rq.shape == shp and rq.dtype.kind == "f"
                  and type(rqd) is np.ndarray and rqd.shape == shp and rqd.dtype.kind == "f"
                  and type(rqdd) is np.ndarray and rqdd.shape == shp and rqdd.dtype.kind == "f")
        t = dyn.t
        q, qd = dyn.q, dyn.qd
        events: list[SafetyEvent] | tuple = ()
        # Measured state: limit margins; their maxima are NaN/inf exactly when q or qd is.
        viol = np.maximum(self._q_lo - q, q - self._q_hi)
        vmax = float(viol.max())
        vr = np.abs(qd)
        vr *= self._inv_v_lim
        vrmax = float(vr.max())
        state_ok = math.isfinite(vmax + vrmax)
        # Command: the saturation ratio is non-finite exactly when tau is; one dot per reference array
        # (an overflow of huge finite values takes the exact path).
        buf = self._buf
        if tau_ok:
            np.abs(tau, out=buf)
            buf *= self._inv_tau_max
            r = float(buf.max())
        fault = not (state_ok and tau_ok and ref_ok
                     and (math.isfinite(r + self._ones @ rq + self._ones @ rqd + self._ones @ rqdd)
                          or _finite_exact(tau, rq, rqd, rqdd)))
        if fault:
            events = self._describe_fault(t, tau, tau_ok, (rq, rqd, rqdd), ref_ok)
            if not state_ok:
                bad = np.flatnonzero(~(np.isfinite(q) & np.isfinite(qd)))
                j = int(bad[0]) if bad.size else 0
                events.append(SafetyEvent(t, NONFINITE_STATE, self.joint_names[j], float(q[j] + qd[j]), float("nan")))
            tau, hold_events = self._hold(dyn, t)
            events.extend(hold_events)
            self.faults += 1
            ratio = float("nan")
            np.abs(tau, out=buf)
            buf *= self._inv_tau_max
            r = float(buf.max())
            status = STATUS_FAULT
        else:
            ratio = r
            if r > self.max_torque_ratio:
                self.max_torque_ratio = r
            status = STATUS_OK
            if self._q_safe is None:
                self._q_safe = np.array(q)
            else:
                np.copyto(self._q_safe, q)
        if r > 1.0:
            events = self._saturate_events(t, tau, buf, events)
            tau = np.clip(tau, -self._tau_max, self._tau_max)
            if not fault:
                status = STATUS_SATURATED
        else:
            tau = tau.copy()
            if self._any_sat:
                self._sat_active[:] = False
                self._any_sat = False
        if state_ok and (vmax > 0.0 or vrmax > self.max_velocity_ratio or self._any_pos or self._any_vel):
            events = self._check_state(t, q, qd, viol, vmax, vr, vrmax, events)
        self.ticks += 1
        if events:
            self._store(events)
            events = tuple(events)
        return SafeCommand(tau, status, ratio, events)

    # -- internals ------------------------------------------------------------------------------
    def _saturate_events(self, t: float, tau: np.ndarray, ratio: np.ndarray, events):
        self.saturations += 1
        over = ratio > 1.0
        self.saturations_per_joint += over
        new = over & ~self._sat_active
        if new.any():
            events = list(events)
            for j in np.flatnonzero(new):
                events.append(SafetyEvent(t, TORQUE_SATURATED, self.joint_names[j], float(tau[j]),
                                          float(np.copysign(self._tau_max[j], tau[j]))))
        self._sat_active = over
        self._any_sat = True
        return events

    def _describe_fault(self, t: float, tau: Any, tau_ok: bool, ref: tuple, ref_ok: bool) -> list[SafetyEvent]:
        events: list[SafetyEvent] = []
        nan = float("nan")
        if not tau_ok:
            shape = getattr(tau, "shape", None)
            events.append(SafetyEvent(t, BAD_TORQUE_SHAPE, "", float(np.size(tau)) if shape is not None else nan,
                                      float(self.n)))
        else:
            bad = np.flatnonzero(~np.isfinite(tau))
            if bad.size:
                j = int(bad[0])
                events.append(SafetyEvent(t, NONFINITE_TORQUE, self.joint_names[j], float(tau[j]), nan))
        if not ref_ok:
            events.append(SafetyEvent(t, BAD_REFERENCE_SHAPE, "", nan, float(self.n)))
        else:
            for a in ref:
                bad = np.flatnonzero(~np.isfinite(a))
                if bad.size:
                    j = int(bad[0])
                    events.append(SafetyEvent(t, NONFINITE_REFERENCE, self.joint_names[j], float(a[j]), nan))
                    break
        return events

    def _hold(self, dyn: Any, t: float) -> tuple[np.ndarray, list[SafetyEvent]]:
        """PD hold on the last safe q; bias only; zeros — the first that is finite."""
        q_hold = self._q_safe if self._q_safe is not None else np.asarray(dyn.q, dtype=float)
        with np.errstate(all="ignore"):
            tau = pd_hold_torque(dyn, q_hold, self._hold_kp, self._hold_kd, dyn.bias_net)
        if np.all(np.isfinite(tau)):
            return tau, []
        bias = np.array(dyn.bias_net, dtype=float)
        if np.all(np.isfinite(bias)):
            return bias, [SafetyEvent(t, HOLD_NONFINITE, "", float("nan"), float("nan"))]
        return np.zeros(self.n), [SafetyEvent(t, HOLD_NONFINITE, "", float("nan"), float("nan"))]

    def _check_state(self, t, q, qd, viol, vmax, vr, vrmax, events):
        if vmax > 0.0:
            self.position_violations += 1
            if vmax > self.max_position_violation_rad:
                self.max_position_violation_rad = vmax
            over = viol > 0.0
            new = over & ~self._pos_active
            if new.any():
                events = list(events)
                for j in np.flatnonzero(new):
                    lim = self._q_lo[j] if q[j] < self._q_lo[j] else self._q_hi[j]
                    events.append(SafetyEvent(t, POSITION_LIMIT, self.joint_names[j], float(q[j]), float(lim)))
            self._pos_active = over
            self._any_pos = True
        elif self._any_pos:
            self._pos_active[:] = False
            self._any_pos = False
        if vrmax > self.max_velocity_ratio:
            self.max_velocity_ratio = vrmax
        if vrmax > 1.0:
            self.velocity_violations += 1
            over = vr > 1.0
            new = over & ~self._vel_active
            if new.any():
                events = list(events)
                for j in np.flatnonzero(new):
                    events.append(SafetyEvent(t, VELOCITY_LIMIT, self.joint_names[j], float(qd[j]),
                                              float(np.copysign(self._v_lim[j], qd[j]))))
            self._vel_active = over
            self._any_vel = True
        elif self._any_vel:
            self._vel_active[:] = False
            self._any_vel = False
        return events

    def _store(self, events) -> None:
        room = self.config.max_events - len(self.events)
        if room >= len(events):
            self.events.extend(events)
        else:
            self.events.extend(events[:max(room, 0)])
            self.events_dropped += len(events) - max(room, 0)

    # -- reporting ------------------------------------------------------------------------------
    def summary(self) -> dict:
        """Counters as plain JSON-able values."""
        return {
            "ticks": self.ticks,
            "faults": self.faults,
            "saturations": self.saturations,
            "saturations_per_joint": {n: int(c) for n, c in zip(self.joint_names, self.saturations_per_joint)},
            "max_torque_ratio": _json_float(self.max_torque_ratio),
            "position_violations": self.position_violations,
            "max_position_violation_rad": _json_float(self.max_position_violation_rad),
            "velocity_violations": self.velocity_violations,
            "max_velocity_ratio": _json_float(self.max_velocity_ratio),
            "events": len(self.events),
            "events_dropped": self.events_dropped,
        }

    def event_dicts(self) -> list[dict]:
        """Stored events as JSON-able dicts ({"t", "kind", "joint", "value", "limit", "source": "safety"})."""
        return [{"t": round(e.t, 4), "kind": e.kind, "joint": e.joint, "value": _json_float(e.value),
                 "limit": _json_float(e.limit), "source": "safety"} for e in self.events]
