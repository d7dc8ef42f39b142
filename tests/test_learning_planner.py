"""Learned and direct planners: plan shapes and lift cue, input/output validation, registry, defaults."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import time  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
from learning_synth import agentview_camera  # noqa: E402

from tcot_hybrid.camera import depth_at_height  # noqa: E402
from tcot_hybrid.errors import CheckpointError, LiftError, PlanningError  # noqa: E402
from tcot_hybrid.learning.checkpoint import camera_meta, load_checkpoint, save_checkpoint, versions  # noqa: E402
from tcot_hybrid.learning.model import ModelConfig, PlannerNet  # noqa: E402
from tcot_hybrid.learning.vocab import Vocabulary, words  # noqa: E402
from tcot_hybrid.planners import Observation, ObservationContext, list_planners, make_planner  # noqa: E402
from tcot_hybrid.planners.direct import DirectPlanner, TcpKinematics  # noqa: E402
from tcot_hybrid.planners.learned import (  # noqa: E402
    YAW_DEFINED_MIN,
    LearnedPlanner,
    LearnedPlannerConfig,
    align_gripper_switches,
    align_switches_to_dwells,
    canonical_hand,
    check_outputs,
    deepen_side_grasps,
    height_plan,
    lowest_plan_height,
)
from tcot_hybrid.errors import ConfigError  # noqa: E402
from tcot_hybrid.robot import load_robot_spec  # noqa: E402

INSTR = "put the cube on the plate"
VOCAB = Vocabulary.build([INSTR, "open the drawer"])


@pytest.fixture(scope="module")
def camera():
    return agentview_camera()


def _save(path, camera, kind="trajectory"):
    torch.manual_seed(0)
    model = PlannerNet(ModelConfig(kind=kind, width=8, vocab_size=len(VOCAB))).eval()
    meta = {"robot": "panda", "camera": camera_meta(camera), "vocabulary": list(VOCAB.tokens),
            "windows": {"L_g": 51, "n_g": 4, "L_l": 8, "n_l": 2}, "data_hash": "t", "metrics": {},
            "versions": versions(), "max_unknown_fraction": 0.5, "direct_horizon": 3}
    return save_checkpoint(path, model, meta)


@pytest.fixture(scope="module")
def planner(tmp_path_factory, camera):
    path = _save(tmp_path_factory.mktemp("ck") / "p.safetensors", camera)
    return LearnedPlanner(load_checkpoint(path, robot="panda", camera=camera, kind="trajectory"), camera)


def _obs(step=0, image=None, q=None, instruction=INSTR, closed=False):
    rng = np.random.default_rng(step)
    if image is None:
        image = rng.integers(0, 255, size=(128, 128, 3), dtype=np.uint8)
    spec = load_robot_spec("panda")
    return Observation(step=step, image=image, depth_m=None, q=spec.home_q.copy() if q is None else q,
                       gripper_closed=closed, instruction=instruction)


def test_depth_at_height_round_trip(camera):
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(0.3, 0.7, 50), rng.uniform(-0.3, 0.3, 50), rng.uniform(0.0, 0.4, 50)]
    uv, depth = camera.project(pts)
    d = depth_at_height(camera, uv, pts[:, 2])
    assert np.allclose(d, depth, atol=1e-9)
    assert np.allclose(camera.unproject(uv, d), pts, atol=1e-9)
    with pytest.raises(LiftError, match="behind"):
        depth_at_height(camera, uv[:1], np.array([5.0]))  # plane above the camera (z = 1 m)
    with pytest.raises(LiftError, match="not finite"):
        depth_at_height(camera, uv[:1], np.array([np.nan]))


def test_global_and_local_plans(planner, camera):
    g = planner.plan(_obs(), mode="global")
    assert g.kind == "global" and len(g) == 51 - 25  # k >= 0 only
    loc = planner.plan(_obs(), mode="local")
    assert loc.kind == "local" and len(loc) == 9
    for plan in (g, loc):
        assert camera.in_image(plan.uv_px).all()
        z = plan.meta["z_m"]
        world = camera.unproject(plan.uv_px, plan.depth_m)
        assert np.allclose(world[:, 2], z, atol=1e-6)  # depth_m is where the ray meets z = z_m
        assert plan.gripper_closed.dtype == bool
    p = planner.success_probability(_obs())
    assert 0.0 <= p <= 1.0
    with pytest.raises(PlanningError, match="mode"):
        planner.plan(_obs(), mode="detect")


def test_same_input_same_plan(planner):
    a, b = planner.plan(_obs(3), mode="global"), planner.plan(_obs(3), mode="global")
    assert np.array_equal(a.uv_px, b.uv_px) and np.array_equal(a.depth_m, b.depth_m)


@pytest.mark.parametrize("image, match", [
    (None, "needs the planner camera image"),
    (np.zeros((128, 128, 3), np.uint8), "blank"),
    (np.full((128, 128, 3), 255, np.uint8), "blank"),
    (np.zeros((64, 64, 3), np.uint8), "shape"),
    (np.zeros((128, 128), np.uint8), "shape"),
    (np.full((128, 128, 3), np.nan, np.float32), "NaN"),
    (np.random.default_rng(0).random((128, 128, 3)).astype(np.float32), "uint8"),
])
def test_bad_images_refused(planner, image, match):
    with pytest.raises(PlanningError, match=match):
        planner.plan(_obs(image=image) if image is not None else Observation(
            step=0, image=None, depth_m=None, q=np.zeros(7), gripper_closed=False, instruction=INSTR), mode="global")


def test_fuzzed_images_never_crash(planner):
    """RELIABILITY #1: refused with PlanningError or planned with finite output; never anything else."""
    rng = np.random.default_rng(1)
    refused = planned = 0
    for i in range(60):
        kind = i % 6
        if kind == 0:
            img = rng.integers(0, 255, size=(128, 128, 3), dtype=np.uint8)
        elif kind == 1:
            img = np.full((128, 128, 3), rng.integers(0, 256), np.uint8)
        elif kind == 2:
            img = rng.random((128, 128, 3)) * 255
        elif kind == 3:
            img = rng.integers(0, 255, size=tuple(rng.integers(1, 200, size=3)), dtype=np.uint8)
        elif kind == 4:
            img = np.where(rng.random((128, 128, 3)) < 0.1, np.inf, 1.0).astype(np.float64)
        else:
            img = rng.integers(-5, 5, size=(128, 128, 3)).astype(np.int16)
        try:
            plan = planner.plan(_obs(image=img), mode="global")
            assert np.isfinite(plan.uv_px).all() and np.isfinite(plan.depth_m).all()
            planned += 1
        except PlanningError:
            refused += 1
    assert refused + planned == 60 and refused >= 40


