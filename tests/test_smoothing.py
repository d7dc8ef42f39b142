"""Ruckig joint smoothing: limits, exact arrival, continuous retargeting, fuzzed invalid input
(RELIABILITY rows 9 and 10), start-state check, braking."""
from __future__ import annotations

import os

# Before anything imports mujoco (GL backend is chosen at import; tcot_hybrid.camera/robot import it).
os.environ.setdefault("MUJOCO_GL", "egl")

import time

import numpy as np
import pytest

from tcot_hybrid.errors import ConfigError, TrajectoryError
from tcot_hybrid.smoothing import JointReference, JointSmoother, SmoothingConfig

# Franka Panda datasheet limits (7 DoF); the smoother only needs arrays, not the robot model.
Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
V_MAX = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
A_MAX = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])
J_MAX = np.array([7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0])
DT = 0.01
DOF = 7
TOL = 1e-9


def make(config: SmoothingConfig = SmoothingConfig(), **overrides) -> JointSmoother:
    kw = dict(q_min=Q_MIN, q_max=Q_MAX, v_max=V_MAX, a_max=A_MAX, j_max=J_MAX, ctrl_dt=DT, config=config)
    kw.update(overrides)
    return JointSmoother(**kw)


def run_to_end(s: JointSmoother, max_ticks: int = 100_000) -> list[JointReference]:
    out = []
    while not s.done:
        out.append(s.step())
        assert len(out) < max_ticks
    return out


def assert_within(s: JointSmoother, refs: list[JointReference], v_lim=None, a_lim=None) -> tuple[float, float, float]:
    """Every sample within q/v/a limits (+1e-9); returns the worst ratios |qd|/v, |qdd|/a and the q excursion."""
    v_lim = s.v_plan if v_lim is None else v_lim
    a_lim = s.a_plan if a_lim is None else a_lim
    q = np.array([r.q for r in refs])
    qd = np.array([r.qd for r in refs])
    qdd = np.array([r.qdd for r in refs])
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(qd)) and np.all(np.isfinite(qdd))
    excursion = max(float(np.max(q - Q_MAX)), float(np.max(Q_MIN - q)))
    assert excursion <= TOL, f"position limit exceeded by {excursion}"
    assert np.all(np.abs(qd) <= v_lim + TOL), f"velocity limit exceeded: {np.max(np.abs(qd) - v_lim)}"
    assert np.all(np.abs(qdd) <= a_lim + TOL), f"acceleration limit exceeded: {np.max(np.abs(qdd) - a_lim)}"
    return float(np.max(np.abs(qd) / v_lim)), float(np.max(np.abs(qdd) / a_lim)), excursion


def random_q(rng, margin: float = 0.0) -> np.ndarray:
    return rng.uniform(Q_MIN + margin, Q_MAX - margin)


def random_moving_state(rng, s: JointSmoother):
    """A state within the planning limits whose velocity can be brought to the limit without overshoot."""
    a0 = rng.uniform(-0.9, 0.9, DOF) * s.a_plan
    v_room = 0.95 * s.v_plan - a0 ** 2 / (2 * s.j_plan)
    v0 = rng.uniform(-1.0, 1.0, DOF) * v_room
    return random_q(rng, margin=0.6), v0, a0


def test_random_problems_stay_within_limits_and_arrive_exactly():
    rng = np.random.default_rng(0)
    s = make()
    n, worst_v, worst_a, n_samples, unsync = 0, 0.0, 0.0, 0, 0
    for i in range(300):
        if i % 2:
            q0, v0, a0 = random_moving_state(rng, s)
            s.reset(q0, v0, a0)
        else:
            s.reset(random_q(rng))
        target = random_q(rng)
        if i % 10 == 0:  # targets exactly on the limits
            target = np.where(rng.random(DOF) < 0.5, Q_MIN, Q_MAX)
        info = s.set_target(target)
        unsync += not info.synchronized
        refs = run_to_end(s)
        rv, ra, _ = assert_within(s, refs)
        worst_v, worst_a = max(worst_v, rv), max(worst_a, ra)
        n += 1
        n_samples += len(refs)
        # Target reached exactly, at rest, at the announced time.
        np.testing.assert_array_equal(refs[-1].q, target)
        np.testing.assert_array_equal(refs[-1].qd, np.zeros(DOF))
        np.testing.assert_array_equal(refs[-1].qdd, np.zeros(DOF))
        assert len(refs) == int(np.ceil(info.total_s / DT - 1e-9)), (len(refs), info)
        # Holds at the end.
        np.testing.assert_array_equal(s.step().q, target)
        assert s.time_remaining == 0.0
    print(
        f"{n} random problems ({n_samples} samples at ctrl_dt): max |qd|/v_plan {worst_v:.6f}, "
        f"max |qdd|/a_plan {worst_a:.6f}; {unsync} needed unsynchronised fallback"
    )


