"""casadi backend (whole-plan IK with IPOPT): its FK against Pinocchio and MuJoCo, its Jacobian against finite
differences, limits in every returned configuration, infeasible plans named by waypoint, bad input refused,
IPOPT's answer never trusted unchecked, and the executor solving a plan before any motion."""
from __future__ import annotations

import functools
import types

import numpy as np
import pinocchio as pin
import pytest

from tcot_hybrid.errors import ConfigError, IKError
from tcot_hybrid.ik import CONVERGED, INFEASIBLE, CasadiConfig, IKConfig, IKTarget, make_ik, rotation_angle
from tcot_hybrid.ik.casadi_ik import CasadiChain
from tcot_hybrid.robot import R_DOWN, build_pinocchio_model, load_robot_spec
from test_ik import fk as mj_fk  # MuJoCo forward kinematics of the full robot model: the independent check

ROBOTS = ("panda", "ur5e")
LIMIT_TOL = 1e-9  # [rad] returned configurations are inside the box (IPOPT bounds + a final clip)


@functools.cache
def spec(robot: str):
    return load_robot_spec(robot)


@functools.cache
def solver(robot: str, **casadi):
    return make_ik("casadi", spec(robot), IKConfig(casadi=CasadiConfig(**casadi)))


@functools.cache
def pin_robot(robot: str):
    return build_pinocchio_model(spec(robot), lock_gripper=True)


