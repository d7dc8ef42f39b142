"""EpisodeRunner: the start of an episode (the arm goes home before the first plan)."""
from __future__ import annotations

import numpy as np
import pytest

from tcot_hybrid.episode import EpisodeRunner
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.executor import ExecutorConfig
from tcot_hybrid.run_config import RunConfig

OFFSET_RAD = np.array([0.03, -0.02, 0.02, 0.03, -0.03, 0.02, 0.03])  # a LIBERO-sized start off home


def _started_off_home(tol) -> tuple[EpisodeRunner, dict]:
    """An oracle episode whose arm stands OFFSET_RAD off home before it starts, and the measured posture when the first
    plan is asked for."""
    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0, planner="oracle",
                                executor=ExecutorConfig(start_home_tol_rad=tol)))
    sim = r.stack.sim
    sim.data.qpos[sim.arm_qpos] = sim.robot.home_q + OFFSET_RAD[:sim.robot.dof]
    sim.data.qvel[sim.arm_dof] = 0.0
    r.stack.executor.resync_to_measured("test start")
    at_first_plan: dict = {}

    def first(runner, step):
        if step == 0:
            at_first_plan["q"] = runner.stack.sim.q.copy()

    r.pre_step_hook = first
    r.run()
    return r, at_first_plan


def test_an_arm_started_off_home_goes_home_before_the_first_plan_on_the_episode_clock():
    r, first = _started_off_home(0.002)
    home = r.stack.sim.robot.home_q
    assert np.abs(first["q"] - home).max() <= 0.002
    ev = [e for e in r.stack.executor.events if e["kind"] == "started_at_home"]
    assert len(ev) == 1 and ev[0]["steps"] == r.homing_steps > 0
    assert ev[0]["start_offset_rad"] == pytest.approx(np.abs(OFFSET_RAD).max(), abs=0.005)
    # the homing steps count against the time limit, and the episode still succeeds
    assert r.success and r.steps + r.homing_steps <= r.max_steps
    rec = r.record(0.0)
    assert rec["homing_steps"] == r.homing_steps
    # retries from home go to the robot's home too, not to the start
    np.testing.assert_allclose(r.stack.executor.home_q, home)


def test_start_home_off_plans_from_where_the_arm_stands():
    r, first = _started_off_home(None)
    home = r.stack.sim.robot.home_q
    assert r.homing_steps == 0 and not [e for e in r.stack.executor.events if e["kind"] == "started_at_home"]
    assert np.abs(first["q"] - home).max() > 0.02


def test_an_arm_at_home_spends_no_steps_going_there():
    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0, planner="oracle"))
    r.run()
    assert r.homing_steps == 0 and r.success


@pytest.mark.parametrize("bad", [0.0, -0.01, float("nan"), True])
def test_a_bad_start_home_tolerance_is_refused(bad):
    with pytest.raises(ConfigError, match="start_home_tol_rad"):
        ExecutorConfig(start_home_tol_rad=bad)
