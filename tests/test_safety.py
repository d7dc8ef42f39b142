"""Safety layer: refuses non-finite or misshapen torques and references, holds position, never clips silently."""
from __future__ import annotations

import json
import time
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from tcot_hybrid.controllers import Command, make_controller
from tcot_hybrid.dynamics import MujocoArmDynamics
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.robot import load_robot_spec, robot_mjspec
from tcot_hybrid.safety import SafetyConfig, SafetyEvent, SafetyLayer
from tcot_hybrid.smoothing import JointReference


@pytest.fixture(scope="module")
def panda():
    return load_robot_spec("panda")


def fake_dyn(spec, *, q=None, qd=None, t=0.0, M=None, bias=None):
    """The attributes the safety layer reads from MujocoArmDynamics."""
    n = spec.dof
    bias = np.zeros(n) if bias is None else np.asarray(bias, dtype=float)
    return SimpleNamespace(t=t, q=np.array(spec.home_q if q is None else q, dtype=float),
                           qd=np.zeros(n) if qd is None else np.asarray(qd, dtype=float),
                           M=np.eye(n) * 0.5 if M is None else np.asarray(M, dtype=float), bias=bias, bias_net=bias)


def ref_at(q, qd=None, qdd=None):
    q = np.asarray(q, dtype=float)
    return JointReference(q, np.zeros_like(q) if qd is None else np.asarray(qd, float),
                          np.zeros_like(q) if qdd is None else np.asarray(qdd, float))


def test_nominal_command_passes_unchanged(panda):
    safety = SafetyLayer(panda)
    dyn = fake_dyn(panda)
    tau = 0.5 * panda.tau_max * np.linspace(-1, 1, panda.dof)
    out = safety.filter(Command(tau), dyn, ref_at(panda.home_q))
    assert out.status == "ok" and out.events == ()
    np.testing.assert_array_equal(out.tau, tau)
    assert out.tau is not tau, "a fresh array: later changes to the command cannot reach the applied torque"
    assert out.max_ratio == pytest.approx(0.5)
    s = safety.summary()
    assert s["ticks"] == 1 and s["faults"] == 0 and s["saturations"] == 0 and s["max_torque_ratio"] == pytest.approx(0.5)
    # A bare array is accepted as the command too.
    assert safety.filter(tau, dyn, ref_at(panda.home_q)).status == "ok"


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_torque_is_refused_and_position_held(panda, bad):
    safety = SafetyLayer(panda)
    q_safe = panda.home_q + 0.01
    safety.filter(np.zeros(panda.dof), fake_dyn(panda, q=q_safe, t=1.0), ref_at(q_safe))
    tau = np.zeros(panda.dof)
    tau[3] = bad
    q_now = q_safe + 0.02  # moved since: the hold pulls back to the last safe position
    out = safety.filter(Command(tau), fake_dyn(panda, q=q_now, t=1.01), ref_at(q_now))
    assert out.status == "fault" and np.all(np.isfinite(out.tau)) and np.all(np.abs(out.tau) <= panda.tau_max)
    assert np.isnan(out.max_ratio)
    ev = out.events[0]
    assert ev == SafetyEvent(1.01, "nonfinite_torque", "joint4", ev.value, ev.limit)
    assert not np.isfinite(ev.value) and np.isnan(ev.limit)
    assert np.all(out.tau < 0), "pulls every joint back toward q_safe"
    np.testing.assert_array_equal(safety.q_safe, q_safe)
    assert safety.faults == 1 and safety.events[-1] == ev


