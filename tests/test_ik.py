"""IK backends (mink, pinocchio) on both robots: convergence, limits, velocity, bad input, faults.

RELIABILITY rows 5-8 are the property tests at the bottom; each prints its counts (run with -s).
Ground truth for every pose check is MuJoCo forward kinematics of the full robot model.
"""
from __future__ import annotations

import collections
import functools
import time

import mujoco
import numpy as np
import pytest

from tcot_hybrid.errors import ConfigError, IKError
from tcot_hybrid.ik import (
    CONVERGED,
    MAX_ITERS,
    NON_FINITE,
    QP_INFEASIBLE,
    STATUSES,
    IKConfig,
    IKTarget,
    list_ik,
    make_ik,
    rotation_angle,
)
from tcot_hybrid.ik.mink_ik import IK_TABLE_GEOM
from tcot_hybrid.robot import R_DOWN, load_robot_spec

ROBOTS = ("panda", "ur5e")
BACKENDS = ("mink", "pinocchio")
COMBOS = [(r, b) for r in ROBOTS for b in BACKENDS]
LIMIT_TOL = 1e-6  # [rad] allowed excursion beyond the limit box (RELIABILITY row 7)
VEL_TOL = 1e-6  # allowed relative excess over v_max (row 8)


@functools.cache
def spec(robot: str):
    return load_robot_spec(robot)


@functools.cache
def solver(robot: str, backend: str, **overrides):
    return make_ik(backend, spec(robot), IKConfig(**overrides))


@functools.cache
def _fk_model(robot: str):
    s = spec(robot)
    m = mujoco.MjModel.from_xml_path(str(s.mjcf_path))
    adr = np.array([m.jnt_qposadr[m.joint(j).id] for j in s.arm_joints])
    return m, mujoco.MjData(m), adr, m.site(s.ee_site).id


