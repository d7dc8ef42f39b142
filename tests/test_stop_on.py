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


def _run_always_done(**fields) -> dict:
    """One episode of ``_cfg()`` with ``fields`` replaced, planned by the learned planner whose detector
    always says the task is done."""
    @register_planner("always_done")
    def _always(ctx):
        planner = make_planner("learned", ctx)
        planner.success_probability = lambda obs: 1.0
        return planner

    try:
        return EpisodeRunner(dataclasses.replace(_cfg(), planner="always_done", **fields)).run()
    finally:
        _FACTORIES.pop("always_done", None)


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
    rec = _run_always_done(stop_hold_steps=2)
    checks = [e for e in rec["events"] if e["kind"] == "stop_check"]
    assert rec["stopped_by"] == "detector" and len(checks) == 2 and checks[-1]["step"] == 17
    assert not rec["success"] and rec["premature_stop"]  # nothing was delivered by step 17


def test_simulator_stopping_is_unchanged_and_records_how_it_stopped():
    rec = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=3)).run()
    assert rec["success"] and rec["stopped_by"] == "simulator" and not rec["premature_stop"]


def test_stop_on_is_validated():
    with pytest.raises(ConfigError, match="stop_on = 'both' is not valid; choose one of auto, simulator, detector, either"):
        RunConfig(stop_on="both")
    with pytest.raises(ConfigError, match="stop_hold_steps"):
        RunConfig(stop_hold_steps=0)
    for asked in ("detector", "either"):
        with pytest.raises(ConfigError, match=f"stop_on = '{asked}' needs.*planner 'oracle' has none"):
            EpisodeRunner(RunConfig(task="goal_cube_in_bowl", stop_on=asked))


def test_either_ends_at_the_predicate_or_at_the_detector_whichever_comes_first():
    rec = EpisodeRunner(dataclasses.replace(_cfg(), stop_on="either")).run()  # the predicate holds first here
    assert rec["stop_on"] == "either" and rec["success"] and rec["stopped_by"] == "simulator"
    assert not rec["premature_stop"]

    rec = _run_always_done(stop_hold_steps=2, stop_on="either")
    assert rec["stopped_by"] == "detector" and rec["steps"] == 17  # checks at 16, 17: not idling to the time limit
    assert not rec["success"] and rec["premature_stop"]


def test_auto_is_either_for_glsr_with_a_detector_on_libero_and_simulator_elsewhere():
    from tcot_hybrid.episode import resolve_stop_on

    class Task:
        def __init__(self, world):
            self.world_kind = world

    class Planner:
        def __init__(self, detector):
            self.has_detector = detector

    def resolved(world, detector=True, mode="glsr", stop_on="auto"):
        cfg = RunConfig(task="goal_cube_in_bowl", stop_on=stop_on, supervisor=SupervisorConfig(mode=mode))
        return resolve_stop_on(cfg, Task(world), Planner(detector))

    assert RunConfig().stop_on == "auto"
    assert resolved("libero") == "either" and resolved("libero", mode="glsr_reset") == "either"
    assert resolved("workcell") == "simulator" and resolved("libero", detector=False) == "simulator"
    assert resolved("libero", mode="global") == "simulator" and resolved("libero", stop_on="simulator") == "simulator"
    rec = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=3, planner="learned",
                                  supervisor=SupervisorConfig(mode="glsr"))).run()
    assert rec["stop_on"] == "simulator"  # the workcell: as before


def test_a_verdict_the_local_plan_overrules_restarts_the_detector_stop_count():
    rec = _run_always_done(stop_hold_steps=15, stop_on="either",
                           supervisor=SupervisorConfig(mode="glsr", confirm_success="local_plan"))
    over = [e["step"] for e in rec["events"] if e.get("reason") == "detector_overruled"]
    assert over, "the learned local plans of goal_cube_in_bowl still move at step 16"
    checks = {e["step"]: e["hold"] for e in rec["events"] if e["kind"] == "stop_check"}
    assert all(checks[s + 1] == 1 for s in over if s + 1 in checks)  # counted afresh after each overrule
    assert rec["detector_overruled"] == len(over)