def test_retargeting_mid_motion_is_continuous_and_within_limits():
    rng = np.random.default_rng(1)
    s = make()
    s.reset(random_q(rng, margin=0.3))
    s.set_target(random_q(rng))
    worst_dq, worst_dv, n_retargets, n_samples = 0.0, 0.0, 0, 0
    prev = s.reference
    samples = [prev]
    for _ in range(400):
        for _ in range(int(rng.integers(1, 40))):
            cur = s.step()
            samples.append(cur)
            prev = cur
        before = s.reference
        np.testing.assert_array_equal(before.q, prev.q)
        s.set_target(random_q(rng, margin=0.0 if rng.random() < 0.2 else 0.3))
        n_retargets += 1
        after0 = s.reference  # new segment starts exactly at the old reference state
        np.testing.assert_allclose(after0.q, before.q, atol=1e-12)
        np.testing.assert_allclose(after0.qd, before.qd, atol=1e-12)
        np.testing.assert_allclose(after0.qdd, before.qdd, atol=1e-9)
        first = s.step()
        samples.append(first)
        # No jump between the last sample of the old segment and the first of the new one.
        dq = np.abs(first.q - before.q) / (s.v_plan * DT)
        dv = np.abs(first.qd - before.qd) / (s.a_plan * DT)
        worst_dq, worst_dv = max(worst_dq, dq.max()), max(worst_dv, dv.max())
        assert np.all(dq <= 1 + 1e-9) and np.all(dv <= 1 + 1e-9)
        prev = first
    samples += run_to_end(s)
    n_samples = len(samples)
    assert_within(s, samples)
    print(
        f"{n_retargets} retargets mid-motion, {n_samples} samples: max |dq|/(v dt) {worst_dq:.3f}, "
        f"max |dqd|/(a dt) {worst_dv:.3f}"
    )


def test_preview_matches_future_steps():
    s = make()
    s.reset(np.zeros(DOF) + (Q_MIN + Q_MAX) / 2)
    s.set_target(Q_MAX - 0.1)
    for _ in range(7):
        s.step()
    pv = s.preview(30)
    assert pv.shape == (30, DOF)
    steps = np.array([s.step().q for _ in range(30)])
    np.testing.assert_array_equal(pv, steps)
    run_to_end(s)
    np.testing.assert_array_equal(s.preview(3), np.tile(Q_MAX - 0.1, (3, 1)))
    assert s.preview(0).shape == (0, DOF)


def test_nonzero_target_velocity_passes_target_then_rests():
    s = make()
    mid = (Q_MIN + Q_MAX) / 2
    s.reset(mid)
    vt = 0.3 * s.v_plan
    info = s.set_target(mid + 0.2, vt)
    refs = run_to_end(s)
    assert info.total_s > info.duration_s
    k = int(np.floor(info.duration_s / DT))
    assert np.all(np.abs(refs[k - 1].q - (mid + 0.2)) <= vt * DT + 1e-9)
    np.testing.assert_array_equal(refs[-1].qd, np.zeros(DOF))
    assert_within(s, refs)


def test_check_start_refuses_a_start_002_rad_off():
    s = make()
    q0 = (Q_MIN + Q_MAX) / 2
    s.reset(q0)
    s.set_target(q0 + 0.3)
    off = q0.copy()
    off[3] += 0.02
    with pytest.raises(TrajectoryError, match="joint 3 differs by 0.02"):
        s.check_start(off)
    near = q0.copy()
    near[3] += 0.005
    s.check_start(near)  # within MoveIt's 0.01 rad
    with pytest.raises(TrajectoryError):
        s.check_start(np.full(DOF, np.nan))


