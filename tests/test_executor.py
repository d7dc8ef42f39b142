"""Executor: plan shaping before IK (square transits) and its settings."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

from tcot_hybrid.errors import ConfigError
from tcot_hybrid.executor import (MAX_SEGMENT_LIBERO_M, RETREAT_NEAR_M, ExecutorConfig, cut_long_segments,
                                  resolve_max_segment, retreat_after_release, square_transits)

H, V = 0.06, 0.02  # the thresholds these tests use


def square(start, start_closed, points, grip):
    return square_transits(np.asarray(start, float), start_closed, np.asarray(points, float), np.asarray(grip, bool),
                           min_horizontal_m=H, min_vertical_m=V)


def test_a_diagonal_descent_moves_over_at_height_then_lowers():
    pts, grip = square([0.4, 0.0, 0.20], True, [[0.6, 0.0, 0.05]], [False])  # carry over, release at the end
    np.testing.assert_allclose(pts, [[0.6, 0.0, 0.20], [0.6, 0.0, 0.05]])
    # the corner keeps the carried object's bit: the release stays at the planned point, not above it
    assert grip.tolist() == [True, False]


def test_a_diagonal_rise_raises_first_then_moves_over():
    pts, grip = square([0.4, 0.0, 0.02], True, [[0.4, 0.0, 0.03], [0.6, 0.1, 0.20]], [True, True])
    np.testing.assert_allclose(pts, [[0.4, 0.0, 0.03], [0.4, 0.0, 0.20], [0.6, 0.1, 0.20]])
    assert grip.tolist() == [True, True, True]


def test_the_first_segment_starts_at_the_tcp_with_the_current_gripper_command():
    # open gripper high up; the plan's first point is a grasp low and far to the side
    pts, grip = square([0.4, 0.0, 0.30], False, [[0.5, 0.2, 0.02], [0.5, 0.2, 0.10]], [True, True])
    np.testing.assert_allclose(pts[0], [0.5, 0.2, 0.30])
    assert grip.tolist() == [False, True, True]  # close at the grasp point, not at the corner above it


@pytest.mark.parametrize("points", [
    [[0.6, 0.0, 0.012], [0.35, 0.0, 0.004]],  # a drag along the table: sideways, (almost) level
    [[0.4, 0.0, 0.05], [0.4, 0.0, 0.30]],     # straight up
    [[0.44, 0.03, 0.12], [0.47, 0.06, 0.08]],  # short diagonal steps (an oracle's 4 cm spacing)
])
def test_level_vertical_and_short_segments_are_left_alone(points):
    start = [0.4, 0.0, 0.015] if points[0][2] < 0.02 else [0.4, 0.0, 0.15]
    grip = [True] * len(points)
    pts, g = square(start, True, points, grip)
    np.testing.assert_array_equal(pts, np.asarray(points))
    assert g.tolist() == grip


def test_squared_path_keeps_every_planned_point_in_order():
    rng = np.random.default_rng(0)
    points = rng.uniform([0.3, -0.25, 0.0], [0.65, 0.25, 0.35], size=(30, 3))
    grip = rng.random(30) < 0.5
    pts, g = square([0.45, 0.0, 0.35], False, points, grip)
    kept = [i for i, p in enumerate(pts) if any(np.array_equal(p, q) for q in points)]
    assert len(pts) > len(points)  # random points: most segments are diagonal
    np.testing.assert_array_equal(pts[kept], points)
    np.testing.assert_array_equal(g[kept], grip)
    # every added corner is level with one neighbour and straight above/below the other
    for i in sorted(set(range(len(pts))) - set(kept)):
        a, c, b = pts[i - 1] if i else np.array([0.45, 0.0, 0.35]), pts[i], pts[i + 1]
        assert (c[2] == a[2] and np.array_equal(c[:2], b[:2])) or (c[2] == b[2] and np.array_equal(c[:2], a[:2]))


def test_oracle_plans_are_never_squared():
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.lift import lift_waypoints
    from tcot_hybrid.run_config import RunConfig

    for task in ("long_stack_three_blocks", "tool_pull_cube_with_stick", "long_open_drawer_put_cube"):
        runner = EpisodeRunner(RunConfig(task=task, seed=3))
        runner.settle()
        runner._step_once(0, may_plan=True)
        plan = runner.plans[0]
        points = lift_waypoints(plan.uv_px, plan.depth_m, runner.stack.camera)
        cfg = ExecutorConfig()
        pts, _ = square_transits(runner.stack.sim.tcp_pos(), False, points, plan.gripper_closed,
                                 min_horizontal_m=cfg.transit_min_horizontal_m, min_vertical_m=cfg.transit_min_vertical_m,
                                 switch_min_horizontal_m=cfg.switch_min_horizontal_m)
        assert len(pts) == len(points), task
        adopted = [e for e in runner.stack.executor.events if e["kind"] == "plan_adopted"]
        assert adopted[0]["corners_added"] == 0


@pytest.mark.parametrize("field,value", [("transit_min_horizontal_m", 0.0), ("transit_min_horizontal_m", -0.1),
                                         ("transit_min_vertical_m", -0.01)])
def test_transit_thresholds_are_checked(field, value):
    with pytest.raises(ConfigError, match=field):
        ExecutorConfig(**{field: value})


def test_squaring_can_be_switched_off():
    assert ExecutorConfig(transit_min_horizontal_m=None).transit_min_horizontal_m is None


def test_executor_squares_sampled_tracks_but_not_a_direct_action():
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.plan import WaypointPlan
    from tcot_hybrid.run_config import RunConfig

    runner = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=0))
    ex, cam = runner.stack.executor, runner.stack.camera
    far_low = ex.sim.tcp_pos() + np.array([0.10, 0.10, -0.15])  # diagonal: 14 cm sideways, 15 cm down
    uv, depth = cam.project(far_low[None])
    for kind, corners in (("local", 1), ("global", 1), ("direct", 0)):
        plan = WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([False]), camera=cam.name, kind=kind)
        assert ex.set_plan(plan)
        assert ex.events[-1]["corners_added"] == corners, kind
        assert len(ex.points) == 1 + corners
        np.testing.assert_allclose(ex.points[-1], far_low, atol=1e-9)


def test_moves_into_and_out_of_a_gripper_switch_are_squared_from_a_smaller_offset():
    # a place descent 2 cm to the side (under the 6 cm transit threshold), then a lift 1 cm to the side
    start, points, grip = [0.40, 0.10, 0.18], [[0.40, 0.12, 0.04], [0.41, 0.12, 0.15]], [False, False]
    plain, _ = square(start, True, points, grip)
    np.testing.assert_array_equal(plain, np.asarray(points))  # the transit rule alone leaves both alone
    pts, g = square_transits(np.asarray(start), True, np.asarray(points), np.asarray(grip), min_horizontal_m=H,
                             min_vertical_m=V, switch_min_horizontal_m=0.005)
    # straight down onto the place point, straight up out of it, then over
    np.testing.assert_allclose(pts, [[0.40, 0.12, 0.18], [0.40, 0.12, 0.04], [0.40, 0.12, 0.15], [0.41, 0.12, 0.15]])
    assert g.tolist() == [True, False, False, False]  # released at the planned point, not above it
    # a segment between two points with the same gripper bit keeps the transit threshold
    mid = [[0.40, 0.12, 0.10], [0.41, 0.13, 0.04]]
    pts, _ = square_transits(np.asarray(start), True, np.asarray(mid), np.array([True, True]), min_horizontal_m=H,
                             min_vertical_m=V, switch_min_horizontal_m=0.005)
    np.testing.assert_array_equal(pts, np.asarray(mid))


def _leaning(deg: float) -> np.ndarray:
    """An approach axis leaning ``deg`` from straight down towards +x."""
    t = np.radians(deg)
    return np.array([np.sin(t), 0.0, -np.cos(t)])


def _square_onto_grasp(start, grasp, approach_axis, *, start_closed=False, closes=True):
    """One descent from ``start`` to ``grasp`` (a grasp when the hand starts open and ``closes``), squared with the
    5 mm switch threshold and the approach axis given."""
    return square_transits(np.asarray(start, float), start_closed, np.asarray([grasp], float), np.array([closes]),
                           min_horizontal_m=H, min_vertical_m=V, switch_min_horizontal_m=0.005,
                           approach=np.asarray([approach_axis], float))


def test_a_leaning_hand_comes_onto_its_grasp_along_its_approach_axis():
    start, grasp = [0.40, 0.00, 0.20], [0.50, 0.02, 0.05]
    pts, g = _square_onto_grasp(start, grasp, _leaning(30.0))
    corner = pts[0]
    assert len(pts) == 2 and np.isclose(corner[2], start[2])  # moved over at the start's height
    along = (np.asarray(grasp) - corner) / np.linalg.norm(np.asarray(grasp) - corner)
    np.testing.assert_allclose(along, _leaning(30.0), atol=1e-9)  # then in along the approach
    assert g.tolist() == [False, True]  # and the hand closes at the planned point
    # a descent that already runs along the approach line gets no corner; 2 cm off the line, one on it
    on_line = np.asarray(grasp) - 0.12 * _leaning(30.0)
    pts, _ = _square_onto_grasp(on_line, grasp, _leaning(30.0))
    np.testing.assert_array_equal(pts, [grasp])
    pts, _ = _square_onto_grasp(on_line + [0.0, 0.02, 0.0], grasp, _leaning(30.0))
    np.testing.assert_allclose(pts, [on_line, grasp], atol=1e-9)


def test_straight_down_and_side_grasps_and_releases_keep_the_corner_above():
    start, grasp = [0.40, 0.00, 0.20], [0.50, 0.02, 0.05]
    above = [[0.50, 0.02, 0.20], grasp]
    for axis in (_leaning(0.0), _leaning(2.0), _leaning(50.0), _leaning(80.0)):  # down, nearly down, past 45, side
        pts, _ = _square_onto_grasp(start, grasp, axis)
        np.testing.assert_allclose(pts, above)
    # a descent of the open hand that grasps nothing there, and a release, are lowered straight down as before
    for start_closed in (False, True):
        pts, _ = _square_onto_grasp(start, grasp, _leaning(30.0), start_closed=start_closed, closes=False)
        np.testing.assert_allclose(pts, above)


def test_the_executor_takes_each_grasps_approach_axis_from_its_planned_rotation():
    from scipy.spatial.transform import Rotation

    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.plan import WaypointPlan
    from tcot_hybrid.robot import R_DOWN
    from tcot_hybrid.run_config import RunConfig

    runner = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=0,
                                     executor=ExecutorConfig(grasp_along_approach=True)))
    ex, cam = runner.stack.executor, runner.stack.camera
    grasp = ex.sim.tcp_pos() + np.array([0.10, 0.05, -0.15])
    # leaning 25 degrees about an axis that is neither x nor y, so a transposed rotation would lean elsewhere
    rot = Rotation.from_rotvec(np.radians(25.0) * np.array([0.6, 0.8, 0.0])).as_matrix() @ R_DOWN
    uv, depth = cam.project(grasp[None])
    plan = WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([True]), camera=cam.name, kind="global",
                        tcp_rot=rot[None])
    assert ex.set_plan(plan)
    corner = ex.points[0]
    assert len(ex.points) == 2 and np.isclose(corner[2], ex.sim.tcp_pos()[2], atol=1e-9)
    along = (ex.points[1] - corner) / np.linalg.norm(ex.points[1] - corner)
    np.testing.assert_allclose(along, rot[:, 2], atol=1e-6)


def test_switch_threshold_is_checked_and_can_be_switched_off():
    with pytest.raises(ConfigError, match="switch_min_horizontal_m"):
        ExecutorConfig(switch_min_horizontal_m=0.0)
    assert ExecutorConfig(switch_min_horizontal_m=None).switch_min_horizontal_m is None
    start, points = np.array([0.40, 0.10, 0.18]), np.array([[0.40, 0.12, 0.04]])
    pts, _ = square_transits(start, True, points, np.array([False]), min_horizontal_m=None, min_vertical_m=V,
                             switch_min_horizontal_m=None)
    np.testing.assert_array_equal(pts, points)


def test_a_reflex_brake_near_a_joint_limit_never_commands_past_it():
    """The tracking reflex brakes the reference from the measured state; a joint moving fast toward a limit it is
    near would stop beyond it. The reference then rests at the measured posture inside the limits instead, the
    event says so, and the commanded positions of every tick stay inside [q_min, q_max] (recorded per episode)."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0))
    r.settle()
    ex, sim = r.stack.executor, r.stack.sim
    j = 3  # joint 4: its upper limit (-0.07 rad) is the one nearest a working posture
    adr = sim.model.joint(sim.robot.arm_joints[j]).qposadr[0]
    dof = sim.model.joint(sim.robot.arm_joints[j]).dofadr[0]
    sim.data.qpos[adr] = sim.robot.q_max[j] - 0.004
    sim.data.qvel[dof] = 0.8 * sim.robot.v_max[j]  # toward the limit: no stop fits in 4 mrad
    import mujoco

    mujoco.mj_forward(sim.model, sim.data)
    assert ex.smoother.brake(sim.q, sim.qd).limit_excursion_rad > 0  # what a plain brake would command
    ex._tracking_reflex(j, 0.3, 0.25)
    ev = [e for e in ex.events if e["kind"] == "reference_stopped_inside_limits"]
    assert len(ev) == 1 and ev[0]["reason"] == "tracking_reflex" and ev[0]["stop_excursion_rad"] > 0
    ahead = ex.smoother.preview(200)
    assert np.all(ahead <= sim.robot.q_max + 1e-12) and np.all(ahead >= sim.robot.q_min - 1e-12)
    for _ in range(50):
        ex.tick()
    rec = r.record(0.0)
    assert rec["max_reference_limit_excess_rad"] == 0.0