def test_bad_joint_state_refused(planner):
    with pytest.raises(PlanningError, match="not finite"):
        planner.plan(_obs(q=np.full(7, np.nan)), mode="global")
    with pytest.raises(PlanningError, match="shape"):
        planner.plan(_obs(q=np.zeros(6)), mode="global")


def test_output_validation(planner, monkeypatch):
    with pytest.raises(PlanningError, match="outside"):
        check_outputs(np.zeros((2, 2)), np.zeros(2), np.array([0.5, 1.5]))
    with pytest.raises(PlanningError, match="not finite"):
        check_outputs(np.array([[1.0, np.nan]]), np.zeros(1), np.array([0.5]))
    with pytest.raises(PlanningError, match="success probability"):
        check_outputs(np.zeros((0, 2)), np.zeros(0), np.zeros(0), 1.2)
    real = planner.model.forward

    def nan_forward(*a, **k):
        out = real(*a, **k)
        if "uv_px" in out:  # the detect prompt skips the waypoint decoder
            out["uv_px"] = out["uv_px"] * float("nan")
        out["success_logit"] = out["success_logit"] * float("nan")
        return out
    monkeypatch.setattr(planner.model, "forward", nan_forward)
    with pytest.raises(PlanningError, match="not finite"):
        planner.plan(_obs(), mode="global")
    with pytest.raises(PlanningError, match="not finite"):
        planner.success_probability(_obs())


