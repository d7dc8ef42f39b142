import math

import pytest

from tcot_hybrid.errors import ConfigError
from tcot_hybrid.evaluation import (aggregate, auroc, detector_metrics, evaluate, longest_first, make_jobs, markdown,
                                    parse_sweep, with_field)
from tcot_hybrid.metrics import wilson_interval
from tcot_hybrid.run_config import RunConfig


def test_auroc_matches_definition():
    assert auroc([0.1, 0.2, 0.8, 0.9], [False, False, True, True]) == 1.0
    assert auroc([0.9, 0.8, 0.2, 0.1], [False, False, True, True]) == 0.0
    assert auroc([0.5, 0.5], [False, True]) == 0.5
    assert auroc([0.1], [True]) is None


def test_sweep_parsing_and_typed_fields():
    field, vals = parse_sweep("ik_params.damping=1e-3,1e-2")
    assert field == "ik_params.damping" and vals == ["1e-3", "1e-2"]
    cfg = with_field(RunConfig(), "ik_params.damping", "0.05")
    assert cfg.ik_params.damping == 0.05
    assert with_field(RunConfig(), "timing.plan_dt", "0.2").timing.plan_dt == 0.2
    with pytest.raises(ConfigError, match="unknown field"):
        with_field(RunConfig(), "ik_params.dampning", "1")
    with pytest.raises(ConfigError, match="plan_dt"):
        with_field(RunConfig(), "timing.plan_dt", "0.105")
    with pytest.raises(ConfigError, match="FIELD=V1,V2"):
        parse_sweep("ik_params.damping")


def test_jobs_cross_product_and_keys_unique():
    jobs = make_jobs(RunConfig(), tasks=["goal_cube_on_plate", "goal_open_drawer"], planners=["oracle"],
                     modes=["global", "glsr"], robots=["panda"], controllers=["computed_torque"], iks=["mink"],
                     episodes=3, seed_start=10, perturbs=["none", "object_moved"], sweep="supervisor.t_l=4,8")
    assert len(jobs) == 2 * 2 * 2 * 2 * 3
    assert len({j.key for j in jobs}) == len(jobs)


def test_aggregate_and_detector_metrics():
    recs = [dict(task="t", suite="goal", planner="learned", mode="glsr", perturb="none", robot="panda",
                 controller="c", ik="mink", sweep="-", seed=i, success=i % 2 == 0,
                 events=[{"kind": "supervisor", "p_success": 0.2, "true_success": False},
                         {"kind": "detector", "p_success": 0.9 if i != 2 else 0.3, "true_success": True}])
            for i in range(4)]
    (cell,) = aggregate(recs)
    assert cell["episodes"] == 4 and cell["successes"] == 2
    assert math.isclose(cell["stderr"], math.sqrt(0.25 / 4))
    assert cell["ci95"] == [round(x, 4) for x in wilson_interval(2, 4)]
    assert cell["perturbation_fired"] is None and cell["premature_stops"] == 0
    det = detector_metrics(recs)["learned"]
    assert det["calls"] == 8 and det["false_alarm_rate"] == 0.5
    assert det["in_episode_frames"] == 4 and det["in_episode_auroc"] is None  # all in-episode frames negative


def test_wilson_interval():
    lo, hi = wilson_interval(5, 5)
    assert round(lo, 3) == 0.566 and hi == 1.0  # "1.00 ± 0.00" at n = 5 was really [0.57, 1.00]
    lo, hi = wilson_interval(0, 20)
    assert lo == 0.0 and round(hi, 3) == 0.161
    lo, hi = wilson_interval(9, 10)
    assert round(lo, 3) == 0.596 and round(hi, 3) == 0.982
    assert wilson_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(6, 5)


def _rec(i, **kw):
    base = dict(task="goal_open_drawer", suite="goal", planner="oracle", mode="global", perturb="target_moved",
                robot="panda", controller="c", ik="mink", sweep="-", seed=i, success=True, events=[])
    return {**base, **kw}