def test_a_reflex_brake_away_from_the_limits_stops_from_the_measured_state():
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0))
    r.settle()
    ex, sim = r.stack.executor, r.stack.sim
    ex._tracking_reflex(0, 0.3, 0.25)
    assert not [e for e in ex.events if e["kind"] == "reference_stopped_inside_limits"]
    np.testing.assert_allclose(ex.smoother.reference.q, sim.q)


def _turned_hand_run(hand_twin: bool, turn: float | None = None):
    """The workcell arm asked for its hand 3 cm lower and turned about its approach axis by ``turn`` [rad] (None: so
    far that joint 7 would end 0.4 rad past its upper limit); returns (events, planned R, goal, final TCP, final R,
    joint travel)."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.plan import WaypointPlan
    from tcot_hybrid.run_config import RunConfig

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0, executor=ExecutorConfig(hand_twin=hand_twin)))
    r.settle()
    ex, cam, sim = r.stack.executor, r.stack.camera, r.stack.sim
    q0 = sim.q.copy()
    if turn is None:
        turn = sim.robot.q_max[6] - q0[6] + 0.4
    c, s = np.cos(turn), np.sin(turn)
    _, R_now = ex.dyn.ee_pose()
    R = R_now @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # about the TCP's own z
    goal = sim.tcp_pos() + np.array([0.0, 0.0, -0.03])
    uv, depth = cam.project(goal[None])
    plan = WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([False]), camera=cam.name, kind="local",
                        tcp_rot=R[None])
    assert ex.set_plan(plan)
    for _ in range(400):
        ex.tick()
    _, R_end = ex.dyn.ee_pose()
    assert np.all(sim.q <= sim.robot.q_max) and np.all(sim.q >= sim.robot.q_min)
    return ex.events, R, goal, sim.tcp_pos().copy(), R_end.copy(), float(np.abs(sim.q - q0).sum())


def test_a_hand_past_joint_7s_limit_is_reached_by_its_half_turned_twin():
    """With ``hand_twin`` the executor solves the same parallel-jaw grasp turned half a turn, reaches the point with
    the same approach axis and the closing axis the other way round, moves the arm less than IK's way around the
    limit, and says so (``hand_turned``); without it the planned orientation is asked as it is."""
    events, R, goal, tcp, R_end, travel = _turned_hand_run(True)
    turned = [e for e in events if e["kind"] == "hand_turned"]
    assert len(turned) == 1 and turned[0]["turned"]
    assert not [e for e in events if e["kind"] == "ik_not_converged"]
    np.testing.assert_allclose(tcp, goal, atol=0.01)
    np.testing.assert_allclose(R_end[:, 2], R[:, 2], atol=0.02)  # same approach axis
    np.testing.assert_allclose(R_end[:, :2], -R[:, :2], atol=0.02)  # closing axis the other way round
    events_off, _, _, _, R_off, travel_off = _turned_hand_run(False)
    assert not [e for e in events_off if e["kind"] == "hand_turned"]
    assert np.abs(R_off[:, :2] - R[:, :2]).max() < 0.02 or [e for e in events_off if e["kind"] == "ik_not_converged"]
    assert travel < travel_off, "the twin is the shorter way for the arm"


def test_the_twin_is_taken_for_travel_only_when_it_saves_more_than_the_margin():
    """Two converged answers: the twin must move the arm TWIN_TRAVEL_MARGIN_RAD less to be taken (a twin 0.06 rad
    shorter of a 5.9 rad mid-carry swing turned a carried bottle's hand and tripped the tracking reflex); a twin
    that converges where the other missed by more than TWIN_MISS_M is taken whatever it travels."""
    from types import SimpleNamespace

    from tcot_hybrid.executor import TWIN_MISS_M, TWIN_TRAVEL_MARGIN_RAD, _twin_is_better

    seed = np.zeros(7)

    def answer(travel: float, converged: bool = True, miss: float = 0.0):
        return SimpleNamespace(q=np.r_[travel, np.zeros(6)], converged=converged, pos_err=miss)

    assert _twin_is_better(answer(2.19), answer(7.47), seed)
    assert not _twin_is_better(answer(5.84), answer(5.90), seed)
    assert not _twin_is_better(answer(5.90 - TWIN_TRAVEL_MARGIN_RAD + 0.01), answer(5.90), seed)
    assert _twin_is_better(answer(5.90 - TWIN_TRAVEL_MARGIN_RAD - 0.01), answer(5.90), seed)
    assert _twin_is_better(answer(9.0), answer(1.0, converged=False, miss=TWIN_MISS_M + 0.01), seed)
    assert not _twin_is_better(answer(0.1, converged=False), answer(5.0), seed)


def test_a_hand_asked_more_than_a_quarter_turn_is_reached_by_the_nearer_twin():
    """A hand asked to turn 130 degrees about its approach axis, which IK reaches inside the limits by turning the wrist
    all that way, is reached by its twin, 50 degrees the other way, with less joint travel (a learned side grasp of the
    ketchup asked such a turn and the arm carried the bottle from an elbow it could not reach the basket with:
    docs/libero-planner.md, "The hand the arm stands nearer"); a hand asked 80 degrees is asked as planned."""
    events, R, goal, tcp, R_end, travel = _turned_hand_run(True, turn=-np.radians(130.0))
    turned = [e for e in events if e["kind"] == "hand_turned"]
    assert len(turned) == 1 and turned[0]["turned"]
    assert turned[0]["other_converged"] and not turned[0]["other_limit_active"]  # the turn alone asked for the twin
    np.testing.assert_allclose(tcp, goal, atol=0.01)
    np.testing.assert_allclose(R_end[:, 2], R[:, 2], atol=0.02)
    np.testing.assert_allclose(R_end[:, :2], -R[:, :2], atol=0.02)
    _, _, _, _, R_off, travel_off = _turned_hand_run(False, turn=-np.radians(130.0))
    np.testing.assert_allclose(R_off, R, atol=0.02)  # without the twin the whole turn is made
    assert travel < travel_off - 1.0
    events, R, goal, tcp, R_end, _ = _turned_hand_run(True, turn=-np.radians(80.0))
    assert not [e for e in events if e["kind"] == "hand_turned"]
    np.testing.assert_allclose(R_end, R, atol=0.02)
    np.testing.assert_allclose(tcp, goal, atol=0.01)


def test_go_home_rises_straight_up_then_returns_to_the_starting_posture():
    """go_home drops the plan, lifts the hand straight up by lift_m (orientation kept), then moves in joint space to the
    posture the scene started from; plan_finished turns true there (event home_reached)."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.plan import WaypointPlan
    from tcot_hybrid.run_config import RunConfig

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0))
    r.settle()
    ex, cam, sim = r.stack.executor, r.stack.camera, r.stack.sim
    home = ex.home_q.copy()
    away = sim.tcp_pos() + np.array([0.10, -0.08, -0.12])
    uv, depth = cam.project(away[None])
    assert ex.set_plan(WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([False]), camera=cam.name,
                                    kind="local"))
    for _ in range(600):
        ex.tick()
        if ex.plan_finished:
            break
    start = sim.tcp_pos().copy()
    assert np.linalg.norm(start - away) < 0.02 and np.abs(sim.q - home).max() > 0.1
    ex.go_home(0.10)
    assert ex.plan is None and not ex.plan_finished
    assert ex.events[-1]["kind"] == "going_home" and ex.events[-1]["lift_converged"]
    path = []
    for _ in range(2000):
        ex.tick()
        path.append(sim.tcp_pos().copy())
        if ex.plan_finished:
            break
    assert ex.plan_finished and ex.events[-1]["kind"] == "home_reached"
    np.testing.assert_allclose(sim.q, home, atol=0.02)
    path = np.array(path)
    top = int(np.argmax(path[:, 2] > start[2] + 0.09))  # first tick 9 cm above where it started
    assert top > 0 and np.linalg.norm(path[:top, :2] - start[:2], axis=1).max() < 0.02  # straight up first