def test_a_plan_below_the_table_is_refused_not_executed(planner, monkeypatch):
    check_outputs(np.zeros((2, 2)), np.array([0.01, -0.005]), np.array([0.5, 0.5]), min_height_m=-0.02)  # grazing: kept
    with pytest.raises(PlanningError, match=r"waypoint 1 has TCP height z_m = -0.5030 m.*learned.min_height_m"):
        check_outputs(np.zeros((3, 2)), np.array([0.1, -0.503, -0.3]), np.full(3, 0.5), min_height_m=-0.02)
    real = planner.model.forward

    def sunk_forward(*a, **k):
        out = real(*a, **k)
        if "z_m" in out:
            out["z_m"] = out["z_m"] - 1.0  # every waypoint a metre lower
        return out
    monkeypatch.setattr(planner.model, "forward", sunk_forward)
    for mode in ("global", "local"):
        with pytest.raises(PlanningError, match="below the lowest allowed"):
            planner.plan(_obs(), mode=mode)


def test_instruction_policy(planner):
    assert words("Put the Cube, on the plate!") == ["put", "the", "cube", "on", "the", "plate"]
    planner.plan(_obs(instruction="Put the cube onto the plate."), mode="global")  # 1 of 6 unknown: accepted
    with pytest.raises(PlanningError, match="never saw"):
        planner.plan(_obs(instruction="stapeln sie die bloecke"), mode="global")
    with pytest.raises(PlanningError, match="empty"):
        planner.plan(_obs(instruction="  ?! "), mode="global")


def test_registry_and_checkpoint_selection(tmp_path, camera):
    assert {"learned", "direct"} <= set(list_planners())
    path = _save(tmp_path / "p.safetensors", camera)
    ctx = ObservationContext(camera=camera, robot_name="panda", options={"checkpoint": str(path)})
    p = make_planner("learned", ctx)
    assert isinstance(p, LearnedPlanner) and p.needs_image
    ctx_bad = ObservationContext(camera=camera, robot_name="ur5e", options={"checkpoint": str(path)})
    with pytest.raises(CheckpointError, match="robot 'panda'"):
        make_planner("learned", ctx_bad)
    with pytest.raises(CheckpointError, match="'trajectory' planner checkpoint"):
        make_planner("direct", ctx)
    ctx_none = ObservationContext(camera=camera, robot_name="ur5e", options={"checkpoint": None})
    with pytest.raises(CheckpointError, match="no shipped trajectory planner checkpoint for robot 'ur5e'"):
        make_planner("learned", ctx_none)


def test_direct_planner_one_waypoint_from_tcp(tmp_path, camera):
    path = _save(tmp_path / "d.safetensors", camera, kind="direct")
    ck = load_checkpoint(path, robot="panda", camera=camera, kind="direct")
    p = DirectPlanner(ck, camera, robot_name="panda")
    assert p.replan_every_step
    obs = _obs()
    plan = p.plan(obs, mode="direct")
    assert plan.kind == "direct" and len(plan) == 1
    target = camera.unproject(plan.uv_px, plan.depth_m)[0]
    tcp = TcpKinematics("panda").tcp(obs.q)
    assert np.allclose(target - tcp, plan.meta["delta_m"], atol=1e-6)


def test_tcp_kinematics_places_the_robot_by_its_mounting_pose():
    """A robot mounted elsewhere (LIBERO: e.g. (-0.66, 0, 0.912), turned or not) has its TCP moved with its base."""
    q = np.array([0.1, -0.4, 0.2, -2.2, 0.1, 1.9, 0.6])
    p0, R0 = TcpKinematics("panda").pose(q)
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 degrees about z
    T[:3, 3] = [-0.66, 0.0, 0.912]
    p1, R1 = TcpKinematics("panda", T).pose(q)
    np.testing.assert_allclose(p1, T[:3, :3] @ p0 + T[:3, 3], atol=1e-12)
    np.testing.assert_allclose(R1, T[:3, :3] @ R0, atol=1e-12)
    for bad, match in ((np.eye(3), "finite 4x4"), (np.full((4, 4), np.nan), "finite 4x4"),
                       (np.diag([2.0, 1.0, 1.0, 1.0]), "not a rigid transform")):
        with pytest.raises(ConfigError, match=match):
            TcpKinematics("panda", bad)


