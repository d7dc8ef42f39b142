"""Perturbations on LIBERO scenes: the off-centre grasp nudges the object along the open fingers' closing axis the
moment before they close (LIBERO's grasps are rims, handles and sides), and is refused by name where no skill
picks anything up."""
import numpy as np
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.episode import EpisodeRunner  # noqa: E402
from tcot_hybrid.perturbations import PerturbConfig  # noqa: E402
from tcot_hybrid.run_config import RunConfig  # noqa: E402

BOWL = "libero_spatial:pick_up_the_black_bowl_next_to_the_ramekin_and_place_it_on_the_plate"


def test_offcenter_grasp_shifts_the_bowl_across_the_fingers_before_they_close():
    cfg = RunConfig(task=BOWL, seed=2100, init="sampled", planner="oracle",
                    perturb=PerturbConfig(name="offcenter_grasp"))
    result = EpisodeRunner(cfg).run()
    fired = [e for e in result["events"] if e["kind"] == "perturbation"]
    assert result["perturbation_fired"] and len(fired) == 1
    moved = np.array(fired[0]["moved_m"])
    assert np.linalg.norm(moved) == pytest.approx(cfg.perturb.strength or 0.025, abs=1e-3) and moved[2] == 0.0
    closes = [e["t"] for e in result["events"] if e["kind"] == "gripper" and e["closed"]]
    assert closes and fired[0]["t"] <= closes[0]  # before the fingers first close
    assert result["fault"] is None


def test_offcenter_grasp_is_refused_by_name_where_nothing_is_picked_up():
    cfg = RunConfig(task="libero_goal:open_the_middle_drawer_of_the_cabinet", seed=2100, init="sampled",
                    planner="oracle", perturb=PerturbConfig(name="offcenter_grasp"))
    result = EpisodeRunner(cfg).run()
    assert result["perturbation_fired"] is False
    assert "no pick-and-place" in result["perturbation_note"]


def test_object_moved_on_a_joint_task_reports_not_fired_instead_of_crashing():
    # the stove's knob skill names a fixture, not a movable object: object_moved used to raise a KeyError
    cfg = RunConfig(task="libero_goal:turn_on_the_stove", seed=100, init="sampled", planner="oracle",
                    perturb=PerturbConfig(name="object_moved"))
    result = EpisodeRunner(cfg).run()
    assert result["fault"] is None and result["perturbation_fired"] is False


def test_object_moved_translates_a_libero_object_and_keeps_it_upright():
    # set_pose writes a pure yaw, which laid LIBERO's bottles (meshes modelled lying along x) on their side
    cfg = RunConfig(task="libero_object:pick_up_the_ketchup_and_place_it_in_the_basket", seed=20000, init="sampled",
                    planner="oracle", perturb=PerturbConfig(name="object_moved"))
    runner = EpisodeRunner(cfg)
    runner.settle()
    world = runner.stack.sim.world
    rot_before, pos_before = world.rot("ketchup_1"), world.pos("ketchup_1")
    for step in range(runner.perturbation.at_step + 1):
        runner._step_once(step, may_plan=step == 0)
    fired = [e for e in runner.stack.executor.events if e["kind"] == "perturbation"]
    assert len(fired) == 1 and fired[0]["object"] == "ketchup_1"
    moved = world.pos("ketchup_1") - pos_before
    assert np.linalg.norm(moved[:2]) == pytest.approx(0.10, abs=0.02)
    assert abs(moved[2]) < 0.005  # still standing on the table, not lying on its side
    assert float(np.trace(rot_before.T @ world.rot("ketchup_1"))) > 2.97  # same orientation (within ~8 degrees)


def test_camera_shift_first_learned_plan_is_lifted_with_a_camera_nearer_the_moved_one(monkeypatch):
    """The planner camera is knocked before the first plan; the learned planner sees the hand where the moved
    camera puts it and lifts its global plan with a re-estimated pose, nearer the moved camera than the nominal.
    One sighting is trusted only with the arm at home, so this layout starts the arm there (no start noise)."""
    from tcot_hybrid.camera import CameraModel
    from tcot_hybrid.libero import scene

    monkeypatch.setattr(scene, "ARM_START_NOISE_RAD", 0.0)

    cfg = RunConfig(task=BOWL, seed=20000, init="sampled", planner="learned",
                    perturb=PerturbConfig(name="camera_shift"))
    runner = EpisodeRunner(cfg)
    runner.settle()
    runner.stack.planner.prepare()
    runner._step_once(0, may_plan=True)
    plan, nominal = runner.plans[0], runner.stack.camera
    assert plan.calibration is not None and plan.lift_camera(nominal) is plan.calibration
    sim = runner.stack.sim
    moved = CameraModel.from_mujoco(sim.model, sim.data, cfg.scene.planner_camera, width=nominal.width,
                                    height=nominal.height)
    table = sim.tcp_pos() + np.c_[np.linspace(-0.15, 0.15, 7), np.linspace(0.1, -0.1, 7), np.full(7, -0.15)]
    seen, _ = moved.project(table)

    def error_px(cam):
        return float(np.median(np.linalg.norm(cam.project(table)[0] - seen, axis=1)))

    assert error_px(plan.calibration) < 0.5 * error_px(nominal)
    assert runner.record(0.0)["camera_calibration"]["refined"] is True


COOKIE_BOX = "libero_spatial:pick_up_the_black_bowl_on_the_cookie_box_and_place_it_on_the_plate"


def test_target_moved_puts_the_plate_where_it_overlaps_nothing():
    # layout 20001: the first spots 10 cm from the plate overlap the cookie box, and a plate dropped there was
    # pushed through the table (sim_fault:OBJECT_BELOW_TABLE in every such episode, whatever the planner)
    cfg = RunConfig(task=COOKIE_BOX, seed=20001, init="sampled", planner="oracle",
                    perturb=PerturbConfig(name="target_moved"))
    runner = EpisodeRunner(cfg)
    runner.settle()
    world = runner.stack.sim.world
    before = world.pos("plate_1")
    assert world.penetrating("plate_1") == []
    world.shift("plate_1", (world.pos("cookies_1")[:2] - before[:2]).tolist() + [0.0])  # onto the box: named
    assert "cookies_1_main" in world.penetrating("plate_1")
    world.shift("plate_1", (before - world.pos("plate_1")).tolist())
    assert world.penetrating("plate_1") == []
    for step in range(runner.perturbation.at_step + 1):
        runner._step_once(step, may_plan=step == 0)
    fired = [e for e in runner.stack.executor.events if e["kind"] == "perturbation"]
    assert len(fired) == 1 and fired[0]["object"] == "plate_1" and fired[0]["spots_overlapping"] >= 1
    assert np.linalg.norm(world.pos("plate_1")[:2] - before[:2]) == pytest.approx(0.10, abs=0.02)
    assert world.penetrating("plate_1") == []
    for step in range(runner.perturbation.at_step + 1, runner.perturbation.at_step + 11):
        runner._step_once(step, may_plan=False)
    assert runner.stack.sim.fault is None and world.pos("plate_1")[2] == pytest.approx(before[2], abs=0.01)