def test_a_plan_ending_at_its_release_leaves_it_straight_up():
    pts = np.array([[0.5, 0.0, 0.3], [0.5, 0.0, 0.1], [0.6, 0.1, 0.2], [0.6, 0.1, 0.12]])
    grip = np.array([False, True, True, False])  # grasp, carry, release at the last point
    out, g, src = retreat_after_release(False, pts, grip, lift_m=0.08)
    assert len(out) == 5 and not g[-1] and src.tolist() == [0, 1, 2, 3, 3]
    np.testing.assert_allclose(out[:4], pts)
    np.testing.assert_allclose(out[-1], pts[-1] + [0, 0, 0.08])
    # the release's own height counts, not the last point's: a plan that ends a little above it still gets the lift
    ends_near = np.vstack([pts, pts[-1] + [0.01, 0, RETREAT_NEAR_M / 2]])
    assert len(retreat_after_release(False, ends_near, np.r_[grip, False], lift_m=0.08)[0]) == 6


@pytest.mark.parametrize("case", ["already_leaves", "no_release", "last_switch_a_grasp", "off"])
def test_no_retreat_where_the_plan_leaves_or_lets_go_of_nothing(case):
    pts = np.array([[0.5, 0.0, 0.3], [0.5, 0.0, 0.1], [0.6, 0.1, 0.12]])
    grip, start_closed, lift = np.array([False, True, False]), False, 0.08
    if case == "already_leaves":
        pts, grip = np.vstack([pts, pts[-1] + [0, 0, RETREAT_NEAR_M + 0.01]]), np.r_[grip, False]
    elif case == "no_release":  # open before the plan and throughout: what it let go of was an earlier plan's
        grip = np.array([False, False, False])
    elif case == "last_switch_a_grasp":
        grip = np.array([False, False, True])
    else:
        lift = None
    out, g, src = retreat_after_release(start_closed, pts, grip, lift_m=lift)
    np.testing.assert_array_equal(out, pts)
    np.testing.assert_array_equal(g, grip)
    assert src.tolist() == list(range(len(pts)))