def test_direct_planner_orientation_per_world(tmp_path, camera):
    """Workcell checkpoints leave the orientation to the executor (top-down, as every workcell demo); a LIBERO one
    holds the TCP orientation of the episode's first observation in every plan, until ``prepare`` (a new episode)."""
    path = _save(tmp_path / "d.safetensors", camera, kind="direct")
    p = DirectPlanner(load_checkpoint(path, kind="direct"), camera, robot_name="panda")
    assert p.plan(_obs(), mode="direct").tcp_rot is None
    ck = load_checkpoint(path, kind="direct")
    ck.meta["world"] = "libero"  # in memory only: what a LIBERO checkpoint's metadata says
    p = DirectPlanner(ck, camera, robot_name="panda")
    first = _obs(0)
    later = _obs(1, q=first.q + 0.2)
    R_first = p.kinematics.pose(first.q)[1]
    assert not np.allclose(R_first, p.kinematics.pose(later.q)[1], atol=1e-3)
    for obs in (first, later):
        np.testing.assert_allclose(p.plan(obs, mode="direct").tcp_rot, R_first[None], atol=1e-12)
    p.prepare()
    np.testing.assert_allclose(p.plan(later, mode="direct").tcp_rot, p.kinematics.pose(later.q)[1][None], atol=1e-12)


def test_tcp_kinematics_matches_simulation():
    from tcot_hybrid.config import TimingConfig
    from tcot_hybrid.scene import SceneConfig
    from tcot_hybrid.sim import Simulation
    from tcot_hybrid.tasks import make_task

    spec = load_robot_spec("panda")
    sim = Simulation(spec, make_task("goal_cube_on_plate"), timing=TimingConfig(), scene=SceneConfig())
    sim.reset(np.random.default_rng(0))
    assert np.allclose(TcpKinematics("panda").tcp(sim.q), sim.tcp_pos(), atol=1e-9)
    sim.close()


def test_inference_shape_and_latency_smoke(planner):
    """Batch-1 latency is printed, not asserted (shared CPUs)."""
    torch.set_num_threads(2)
    obs = _obs()
    planner.infer(obs, "global")
    t = []
    for _ in range(10):
        t0 = time.perf_counter()
        out = planner.infer(obs, "global")
        t.append(time.perf_counter() - t0)
    assert out["uv_px"].shape == (60, 2) and out["z_m"].shape == (60,) and out["grip_logit"].shape == (60,)
    print(f"batch-1 inference (test model, width 8): median {1e3 * np.median(t):.2f} ms")


def test_gripper_switch_moves_to_the_bottom_of_its_descent():
    # measured shape (stack task, seed 2001): the close predicted one waypoint after the lowest point
    z = np.array([.34, .10, .015, .035, .20, .13, .07, .072, .18, .10, .016, .021, .086, .17, .13])
    g = np.array([0, 0, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 1, 1, 1], bool)
    out = align_gripper_switches(z, g, window=2, min_rise_m=0.015)
    assert np.flatnonzero(np.diff(out.astype(int))).tolist() == [1, 6, 9]  # close at 2, open at 7, close at 10
    assert out[10] and not out[9] and out[2] and not out[7]
    assert np.array_equal(align_gripper_switches(z, g, window=0, min_rise_m=0.015), g)  # 0 = off


