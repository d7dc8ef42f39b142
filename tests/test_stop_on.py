"""--stop-on detector: the planner's failure detector ends the episode; the predicate judges afterwards."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import dataclasses

import pytest

from tcot_hybrid.episode import EpisodeRunner
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.planners import _FACTORIES, make_planner, register_planner
from tcot_hybrid.run_config import RunConfig
from tcot_hybrid.supervision import SupervisorConfig


def _cfg(**kw):
    return RunConfig(task="goal_cube_in_bowl", seed=3, planner="learned", stop_on="detector",
                     supervisor=SupervisorConfig(mode="glsr"), **kw)


def test_detector_stopped_episode_is_judged_by_the_predicate_afterwards():
    rec = EpisodeRunner(_cfg()).run()
    checks = [e for e in rec["events"] if e["kind"] == "stop_check"]
    assert rec["stop_on"] == "detector" and rec["stopped_by"] in ("detector", "time_limit")
    assert checks and all(e["step"] >= 16 for e in checks)  # asked from t_f on
    assert all("true_success" in e and 0.0 <= e["p_success"] <= 1.0 for e in checks)
    if rec["stopped_by"] == "detector":  # the last stop_hold_steps checks all said "done"
        hold = RunConfig().stop_hold_steps
        assert [e["hold"] for e in checks[-hold:]] == list(range(1, hold + 1))
        assert rec["premature_stop"] == (not rec["success"])
    assert not [e for e in rec["events"] if e["kind"] == "detector"]  # no post-success probes: no simulator stop


def test_a_detector_that_always_says_done_stops_prematurely():
    @register_planner("always_done")
    def _always(ctx):
        planner = make_planner("learned", ctx)
        planner.success_probability = lambda obs: 1.0
        return planner

    try:
        cfg = dataclasses.replace(_cfg(stop_hold_steps=2), planner="always_done")
        rec = EpisodeRunner(cfg).run()
    finally:
        _FACTORIES.pop("always_done", None)
    checks = [e for e in rec["events"] if e["kind"] == "stop_check"]
    assert rec["stopped_by"] == "detector" and len(checks) == 2 and checks[-1]["step"] == 17
    assert not rec["success"] and rec["premature_stop"]  # nothing was delivered by step 17


def test_simulator_stopping_is_unchanged_and_records_how_it_stopped():
    rec = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=3)).run()
    assert rec["success"] and rec["stopped_by"] == "simulator" and not rec["premature_stop"]


def test_stop_on_is_validated():
    with pytest.raises(ConfigError, match="stop_on = 'both' is not valid; choose one of simulator, detector"):
        RunConfig(stop_on="both")
    with pytest.raises(ConfigError, match="stop_hold_steps"):
        RunConfig(stop_hold_steps=0)
    with pytest.raises(ConfigError, match="planner 'oracle' has none"):
        EpisodeRunner(RunConfig(task="goal_cube_in_bowl", stop_on="detector"))