def test_a_release_at_the_first_point_counts_from_the_gripper_command_before_the_plan():
    pts = np.array([[0.6, 0.1, 0.12], [0.6, 0.1, 0.13]])
    out, _, _ = retreat_after_release(True, pts, np.array([False, False]), lift_m=0.05)
    np.testing.assert_allclose(out[-1], pts[-1] + [0, 0, 0.05])
    with pytest.raises(ConfigError, match="release_retreat_m"):
        ExecutorConfig(release_retreat_m=0.0)


@pytest.mark.parametrize("z, grip, closed_at, expect", [
    ([0.90, 0.95, 1.00, 0.96, 0.96], [0, 1, 1, 1, 0], 1, 0.04),  # lift to 1.00, put down at 0.96
    ([0.90, 0.92, 1.05, 1.05, 1.00], [0, 1, 1, 0, 0], 1, 0.0),  # opened at the top: in the air
    ([0.90, 0.92, 1.05, 1.01, 1.02], [0, 1, 1, 1, 1], 1, None),  # never opened again
    ([1.00, 0.90, 0.95, 0.93], [1, 1, 0, 0], 0, 0.05),  # closed at the first point, released at the third
    ([0.90, 1.00, 0.97, 0.90, 0.90], [0, 1, 1, 0, 1], 1, 0.10),  # only up to the first release
])
def test_put_down_before_release_measures_the_closed_stretch(z, grip, closed_at, expect):
    from tcot_hybrid.executor import put_down_before_release

    points = np.column_stack([np.zeros(len(z)), np.zeros(len(z)), z])
    got = put_down_before_release(points, np.array(grip, bool), closed_at)
    assert got == pytest.approx(expect) if expect is not None else got is None