def fk(robot: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """TCP pose from MuJoCo for arm configuration q (may lie outside the limits)."""
    m, d, adr, sid = _fk_model(robot)
    d.qpos[:] = m.qpos0
    d.qpos[adr] = q
    mujoco.mj_kinematics(m, d)
    return d.site_xpos[sid].copy(), d.site_xmat[sid].reshape(3, 3).copy()


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def box_excess(ik, q: np.ndarray) -> np.ndarray:
    """Per-joint distance outside [lower, upper] [rad] (0 inside)."""
    return np.maximum(ik.lower - q, 0.0) + np.maximum(q - ik.upper, 0.0)


def check_step(ik, q_prev: np.ndarray, q_new: np.ndarray, iters: int) -> tuple[int, float]:
    """(limit violations, velocity ratio) of one solve that took ``iters`` steps from q_prev.

    A joint inside the box must stay inside; a joint outside must not get farther out.
    The velocity ratio is max |dq| / (iters * max_step); <= 1 per step when iters == 1."""
    before, after = box_excess(ik, q_prev), box_excess(ik, q_new)
    allowed = np.where(before > 0.0, before, 0.0) + LIMIT_TOL
    violations = int(np.sum(after > allowed))
    ratio = float(np.max(np.abs(q_new - q_prev) / (max(iters, 1) * ik.max_step)))
    return violations, ratio


# -- registry and configuration ---------------------------------------------------------------------


def test_registry_lists_the_backends_and_rejects_unknown_names():
    assert list_ik() == ["casadi", "mink", "pinocchio"]
    with pytest.raises(ConfigError) as err:
        make_ik("trac_ik", spec("panda"))
    assert "trac_ik" in str(err.value) and "mink" in str(err.value) and "pinocchio" in str(err.value)


@pytest.mark.parametrize(
    "field, value",
    [
        ("max_iters", 0),
        ("max_iters", 2.5),
        ("max_iters", True),
        ("pos_tol_m", 0.0),
        ("rot_tol_rad", float("nan")),
        ("damping", 0.0),
        ("damping", -1e-3),
        ("posture_cost", -1.0),
        ("orientation_cost", float("inf")),
        ("step_dt_s", 0.0),
        ("solver", "cvxopt_not_installed"),
        ("velocity_scale", 0.0),
        ("velocity_scale", 1.5),
        ("limit_margin_rad", -0.01),
        ("posture_target", "elbow_up"),
        ("collision_avoidance", "yes"),
        ("collision_avoidance", 1),
        ("table_clearance_m", -0.01),
    ],
)
def test_config_rejects_bad_values_naming_the_field(field, value):
    with pytest.raises(ConfigError, match=field):
        IKConfig(**{field: value})


@pytest.mark.parametrize("backend", BACKENDS)
def test_margin_larger_than_joint_range_is_refused(backend):
    with pytest.raises(ConfigError, match="limit_margin_rad"):
        make_ik(backend, spec("panda"), IKConfig(limit_margin_rad=2.0))


def test_margin_larger_than_joint_range_is_refused_before_a_run_builds_anything():
    from tcot_hybrid.episode import validate_names
    from tcot_hybrid.run_config import RunConfig

    with pytest.raises(ConfigError, match=r"limit_margin_rad = 2.0 leaves no range for joints \['joint2'"):
        validate_names(RunConfig(ik_params=IKConfig(limit_margin_rad=2.0)))
    validate_names(RunConfig(ik_params=IKConfig(limit_margin_rad=0.2)))


def test_collision_avoidance_is_refused_by_pinocchio_backend():
    with pytest.raises(ConfigError, match=r"ik_params.collision_avoidance = True .* \['mink'\], not by 'pinocchio'"):
        make_ik("pinocchio", spec("panda"), IKConfig(collision_avoidance=True))


def test_a_run_asking_pinocchio_for_collision_avoidance_is_refused_before_anything_is_built():
    from tcot_hybrid.episode import validate_names
    from tcot_hybrid.run_config import RunConfig

    with pytest.raises(ConfigError, match="ik_params.collision_avoidance"):
        validate_names(RunConfig(ik="pinocchio", ik_params=IKConfig(collision_avoidance=True)))
    validate_names(RunConfig(ik="mink", ik_params=IKConfig(collision_avoidance=True)))  # mink has it


# -- input validation -------------------------------------------------------------------------------


@pytest.mark.parametrize("robot, backend", COMBOS)
def test_unusable_input_raises_ik_error_naming_the_value(robot, backend):
    ik = solver(robot, backend)
    home = spec(robot).home_q
    good = IKTarget(np.array([0.5, 0.0, 0.2]), R_DOWN)
    bad_targets = {
        "target.pos": IKTarget(np.array([0.5, np.nan, 0.2]), R_DOWN),
        "target.pos must have shape": IKTarget(np.array([0.5, 0.0]), R_DOWN),
        "target.rot must be finite": IKTarget(good.pos, np.full((3, 3), np.inf)),
        "target.rot must have shape": IKTarget(good.pos, np.eye(2)),
        "rotation matrix": IKTarget(good.pos, 1.01 * np.eye(3)),
        "det": IKTarget(good.pos, np.diag([1.0, 1.0, -1.0])),  # a reflection
        "IKTarget": None,
    }
    for match, target in bad_targets.items():
        with pytest.raises(IKError, match=match):
            ik.solve(target, home)
    for match, seed in {
        "seed must be finite": np.where(np.arange(ik.dof) == 2, np.nan, home),
        "seed must have shape": np.zeros(ik.dof + 1),
        "seed must be a numeric": ["a"] * ik.dof,
    }.items():
        with pytest.raises(IKError, match=match):
            ik.solve(good, seed)


@pytest.mark.parametrize("robot, backend", COMBOS)
def test_solve_does_not_modify_inputs_and_is_deterministic(robot, backend):
    ik = solver(robot, backend)
    seed = spec(robot).home_q.copy()
    target = IKTarget(np.array([0.55, -0.1, 0.15]), R_DOWN.copy())
    a = ik.solve(target, seed)
    b = ik.solve(target, seed)
    assert np.array_equal(seed, spec(robot).home_q)
    assert np.array_equal(a.q, b.q) and a.iters == b.iters and a.status == b.status
    assert a.status in STATUSES


# -- convergence --------------------------------------------------------------------------------------


def _reachable_problems(robot: str, ik, n: int, seed: int):
    """FK of random in-limit configurations near the top-down home pose, seeded nearby."""
    rng = np.random.default_rng(seed)
    home = spec(robot).home_q
    for _ in range(n):
        q_true = np.clip(home + rng.uniform(-0.4, 0.4, ik.dof), ik.lower, ik.upper)
        q_seed = np.clip(q_true + rng.uniform(-0.1, 0.1, ik.dof), ik.lower, ik.upper)
        yield IKTarget(*fk(robot, q_true)), q_seed


@pytest.mark.parametrize("robot, backend", COMBOS)
def test_reachable_targets_converge_and_fk_matches(robot, backend):
    ik = solver(robot, backend)
    cfg = ik.config
    for target, q_seed in _reachable_problems(robot, ik, 25, seed=1):
        res = ik.solve(target, q_seed)
        assert res.converged and res.status == CONVERGED, res
        assert res.pos_err <= cfg.pos_tol_m and res.rot_err <= cfg.rot_tol_rad
        p, R = fk(robot, res.q)  # independent check in MuJoCo (covers the Pinocchio model too)
        assert np.linalg.norm(p - target.pos) <= cfg.pos_tol_m + 1e-6
        assert rotation_angle(R, target.rot) <= cfg.rot_tol_rad + 1e-6
        assert np.all(box_excess(ik, res.q) <= LIMIT_TOL)


@pytest.mark.parametrize("robot, backend", COMBOS)
def test_tcp_pose_is_the_forward_kinematics_and_refuses_a_bad_q(robot, backend):
    ik = solver(robot, backend)
    rng = np.random.default_rng(4)
    for _ in range(10):
        q = rng.uniform(ik.lower, ik.upper)
        p, R = ik.tcp_pose(q)
        p_ref, R_ref = fk(robot, q)  # MuJoCo's, independent of the backend's model
        np.testing.assert_allclose(p, p_ref, atol=1e-7)
        assert rotation_angle(R, R_ref) < 1e-6
    for match, q in {"q must be finite": np.full(ik.dof, np.nan), "q must have shape": np.zeros(ik.dof - 1),
                     "q must be a numeric": ["a"] * ik.dof}.items():
        with pytest.raises(IKError, match=match):
            ik.tcp_pose(q)


@pytest.mark.parametrize("robot, backend", COMBOS)
def test_strong_posture_far_from_home_does_not_bias_the_solution(robot, backend):
    """The posture pull is released near the target, so 1.2 rad from home a 2x default posture_cost
    still converges to tolerance (a permanent pull left up to 18 mm error; 8/10 cases failed)."""
    ik = solver(robot, backend, posture_cost=0.02)
    rng = np.random.default_rng(4)
    home = spec(robot).home_q
    for _ in range(10):
        q_true = np.clip(home + rng.choice([-1.0, 1.0], ik.dof) * 1.2, ik.lower, ik.upper)
        target = IKTarget(*fk(robot, q_true))
        res = ik.solve(target, np.clip(q_true + rng.uniform(-0.05, 0.05, ik.dof), ik.lower, ik.upper))
        assert res.converged, res


@pytest.mark.parametrize("robot", ROBOTS)
def test_mink_with_osqp_converges_like_daqp(robot):
    ik = solver(robot, "mink", solver="osqp")
    for target, q_seed in _reachable_problems(robot, ik, 8, seed=2):
        res = ik.solve(target, q_seed)
        assert res.converged, res
        assert np.linalg.norm(fk(robot, res.q)[0] - target.pos) <= ik.config.pos_tol_m + 1e-6


@pytest.mark.parametrize("robot, backend", COMBOS)
@pytest.mark.parametrize("posture_target", ["home", "seed"])
def test_waypoint_walk_across_workspace_converges(robot, backend, posture_target):
    """Top-down waypoints over x 0.3-0.65, y +-0.25, z 0.02-0.4, each seeded from the last solution."""
    ik = solver(robot, backend, posture_target=posture_target)
    rng = np.random.default_rng(3)
    q = spec(robot).home_q.copy()
    n, ok, times = 80, 0, []
    for _ in range(n):
        pos = np.array([rng.uniform(0.3, 0.65), rng.uniform(-0.25, 0.25), rng.uniform(0.02, 0.4)])
        t0 = time.perf_counter()
        res = ik.solve(IKTarget(pos, R_DOWN), q)
        times.append(time.perf_counter() - t0)
        ok += res.converged
        assert np.all(np.isfinite(res.q)) and np.all(box_excess(ik, res.q) <= LIMIT_TOL)
        q = res.q
    print(f"{robot}/{backend}/{posture_target}: walk {ok}/{n} converged, median {1e3 * np.median(times):.2f} ms")
    assert ok / n >= 0.98


@pytest.mark.parametrize("robot, backend", COMBOS)
def test_unreachable_target_is_best_effort_within_limits(robot, backend):
    """RELIABILITY row 5: a target 2 m away -> not converged, finite, inside the limits, closer than before."""
    ik = solver(robot, backend, max_iters=60)
    home = spec(robot).home_q
    target = IKTarget(np.array([2.0, 0.3, 0.5]), R_DOWN)
    res = ik.solve(target, home)
    assert not res.converged and res.status == MAX_ITERS and res.iters == 60
    assert np.all(np.isfinite(res.q)) and np.all(box_excess(ik, res.q) <= LIMIT_TOL)
    assert res.pos_err < np.linalg.norm(fk(robot, home)[0] - target.pos)  # it moved toward the target
    assert res.pos_err == pytest.approx(np.linalg.norm(fk(robot, res.q)[0] - target.pos), abs=1e-9)


@pytest.mark.parametrize("robot, backend", COMBOS)
def test_seed_outside_limits_walks_inward_at_vmax(robot, backend):
    ik1 = solver(robot, backend, max_iters=1)
    home = spec(robot).home_q
    seed = home.copy()
    seed[0] = ik1.upper[0] + 0.5  # far outside: needs several steps
    seed[2] = ik1.lower[2] - 0.3 * ik1.max_step[2]  # just outside: one partial step
    # Target: the pose of the seed brought into the box (reachable from where recovery ends).
    target = IKTarget(*fk(robot, np.clip(seed, ik1.lower, ik1.upper)))
    res = ik1.solve(target, seed)
    assert res.iters == 1 and res.limit_active
    assert res.q[0] == pytest.approx(seed[0] - ik1.max_step[0], abs=1e-12)  # inward by exactly one v_max step
    assert res.q[2] == pytest.approx(ik1.lower[2], abs=1e-12)
    # With enough iterations it comes back inside and still solves the task.
    full = solver(robot, backend).solve(target, seed)
    assert full.converged, full
    assert np.all(box_excess(ik1, full.q) <= LIMIT_TOL)


@pytest.mark.parametrize("robot, backend", COMBOS)
def test_target_beyond_joint_limit_keeps_the_margin(robot, backend):
    """A TCP pose that needs a joint 0.5 rad past its limit: the joint stops at the margin."""
    ik = solver(robot, backend, max_iters=100)
    s = spec(robot)
    # The last joint whose range is small enough that q_max + 0.5 has no 2 pi equivalent in range.
    j = max(i for i in range(ik.dof) if s.q_max[i] - s.q_min[i] < 2 * np.pi - 1.0)
    q_beyond = s.home_q.copy()
    q_beyond[j] = s.q_max[j] + 0.5
    res = ik.solve(IKTarget(*fk(robot, q_beyond)), s.home_q)
    assert np.all(box_excess(ik, res.q) <= LIMIT_TOL)
    assert res.limit_active and not res.converged
    # Best effort: the joint went most of the way toward its limit (another may have stopped it first).
    assert res.q[j] > s.home_q[j] + 0.5 * (ik.upper[j] - s.home_q[j])


# -- collision avoidance (mink only) --------------------------------------------------------------------


@pytest.mark.parametrize("robot", ROBOTS)
def test_collision_avoidance_keeps_the_hand_above_the_table(robot):
    ik = solver(robot, "mink", collision_avoidance=True)
    clearance = ik.config.table_clearance_m
    model, data = ik.model, ik.configuration.data
    table = model.geom(IK_TABLE_GEOM).id
    hand = ik.hand_geoms()
    home = spec(robot).home_q

    def min_distance(q):
        data.qpos[:] = q  # arm-only model in spec order (checked by _qidx)
        mujoco.mj_kinematics(model, data)
        return min(mujoco.mj_geomDistance(model, data, g, table, 1.0, None) for g in hand)

    assert np.array_equal(ik._qidx, np.arange(ik.dof))
    below = ik.solve(IKTarget(np.array([0.5, 0.0, -0.05]), R_DOWN), home)
    assert not below.converged
    # The limit is linearised per step, so the clearance is approached, not kept exactly; no contact.
    gap = min_distance(below.q)
    print(f"{robot}: hand-table distance {1e3 * gap:.2f} mm (clearance {1e3 * clearance:.1f} mm)")
    assert 0.0 < gap < clearance + 0.01
    # Without the limit the same target drives the hand into the table.
    plain = solver(robot, "mink").solve(IKTarget(np.array([0.5, 0.0, -0.05]), R_DOWN), home)
    assert min_distance(plain.q) < 0.0
    above = ik.solve(IKTarget(np.array([0.5, 0.1, 0.2]), R_DOWN), home)
    assert above.converged, above


# -- injected solver faults (RELIABILITY row 6, explicit) ---------------------------------------------


def test_mink_qp_failure_and_non_finite_step_hold_the_last_safe_q(monkeypatch):
    import mink

    from tcot_hybrid.ik import mink_ik

    ik = make_ik("mink", spec("panda"))
    home = spec("panda").home_q
    target = IKTarget(np.array([0.6, 0.2, 0.1]), R_DOWN)

    def raise_infeasible(*args, **kwargs):
        raise mink.NoSolutionFound("daqp")

    monkeypatch.setattr(mink_ik.mink, "solve_ik", raise_infeasible)
    res = ik.solve(target, home)
    assert res.status == QP_INFEASIBLE and not res.converged and np.array_equal(res.q, home)

    monkeypatch.setattr(mink_ik.mink, "solve_ik", lambda *a, **k: np.full(ik.dof, np.nan))
    res = ik.solve(target, home)
    assert res.status == NON_FINITE and np.array_equal(res.q, home)


def test_pinocchio_non_finite_jacobian_holds_the_last_safe_q(monkeypatch):
    from tcot_hybrid.ik import pinocchio_ik

    ik = make_ik("pinocchio", spec("ur5e"))
    home = spec("ur5e").home_q
    real = pinocchio_ik.pin.computeFrameJacobian
    monkeypatch.setattr(pinocchio_ik.pin, "computeFrameJacobian", lambda *a: real(*a) * np.nan)
    res = ik.solve(IKTarget(np.array([0.6, 0.2, 0.1]), R_DOWN), home)
    assert res.status == NON_FINITE and not res.converged and np.array_equal(res.q, home)


# -- property tests: RELIABILITY rows 6-8 ---------------------------------------------------------------


def _fuzz_problem(rng: np.random.Generator, robot: str, ik):
    """A random IK problem: sane, far, absurd-but-finite targets; seeds inside, outside, far outside."""
    kind = rng.integers(6)
    if kind == 0:  # reachable
        q = np.clip(spec(robot).home_q + rng.uniform(-0.8, 0.8, ik.dof), ik.lower, ik.upper)
        pos, rot = fk(robot, q)
    elif kind == 1:  # anywhere within a few metres, any orientation
        pos, rot = rng.uniform(-3.0, 3.0, 3), random_rotation(rng)
    elif kind == 2:  # garbage magnitudes, still finite
        pos, rot = rng.choice([-1.0, 1.0], 3) * 10.0 ** rng.uniform(1, 300, 3), random_rotation(rng)
    elif kind == 3:  # needs joints beyond their limits
        q = spec(robot).q_max + rng.uniform(0.0, 1.5, ik.dof) * rng.choice([0, 1], ik.dof)
        pos, rot = fk(robot, q)
    elif kind == 4:  # at the robot base / singular
        pos, rot = rng.normal(0.0, 1e-3, 3), random_rotation(rng)
    else:  # tiny or denormal positions
        pos, rot = rng.choice([0.0, 1e-300, -5e-324], 3), np.eye(3)
    span = spec(robot).q_max - spec(robot).q_min
    seed_kind = rng.integers(3)
    if seed_kind == 0:
        seed = rng.uniform(ik.lower, ik.upper)
    elif seed_kind == 1:
        seed = rng.uniform(spec(robot).q_min - 0.5 * span, spec(robot).q_max + 0.5 * span)
    else:
        seed = rng.choice([-1.0, 1.0], ik.dof) * 10.0 ** rng.uniform(0, 6, ik.dof)
    return IKTarget(np.asarray(pos, float), rot), seed


def test_fuzz_10k_problems_no_exception_no_non_finite_output():
    """RELIABILITY row 6: >= 10,000 random problems over 2 robots x 2 backends, 3 iterations each."""
    per_combo = 2500
    total = uncaught = non_finite = violations = 0
    max_ratio = 0.0
    statuses: collections.Counter = collections.Counter()
    for i, (robot, backend) in enumerate(COMBOS):
        ik = solver(robot, backend, max_iters=3)
        rng = np.random.default_rng(100 + i)
        for _ in range(per_combo):
            target, seed = _fuzz_problem(rng, robot, ik)
            total += 1
            try:
                res = ik.solve(target, seed)
            except Exception as exc:  # noqa: BLE001 - counting is the point
                uncaught += 1
                print(f"uncaught {type(exc).__name__}: {exc}")
                continue
            statuses[f"{backend}:{res.status}"] += 1
            outputs = np.concatenate([res.q, [res.pos_err, res.rot_err]])
            non_finite += int(not np.all(np.isfinite(outputs)))
            v, ratio = check_step(ik, seed, res.q, res.iters)
            violations += v
            max_ratio = max(max_ratio, ratio)
    print(f"fuzz: {total} problems, {uncaught} uncaught, {non_finite} non-finite q, {violations} limit "
          f"violations, max |dq|/(iters*vmax*dt) {max_ratio:.6f}, statuses {dict(statuses)}")
    assert total >= 10_000
    assert uncaught == 0 and non_finite == 0 and violations == 0
    assert max_ratio <= 1.0 + VEL_TOL


def test_limits_and_velocity_over_10k_single_steps():
    """RELIABILITY rows 7 and 8: >= 10,000 single IK steps (max_iters = 1, chained) from seeds outside
    the limits toward targets beyond the joint limits or far away: 0 limit violations beyond 1e-6 rad,
    joints outside never move outward, and |dq| / step_dt <= v_max * velocity_scale."""
    episodes, steps = 50, 50
    total = violations = outward = 0
    max_ratio = 0.0
    for robot, backend in COMBOS:
        for scale in (1.0, 0.5):
            ik = solver(robot, backend, max_iters=1, velocity_scale=scale)
            s = spec(robot)
            rng = np.random.default_rng(7)
            for _ in range(episodes // 2):
                span = s.q_max - s.q_min
                q = rng.uniform(s.q_min - 0.6 * span, s.q_max + 0.6 * span)  # mostly outside
                if rng.random() < 0.5:
                    q_goal = s.q_max + rng.uniform(0.0, 1.0, ik.dof) * rng.choice([0, 1], ik.dof)
                    target = IKTarget(*fk(robot, q_goal))
                else:
                    target = IKTarget(rng.uniform(-2.0, 2.0, 3), random_rotation(rng))
                for _ in range(steps):
                    res = ik.solve(target, q)
                    assert res.iters <= 1 and np.all(np.isfinite(res.q))
                    v, ratio = check_step(ik, q, res.q, 1)
                    violations += v
                    max_ratio = max(max_ratio, ratio)
                    out_before = box_excess(ik, q)
                    # Outside joints move inward by min(max_step, distance) exactly (recovery phase).
                    moving = out_before > 0.0
                    if np.any(moving):
                        gain = out_before[moving] - box_excess(ik, res.q)[moving]
                        expect = np.minimum(ik.max_step[moving], out_before[moving])
                        outward += int(np.sum(gain < expect - 1e-9))
                    total += 1
                    q = res.q
    print(f"limits: {total} steps, {violations} limit violations (> {LIMIT_TOL} rad), {outward} slow/outward "
          f"recoveries, max |dq|/(vmax*scale*dt) {max_ratio:.9f}")
    assert total >= 10_000
    assert violations == 0 and outward == 0
    assert max_ratio <= 1.0 + VEL_TOL
    assert max_ratio >= 0.999  # the limit is actually reached, so the bound above is tested