@pytest.mark.parametrize("field", ["q", "qd", "qdd"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_reference_is_refused(panda, field, bad):
    safety = SafetyLayer(panda)
    arrays = {"q": panda.home_q.copy(), "qd": np.zeros(panda.dof), "qdd": np.zeros(panda.dof)}
    arrays[field][5] = bad
    out = safety.filter(Command(np.ones(panda.dof)), fake_dyn(panda), JointReference(**arrays))
    assert out.status == "fault"
    assert [(e.kind, e.joint) for e in out.events] == [("nonfinite_reference", "joint6")]
    np.testing.assert_allclose(out.tau, 0.0, atol=1e-12)  # at q_safe, at rest, no bias: zero hold torque


def test_wrong_shapes_and_types_are_faults(panda):
    safety = SafetyLayer(panda)
    dyn = fake_dyn(panda)
    good_ref = ref_at(panda.home_q)
    for tau in (np.zeros(3), np.zeros((panda.dof, 1)), None, [0.0] * panda.dof, np.zeros(panda.dof, dtype=int)):
        out = safety.filter(Command(tau), dyn, good_ref)
        assert out.status == "fault" and out.events[0].kind == "bad_torque_shape"
        assert out.tau.shape == (panda.dof,) and np.all(np.isfinite(out.tau))
    out = safety.filter(np.zeros(panda.dof), dyn, JointReference(np.zeros(2), np.zeros(2), np.zeros(2)))
    assert out.status == "fault" and out.events[0].kind == "bad_reference_shape"
    out = safety.filter(np.zeros(panda.dof), dyn, object())
    assert out.status == "fault" and out.events[0].kind == "bad_reference_shape"
    assert safety.faults == 7


def test_saturation_is_reported_never_silent(panda):
    safety = SafetyLayer(panda)
    dyn = fake_dyn(panda)
    ref = ref_at(panda.home_q)
    tau = np.zeros(panda.dof)
    tau[1], tau[6] = -2.0 * panda.tau_max[1], 1.5 * panda.tau_max[6]
    out = safety.filter(tau, dyn, ref)
    assert out.status == "saturated" and out.max_ratio == pytest.approx(2.0)
    assert out.tau[1] == -panda.tau_max[1] and out.tau[6] == panda.tau_max[6] and out.tau[0] == 0.0
    assert [(e.kind, e.joint, e.value, e.limit) for e in out.events] == [
        ("torque_saturated", "joint2", tau[1], -panda.tau_max[1]),
        ("torque_saturated", "joint7", tau[6], panda.tau_max[6]),
    ]
    # Still saturated: counted, not re-logged.
    out2 = safety.filter(tau, dyn, ref)
    assert out2.status == "saturated" and out2.events == ()
    # Released and saturated again: a new event.
    safety.filter(np.zeros(panda.dof), dyn, ref)
    out3 = safety.filter(tau, dyn, ref)
    assert len(out3.events) == 2
    s = safety.summary()
    assert s["saturations"] == 3 and s["saturations_per_joint"]["joint2"] == 3 and s["max_torque_ratio"] == pytest.approx(2.0)
    assert len(safety.events) == 4


def test_exactly_at_the_limit_is_not_saturation(panda):
    safety = SafetyLayer(panda)
    out = safety.filter(np.array(panda.tau_max, dtype=float), fake_dyn(panda), ref_at(panda.home_q))
    assert out.status == "ok" and out.max_ratio == 1.0


def test_huge_finite_values_take_the_exact_path(panda):
    """Dot-product finiteness checks overflow on 1e200; the layer must not call that a fault."""
    safety = SafetyLayer(panda)
    out = safety.filter(np.full(panda.dof, 1e200), fake_dyn(panda), ref_at(np.full(panda.dof, 1e200)))
    assert out.status == "saturated" and np.all(np.abs(out.tau) == panda.tau_max)


def test_hold_degrades_to_bias_then_zero(panda):
    safety = SafetyLayer(panda)
    bias = np.arange(panda.dof, dtype=float)
    out = safety.filter(np.full(panda.dof, np.nan), fake_dyn(panda, M=np.full((7, 7), np.nan), bias=bias),
                        ref_at(panda.home_q))
    assert out.status == "fault" and "hold_nonfinite" not in [e.kind for e in out.events]
    np.testing.assert_allclose(out.tau, bias)  # inertia unusable: bias (gravity) only
    out = safety.filter(np.full(panda.dof, np.nan), fake_dyn(panda, q=np.full(7, np.nan), bias=bias),
                        ref_at(panda.home_q))
    # Measured q is NaN: the last safe q is unknown -> PD term non-finite -> bias only.
    assert [e.kind for e in out.events] == ["nonfinite_torque", "nonfinite_state", "hold_nonfinite"]
    np.testing.assert_allclose(out.tau, bias)
    out = safety.filter(np.full(panda.dof, np.nan), fake_dyn(panda, q=np.full(7, np.nan), bias=np.full(7, np.inf)),
                        ref_at(panda.home_q))
    np.testing.assert_array_equal(out.tau, 0.0)


def test_non_finite_state_is_a_fault_even_with_a_finite_command(panda):
    safety = SafetyLayer(panda)
    safety.filter(np.zeros(7), fake_dyn(panda), ref_at(panda.home_q))
    qd = np.zeros(7)
    qd[4] = np.nan
    out = safety.filter(np.ones(7), fake_dyn(panda, qd=qd), ref_at(panda.home_q))
    assert out.status == "fault" and [(e.kind, e.joint) for e in out.events][:1] == [("nonfinite_state", "joint5")]
    assert np.all(np.isfinite(out.tau))
    np.testing.assert_array_equal(safety.q_safe, panda.home_q)


def test_position_and_velocity_limit_events(panda):
    safety = SafetyLayer(panda, SafetyConfig(position_tolerance_rad=0.001))
    ref = ref_at(panda.home_q)
    q = panda.home_q.copy()
    q[3] = panda.q_max[3] + 0.0005  # inside the tolerance: no event
    assert safety.filter(np.zeros(7), fake_dyn(panda, q=q), ref).events == ()
    q[3] = panda.q_max[3] + 0.01
    q[0] = panda.q_min[0] - 0.02
    qd = np.zeros(7)
    qd[5] = -1.2 * panda.v_max[5]
    out = safety.filter(np.zeros(7), fake_dyn(panda, q=q, qd=qd, t=2.0), ref)
    kinds = {(e.kind, e.joint): e for e in out.events}
    assert kinds[("position_limit", "joint4")].limit == pytest.approx(panda.q_max[3] + 0.001)
    assert kinds[("position_limit", "joint1")].value == q[0]
    assert kinds[("velocity_limit", "joint6")].limit == -panda.v_max[5]
    assert out.status == "ok", "limit events do not change the command"
    assert safety.filter(np.zeros(7), fake_dyn(panda, q=q, qd=qd), ref).events == ()  # edge-triggered
    s = safety.summary()
    assert s["position_violations"] == 2 and s["velocity_violations"] == 2
    assert s["max_position_violation_rad"] == pytest.approx(0.019)
    assert s["max_velocity_ratio"] == pytest.approx(1.2)


def test_event_log_cap_summary_and_json(panda):
    safety = SafetyLayer(panda, SafetyConfig(max_events=5))
    for k in range(8):
        safety.filter(np.full(7, np.nan), fake_dyn(panda, t=0.01 * k), ref_at(panda.home_q))
    assert len(safety.events) == 5 and safety.events_dropped == 3 and safety.faults == 8
    text = json.dumps({"summary": safety.summary(), "events": safety.event_dicts()}, allow_nan=False)
    first = json.loads(text)["events"][0]
    assert first == {"t": 0.0, "kind": "nonfinite_torque", "joint": "joint1", "value": "nan", "limit": "nan",
                     "source": "safety"}
    safety.reset()
    assert safety.summary()["faults"] == 0 and safety.events == [] and safety.q_safe is None


def test_config_validation(panda):
    for bad in ({"hold_kp_scale": 0.0}, {"position_tolerance_rad": -1.0}, {"max_events": 1.5},
                {"velocity_tolerance": float("nan")}):
        with pytest.raises(ConfigError, match=next(iter(bad))):
            SafetyConfig(**bad)


def test_fuzzed_commands_never_yield_unsafe_torque(panda):
    """>= 1,000 fuzzed commands/references: every output finite and within tau_max; every bad input a fault."""
    rng = np.random.default_rng(0)
    safety = SafetyLayer(panda)
    bad_inputs = 0
    for k in range(2000):
        tau = rng.normal(0, 2, panda.dof) * panda.tau_max
        ref = ref_at(panda.home_q + rng.normal(0, 0.1, 7), rng.normal(0, 1, 7), rng.normal(0, 5, 7))
        kind = rng.integers(0, 5)
        if kind == 1:
            tau[rng.integers(7)] = rng.choice([np.nan, np.inf, -np.inf])
        elif kind == 2:
            getattr(ref, ("q", "qd", "qdd")[rng.integers(3)])[rng.integers(7)] = rng.choice([np.nan, np.inf])
        elif kind == 3:
            tau = tau[: rng.integers(0, 7)]
        bad = kind in (1, 2, 3)
        bad_inputs += bad
        dyn = fake_dyn(panda, q=panda.home_q + rng.normal(0, 0.05, 7), qd=rng.normal(0, 1, 7), t=k * 0.01,
                       bias=rng.normal(0, 5, 7))
        out = safety.filter(tau, dyn, ref)
        assert np.all(np.isfinite(out.tau)) and np.all(np.abs(out.tau) <= panda.tau_max)
        assert (out.status == "fault") == bad
    assert safety.faults == bad_inputs > 1000 * 0.5


def test_closed_loop_fault_holds_position_and_recovers(panda):
    """A controller emitting NaN for 1 s mid-motion: the arm holds near the last safe position, no NaN
    reaches MuJoCo; afterwards the (reset) controller resumes."""
    s = robot_mjspec(panda)
    s.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    floor = s.worldbody.add_geom()
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = [2, 2, 0.1]
    cube = s.worldbody.add_body()
    cube.pos = [0.5, 0.25, 0.02]
    cube.add_freejoint()
    g = cube.add_geom()
    g.type = mujoco.mjtGeom.mjGEOM_BOX
    g.size = [0.02] * 3
    m = s.compile()
    d = mujoco.MjData(m)
    dyn = MujocoArmDynamics(m, d, panda)
    d.qpos[dyn.qpos_adr] = panda.home_q
    mujoco.mj_forward(m, d)
    ctrl = make_controller("computed_torque", panda, ctrl_dt=0.01)
    safety = SafetyLayer(panda)
    w = 2 * np.pi * 0.5

    def ref_fn(t):
        return ref_at(panda.home_q + 0.2 * np.sin(w * t), 0.2 * w * np.cos(w * t) * np.ones(7),
                      -0.2 * w * w * np.sin(w * t) * np.ones(7))

    statuses, q_at_fault, drift, costs = [], None, 0.0, []
    last_tau = None
    for k in range(300):
        mujoco.mj_step1(m, d)
        dyn.update()
        ref = ref_fn(d.time)
        cmd = ctrl.compute(dyn, ref)
        if 100 <= k < 200:
            cmd = cmd._replace(tau=cmd.tau * np.nan)
        if k == 200:
            ctrl.reset(dyn, last_tau)  # bumpless resume from the hold torque
            cmd = ctrl.compute(dyn, ref)
        t0 = time.perf_counter()
        out = safety.filter(cmd, dyn, ref)
        costs.append(time.perf_counter() - t0)
        assert np.all(np.isfinite(out.tau))
        if k == 100:
            q_at_fault = safety.q_safe.copy()
        if 100 <= k < 200:
            drift = max(drift, float(np.abs(dyn.q - q_at_fault).max()))
        statuses.append(out.status)
        last_tau = out.tau
        dyn.write_ctrl(out.tau)
        mujoco.mj_step2(m, d)
        for _ in range(4):
            mujoco.mj_step(m, d)
    assert statuses[100:200] == ["fault"] * 100 and set(statuses[200:]) == {"ok"}
    # Critically damped stop from 0.63 rad/s with w = 20 rad/s: v / (e w) = 12 mrad.
    assert drift < 0.02, f"held within {drift * 1e3:.1f} mrad of the last safe position (was moving at 0.6 rad/s)"
    assert np.abs(dyn.q - q_at_fault).max() < 0.3  # did not fall
    assert np.abs(ref_fn(dyn.t).q - dyn.q).max() < 2e-3  # tracking again after recovery
    assert safety.faults == 100 and sum(e.kind == "nonfinite_torque" for e in safety.events) == 100
    assert not any(d.warning[i].number for i in range(len(d.warning)))
    print(f"\nsafety filter median {np.median(costs) * 1e6:.1f} us; hold drift {drift * 1e3:.2f} mrad")