@pytest.mark.parametrize("field, value", [("touch_retry_depth_m", 0.0), ("touch_retry_depth_m", -0.05),
                                          ("touch_retry_radius_m", 0.0), ("touch_step_m", -0.01),
                                          ("touch_force_n", 0.0), ("touch_force_n", float("nan"))])
def test_touch_settings_are_checked(field, value):
    with pytest.raises(ConfigError, match=field):
        ExecutorConfig(**{field: value})


def test_a_touch_step_deeper_than_the_touch_is_refused():
    with pytest.raises(ConfigError, match="touch_step_m = 0.1 m is deeper than touch_retry_depth_m = 0.08"):
        ExecutorConfig(touch_retry_depth_m=0.08, touch_step_m=0.1)
    ExecutorConfig(touch_retry_depth_m=None, touch_step_m=0.1)  # off: nothing to check it against


def test_an_empty_grasp_is_remembered_until_the_scene_is_reset_and_a_hand_without_a_force_sensor_closes_as_planned():
    """The workcell Panda has no wrist force sensor: a retried grasp closes where planned, and says once why it did
    not touch down (``touch_unavailable``)."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.plan import WaypointPlan
    from tcot_hybrid.run_config import RunConfig

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0, executor=ExecutorConfig(touch_retry_depth_m=0.08)))
    r.settle()
    ex, cam, sim = r.stack.executor, r.stack.camera, r.stack.sim
    assert sim.wrist_force() is None
    _, R = ex.dyn.ee_pose()
    grasp = sim.tcp_pos() + np.array([0.0, 0.0, -0.05])

    def close_at_grasp() -> np.ndarray:
        uv, depth = cam.project(grasp[None])
        assert ex.set_plan(WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([True]), camera=cam.name,
                                        kind="local", tcp_rot=R[None]))
        for _ in range(400):
            ex.tick()
            if sim.gripper_closed_cmd():
                return sim.tcp_pos()
        raise AssertionError("the gripper never closed")

    first = close_at_grasp()
    assert ex.empty_grasp_points == []
    ex.open_empty_gripper(0.001)  # as GLSR's empty-grasp check does
    assert len(ex.empty_grasp_points) == 1
    np.testing.assert_allclose(ex.empty_grasp_points[0], first, atol=1e-3)  # read one control tick apart
    second = close_at_grasp()
    said = [e for e in ex.events if e["kind"] == "touch_unavailable"]
    assert len(said) == 1 and not [e for e in ex.events if e["kind"] == "touch"]
    assert np.linalg.norm(second - grasp) < ex.config.reach_tol_m + 0.002
    ex.reset_after_scene_reset()
    assert ex.empty_grasp_points == []


def test_a_long_segment_is_cut_into_equal_pieces_on_its_line():
    """An 18 cm descent with pieces of at most 4 cm: five equal pieces on the planned line, each cut point passing
    through (the gripper bit of the segment's start) and taking its segment end's index (so its orientation); a
    short segment is left alone."""
    start = np.array([0.0, 0.0, 0.30])
    points = np.array([[0.0, 0.0, 0.12], [0.02, 0.0, 0.12]])
    p, g, index = cut_long_segments(start, False, points, np.array([False, True]), max_segment_m=0.04)
    np.testing.assert_allclose(p[:5, 2], [0.264, 0.228, 0.192, 0.156, 0.12])
    np.testing.assert_allclose(p[:5, :2], 0.0)
    np.testing.assert_allclose(p[5], points[1])
    np.testing.assert_array_equal(g, [False] * 5 + [True])  # the grasp still closes at its planned point
    np.testing.assert_array_equal(index, [0, 0, 0, 0, 0, 1])

    carry = np.array([[0.02, 0.0, 0.30], [0.02, 0.0, 0.12]])  # a short move over, then the long descent
    p, g, index = cut_long_segments(start, True, carry, np.array([True, False]), max_segment_m=0.04)
    assert index.tolist() == [0, 1, 1, 1, 1, 1]
    np.testing.assert_array_equal(g, [True] * 5 + [False])  # carried closed down to the release


def test_the_first_cut_carries_the_gripper_command_of_now():
    """The first segment starts at the TCP with the gripper as it is: its cut points keep that command, so a plan
    whose first point releases opens there, not at the first cut."""
    p, g, _ = cut_long_segments(np.zeros(3), True, np.array([[0.0, 0.0, -0.1]]), np.array([False]),
                                max_segment_m=0.04)
    np.testing.assert_array_equal(g, [True, True, False])
    np.testing.assert_allclose(np.diff(p[:, 2]), [-0.1 / 3] * 2)


@pytest.mark.parametrize("length", [0.0, 0.04, 0.0399])
def test_segments_no_longer_than_the_limit_and_a_switched_off_cut_leave_the_plan_alone(length):
    points = np.array([[length, 0.0, 0.0]])
    p, g, index = cut_long_segments(np.zeros(3), False, points, np.array([True]), max_segment_m=0.04)
    np.testing.assert_array_equal(p, points)
    assert g.tolist() == [True] and index.tolist() == [0]
    p, _, _ = cut_long_segments(np.zeros(3), False, np.array([[1.0, 0, 0]]), np.array([True]), max_segment_m=None)
    assert len(p) == 1


def test_a_cut_point_asks_its_segment_ends_orientation_so_the_twin_is_chosen_where_it_was():
    """Cut points take the orientation of their segment's end, as squared corners do: the hand turns on the first
    piece, where the executor decides on the half-turned twin as it would without the cut."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.plan import WaypointPlan
    from tcot_hybrid.run_config import RunConfig

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0,
                                executor=ExecutorConfig(max_segment_m=0.04, cut_segments="vertical")))
    r.settle()
    ex, cam, sim = r.stack.executor, r.stack.camera, r.stack.sim
    _, R_now = ex.dyn.ee_pose()
    c, s = np.cos(1.2), np.sin(1.2)
    R = R_now @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    goal = sim.tcp_pos() + np.array([0.0, 0.0, -0.15])
    uv, depth = cam.project(goal[None])
    assert ex.set_plan(WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([False]), camera=cam.name,
                                    kind="local", tcp_rot=R[None]))
    assert ex.events[-1]["cuts_added"] == 3 and len(ex.points) == 4
    np.testing.assert_allclose(ex.rots, np.broadcast_to(R, (4, 3, 3)))