def test_push_beyond_velocity_limit_brakes_then_continues():
    s = make()
    q0 = (Q_MIN + Q_MAX) / 2
    v_push = 1.5 * s.v_plan * np.sign(np.arange(DOF) % 2 - 0.5)  # beyond planning limits, within v_max
    s.reset(q0, v_push)
    target = q0 + 0.4
    info = s.set_target(target)
    assert info.brake_s > 0
    refs = run_to_end(s)
    n_brake = int(np.floor(info.brake_s / DT))  # samples taken at t <= brake_s
    speed = np.array([np.abs(r.qd) for r in refs[:n_brake]])
    assert np.all(np.diff(speed, axis=0) <= 1e-9), "brake must not speed any joint up"
    assert_within(s, refs[:n_brake], v_lim=np.abs(v_push), a_lim=s.a_max)
    assert_within(s, refs[n_brake:])
    np.testing.assert_array_equal(refs[-1].q, target)


def test_brake_stops_faster_than_planned_stop_and_accepts_bad_states():
    s = make()
    q0 = (Q_MIN + Q_MAX) / 2
    s.reset(q0)
    s.set_target(q0 + 1.0)
    for _ in range(30):
        s.step()
    moving = s.reference
    assert np.abs(moving.qd).max() > 0.1
    info = s.brake()
    refs = run_to_end(s)
    np.testing.assert_array_equal(refs[-1].qd, np.zeros(DOF))
    assert_within(s, refs, v_lim=s.v_plan, a_lim=s.a_max)
    normal = make()
    normal.reset(moving.q, moving.qd, moving.qdd)
    assert info.duration_s < normal.time_remaining
    print(f"brake from {np.abs(moving.qd).max():.2f} rad/s: {info.duration_s * 1e3:.0f} ms (planned stop {normal.time_remaining * 1e3:.0f} ms)")

    # Measured state already beyond the limits and moving outward: still brakes, reports the excursion.
    q_bad = Q_MAX + 0.05
    info = s.brake(q_bad, np.full(DOF, 0.5))
    assert info.limit_excursion_rad > 0.05
    refs = run_to_end(s)
    np.testing.assert_array_equal(refs[-1].qd, np.zeros(DOF))
    # ... and only brake() accepts it: reset refuses to start there.
    with pytest.raises(TrajectoryError, match="outside"):
        s.reset(q_bad)


def test_state_that_cannot_stop_inside_limits_is_refused_and_reference_kept():
    s = make()
    q0 = (Q_MIN + Q_MAX) / 2
    s.reset(q0)
    s.set_target(q0 + 0.2)
    before = s.reference
    q_edge = Q_MAX - 0.001
    with pytest.raises(TrajectoryError, match="cannot be stopped inside the limits"):
        s.reset(q_edge, s.v_plan * 0.9)
    np.testing.assert_array_equal(s.reference.q, before.q)


def test_tiny_limits_make_ruckig_fail_with_typed_error():
    s = make(v_max=np.full(DOF, 1e-9), a_max=np.full(DOF, 1e-9), j_max=np.full(DOF, 1e-9))
    s.reset((Q_MIN + Q_MAX) / 2)
    with pytest.raises(TrajectoryError, match="Ruckig"):
        s.set_target(Q_MAX)


def test_must_reset_before_use():
    s = make()
    for call in (s.step, lambda: s.set_target(np.zeros(DOF)), lambda: s.preview(2), lambda: s.brake()):
        with pytest.raises(TrajectoryError, match="reset"):
            call()


def _invalid_values(rng, good: np.ndarray, *, lo=None, hi=None, positive=False):
    """One invalid variant of a per-joint vector."""
    kind = int(rng.integers(9 if (lo is not None or positive) else 7))
    bad = good.astype(float).copy()
    j = int(rng.integers(len(good)))
    if kind == 0:
        bad[j] = np.nan
    elif kind == 1:
        bad[j] = rng.choice([np.inf, -np.inf])
    elif kind == 2:
        return np.resize(bad, len(good) + int(rng.choice([-1, 1, 2, -len(good)])))
    elif kind == 3:
        return bad.reshape(1, -1)
    elif kind == 4:
        return rng.choice(np.array([None, "abc", object(), {"a": 1}], dtype=object))
    elif kind == 5:
        return [str(x) for x in bad[:-1]] + ["x"]
    elif kind == 6:
        return float(bad[0]) if rng.random() < 0.5 else np.zeros((len(good), 2))
    elif positive:
        bad[j] = 0.0 if kind == 7 else -abs(rng.normal()) - 1e-12
    else:
        bad[j] = hi[j] + 10 ** rng.uniform(-8, 1) if kind == 7 else lo[j] - 10 ** rng.uniform(-8, 1)
    return bad