def test_gripper_switch_kept_on_flat_segments_and_never_crosses_another_switch():
    z = np.array([.05, .05, .051, .049, .05, .05])  # a horizontal pull (drawer): nothing to move
    g = np.array([0, 1, 1, 1, 0, 0], bool)
    assert np.array_equal(align_gripper_switches(z, g, window=2, min_rise_m=0.015), g)
    z = np.array([.3, .02, .2, .2, .01, .3])
    g = np.array([0, 0, 1, 0, 0, 1], bool)  # switches at 2, 3, 5: each moves only inside its own span
    out = align_gripper_switches(z, g, window=3, min_rise_m=0.015)
    assert np.flatnonzero(np.diff(out.astype(int))).size == 3
    assert out[1] and not out[0]


# measured shape (tool task, evaluation seed 1001, x/z of the t = 0 plan, y constant): the release predicted
# at waypoint 10, mid-drag; the drag ends at waypoint 11, where the arm dwells
DRAG_X = [.453, .385, .354, .346, .347, .349, .36, .363, .569, .549, .427, .33, .328, .329, .33]
DRAG_Z = [.351, .24, .14, .057, .01, .007, .064, .107, .074, .007, .001, .014, .016, .015, .015]
DRAG_G = [0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0]


def _drag():
    return np.c_[DRAG_X, np.full(len(DRAG_X), 0.06), DRAG_Z], np.array(DRAG_G, bool)


def test_a_release_the_arm_leaves_at_once_moves_to_where_the_arm_dwells():
    pts, g = _drag()
    out = align_switches_to_dwells(pts, g, window=2, leave_m=0.03, dwell_m=0.01)
    assert np.flatnonzero(np.diff(out.astype(int))).tolist() == [3, 10]  # close at 4 (kept), open at 11
    assert np.array_equal(align_switches_to_dwells(pts, g, window=0, leave_m=0.03, dwell_m=0.01), g)  # off


def test_switches_at_a_dwell_or_without_one_nearby_are_kept():
    pts, g = _drag()
    g = np.array([0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0], bool)  # release already at the dwell
    assert np.array_equal(align_switches_to_dwells(pts, g, window=2, leave_m=0.03, dwell_m=0.01), g)
    pts = np.c_[np.linspace(0.3, 0.6, 8), np.zeros(8), np.full(8, 0.1)]  # moving all the time: nowhere to go
    g = np.array([0, 0, 0, 1, 1, 1, 1, 1], bool)
    assert np.array_equal(align_switches_to_dwells(pts, g, window=3, leave_m=0.03, dwell_m=0.01), g)


def test_dwell_alignment_applies_to_time_spaced_global_plans_only(camera):
    pts, g = _drag()
    uv, depth = camera.project(pts)
    cfg = LearnedPlannerConfig()

    def plan(kind, config=cfg, spacing="time"):
        return height_plan(camera, uv, pts[:, 2], g, kind=kind, step=0, config=config, global_spacing=spacing)

    assert np.flatnonzero(np.diff(plan("global").gripper_closed.astype(int))).tolist() == [3, 10]
    assert np.array_equal(plan("local").gripper_closed, g)
    assert np.array_equal(plan("global", spacing="events").gripper_closed, g)  # event plans show no dwells
    assert np.array_equal(plan("global", config=LearnedPlannerConfig(dwell_leave_m=None)).gripper_closed, g)


def test_event_spaced_global_plans_keep_their_switches(camera):
    """In an event-spaced global plan every switch ends its piece by construction; snapping it to the lowest
    point nearby (a timing-slip fix for time-spaced plans) moved the tool task's release, at the end of a
    drag, back to the drag's start."""
    x = np.array([0.30, 0.40, 0.50, 0.42, 0.34, 0.34])
    z = np.array([0.10, 0.05, -0.002, 0.0, 0.02, 0.10])  # down to the drag, drag, release 2 cm up, lift
    g = np.array([1, 1, 1, 1, 0, 0], bool)
    uv, _ = camera.project(np.c_[x, np.full(6, 0.06), z])
    cfg = LearnedPlannerConfig()

    def plan(kind, spacing):
        return height_plan(camera, uv, z, g, kind=kind, step=0, config=cfg, global_spacing=spacing).gripper_closed

    assert np.array_equal(plan("global", "events"), g)
    assert np.flatnonzero(np.diff(plan("global", "time").astype(int))).tolist() == [1]  # snapped to z = -0.2 cm
    assert np.flatnonzero(np.diff(plan("local", "events").astype(int))).tolist() == [1]  # local plans: eq. 5
    with pytest.raises(ConfigError, match="global_spacing = 'event' is not valid; choose one of time, events"):
        plan("global", "event")