def test_which_segments_are_cut():
    """"closed_descents": only a closed hand's (near) vertical descent; "vertical": rises and open descents too, never a
    move over; "all": every long segment."""
    start = np.array([0.0, 0.0, 0.30])
    points = np.array([[0.0, 0.0, 0.10],  # open descent (20 cm)
                       [0.0, 0.0, 0.10],  # close
                       [0.03, 0.0, 0.30],  # closed rise, 8.5 degrees off vertical
                       [0.23, 0.0, 0.30],  # closed move over (20 cm)
                       [0.23, 0.0, 0.10],  # closed descent (20 cm)
                       [0.23, 0.0, 0.10]])  # release
    grip = np.array([False, True, True, True, True, False])
    cuts = {}
    for which in ("closed_descents", "vertical", "all"):
        _, g, index = cut_long_segments(start, False, points, grip, max_segment_m=0.05, which=which)
        cuts[which] = np.bincount(index, minlength=len(points)) - 1  # cut points added before each planned point
        assert g[np.flatnonzero(np.r_[np.diff(index) > 0, True])].tolist() == grip.tolist()  # at the planned points
    assert cuts["closed_descents"].tolist() == [0, 0, 0, 0, 3, 0]
    assert cuts["vertical"].tolist() == [3, 0, 4, 0, 3, 0]
    assert cuts["all"].tolist() == [3, 0, 4, 3, 3, 0]