def test_fuzzed_invalid_inputs_all_raise_trajectory_error():
    rng = np.random.default_rng(3)
    base = make()
    q_mid = (Q_MIN + Q_MAX) / 2
    base.reset(q_mid)
    base.set_target(q_mid + 0.3)
    for _ in range(5):
        base.step()
    counts: dict[str, int] = {}
    crashes = []
    n = 0
    limits = dict(q_min=Q_MIN, q_max=Q_MAX, v_max=V_MAX, a_max=A_MAX, j_max=J_MAX)
    while n < 12_000:
        case = int(rng.integers(8))
        ref_before = base.reference
        try:
            if case == 0:  # constructor limits
                field = str(rng.choice(list(limits)))
                kw = dict(limits)
                if field in ("q_min", "q_max") and rng.random() < 0.3:  # empty or inverted range
                    kw["q_min"], kw["q_max"] = Q_MAX, Q_MIN
                else:
                    kw[field] = _invalid_values(rng, limits[field], positive=field not in ("q_min", "q_max"))
                label = f"ctor {field}"
                JointSmoother(**kw, ctrl_dt=DT)
            elif case == 1:
                label = "ctor ctrl_dt"
                JointSmoother(**limits, ctrl_dt=rng.choice(np.array([0.0, -0.01, np.nan, np.inf, None, "0.01", True], dtype=object)))
            elif case == 2:
                label = "reset q"
                base_copy = make()
                base_copy.reset(_invalid_values(rng, q_mid, lo=Q_MIN, hi=Q_MAX))
            elif case == 3:
                label = "reset qd/qdd"
                base_copy = make()
                bad = _invalid_values(rng, np.zeros(DOF))
                if bad is None:
                    continue  # None means "zero" here: valid
                base_copy.reset(q_mid, *((bad, None) if rng.random() < 0.5 else (None, bad)))
            elif case == 4:
                label = "set_target q_target"
                base.set_target(_invalid_values(rng, q_mid, lo=Q_MIN, hi=Q_MAX))
            elif case == 5:
                label = "set_target qd_target"
                bad = _invalid_values(rng, np.zeros(DOF), lo=-base.v_plan, hi=base.v_plan)
                if bad is None:
                    continue  # None means "zero": valid
                base.set_target(q_mid, bad)
            elif case == 6:
                label = "check_start/brake state"
                bad = _invalid_values(rng, q_mid)
                if bad is None:
                    continue  # brake(None) brakes from the reference: valid
                (base.check_start if rng.random() < 0.5 else base.brake)(bad)
            else:
                label = "preview n"
                base.preview(rng.choice(np.array([-1, 1.5, "3", None, True], dtype=object)))
        except TrajectoryError:
            counts[label] = counts.get(label, 0) + 1
            n += 1
            # A refused call leaves the reference untouched (the robot keeps its last valid plan).
            now = base.reference
            if not (np.array_equal(now.q, ref_before.q) and np.array_equal(now.qd, ref_before.qd)):
                crashes.append((label, "reference changed"))
            continue
        except Exception as exc:  # noqa: BLE001 - counting every non-typed error is the point
            crashes.append((label, repr(exc)))
            n += 1
            continue
        crashes.append((label, "accepted"))
        n += 1
    print(f"smoothing fuzz: {n} invalid inputs, {sum(counts.values())} TrajectoryError, {len(crashes)} other; {counts}")
    assert not crashes, crashes[:10]
    assert sum(counts.values()) >= 10_000


def test_config_validation():
    for bad in (
        dict(velocity_scale=0.0),
        dict(velocity_scale=1.01),
        dict(acceleration_scale=-0.1),
        dict(jerk_scale=np.nan),
        dict(start_tolerance_rad=0.0),
        dict(start_tolerance_rad=np.inf),
    ):
        with pytest.raises(ConfigError):
            SmoothingConfig(**bad)
    s = make(SmoothingConfig(velocity_scale=1.0, acceleration_scale=0.25, jerk_scale=0.1))
    np.testing.assert_allclose(s.v_plan, V_MAX)
    np.testing.assert_allclose(s.a_plan, 0.25 * A_MAX)
    with pytest.raises(TrajectoryError, match="SmoothingConfig"):
        make(config={"velocity_scale": 0.5})