def test_never_fired_perturbations_are_marked_not_reported_as_perturbed_success():
    note = "task goal_open_drawer has no target receptacle"
    recs = [_rec(i, perturbation_fired=False, perturbation_note=note) for i in range(3)]
    recs += [_rec(i, task="goal_cube_in_bowl", perturbation_fired=i > 0, perturbation_note=None if i else "x")
             for i in range(3)]
    cells = {c["task"]: c for c in aggregate(recs)}
    assert cells["goal_open_drawer"]["perturbation_fired"] == 0
    assert cells["goal_open_drawer"]["perturbation_notes"] == [note]
    assert cells["goal_cube_in_bowl"]["perturbation_fired"] == 2
    md = markdown({"cells": list(cells.values())})
    row = next(line for line in md.splitlines() if line.startswith("| goal_open_drawer |"))
    assert "not fired (n=3)" in row and "1.00 [" not in row
    assert f"`target_moved` on `goal_open_drawer`: fired in 0 of 3 episodes ({note})" in md
    assert "`target_moved` on `goal_cube_in_bowl`: fired in 2 of 3 episodes (x)" in md
    # pooled: the never-fired cell is left out of the rate (n = 3), the fired column counts every episode
    assert "| target_moved | oracle (global) | 1.000 | [0.439, 1.000] | 3 | 2/6 |" in md


def test_in_episode_auroc_counts_each_step_once():
    ev = lambda kind, step, p, y: {"kind": kind, "step": step, "p_success": p, "true_success": y}  # noqa: E731
    recs = [_rec(0, planner="learned", mode="glsr", perturb="none", stop_on="detector", premature_stop=False, events=[
        ev("supervisor", 16, 0.1, False), ev("stop_check", 16, 0.1, False),  # same frame, asked twice
        ev("supervisor", 17, 0.2, False), ev("stop_check", 18, 0.9, True), ev("stop_check", 19, 0.95, True)]),
        _rec(1, planner="learned", mode="glsr", perturb="none", stop_on="detector", premature_stop=True,
             success=False, events=[ev("stop_check", 16, 0.8, False)])]
    det = detector_metrics(recs)["learned"]
    assert det["in_episode_frames"] == 5 and det["in_episode_positives"] == 2
    assert det["in_episode_auroc"] == 1.0 and det["calls"] == 5
    (cell,) = aggregate(recs)
    assert cell["premature_stops"] == 1 and cell["stop_on"] == "detector"
    assert "premature stops" in markdown({"cells": [cell], "detector": detector_metrics(recs)})


def test_evaluate_resumes(tmp_path, monkeypatch):
    import torch

    import tcot_hybrid.evaluation.running as running

    for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(k, raising=False)
    threads, real = [], running.run_job

    def spy(job):  # episodes in this process run on one torch thread, as in a worker
        threads.append(torch.get_num_threads())
        return real(job)

    monkeypatch.setattr(running, "run_job", spy)
    jobs = make_jobs(RunConfig(), tasks=["goal_open_drawer"], planners=["oracle"], modes=["global"],
                     robots=["panda"], controllers=["computed_torque"], iks=["mink"], episodes=2, seed_start=1000)
    torch.set_num_threads(2)
    first = evaluate(jobs, tmp_path, workers=1, progress=False)
    assert first["ran_now"] == 2 and first["cells"][0]["successes"] == 2
    assert threads == [1, 1] and torch.get_num_threads() == 2
    again = evaluate(jobs, tmp_path, workers=1, progress=False)
    assert again["ran_now"] == 0 and again["cells"] == first["cells"]