def _closed_descent_run(opening_m: float | None):
    """The workcell hand closed in the air (fingers held ``opening_m`` apart, as by an object, or None: as they close
    on nothing), then a plan 15 cm straight down with it closed, ``cut_segments`` "holding_descents"; returns the
    executor after the plan."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.plan import WaypointPlan
    from tcot_hybrid.run_config import RunConfig

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0,
                                executor=ExecutorConfig(max_segment_m=0.04, cut_segments="holding_descents")))
    r.settle()
    ex, cam, sim = r.stack.executor, r.stack.camera, r.stack.sim
    sim.set_gripper(True)
    for _ in range(60):
        ex.tick()
    if opening_m is not None:
        sim.gripper_opening_m = lambda: opening_m
    goal = sim.tcp_pos() + np.array([0.0, 0.0, -0.15])
    uv, depth = cam.project(goal[None])
    assert ex.set_plan(WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([True]), camera=cam.name,
                                    kind="local"))
    assert ex.events[-1]["kind"] in ("plan_adopted", "segment_cut")
    for _ in range(800):
        ex.tick()
        if ex.plan_finished:
            break
    assert ex.plan_finished and np.linalg.norm(sim.tcp_pos() - goal) < 0.01
    return ex


def test_a_holding_hands_descent_is_cut_when_it_begins_and_an_empty_closed_hands_is_not():
    """"holding_descents": the cut is decided as the segment begins, on the fingers' opening: a hand closed on an
    object (fingers apart) goes down the planned line in 4 cm pieces; a hand closed on purpose with nothing in it (a
    push) keeps the smoother's path."""
    held = _closed_descent_run(0.02)
    cut = [e for e in held.events if e["kind"] == "segment_cut"]
    assert len(cut) == 1 and cut[0]["pieces"] == 4 and len(held.points) == 4
    assert np.all(np.diff(held.points[:, 2]) < 0) and np.allclose(held.point_source, 0)
    empty = _closed_descent_run(None)
    assert not [e for e in empty.events if e["kind"] == "segment_cut"] and len(empty.points) == 1
    adopted = [e for e in held.events if e["kind"] == "plan_adopted"][-1]
    assert adopted["cuts_added"] == 0  # nothing is cut when the plan is adopted