def pin_fk(robot: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pr = pin_robot(robot)
    data = pr.model.createData()
    qm = np.empty(len(q))
    qm[pr.arm_q_idx] = q
    pin.framesForwardKinematics(pr.model, data, qm)
    T = data.oMf[pr.tcp_frame_id]
    return T.translation.copy(), T.rotation.copy()


def inside(ik, Q: np.ndarray) -> bool:
    Q = np.atleast_2d(Q)
    return bool(np.all(np.isfinite(Q)) and np.all(Q >= ik.lower - LIMIT_TOL) and np.all(Q <= ik.upper + LIMIT_TOL))


def reachable_plan(robot: str, ik, rng: np.random.Generator, n: int, spread: float = 0.5):
    """FK of a random walk of in-limit configurations (top-down-ish around home): a plan known to be feasible."""
    q = spec(robot).home_q.copy()
    P, R = [], []
    for _ in range(n):
        q = np.clip(q + rng.uniform(-spread, spread, ik.dof) / 2, ik.lower, ik.upper)
        p, Rq = mj_fk(robot, q)
        P.append(p)
        R.append(Rq)
    return np.array(P), np.array(R)


# -- forward kinematics -------------------------------------------------------------------------------


@pytest.mark.parametrize("robot", ROBOTS)
def test_fk_matches_pinocchio_to_1e9_over_random_configurations(robot):
    chain = solver(robot).chain
    s = spec(robot)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(500):  # inside and up to 1 rad beyond the limits
        q = rng.uniform(s.q_min - 1.0, s.q_max + 1.0)
        p, R = chain.pose(q)
        p_ref, R_ref = pin_fk(robot, q)
        worst = max(worst, np.abs(p - p_ref).max(), np.abs(R - R_ref).max())
    print(f"{robot}: casadi FK vs Pinocchio, max abs error over 500 configurations {worst:.2e}")
    assert worst <= 1e-9
    # and MuJoCo agrees (the simulation's own model)
    for _ in range(20):
        q = rng.uniform(s.q_min, s.q_max)
        p, R = chain.pose(q)
        p_mj, R_mj = mj_fk(robot, q)
        assert np.abs(p - p_mj).max() <= 1e-6 and np.abs(R - R_mj).max() <= 1e-6


@pytest.mark.parametrize("robot", ROBOTS)
def test_fk_jacobian_matches_finite_differences_and_pinocchio(robot):
    import casadi as ca

    chain = solver(robot).chain
    q_sym = ca.SX.sym("q", chain.dof)
    p_sym, R_sym = chain.fk(q_sym)
    jac = ca.Function("J", [q_sym], [ca.jacobian(ca.vertcat(p_sym, ca.vec(R_sym)), q_sym)])
    s = spec(robot)
    rng = np.random.default_rng(1)
    h = 1e-6
    pr = pin_robot(robot)
    data = pr.model.createData()
    for _ in range(30):
        q = rng.uniform(s.q_min, s.q_max)
        J = np.asarray(jac(q))

        def flat(qq):
            p, R = chain.pose(qq)
            return np.concatenate([p, R.reshape(-1, order="F")])

        J_fd = np.column_stack([(flat(q + h * e) - flat(q - h * e)) / (2 * h) for e in np.eye(chain.dof)])
        assert np.abs(J - J_fd).max() <= 1e-7
        # the linear part is Pinocchio's frame Jacobian (world-aligned), in spec joint order
        qm = np.empty(len(q))
        qm[pr.arm_q_idx] = q
        J_pin = pin.computeFrameJacobian(pr.model, data, qm, pr.tcp_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(J[:3], J_pin[:3, pr.arm_q_idx], atol=1e-9)


def test_fk_is_generated_for_any_chain_of_revolute_and_prismatic_joints():
    """A bring-your-own arm: unaligned revolute axes, a prismatic joint, a branch, a frame off a middle joint."""
    model = pin.Model()
    rng = np.random.default_rng(2)

    def placement():
        return pin.SE3(pin.exp3(rng.normal(size=3)), rng.uniform(-0.3, 0.3, 3))

    j1 = model.addJoint(0, pin.JointModelRevoluteUnaligned(*(rng.normal(size=3))), placement(), "j1")
    j2 = model.addJoint(j1, pin.JointModelPrismaticUnaligned(*(rng.normal(size=3))), placement(), "j2")
    j3 = model.addJoint(j1, pin.JointModelRY(), placement(), "j3_branch")
    j4 = model.addJoint(j2, pin.JointModelRX(), placement(), "j4")
    j5 = model.addJoint(j4, pin.JointModelPZ(), placement(), "j5")
    del j3
    fid = model.addFrame(pin.Frame("tcp", j5, 0, placement(), pin.FrameType.OP_FRAME))
    names = ("j1", "j2", "j3_branch", "j4", "j5")
    fake_spec = types.SimpleNamespace(dof=5, name="byo", q_min=-np.ones(5), q_max=np.ones(5))
    robot = types.SimpleNamespace(model=model, spec=fake_spec, arm_q_idx=np.arange(5), tcp_frame_id=fid,
                                  joint_names=names)
    chain = CasadiChain(robot)
    data = model.createData()
    for _ in range(100):
        q = rng.uniform(-2, 2, 5)
        pin.framesForwardKinematics(model, data, q)
        p, R = chain.pose(q)
        assert np.abs(p - data.oMf[fid].translation).max() <= 1e-9
        assert np.abs(R - data.oMf[fid].rotation).max() <= 1e-9
    assert chain.n_heights == 1 + 4  # the TCP and the origins of j2-j5 (j1 sits at a fixed place)


# -- whole-plan solves ---------------------------------------------------------------------------------


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("warm_start", ["pinocchio", "current"])
def test_feasible_plans_converge_with_every_waypoint_on_target_and_inside_the_limits(robot, warm_start):
    ik = solver(robot, warm_start=warm_start)
    cfg = ik.config
    rng = np.random.default_rng(3)
    n_ok = 0
    for trial in range(6):
        P, R = reachable_plan(robot, ik, rng, n=8)
        res = ik.solve_plan(P, R, spec(robot).home_q)
        assert res.q.shape == (8, ik.dof) and inside(ik, res.q)
        n_ok += res.converged
        if not res.converged:
            continue
        assert res.offending == () and res.worst is None
        for i in range(8):  # independent check in MuJoCo
            p, Rq = mj_fk(robot, res.q[i])
            assert np.linalg.norm(p - P[i]) <= cfg.pos_tol_m + 1e-6
            assert rotation_angle(Rq, R[i]) <= cfg.rot_tol_rad + 1e-6
            assert p[2] >= -1e-6 or P[i][2] < 0  # above the support surface (z = 0)
    print(f"{robot}/{warm_start}: {n_ok}/6 random 8-waypoint plans converged")
    assert n_ok >= 5


@pytest.mark.parametrize("robot", ROBOTS)
def test_limits_are_respected_in_every_returned_configuration(robot):
    """Feasible, unreachable, below-the-table and beyond-the-joint-limit targets, seeds inside and outside the box."""
    ik = solver(robot)
    s = spec(robot)
    rng = np.random.default_rng(4)
    statuses = []
    for trial in range(12):
        P, R = reachable_plan(robot, ik, rng, n=5, spread=1.5)
        if trial % 3 == 1:
            P[rng.integers(5)] = rng.uniform([-1.5, -1.5, -0.3], [1.5, 1.5, 1.5])  # anywhere, often unreachable
        if trial % 3 == 2:
            R = np.array([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(5)])
            R[np.linalg.det(R) < 0] *= -1
        q0 = rng.uniform(s.q_min - 0.3, s.q_max + 0.3)  # the arm may start slightly outside the box
        res = ik.solve_plan(P, R, q0)
        statuses.append(res.status)
        assert inside(ik, res.q), res
        assert np.all(np.isfinite(res.pos_err)) and np.all(np.isfinite(res.rot_err))
        assert (res.status == CONVERGED) == (len(res.offending) == 0)
    print(f"{robot}: statuses {statuses}")
    # single-waypoint interface: same guarantee
    for _ in range(10):
        pos = rng.uniform([-1.0, -1.0, -0.2], [1.0, 1.0, 1.2])
        r = ik.solve(IKTarget(pos, R_DOWN), rng.uniform(s.q_min - 0.3, s.q_max + 0.3))
        assert inside(ik, r.q) and r.converged == (r.status == CONVERGED)


@pytest.mark.parametrize("robot", ROBOTS)
def test_infeasible_plan_names_the_offending_waypoint_and_how_far_off(robot):
    ik = solver(robot)
    rng = np.random.default_rng(5)
    P, R = reachable_plan(robot, ik, rng, n=6, spread=0.3)
    home = spec(robot).home_q
    assert ik.solve_plan(P, R, home).converged
    # waypoint 3: 5 cm below the table top (the TCP must stay above it) -> 5 cm off, the others met
    below = P.copy()
    below[3] = [0.45, 0.05, -0.05]
    res = ik.solve_plan(below, np.broadcast_to(R_DOWN, (6, 3, 3)), home)
    assert res.status == INFEASIBLE and res.worst == 3 and res.offending == (3,)
    assert res.pos_err[3] == pytest.approx(0.05, abs=2e-3)
    assert np.all(np.delete(res.pos_err, 3) <= ik.config.pos_tol_m)
    assert np.all(res.height_margin >= -1e-6) and inside(ik, res.q)
    # waypoint 1: 2 m away -> reported with the distance the arm stays short by (> 0.5 m)
    far = P.copy()
    far[1] = [2.0, 0.0, 0.4]
    res = ik.solve_plan(far, R, home)
    assert res.status == INFEASIBLE and res.worst == 1 and res.pos_err[1] > 0.5 and inside(ik, res.q)


def test_min_height_is_a_hard_bound_on_the_tcp():
    ik = solver("panda", min_height_m=0.05)
    target = np.array([[0.45, 0.0, 0.03]])  # 3 cm above the table: under the 5 cm bound
    res = ik.solve_plan(target, R_DOWN[None], spec("panda").home_q)
    assert res.status == INFEASIBLE and res.offending == (0,)
    assert res.pos_err[0] == pytest.approx(0.02, abs=2e-3)
    assert mj_fk("panda", res.q[0])[0][2] >= 0.05 - 1e-6


def test_soft_orientation_meets_positions_and_trades_rotation():
    ik = solver("ur5e", orientation="soft", orientation_weight=1.0)
    rng = np.random.default_rng(6)
    P, R = reachable_plan("ur5e", ik, rng, n=4, spread=0.3)
    tilted = np.array([Ri @ pin.exp3(np.array([0.0, 0.3, 0.0])) for Ri in R])  # 0.3 rad off: soft
    res = ik.solve_plan(P, tilted, spec("ur5e").home_q)
    assert res.converged and np.all(res.pos_err <= ik.config.pos_tol_m)


def test_single_waypoint_solve_matches_the_iksolver_contract():
    ik = solver("panda")
    seed = spec("panda").home_q.copy()
    target = IKTarget(np.array([0.55, -0.1, 0.15]), R_DOWN.copy())
    a, b = ik.solve(target, seed), ik.solve(target, seed)
    assert np.array_equal(seed, spec("panda").home_q)  # inputs untouched
    assert a.converged and a.status == CONVERGED and np.array_equal(a.q, b.q)
    p, R = mj_fk("panda", a.q)
    assert np.linalg.norm(p - target.pos) <= 1e-6 and rotation_angle(R, R_DOWN) <= 1e-6


# -- IPOPT's answer is checked, never assumed -----------------------------------------------------------


def test_a_solver_claiming_success_with_a_wrong_answer_is_not_believed(monkeypatch):
    ik = make_ik("casadi", spec("panda"))
    P = np.array([[0.5, 0.0, 0.3], [0.5, 0.1, 0.1]])
    R = np.broadcast_to(R_DOWN, (2, 3, 3))
    home = spec("panda").home_q

    def lying(built, X0, params):
        return np.tile(home, (len(X0), 1)), "Solve_Succeeded", 1  # "solved", but home is not on the targets

    monkeypatch.setattr(ik, "_warm_starts", ("current",))
    monkeypatch.setattr(ik, "_run", lying)
    res = ik.solve_plan(P, R, home)
    assert res.status == INFEASIBLE and set(res.offending) == {0, 1} and res.solver_status == "Solve_Succeeded"

    def nan(built, X0, params):
        return np.full_like(X0, np.nan), "Solve_Succeeded", 1

    monkeypatch.setattr(ik, "_run", nan)
    res = ik.solve_plan(P, R, home)
    assert not res.converged and inside(ik, res.q)

    def error(built, X0, params):
        return None, "error: Invalid_Number_Detected", 0

    monkeypatch.setattr(ik, "_run", error)
    res = ik.solve_plan(P, R, home)
    assert res.status == "non_finite" and inside(ik, res.q)


def test_iteration_cap_is_reported_as_max_iters(monkeypatch):
    ik = make_ik("casadi", spec("panda"), IKConfig(casadi=CasadiConfig(max_iters=1, warm_start="current")))
    monkeypatch.setattr(ik, "_warm_starts", ("current",))  # (the per-waypoint chain alone would meet these targets)
    P = np.array([[0.3, 0.3, 0.1], [0.6, -0.3, 0.1]])
    res = ik.solve_plan(P, np.broadcast_to(R_DOWN, (2, 3, 3)), spec("panda").home_q)
    assert res.status == "max_iters" and not res.converged and inside(ik, res.q)


# -- bad input ------------------------------------------------------------------------------------------


def test_nan_wrong_shapes_non_rotations_and_out_of_range_inputs_are_refused():
    ik = solver("panda")
    home = spec("panda").home_q
    P = np.array([[0.5, 0.0, 0.3], [0.5, 0.1, 0.1], [0.4, 0.1, 0.1]])
    R = np.array(np.broadcast_to(R_DOWN, (3, 3, 3)))
    cases = {
        "waypoint 1": (np.where(np.arange(3)[:, None] == 1, np.nan, P), R, home),
        "rotations must be finite; waypoint 2": (P, np.where(np.arange(3)[:, None, None] == 2, np.inf, R), home),
        "positions must have shape": (P[:, :2], R, home),
        r"rotations must have shape \(3, 3, 3\)": (P, R[:2], home),
        r"rotations\[0\] must be a rotation": (P, np.concatenate([1.01 * R[:1], R[1:]]), home),
        r"rotations\[1\] must be a rotation": (P, np.concatenate([R[:1], np.diag([1.0, 1.0, -1.0])[None], R[2:]]), home),
        "out of range": (np.array([[0.5, 0.0, 0.3], [1e6, 0.0, 0.0], [0.4, 0.1, 0.1]]), R, home),
        "seed must be finite": (P, R, np.where(np.arange(7) == 3, np.nan, home)),
        "seed must have shape": (P, R, home[:6]),
        "N >= 1": (np.zeros((0, 3)), np.zeros((0, 3, 3)), home),
        "positions must be an": ("abc", R, home),
    }
    for match, (p, r, q) in cases.items():
        with pytest.raises(IKError, match=match):
            ik.solve_plan(p, r, q)
    for bad in (float("nan"), 1e9, "table"):
        with pytest.raises(IKError, match="support_z"):
            ik.solve_plan(P, R, home, support_z=bad)
    with pytest.raises(IKError, match="max_waypoints = 2"):
        solver("panda", max_waypoints=2).solve_plan(P, R, home)
    with pytest.raises(IKError, match="out of range"):  # the single-waypoint interface too
        ik.solve(IKTarget(np.array([0.0, 1e300, 0.0]), R_DOWN), home)


@pytest.mark.parametrize("field, value", [
    ("travel_weight", -1.0), ("posture_weight", float("nan")), ("orientation", "tilted"),
    ("orientation_weight", 0.0), ("min_height_m", float("inf")), ("min_height_m", 50.0),
    ("support_z_m", float("nan")), ("max_iters", 0), ("tol", 0.0), ("warm_start", "trac_ik"),
    ("max_waypoints", 0), ("max_time_s", -1.0),
])
def test_casadi_config_rejects_bad_values_naming_the_field(field, value):
    with pytest.raises(ConfigError, match=f"ik_params.casadi.{field}"):
        CasadiConfig(**{field: value})


def test_casadi_config_needs_some_cost_and_loads_from_a_nested_mapping():
    with pytest.raises(ConfigError, match="travel_weight"):
        CasadiConfig(travel_weight=0.0, posture_weight=0.0)
    from tcot_hybrid.run_config import from_mapping, RunConfig

    cfg = from_mapping(RunConfig, {"ik": "casadi", "ik_params": {"casadi": {"min_height_m": 0.01}}})
    assert cfg.ik_params.casadi.min_height_m == 0.01
    with pytest.raises(ConfigError, match="unknown key"):
        from_mapping(RunConfig, {"ik_params": {"casadi": {"min_hieght_m": 0.01}}})


# -- in the stack: solved before any motion, never inside the control tick ----------------------------


def _runner(task: str, seed: int, **kw):
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig

    return EpisodeRunner(RunConfig(task=task, seed=seed, ik="casadi", **kw))


def test_executor_refuses_an_infeasible_plan_before_any_motion():
    from tcot_hybrid.plan import WaypointPlan

    runner = _runner("goal_cube_in_bowl", 0)
    runner.settle()
    ex, cam = runner.stack.executor, runner.stack.camera
    ok_point = ex.sim.tcp_pos() + np.array([0.05, 0.0, -0.05])
    low_point = np.array([ok_point[0], ok_point[1], 0.004])  # 4 mm above the table ...
    uv, depth = cam.project(np.array([ok_point, low_point]))
    q_before, target_before = ex.sim.q.copy(), ex.smoother.reference.q.copy()
    strict = make_ik("casadi", runner.stack.robot, IKConfig(casadi=CasadiConfig(min_height_m=0.02)))
    ex.ik = strict  # ... under a 2 cm height bound
    plan = WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([False, False]), camera=cam.name, kind="local")
    assert not ex.set_plan(plan)
    ev = [e for e in ex.events if e["kind"] == "ik_plan_infeasible"]
    assert len(ev) == 1 and ev[0]["waypoint"] == 1 and ev[0]["pos_err_m"] == pytest.approx(0.016, abs=2e-3)
    assert ex.plans_infeasible == 1 and ex.plan is None and ex.phase == "idle"
    np.testing.assert_array_equal(ex.smoother.reference.q, target_before)  # no motion was commanded
    np.testing.assert_array_equal(ex.sim.q, q_before)
    # the supervisor sees it and replans
    assert runner.supervisor._geometric_reason(ex) == "ik_plan_infeasible"


def test_plans_are_solved_at_adoption_never_inside_the_control_tick(monkeypatch):
    runner = _runner("long_stack_three_blocks", 501)
    ex = runner.stack.executor
    calls = {"plan": 0, "in_tick": 0}
    in_tick = {"now": False}
    real_tick, real_solve_plan = ex.control_tick, ex.ik.solve_plan

    def tick():
        in_tick["now"] = True
        try:
            real_tick()
        finally:
            in_tick["now"] = False

    def solve_plan(*a, **k):
        calls["plan"] += 1
        calls["in_tick"] += in_tick["now"]
        return real_solve_plan(*a, **k)

    def no_single(*a, **k):
        raise AssertionError("per-waypoint IK called while a whole-plan solution exists")

    monkeypatch.setattr(ex, "control_tick", tick)
    monkeypatch.setattr(ex.ik, "solve_plan", solve_plan)
    monkeypatch.setattr(ex.ik, "solve", no_single)
    rec = runner.run()
    assert rec["success"] and calls["plan"] >= 1 and calls["in_tick"] == 0
    assert rec["max_joint_limit_violation_rad"] == 0.0 and rec["plans_infeasible"] == 0


def test_a_yawed_plan_per_waypoint_ik_cannot_finish_is_solved_whole():
    """ur5e, yawed pick-and-place plan of seed 503 (docs/ik-plans): the per-waypoint chains end in a wrist-limit
    corner at the place (waypoints 3-5 not converged); the whole-plan solve picks a branch that reaches them all."""
    from tcot_hybrid.ik.plan_study import compare_plan, yawed_plan

    P, R = yawed_plan(503)
    solvers = {name: make_ik(name, spec("ur5e")) for name in ("mink", "pinocchio", "casadi")}
    row = compare_plan(solvers, {"source": "yawed", "task": "-", "seed": 503, "positions": P, "rotations": R,
                                 "q_start": spec("ur5e").home_q.copy()})
    assert row["mink"]["not_converged"] and row["pinocchio"]["not_converged"]
    assert row["casadi"]["status"] == CONVERGED and row["casadi"]["max_pos_err_m"] <= 1e-3
    res = solvers["casadi"].solve_plan(P, R, spec("ur5e").home_q)
    for i in range(len(P)):  # checked in MuJoCo
        p, Rq = mj_fk("ur5e", res.q[i])
        assert np.linalg.norm(p - P[i]) <= 1e-3 + 1e-6 and rotation_angle(Rq, R[i]) <= 1e-2 + 1e-6


def test_ik_plans_command_writes_counts_and_refuses_unknown_sources(tmp_path):
    import json

    from tcot_hybrid.ik.plan_study import cmd_ik_plans

    out = tmp_path / "ikp"
    assert cmd_ik_plans(["--robots", "ur5e", "--sources", "yawed", "--seed-start", "503", "--seeds", "1",
                         "--out", str(out)]) == 0
    result = json.loads((out / "ik_plans.json").read_text())
    (s,) = result["summary"]
    assert s["plans"] == 1 and s["mink_failed"] == 1 and s["helps_vs_mink_failed"] == 1 and s["hurts_vs_mink"] == 0
    assert "helps: mink failed, casadi solved" in (out / "ik_plans.md").read_text()
    with pytest.raises(ConfigError, match="valid sources: workcell, yawed"):
        cmd_ik_plans(["--sources", "random", "--out", str(out)])
