"""Tasks: registry, seeded layouts, predicates false at reset, oracle path inside the planner image."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.config import TimingConfig
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.planners.oracle import OraclePlanner
from tcot_hybrid.robot import load_robot_spec
from tcot_hybrid.scene import SceneConfig
from tcot_hybrid.sim import Simulation
from tcot_hybrid.tasks import SUITES, list_tasks, make_task

TASKS = [t.name for t in list_tasks()]


def test_suites_and_count():
    suites = {t.suite for t in list_tasks()}
    assert {"spatial", "object", "goal", "long"} <= suites <= set(SUITES)
    assert len(TASKS) >= 10
    assert all(t.instruction and t.time_limit_s > 0 for t in list_tasks())


def test_unknown_task_lists_valid_names():
    with pytest.raises(ConfigError) as exc:
        make_task("no_such_task")
    assert "goal_cube_on_plate" in str(exc.value)


@pytest.fixture(scope="module")
def panda():
    return load_robot_spec("panda")


@pytest.mark.parametrize("name", TASKS)
def test_layout_is_seeded_not_yet_solved_and_plannable(panda, name):
    sim = Simulation(panda, make_task(name), timing=TimingConfig(), scene=SceneConfig())
    layouts = []
    for seed in (3, 3, 4):
        sim.reset(np.random.default_rng(seed))
        layouts.append(sim.data.qpos.copy())
        assert not sim.task.success(sim.world), f"{name} seed {seed} is solved at reset"
    assert np.array_equal(layouts[0], layouts[1]), "same seed must give the same layout"
    assert not np.array_equal(layouts[0], layouts[2]), "different seeds must give different layouts"
    cam = CameraModel.from_mujoco(sim.model, sim.data, "agentview", width=128, height=128)
    points, grip = OraclePlanner(sim.task, sim.world, cam).path()
    uv, depth = cam.project(points)
    assert cam.in_image(uv).all(), f"{name}: oracle path leaves the planner image"
    assert (depth > cam.near_m).all()
    assert grip.any() and not grip[-1], f"{name}: the oracle must grasp something and end released"
    assert np.all(np.linalg.norm(np.diff(points, axis=0), axis=1) <= 0.04 + 1e-9)
