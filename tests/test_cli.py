"""The command-line contract: listing, one episode record, clear errors with non-zero exit codes."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ENV = {**os.environ, "MUJOCO_GL": "egl"}
WORKCELL_CHECKPOINT = str(Path(__file__).parents[1] / "tcot_hybrid" / "checkpoints" / "panda_default.safetensors")


def tcot(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "tcot_hybrid.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env=ENV)


def test_list_json_has_every_family():
    r = tcot("list", "--json")
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    assert {"tasks", "robots", "controllers", "ik", "planners", "perturbations"} <= data.keys()
    assert {t["suite"] for t in data["tasks"]} >= {"spatial", "object", "goal", "long"}
    assert all({"name", "suite", "instruction"} <= t.keys() for t in data["tasks"])
    assert all({"name", "description"} <= p.keys() for p in data["perturbations"])


def test_run_writes_the_episode_record(tmp_path):
    r = tcot("run", "--task", "goal_open_drawer", "--seed", "3", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    rec = json.loads((tmp_path / "episode.json").read_text())
    for key in ("task", "robot", "controller", "ik", "planner", "seed", "success", "sim_time_s", "wall_time_s",
                "steps", "events", "max_joint_limit_violation_rad", "max_velocity_ratio", "config_hash",
                "robot_model_hash"):
        assert key in rec, key
    assert rec["success"] is True and rec["max_joint_limit_violation_rad"] == 0.0
    assert "SUCCESS" in r.stdout
    # what it ran on: episodes repeat exactly on one machine, not across machines
    assert {"tcot_hybrid", "mujoco", "numpy", "python", "cpu", "avx512"} <= set(rec["versions"])
    assert rec["versions"]["cpu"] and rec["versions"]["avx512"] in (True, False, None)


@pytest.mark.parametrize("args, fragment", [
    (["run", "--task", "no_such_task"], "goal_cube_on_plate"),
    (["run", "--task", "goal_open_drawer", "--robot", "r2d2"], "panda"),
    (["run", "--task", "goal_open_drawer", "--controller", "bangbang"], "computed_torque"),
    (["run", "--task", "goal_open_drawer", "--ik", "magic"], "pinocchio"),
    (["run", "--task", "goal_open_drawer", "--planner", "psychic"], "oracle"),
    (["run", "--task", "goal_open_drawer", "--timing.sim-dt", "nan"], "sim_dt"),
    (["run", "--task", "goal_open_drawer", "--perturb.name", "meteor"], "object_moved"),
    (["run", "--task", "goal_open_drawer", "--perturb", "meteor"], "object_moved"),
    (["run", "--task", "goal_open_drawer", "--controller-params", "kp_scael", "2"], "kp_scale"),
    (["eval", "--suite", "nope"], "spatial"),
    # a checkpoint no planner of the run loads would be ignored
    (["run", "--task", "goal_open_drawer", "--planner", "oracle", "--checkpoint", WORKCELL_CHECKPOINT],
     "loaded by no planner of this run (oracle); the planners that load one: direct, learned"),
    (["eval", "--tasks", "goal_open_drawer", "--planners", "oracle", "--checkpoint", WORKCELL_CHECKPOINT],
     "loaded by no planner of this run (oracle)"),
    (["frobnicate"], "valid commands"),
])
def test_bad_input_exits_nonzero_and_names_valid_choices(args, fragment, tmp_path):
    r = tcot(*args, "--out", str(tmp_path)) if args[0] in ("run", "eval") else tcot(*args)
    assert r.returncode != 0
    assert fragment in r.stderr + r.stdout


def test_run_refuses_a_timeline_it_cannot_draw_before_the_episode(tmp_path):
    """matplotlib would fail on the suffix only after the episode; the run is refused first, naming the formats."""
    r = tcot("run", "--task", "goal_open_drawer", "--timeline", str(tmp_path / "timeline.txt"), "--out", str(tmp_path))
    assert r.returncode != 0
    assert "'.txt'" in r.stderr and ".png" in r.stderr and ".svg" in r.stderr
    assert not (tmp_path / "episode.json").exists() and not (tmp_path / "timeline.txt").exists()
    r = tcot("run", "--task", "goal_open_drawer", "--timeline", str(tmp_path / "timeline.png"), "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "timeline.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_malformed_config_file_refused(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("timing:\n  ctrl_dt: fast\n")
    r = tcot("run", "--config", str(cfg), "--out", str(tmp_path))
    assert r.returncode != 0 and "ctrl_dt" in r.stderr


def test_run_perturb_shorthand():
    from tcot_hybrid.cli import RunCommand, parse_with_config, perturb_shorthand

    for argv in (["--perturb", "object_drop"], ["--perturb=object_drop"], ["--perturb.name", "object_drop"]):
        cmd = parse_with_config(RunCommand, perturb_shorthand(["--task", "goal_cube_on_plate", *argv]), "tcot run")
        assert cmd.cfg.perturb.name == "object_drop"
    assert perturb_shorthand(["--perturb.strength", "0.05"]) == ["--perturb.strength", "0.05"]


def test_run_infers_on_one_torch_thread_as_eval_does(tmp_path, monkeypatch):
    """A LIBERO episode replayed with `tcot run` went another way than in `tcot eval` (two torch threads against the
    worker's one change the network's last bits): `tcot run` infers on one thread too, and restores the count."""
    import torch

    from tcot_hybrid import episode
    from tcot_hybrid.cli import main
    from tcot_hybrid.workers import ONE_THREAD_ENV

    for k in ONE_THREAD_ENV:
        monkeypatch.delenv(k, raising=False)
    seen = []
    run = episode.EpisodeRunner.run
    monkeypatch.setattr(episode.EpisodeRunner, "run",
                        lambda self, *a, **kw: seen.append(torch.get_num_threads()) or run(self, *a, **kw))
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        assert main(["run", "--task", "goal_open_drawer", "--seed", "3", "--planner", "learned",
                     "--out", str(tmp_path)]) == 0
        assert seen == [1] and torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