def test_timing_report():
    """Measured, not asserted: segment computation and per-tick step() cost for 7 DoF."""
    rng = np.random.default_rng(4)
    s = make()
    s.reset((Q_MIN + Q_MAX) / 2)
    seg_times, tick_times = [], []
    for _ in range(200):
        t0 = time.perf_counter()
        s.set_target(random_q(rng))
        seg_times.append(time.perf_counter() - t0)
        for _ in range(int(rng.integers(5, 30))):
            t0 = time.perf_counter()
            s.step()
            tick_times.append(time.perf_counter() - t0)
    seg_us, tick_us = np.array(seg_times) * 1e6, np.array(tick_times) * 1e6
    print(
        f"7-DoF set_target: median {np.median(seg_us):.0f} us, p99 {np.percentile(seg_us, 99):.0f} us; "
        f"step(): median {np.median(tick_us):.1f} us, p99 {np.percentile(tick_us, 99):.1f} us over {len(tick_us)} ticks"
    )


def test_velocity_phase_position_bounds_match_dense_sampling():
    """Ruckig's position_extrema are wrong for the velocity interface; ours must bound the samples tightly."""
    from tcot_hybrid.smoothing import _position_bounds

    rng = np.random.default_rng(5)
    s = make()
    worst_gap = 0.0
    for _ in range(200):
        q0 = random_q(rng, margin=0.5)
        qd0 = rng.uniform(-1.5, 1.5, DOF) * s.v_max
        qdd0 = rng.uniform(-1.5, 1.5, DOF) * s.a_max  # also beyond the limits: Ruckig's brake pre-profile
        s.brake(q0, qd0, qdd0)
        phase = s._phases[0]
        assert phase.velocity_interface
        bounds = np.array(_position_bounds(phase))
        ts = np.linspace(0.0, phase.duration, 2001)
        q = np.array([phase.trajectory.at_time(t)[0] for t in ts])
        lo, hi = q.min(axis=0), q.max(axis=0)
        assert np.all(bounds[:, 0] <= lo + 1e-12) and np.all(bounds[:, 1] >= hi - 1e-12)
        worst_gap = max(worst_gap, float(np.max(lo - bounds[:, 0])), float(np.max(bounds[:, 1] - hi)))
    print(f"velocity-phase bounds vs 2001-point sampling: loosest by {worst_gap:.2e} rad")
    assert worst_gap <= 1e-5


def test_move_position_bounds_match_dense_sampling_and_catch_an_overshoot_past_a_limit():
    """Moves (position interface) started while moving: our bounds enclose the sampled trajectory. Ruckig 0.19.4's
    position_extrema missed the overshoot of one such move on LIBERO (joint 6 heading for its upper limit at
    1.13 rad/s, target behind it): a retarget that reaches past the limit must be refused, not installed."""
    from tcot_hybrid.smoothing import _position_bounds

    rng = np.random.default_rng(6)
    s = make()
    worst_gap, overshoots = 0.0, 0
    for _ in range(200):
        q0 = random_q(rng, margin=0.5)
        s.reset(q0, rng.uniform(-0.6, 0.6, DOF) * s.v_plan)  # moving (a stop installed), inside the plan limits
        target = random_q(rng, margin=0.5)
        try:
            s.set_target(target)
        except TrajectoryError:
            continue
        for phase in s._phases:
            bounds = np.array(_position_bounds(phase))
            ts = np.linspace(0.0, phase.duration, 2001)
            q = np.array([phase.trajectory.at_time(t)[0] for t in ts])
            lo, hi = q.min(axis=0), q.max(axis=0)
            assert np.all(bounds[:, 0] <= lo + 1e-12) and np.all(bounds[:, 1] >= hi - 1e-12)
            worst_gap = max(worst_gap, float(np.max(lo - bounds[:, 0])), float(np.max(bounds[:, 1] - hi)))
            ruckig_hi = np.array([b.max for b in phase.trajectory.position_extrema])
            overshoots += bool(np.any(hi > ruckig_hi + 1e-6))
    print(f"move bounds vs 2001-point sampling: loosest by {worst_gap:.2e} rad; Ruckig's extrema short in {overshoots}")
    assert worst_gap <= 1e-5
    # joint 6 (index 5) heading for its upper limit, the target behind it: the move would pass the limit
    q0 = np.array([0.0, 0.3, 0.0, -1.5, 0.0, Q_MAX[5] - 0.145, 0.8])
    qd0 = np.zeros(DOF)
    qd0[5] = 1.13
    s.reset(q0, qd0)
    target = q0.copy()
    target[5] = Q_MAX[5] - 0.05
    try:
        s.set_target(target)
    except TrajectoryError as exc:
        assert "joint 5" in str(exc)
        return
    refs = run_to_end(s)
    assert max(r.q[5] for r in refs) <= Q_MAX[5] + 1e-9


