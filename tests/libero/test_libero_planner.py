"""The learned planner on LIBERO end to end on a tiny budget: oracle demonstrations on sampled layouts (training
seeds) → a small network trained for one short epoch → its checkpoint (world, robot, per-scene camera, rotation
head) → one GLSR episode on a shipped init state with plans that carry a TCP orientation per waypoint."""
import dataclasses
import json

import numpy as np
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.data.dataset import open_demos  # noqa: E402
from tcot_hybrid.episode import EpisodeRunner  # noqa: E402
from tcot_hybrid.errors import CheckpointError  # noqa: E402
from tcot_hybrid.learning.checkpoint import checkpoints_dir, load_checkpoint, meta_path, task_models  # noqa: E402
from tcot_hybrid.learning.model import ModelConfig  # noqa: E402
from tcot_hybrid.learning.train import train  # noqa: E402
from tcot_hybrid.learning.train_config import TrainConfig  # noqa: E402
from tcot_hybrid.run_config import RunConfig, SupervisorConfig  # noqa: E402

SPATIAL_TASK = "libero_spatial:pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate"


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory, libero_demos):
    d = tmp_path_factory.mktemp("libero_planner")
    data = libero_demos  # conftest: three oracle demonstrations on sampled layouts (training seeds 0-2)
    cfg = TrainConfig(data=str(data), out=str(d / "tiny.safetensors"), height_ref="camera", threads=1,
                      model=ModelConfig(width=8, rot_head=True, z_offset_m=-0.5),
                      windows=dataclasses.replace(TrainConfig().windows, global_spacing="events"),
                      max_epochs=1, stage1_epochs=0, epoch_samples=32, batch_size=16, val_max_frames=40)
    res = train(cfg, progress=False, log=lambda *a: None)
    return data, res


def test_demos_carry_their_camera_and_orientation(tiny_checkpoint):
    data, _ = tiny_checkpoint
    with open_demos(data) as f:
        assert f.camera_per_demo and f.env_args["world"] == "libero"
        for name in f.demos:
            cam = f.camera_model(name)
            a = f.read(name, ["obs/robot0_eef_pos", "obs/eef_uv_px", "obs/robot0_eef_quat"])
            uv, _ = cam.project(a["obs/robot0_eef_pos"].astype(float))  # the pixels are this demo's camera's
            np.testing.assert_allclose(a["obs/eef_uv_px"], uv, atol=1e-3)
            assert f.info(name).success


def test_checkpoint_records_world_robot_and_is_refused_in_the_workcell(tiny_checkpoint):
    _, res = tiny_checkpoint
    meta = json.loads(meta_path(res.checkpoint).read_text())
    assert (meta["world"], meta["robot"], meta["height_ref"]) == ("libero", "libero_panda", "camera")
    assert meta["camera"]["per_scene"] and meta["model"]["rot_head"]
    assert np.isfinite(res.metrics["global_rot_deg_median"])
    data, _ = tiny_checkpoint  # the planner's floor: the lowest TCP height its training demos reached, from the camera
    with open_demos(data) as f:
        cam = f.camera_model(f.mask("train")[0])
        low = min(float(f.read(n, ["obs/robot0_eef_pos"])["obs/robot0_eef_pos"][:, 2].min()) for n in f.mask("train"))
    (entry,) = meta["lowest_tcp_by_camera"]  # one scene: one camera
    np.testing.assert_allclose(entry["camera_pos_m"], cam.T_world_cam[:3, 3], atol=1e-4)
    assert low - 1e-4 <= entry["lowest_z_m"] + cam.T_world_cam[2, 3] <= low + 0.02
    with open_demos(data) as f:  # and the table top those demos recorded: the floor counts from it
        support = min(f.support_z(n) for n in f.mask("train"))
    assert entry["support_z_m"] + cam.T_world_cam[2, 3] == pytest.approx(support, abs=1e-4) and support < low
    with pytest.raises(CheckpointError, match="'libero' world.*'workcell' world"):
        load_checkpoint(res.checkpoint, world="workcell")
    with pytest.raises(CheckpointError, match="'libero' world.*'workcell' world"):
        EpisodeRunner(RunConfig(task="goal_cube_in_bowl", planner="learned", checkpoint=str(res.checkpoint)))