@pytest.mark.parametrize("value", [0.0, -0.04, "always"])
def test_the_segment_limit_is_checked(value):
    with pytest.raises(ConfigError, match="max_segment_m") as err:
        ExecutorConfig(max_segment_m=value)
    assert str(value) in str(err.value) and ("auto" in str(err.value) or "> 0" in str(err.value))
    with pytest.raises(ConfigError, match="cut_segments.*closed_descents"):
        ExecutorConfig(cut_segments="diagonal")


def test_the_segment_limit_is_auto_a_holding_hands_descents_on_libero_and_off_on_the_workcell():
    cfg = ExecutorConfig()
    assert cfg.max_segment_m == "auto" and cfg.cut_segments == "holding_descents"
    assert resolve_max_segment("auto", "libero") == MAX_SEGMENT_LIBERO_M == 0.04
    assert resolve_max_segment("auto", "workcell") is None
    assert resolve_max_segment(0.02, "workcell") == 0.02 and resolve_max_segment(None, "libero") is None


def test_a_cut_plan_keeps_the_hand_near_its_planned_line():
    """A learned-style plan of one far, low point (squared into a move over and a descent): between two far IK
    targets the joint-space reference bows off the planned line; cut into 4 cm pieces, the hand stays within
    about a blend's corner of it."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.plan import WaypointPlan
    from tcot_hybrid.run_config import RunConfig

    def run(cut):
        r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0,
                                    executor=ExecutorConfig(max_segment_m=cut, cut_segments="all")))
        r.settle()
        ex, cam, sim = r.stack.executor, r.stack.camera, r.stack.sim
        start = sim.tcp_pos().copy()
        goal = start + np.array([0.18, -0.12, -0.16])
        uv, depth = cam.project(goal[None])
        assert ex.set_plan(WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([False]), camera=cam.name,
                                        kind="local"))
        assert ex.events[-1]["corners_added"] == 1 and (ex.events[-1]["cuts_added"] > 0) == (cut is not None)
        line = np.stack([start, np.r_[goal[:2], start[2]], goal])  # over at height, then down
        off = 0.0
        for _ in range(1500):
            ex.tick()
            p = sim.tcp_pos()
            off = max(off, min(_off_segment(p, line[k], line[k + 1]) for k in range(2)))
            if ex.plan_finished:
                break
        assert ex.plan_finished and np.linalg.norm(sim.tcp_pos() - goal) < 0.01
        return off

    bowed, cut = run(None), run(0.04)
    assert bowed > 0.02 and cut < 0.5 * bowed and cut < 0.015, (bowed, cut)


def _off_segment(p, a, b) -> float:
    d = b - a
    t = float(np.clip(np.dot(p - a, d) / np.dot(d, d), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * d)))