def test_learned_planner_config_validated():
    with pytest.raises(ConfigError, match="switch_window"):
        LearnedPlannerConfig(switch_window=-1)
    with pytest.raises(ConfigError, match="switch_min_rise_m"):
        LearnedPlannerConfig(switch_min_rise_m=-0.1)
    with pytest.raises(ConfigError, match="dwell_leave_m"):
        LearnedPlannerConfig(dwell_leave_m=0.0)
    with pytest.raises(ConfigError, match="dwell_step_m"):
        LearnedPlannerConfig(dwell_step_m=-0.01)
    with pytest.raises(ConfigError, match="min_height_m"):
        LearnedPlannerConfig(min_height_m=float("nan"))
    with pytest.raises(ConfigError, match="side_grasp_depth_m"):
        LearnedPlannerConfig(side_grasp_depth_m=-0.01)


def _hand(approach) -> np.ndarray:
    """A TCP orientation whose approach axis (z) is ``approach``."""
    z = np.asarray(approach, float) / np.linalg.norm(approach)
    x = np.cross([0.0, 1.0, 0.0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.c_[x, np.cross(z, x), z]


def test_side_grasps_go_deeper_along_their_approach_and_nothing_else_moves():
    pts = np.array([[0.0, -0.20, 1.0], [0.0, -0.14, 1.0], [0.0, -0.02, 1.0], [0.0, -0.02, 1.1],
                    [0.1, 0.0, 0.95], [0.1, 0.0, 1.1]])
    closed = np.array([0, 1, 1, 0, 1, 1], bool)  # a handle grasped sideways and pulled; a top-down pick
    side, down = _hand([0.0, -1.0, 0.05]), _hand([0.0, 0.0, -1.0])
    rot = np.stack([side, side, side, side, down, down])
    out = deepen_side_grasps(pts, closed, rot, 0.01)
    moved = np.linalg.norm(out - pts, axis=1)
    assert np.isclose(moved[1], 0.01) and np.allclose(np.delete(moved, 1), 0.0)
    assert np.isclose((out[1] - pts[1]) @ side[:, 2], 0.01)  # along the approach, into the handle
    assert np.array_equal(deepen_side_grasps(pts, np.ones(6, bool), rot, 0.01), pts)  # already holding: no grasp
    tilted = np.stack([_hand([0.0, -1.0, -0.7])] * 6)  # 35 degrees down: a rim grasp, not a side grasp
    assert np.array_equal(deepen_side_grasps(pts, closed, tilted, 0.01), pts)


def test_side_grasp_depth_reaches_the_plan_and_off_leaves_it(camera):
    pts = np.array([[0.5, -0.20, 0.12], [0.5, -0.14, 0.12], [0.5, -0.02, 0.12]])  # in the workcell camera's view
    g = np.array([0, 1, 1], bool)
    rot = np.stack([_hand([0.0, -1.0, 0.0])] * 3)
    uv, _ = camera.project(pts)

    def lifted(depth_m):
        cfg = LearnedPlannerConfig(side_grasp_depth_m=depth_m)
        p = height_plan(camera, uv, pts[:, 2], g, kind="local", step=0, config=cfg, global_spacing="time",
                        tcp_rot=rot)
        return camera.unproject(p.uv_px, p.depth_m)

    assert np.allclose(lifted(0.0), pts, atol=1e-9)
    assert np.allclose(lifted(0.012) - pts, [[0, 0, 0], [0, -0.012, 0], [0, 0, 0]], atol=1e-9)


def test_rotation_head_and_camera_heights_become_world_tcp_rot_and_world_z(tmp_path, camera, monkeypatch):
    """A LIBERO-style checkpoint (rot_head, height_ref camera): the plan's z is the network's height plus the
    camera's, and tcp_rot is the camera-frame 6D output turned into the world with the camera's calibration."""
    from scipy.spatial.transform import Rotation

    from tcot_hybrid.learning.model import matrix_to_rot6

    torch.manual_seed(0)
    model = PlannerNet(ModelConfig(width=8, vocab_size=len(VOCAB), rot_head=True, z_offset_m=-0.5)).eval()
    meta = {"robot": "panda", "camera": {**camera_meta(camera), "per_scene": True}, "world": "libero",
            "height_ref": "camera", "vocabulary": list(VOCAB.tokens),
            "windows": {"L_g": 51, "n_g": 4, "L_l": 8, "n_l": 2}, "data_hash": "t", "metrics": {},
            "versions": versions(), "max_unknown_fraction": 0.5, "direct_horizon": 3}
    path = save_checkpoint(tmp_path / "lib.safetensors", model, meta)
    # random hands include side grasps, which go deeper along their approach by default: off, heights stay exact
    p = LearnedPlanner(load_checkpoint(path, camera=camera, world="libero"), camera,
                       config=LearnedPlannerConfig(side_grasp_depth_m=0.0))
    R_cam = Rotation.random(60, random_state=1).as_matrix()
    cam_z = float(camera.T_world_cam[2, 3])
    real = p.model.forward

    def fixed(*a, **k):
        out = real(*a, **k)
        if "uv_px" in out:
            out["z_m"] = torch.full_like(out["z_m"], 0.3 - cam_z)  # 0.3 m in the world
            sel = k.get("waypoints")  # the planner asks for its executed waypoints only
            R = R_cam[sel] if isinstance(sel, slice) else R_cam
            out["rot6"] = torch.from_numpy(matrix_to_rot6(R) * 2.0)[None].float()  # unnormalised columns
        return out
    monkeypatch.setattr(p.model, "forward", fixed)
    g = p.plan(_obs(), mode="global")
    np.testing.assert_allclose(camera.unproject(g.uv_px, g.depth_m)[:, 2], 0.3, atol=1e-5)
    np.testing.assert_allclose(g.tcp_rot, canonical_hand(camera.T_world_cam[:3, :3] @ R_cam[25:51]), atol=1e-5)
    loc = p.plan(_obs(), mode="local")
    np.testing.assert_allclose(loc.tcp_rot, canonical_hand(camera.T_world_cam[:3, :3] @ R_cam[51:]), atol=1e-5)

    def degenerate(*a, **k):
        out = fixed(*a, **k)
        if "rot6" in out:
            out["rot6"] = torch.zeros_like(out["rot6"])
        return out
    monkeypatch.setattr(p.model, "forward", degenerate)
    with pytest.raises(PlanningError, match="orientation output cannot be made a rotation"):
        p.plan(_obs(), mode="global")


def test_workcell_plans_stay_top_down(planner):
    assert planner.plan(_obs(), mode="global").tcp_rot is None


def test_orientations_are_brought_into_the_oracles_yaw_range_by_the_parallel_jaw_symmetry():
    """The rotation head is trained up to the 180-degree turn about the approach axis; the plan carries the one of
    the two equivalent hands whose yaw lies in the oracle's range, tilted hands included."""
    from scipy.spatial.transform import Rotation

    from tcot_hybrid.libero.grasps import YAW_MIN_RAD, top_down, yaw_from_home

    for deg in range(-175, 180, 10):
        a = np.deg2rad(deg)
        R = top_down([np.cos(a), np.sin(a)])  # the oracle's choice of the two
        flipped = R @ np.diag([-1.0, -1.0, 1.0])
        np.testing.assert_allclose(canonical_hand(np.stack([R, flipped])), np.stack([R, R]), atol=1e-12)
    R = Rotation.random(200, random_state=3).as_matrix()
    out = canonical_hand(R)
    defined = 0
    for r, o in zip(R, out):
        assert np.allclose(o, r) or np.allclose(o, r @ np.diag([-1.0, -1.0, 1.0]))  # same grasp
        if np.hypot(o[0, 1], o[1, 1]) >= YAW_DEFINED_MIN:
            defined += 1
            assert YAW_MIN_RAD - np.pi - 1e-9 <= yaw_from_home(o) <= YAW_MIN_RAD + 1e-9
        np.testing.assert_allclose(o[:, 2], r[:, 2])  # the approach axis is kept
    assert defined > 150


def test_side_grasps_without_a_yaw_keep_the_wrist_from_half_turns():
    """A hand closing vertically (a drawer handle from the front) has no yaw; the network's turn of it is noise. Each
    such waypoint takes the equivalent hand nearest the previous one (the first: the home hand's x axis), so
    consecutive waypoints never differ by a half turn about the approach axis."""
    from tcot_hybrid.libero.grasps import frame
    from tcot_hybrid.ik.base import rotation_angle

    flip = np.diag([-1.0, -1.0, 1.0])
    rng = np.random.default_rng(0)
    side = [frame([0.0, -1.0, 0.02 * k], [0.01 * rng.standard_normal(), 0.05 * k, 1.0]) for k in range(-3, 4)]
    noisy = np.stack([R @ flip if rng.random() < 0.5 else R for R in side])
    out = canonical_hand(noisy)
    assert out[0][:, 0] @ np.array([1.0, 0.0, 0.0]) > 0.9  # the home hand's x axis
    assert max(rotation_angle(a, b) for a, b in zip(out[:-1], out[1:])) < 0.2
    for o, r in zip(out, noisy):
        assert np.allclose(o, r) or np.allclose(o, r @ flip)


def test_camera_referenced_checkpoints_bound_heights_from_their_demonstrations(camera):
    """learned.min_height_m on a height_ref: camera checkpoint counts from the lowest TCP height its demonstrations
    reached under the nearest training camera (tables stand at different heights); world checkpoints keep z = 0."""
    cam_pos = np.asarray(camera.T_world_cam)[:3, 3]
    far = (cam_pos + [0.5, 0.0, 0.0]).tolist()
    meta = {"height_ref": "camera", "lowest_tcp_by_camera": [
        {"camera_pos_m": (cam_pos + [0.03, 0.0, 0.0]).tolist(), "lowest_z_m": -0.40},  # this camera, shifted 3 cm
        {"camera_pos_m": far, "lowest_z_m": -0.90}]}
    z, note = lowest_plan_height(meta, camera, -0.02)
    assert z == pytest.approx(cam_pos[2] - 0.40 - 0.02) and "under this camera" in note
    z, note = lowest_plan_height({**meta, "lowest_tcp_by_camera": meta["lowest_tcp_by_camera"][1:]}, camera, -0.02)
    assert z == pytest.approx(cam_pos[2] - 0.90 - 0.02) and "none within 10 cm" in note  # unknown camera: loosest
    assert lowest_plan_height({"height_ref": "world"}, camera, -0.02) == (-0.02, "learned.min_height_m; table top at 0")
    assert lowest_plan_height({"height_ref": "camera"}, camera, -0.03)[0] == -0.03  # written before the record
    # checkpoints that record the support surface under each camera count from it (the table top, as on the workcell)
    with_support = {"height_ref": "camera", "lowest_tcp_by_camera": [
        {**e, "support_z_m": e["lowest_z_m"] - 0.03} for e in meta["lowest_tcp_by_camera"]]}
    z, note = lowest_plan_height(with_support, camera, -0.02)
    assert z == pytest.approx(cam_pos[2] - 0.43 - 0.02) and "support surface" in note and "under this camera" in note
    with pytest.raises(PlanningError, match=r"waypoint 0 has TCP height z_m = 0.3000 m.*lowest allowed 0.3800 m "
                                            r"\(learned.min_height_m -0.02 m from the lowest TCP height"):
        check_outputs(np.zeros((1, 2)), np.array([0.3]), np.array([0.5]), min_height_m=0.38,
                      floor_note=lowest_plan_height(meta, camera, -0.02)[1])