def test_one_glsr_episode_with_the_tiny_planner(tiny_checkpoint):
    _, res = tiny_checkpoint
    cfg = RunConfig(task=SPATIAL_TASK, seed=0, init="shipped", planner="learned", checkpoint=str(res.checkpoint),
                    supervisor=SupervisorConfig(mode="glsr", t_f=8, t_l=4))
    runner = EpisodeRunner(cfg)
    runner.stack.task.time_limit_s = 2.5  # 25 planner steps: a global plan, detection and local replans
    try:
        result = runner.run()
    finally:
        runner.stack.sim.close()
    assert runner.plans, result["events"][:5]
    kinds = {p.kind for p in runner.plans}
    assert "global" in kinds
    for plan in runner.plans:  # the orientation head reaches the plan: a rotation per waypoint, world frame
        assert plan.tcp_rot is not None and plan.tcp_rot.shape == (len(plan), 3, 3)
        np.testing.assert_allclose(np.linalg.det(plan.tcp_rot), 1.0, atol=1e-6)
    assert any(e["kind"] == "supervisor" for e in result["events"])
    assert result["max_joint_limit_violation_rad"] < 0.05


LONG_TASK = "libero_10:LIVING_ROOM_SCENE2_put_both_the_alphabet_soup_and_the_tomato_sauce_in_the_basket"


STOVE_TASK = "libero_10:KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it"


@pytest.mark.parametrize("task, stem", [(LONG_TASK, "libero_panda_libero_10"), (SPATIAL_TASK, "libero_panda_default"),
                                        ("libero_goal:turn_on_the_stove", "libero_panda_libero_goal"),
                                        (STOVE_TASK, "libero_panda_default"),
                                        ("libero_goal:open_the_top_drawer_and_put_the_bowl_inside",
                                         "libero_panda_default")])
def test_learned_planner_loads_its_suites_own_shipped_model(task, stem):
    """Without --checkpoint, a libero_10 or libero_goal task's learned planner is its suite's own model (the paper's
    TCoT row), a spatial task's the four-suite one, and a task routed to the four-suite one (task_models.json: libero_10's
    stove, libero_goal's top drawer with the bowl) that one; the resume key's checkpoint hash is that of the file loaded."""
    from tcot_hybrid.evaluation.jobs import checkpoint_digest

    cfg = RunConfig(task=task, seed=0, init="shipped", planner="learned")
    runner = EpisodeRunner(cfg)
    try:
        loaded = runner.stack.planner.checkpoint_path
    finally:
        runner.stack.sim.close()
    assert loaded.stem == stem
    other = "libero_panda_default" if stem != "libero_panda_default" else "libero_panda_libero_10"
    assert checkpoint_digest(cfg) != checkpoint_digest(dataclasses.replace(cfg, checkpoint=str(
        loaded.with_name(other + loaded.suffix))))
    assert checkpoint_digest(cfg) == checkpoint_digest(dataclasses.replace(cfg, checkpoint=str(loaded)))


def test_every_shipped_task_route_names_a_task_and_a_shipped_model_trained_on_its_suite():
    """The shipped task_models.json: every routed task is one the registry knows, its model is shipped (task_models
    refuses otherwise) and was trained on the task's suite among others."""
    from tcot_hybrid.tasks import make_task

    for task, stem in task_models("libero_panda").items():
        suite = make_task(task).suite
        suites = json.loads(meta_path(checkpoints_dir() / f"{stem}.safetensors").read_text())["train_config"]["suites"]
        assert not suites or suite in suites, (task, stem, suites)  # []: every suite of its demonstrations
