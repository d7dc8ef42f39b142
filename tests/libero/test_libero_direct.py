"""The paper's direct (next-action) baseline on LIBERO: its TCP in the world frame plans are lifted in (the robot's
mounting pose, not the world origin), a checkpoint that records its world and is refused in the other one, and one
short episode through lift → IK → Ruckig → controller on a tiny budget, the hand held at its starting
orientation."""
import dataclasses
import json

import mujoco
import numpy as np
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.episode import EpisodeRunner  # noqa: E402
from tcot_hybrid.errors import CheckpointError  # noqa: E402
from tcot_hybrid.learning.checkpoint import checkpoints_dir, default_checkpoint, load_checkpoint, meta_path  # noqa: E402
from tcot_hybrid.learning.model import ModelConfig  # noqa: E402
from tcot_hybrid.learning.train import train  # noqa: E402
from tcot_hybrid.learning.train_config import TrainConfig  # noqa: E402
from tcot_hybrid.planners.direct import DirectPlanner  # noqa: E402
from tcot_hybrid.run_config import RunConfig  # noqa: E402

SPATIAL_TASK = "libero_spatial:pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate"


@pytest.fixture(scope="module")
def tiny_direct(tmp_path_factory, libero_demos):
    d = tmp_path_factory.mktemp("libero_direct")
    cfg = TrainConfig(data=str(libero_demos), out=str(d / "direct.safetensors"), kind="direct", threads=1,
                      model=ModelConfig(width=8), max_epochs=1, epoch_samples=32, batch_size=16, val_max_frames=40)
    return train(cfg, progress=False, log=lambda *a: None).checkpoint


@pytest.fixture(scope="module")
def direct_runner(tiny_direct):
    runner = EpisodeRunner(RunConfig(task=SPATIAL_TASK, seed=0, init="sampled", robot="auto", planner="direct",
                                     checkpoint=str(tiny_direct)))
    yield runner
    runner.stack.sim.close()


def test_direct_tcp_is_the_simulators_tcp_site(direct_runner):
    """On a tabletop scene (robot base at (-0.66, 0, 0.912)), for the settled posture and random postures: the
    planner's forward kinematics, placed by the mounting pose it was given, is the scene's TCP site."""
    sim, planner = direct_runner.stack.sim, direct_runner.stack.planner
    assert isinstance(planner, DirectPlanner)
    assert np.linalg.norm(sim.T_world_base[:3, 3]) > 0.5  # not the world origin: the frame matters here
    spec = direct_runner.stack.robot
    lo, hi = np.array(spec.q_min), np.array(spec.q_max)
    qpos0 = sim.data.qpos.copy()
    idx, site = sim.arm_qpos, sim.ee_site
    try:
        for q in [sim.q.copy(), *np.random.default_rng(0).uniform(lo, hi, size=(4, len(lo)))]:
            sim.data.qpos[idx] = q
            mujoco.mj_kinematics(sim.model, sim.data)
            pos, rot = planner.kinematics.pose(q)
            np.testing.assert_allclose(pos, sim.data.site_xpos[site], atol=1e-9)
            np.testing.assert_allclose(rot, sim.data.site_xmat[site].reshape(3, 3), atol=1e-9)
    finally:
        sim.data.qpos[:] = qpos0
        mujoco.mj_forward(sim.model, sim.data)


def test_direct_checkpoint_records_libero_and_worlds_refuse_each_other(tiny_direct):
    meta = json.loads(meta_path(tiny_direct).read_text())
    assert (meta["world"], meta["robot"], meta["kind"]) == ("libero", "libero_panda", "direct")
    assert meta["camera"]["per_scene"]
    with pytest.raises(CheckpointError, match="'libero' world.*'workcell' world"):
        EpisodeRunner(RunConfig(task="goal_cube_in_bowl", planner="direct", checkpoint=str(tiny_direct)))
    workcell = checkpoints_dir() / "panda_direct_default.safetensors"
    with pytest.raises(CheckpointError, match="'workcell' world.*'libero' world"):
        EpisodeRunner(RunConfig(task=SPATIAL_TASK, seed=0, init="sampled", robot="auto", planner="direct",
                                checkpoint=str(workcell)))


def test_shipped_libero_direct_checkpoint_is_picked_on_libero_only():
    path = default_checkpoint("libero_panda", "direct")
    assert path.name == "libero_panda_direct_default.safetensors"
    ck = load_checkpoint(path, robot="libero_panda", kind="direct", world="libero")
    assert ck.meta["world"] == "libero" and ck.meta["camera"]["per_scene"]
    with pytest.raises(CheckpointError, match="'libero' world.*'workcell' world"):
        load_checkpoint(path, kind="direct", world="workcell")


def test_one_short_direct_episode_runs_without_a_fault(direct_runner):
    runner = direct_runner
    runner.stack.task.time_limit_s = 1.5  # 15 planner steps, a direct plan at every one
    start_rot = runner.stack.planner.kinematics.pose(runner.stack.sim.q)[1]
    result = runner.run()
    assert result["fault"] is None, result["events"][-3:]
    assert len(runner.plans) >= 10 and {p.kind for p in runner.plans} == {"direct"}
    first = runner.plans[0].tcp_rot[0]  # the hand at the first observation (after the scene settled)
    np.testing.assert_allclose(first, start_rot, atol=0.05)
    for plan in runner.plans:  # one waypoint each, the hand held at the episode's starting orientation
        assert len(plan) == 1 and plan.tcp_rot is not None
        np.testing.assert_array_equal(plan.tcp_rot[0], first)
    adopted = [e for e in result["events"] if e["kind"] == "plan_adopted"]
    assert len(adopted) >= len(runner.plans) // 2
    assert result["max_joint_limit_violation_rad"] < 0.05