def test_brake_reports_excursion_when_it_cannot_stop_in_time():
    s = make()
    q0 = Q_MAX - 0.01
    qd0 = 0.8 * s.v_max
    info = s.brake(q0, qd0)
    refs = run_to_end(s)
    sampled = float(np.max(np.array([r.q for r in refs]) - Q_MAX))
    assert sampled > 0 and info.limit_excursion_rad >= sampled - 1e-12
    assert info.limit_excursion_rad <= sampled + 0.5 * float(np.max(s.v_max)) * DT


def test_unsynchronised_fallback_when_synchronised_segment_leaves_limits(monkeypatch):
    import tcot_hybrid.smoothing as smoothing

    real = smoothing._position_bounds
    calls = {"n": 0}

    def first_move_exceeds(phase):
        bounds = real(phase)
        if not phase.velocity_interface and calls["n"] == 0:
            calls["n"] += 1
            return [(lo, Q_MAX[0] + 1.0) if j == 0 else (lo, hi) for j, (lo, hi) in enumerate(bounds)]
        return bounds

    monkeypatch.setattr(smoothing, "_position_bounds", first_move_exceeds)
    s = make()
    q0 = (Q_MIN + Q_MAX) / 2
    s.reset(q0)
    info = s.set_target(q0 + np.linspace(0.1, 0.7, DOF))
    assert not info.synchronized
    refs = run_to_end(s)
    assert_within(s, refs)
    np.testing.assert_array_equal(refs[-1].q, q0 + np.linspace(0.1, 0.7, DOF))


@pytest.mark.parametrize("robot", ["panda", "ur5e"])
def test_from_spec_with_shipped_robots(robot):
    from tcot_hybrid.robot import load_robot_spec

    spec = load_robot_spec(robot)
    s = JointSmoother.from_spec(spec, ctrl_dt=DT)
    assert s.dof == spec.dof
    s.reset(spec.home_q)
    target = spec.home_q + 0.2 * (spec.q_max - spec.home_q)
    s.set_target(target)
    refs = run_to_end(s)
    np.testing.assert_array_equal(refs[-1].q, target)
    q = np.array([r.q for r in refs])
    assert np.all(q <= spec.q_max + TOL) and np.all(q >= spec.q_min - TOL)
    assert np.all(np.abs([r.qd for r in refs]) <= s.v_plan + TOL)


def _at(f: float) -> np.ndarray:
    """Every joint at fraction f of its range."""
    return Q_MIN + f * (Q_MAX - Q_MIN)


def _drag_model(c: float, inertia: float):
    """A torque model like robosuite's air on the Panda: inertia * qdd + c * qd |qd| per joint [N m]."""
    calls = []

    def torques(q, qd, qdd):
        calls.append(len(q))
        return inertia * qdd + c * qd * np.abs(qd)
    return torques, calls


