"""GLSR supervisor (Algorithm 1) as a state machine, driven with the privileged oracle."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest

from tcot_hybrid.episode import EpisodeRunner
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.executor import ExecutorConfig
from tcot_hybrid.perturbations import PerturbConfig
from tcot_hybrid.run_config import RunConfig
from tcot_hybrid.supervision import Supervisor, SupervisorConfig


class FakePlanner:
    replan_every_step = False

    def __init__(self, p):
        self.p = p

    def success_probability(self, obs):
        return self.p


class FakeExecutor:
    ik_failures = 0
    plan_finished = False


def decisions(cfg, p, steps):
    sup = Supervisor(cfg, FakePlanner(p))
    return [sup.decide(t, observe=lambda: None, executor=FakeExecutor()) for t in range(steps)]


def test_algorithm1_global_then_frozen_then_local_every_t_l_when_not_successful():
    cfg = SupervisorConfig(mode="glsr", t_f=10, t_l=4)
    ds = decisions(cfg, 0.1, 25)
    planned = {t: d.plan_mode for t, d in enumerate(ds) if d.plan_mode}
    assert planned == {0: "global", 12: "local", 16: "local", 20: "local", 24: "local"}
    # frozen until t_f: no detector calls, no events
    assert all(d.event is None for d in ds[1:11])
    # from t_f on every step logs the detector's probability
    assert all(d.event and d.event["p_success"] == 0.1 for d in ds[11:])


def test_frozen_phase_ends_when_the_global_plan_has_been_carried_out():
    class DoneAfter5(FakeExecutor):
        def __init__(self):
            self.t = 0

        @property
        def plan_finished(self):
            return self.t > 5

    sup, ex = Supervisor(SupervisorConfig(mode="glsr", t_f=50, t_l=4), FakePlanner(0.1)), DoneAfter5()
    ds = []
    for t in range(14):
        ex.t = t
        ds.append(sup.decide(t, observe=lambda: None, executor=ex))
    assert all(d.event is None for d in ds[1:6])  # still following the frozen plan
    assert ds[6].event["state"] == "detect" and ds[6].event["p_success"] == 0.1  # detection from here
    assert [t for t, d in enumerate(ds) if d.plan_mode] == [0, 8, 12]


def test_no_replan_while_judged_successful():
    ds = decisions(SupervisorConfig(mode="glsr", t_f=3, t_l=2), 0.9, 12)
    assert [t for t, d in enumerate(ds) if d.plan_mode] == [0]
    assert ds[6].event["reason"] == "judged_successful"


def test_global_and_local_modes():
    assert [t for t, d in enumerate(decisions(SupervisorConfig(mode="global"), 0.0, 30)) if d.plan_mode] == [0]
    local = decisions(SupervisorConfig(mode="local", t_l=5), 0.0, 16)
    assert [(t, d.plan_mode) for t, d in enumerate(local) if d.plan_mode] == [(0, "local"), (5, "local"),
                                                                            (10, "local"), (15, "local")]


def test_reset_variant_resets_once_then_plans_locally():
    ds = decisions(SupervisorConfig(mode="glsr_reset", t_f=4, t_l=2, max_resets=1), 0.0, 12)
    assert [t for t, d in enumerate(ds) if d.reset] == [6]
    assert [t for t, d in enumerate(ds) if d.plan_mode == "local"] == [6, 8, 10]


@pytest.mark.parametrize("kw", [dict(mode="sometimes"), dict(t_l=0), dict(t_f=-1), dict(success_threshold=1.5)])
def test_bad_supervisor_config(kw):
    with pytest.raises(ConfigError):
        SupervisorConfig(**kw)


def test_glsr_recovers_where_frozen_global_plan_fails():
    """A moved object defeats the frozen global plan; GLSR's local replans recover (oracle planner)."""
    out = {}
    for mode in ("global", "glsr"):
        cfg = RunConfig(task="goal_cube_in_bowl", seed=1, supervisor=SupervisorConfig(mode=mode, t_f=30),
                        perturb=PerturbConfig(name="object_moved"))
        rec = EpisodeRunner(cfg).run()
        out[mode] = rec
        assert any(e["kind"] == "perturbation" for e in rec["events"])
    assert not out["global"]["success"] and out["glsr"]["success"]
    reasons = [e.get("reason") for e in out["glsr"]["events"] if e["kind"] == "supervisor"]
    assert "not_successful" in reasons


def test_stop_match_radius_is_validated():
    with pytest.raises(ConfigError, match="stop_match_m"):
        ExecutorConfig(stop_match_m=0.0)


@pytest.mark.parametrize("seed", [500, 501, 502])  # development (tuning) seeds, docs/seeds.md
def test_glsr_hands_a_drawer_pull_over_to_local_plans(seed):
    """Regression: when every replan (each t_l steps) restarted the wait at a stop its local plan had moved by
    1-4 cm, GLSR's first local plan (approaching the handle) left the arm hovering above the handle without
    ever closing the gripper (shipped checkpoint; ExecutorConfig.stop_match_m): 21.8 s or never, where the
    hand-over takes under 5 s."""
    cfg = RunConfig(task="goal_open_drawer", seed=seed, planner="learned", supervisor=SupervisorConfig(mode="glsr"))
    rec = EpisodeRunner(cfg).run()
    assert rec["success"] and rec["fault"] is None
    assert rec["success_time_s"] < 10.0  # not hovering
    assert any(e.get("plan") == "local" for e in rec["events"] if e["kind"] == "supervisor")