def test_job_key_follows_the_checkpoint_file(tmp_path):
    """A retrained checkpoint at the same path must not inherit the old one's finished episodes on resume."""
    import dataclasses

    ck = tmp_path / "planner.safetensors"
    ck.write_bytes(b"first weights")

    def key(planner="learned", checkpoint=str(ck)):
        (job,) = make_jobs(dataclasses.replace(RunConfig(), checkpoint=checkpoint), tasks=["goal_cube_on_plate"],
                           planners=[planner], modes=["global"], robots=["panda"], controllers=["computed_torque"],
                           iks=["mink"], episodes=1, seed_start=1000)
        return job.key

    before = key()
    ck.write_bytes(b"retrained weights, same path")
    assert key() != before
    weights_only = key()
    meta = tmp_path / "planner.json"
    meta.write_text('{"model": {"readout_radius_cells": 0}}')
    with_meta = key()
    meta.write_text('{"model": {"readout_radius_cells": 2}}')  # an inference setting lives in the metadata
    assert len({weights_only, with_meta, key()}) == 3
    shipped = key(checkpoint=None)
    assert shipped != key() and shipped.count("|") == key().count("|")  # the shipped default is hashed too
    assert key("oracle", None).count("|") == before.count("|") - 1  # no checkpoint, no hash in the key


def test_job_key_follows_the_task_code(monkeypatch):
    """An episode run with other task code (e.g. a changed oracle script) must not be credited on resume."""
    from tcot_hybrid.evaluation import jobs as evaluation

    (job,) = make_jobs(RunConfig(), tasks=["tool_pull_cube_with_stick"], planners=["oracle"], modes=["global"],
                       robots=["panda"], controllers=["computed_torque"], iks=["mink"], episodes=1, seed_start=1000)
    assert evaluation.task_code_digest() in job.key.split("|")
    monkeypatch.setattr(evaluation, "task_code_digest", lambda: "other task code")
    assert job.key.split("|")[-1] == "other task code"


def test_longest_tasks_are_scheduled_first():
    from tcot_hybrid.tasks import make_task

    jobs = make_jobs(RunConfig(), tasks=["goal_cube_on_plate", "tool_pull_cube_with_stick", "long_stack_three_blocks"],
                     planners=["oracle"], modes=["global"], robots=["panda"], controllers=["computed_torque"],
                     iks=["mink"], episodes=2, seed_start=1000)
    ordered = longest_first(jobs)
    limits = [make_task(j.cfg.task).time_limit_s for j in ordered]
    assert limits == sorted(limits, reverse=True) and sorted(j.key for j in ordered) == sorted(j.key for j in jobs)


def test_several_ik_backends_get_a_side_by_side_table_with_time_and_tracking_error():
    from tcot_hybrid.evaluation.reports import markdown

    def rec(ik, seed, ok, t, err, fails=0, infeasible=0):
        return {"task": "goal_cube_on_plate", "suite": "goal", "planner": "oracle", "mode": "global", "perturb": "none",
                "robot": "panda", "controller": "computed_torque", "ik": ik, "seed": seed, "success": ok,
                "success_time_s": t if ok else None, "sim_time_s": t, "max_tracking_error_rad": err,
                "ik_failures": fails, "plans_infeasible": infeasible, "max_joint_limit_violation_rad": 0.0}
    records = [rec("mink", 0, True, 4.0, 0.01), rec("mink", 1, True, 6.0, 0.03, fails=2),
               rec("casadi", 0, True, 5.0, 0.02), rec("casadi", 1, False, 9.0, 0.04, infeasible=1)]
    text = markdown({"cells": aggregate(records)})
    assert "#### IK backends" in text
    assert "| panda | mink | 1.000 [0.342, 1.000] n=2 | 5.0 | 0.02 | 2 | 0 | 0.0e+00 |" in text
    assert "| panda | casadi | 0.500 [0.095, 0.905] n=2 | 7.0 | 0.03 | 0 | 1 | 0.0e+00 |" in text
    one_ik = markdown({"cells": aggregate([r for r in records if r["ik"] == "mink"])})
    assert "IK backends" not in one_ik