def test_a_move_that_asks_too_much_torque_is_slowed_until_it_fits():
    tau_max = np.full(DOF, 12.0)
    cfg = SmoothingConfig(torque_fraction=0.8)
    torques, calls = _drag_model(c=7.0, inertia=0.7)
    fast = make(cfg)  # no model: the time-optimal move
    slow = make(cfg, tau_max=tau_max, torques=torques)
    q0, q1 = _at(0.3), _at(0.7)
    for s in (fast, slow):
        s.reset(q0)
    info_fast, info = fast.set_target(q1), slow.set_target(q1)
    assert calls, "the torque model was asked"
    assert info.time_stretch > 1.0 and info.torque_ratio <= 1.0 + 1e-9
    assert info.duration_s > info_fast.duration_s
    refs = run_to_end(slow)
    tau = torques(*(np.array([getattr(r, f) for r in refs]) for f in ("q", "qd", "qdd")))
    # sampled every TORQUE_SAMPLE_S, checked here every tick: within the budget up to the sampling's miss
    assert np.abs(tau).max() <= 0.8 * 12.0 * 1.02
    np.testing.assert_allclose(refs[-1].q, q1, atol=TOL)
    fast_refs = run_to_end(fast)
    fast_tau = torques(*(np.array([getattr(r, f) for r in fast_refs]) for f in ("q", "qd", "qdd")))
    assert np.abs(fast_tau).max() > 0.8 * 12.0, "the unslowed move would have asked more than the budget"


def test_a_move_within_the_torque_budget_is_not_slowed():
    torques, _ = _drag_model(c=0.01, inertia=0.01)
    s = make(tau_max=np.full(DOF, 80.0), torques=torques)
    ref = make()
    for x in (s, ref):
        x.reset(_at(0.4))
    a, b = s.set_target(_at(0.45)), ref.set_target(_at(0.45))
    assert a.time_stretch == 1.0 and 0.0 < a.torque_ratio <= 1.0
    assert a.duration_s == b.duration_s


def test_gravity_beyond_the_budget_stops_at_the_largest_stretch():
    """A load slowing cannot help (static torque over the budget): the move is stretched at most MAX_TIME_STRETCH
    times and reports that it still does not fit."""
    s = make(tau_max=np.full(DOF, 10.0), torques=lambda q, qd, qdd: np.full(q.shape, 9.0) + qdd)
    s.reset(_at(0.4))
    info = s.set_target(_at(0.5))
    assert info.time_stretch == pytest.approx(JointSmoother.MAX_TIME_STRETCH)
    assert info.torque_ratio > 1.0


def test_torque_model_misuse_is_refused():
    with pytest.raises(TrajectoryError, match="tau_max"):
        make(torques=lambda q, qd, qdd: qdd)
    with pytest.raises(TrajectoryError, match=r"tau_max\[2\]"):
        make(torques=lambda q, qd, qdd: qdd, tau_max=[1, 1, 0, 1, 1, 1, 1])
    s = make(torques=lambda q, qd, qdd: np.full((len(q), 3), 1.0), tau_max=np.full(DOF, 10.0))
    s.reset(_at(0.4))
    with pytest.raises(TrajectoryError, match="torque model returned"):
        s.set_target(_at(0.5))
    np.testing.assert_array_equal(s.reference.q, _at(0.4)), "a refused call leaves the reference"
    for bad in (0.0, 1.5, -0.1):
        with pytest.raises(ConfigError, match="torque_fraction"):
            SmoothingConfig(torque_fraction=bad)
    off = make(SmoothingConfig(torque_fraction=None), torques=lambda q, qd, qdd: 1 / 0)
    off.reset(_at(0.4))
    assert off.set_target(_at(0.5)).time_stretch == 1.0, "torque_fraction None: no check"


def test_a_move_planned_k_times_slower_takes_k_times_as_long_and_keeps_within_the_scaled_limits():
    q0 = (Q_MIN + Q_MAX) / 2
    q1 = q0 + 0.05
    base = make()
    base.reset(q0)
    normal = base.set_target(q1).duration_s
    s = make()
    s.reset(q0)
    info = s.set_target(q1, slower=np.float32(4.0))  # any real number
    slow = info.duration_s
    assert info.time_stretch == pytest.approx(4.0)
    assert slow == pytest.approx(4.0 * normal, rel=0.02)
    refs = run_to_end(s)
    np.testing.assert_allclose(refs[-1].q, q1, atol=1e-9)
    assert max(np.abs(r.qd).max() for r in refs) <= (s.v_plan / 4.0).max() + 1e-9


@pytest.mark.parametrize("slower", [0.5, 0.0, -2.0, float("nan"), float("inf"), True, "2", None])
def test_a_move_cannot_be_planned_faster_or_by_a_non_number(slower):
    s = make()
    q0 = (Q_MIN + Q_MAX) / 2
    s.reset(q0)
    with pytest.raises(TrajectoryError, match="slower"):
        s.set_target(q0 + 0.05, slower=slower)
