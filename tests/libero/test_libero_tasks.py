"""LIBERO names in the task registry and the CLI: listing, bad input, and the LIBERO-less install's error."""
import json
from pathlib import Path

import pytest

import tcot_hybrid.libero as libero_pkg
from tcot_hybrid.cli import main
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.run_config import RunConfig
from tcot_hybrid.tasks import default_robot, list_all_tasks, make_task, suite_task_names

STANDARD = ("libero_spatial", "libero_object", "libero_goal", "libero_10")


def test_without_libero_the_names_say_how_to_install(monkeypatch, capsys):
    monkeypatch.setattr(libero_pkg, "libero_available", lambda: False)
    for bad in (lambda: make_task("libero_spatial:anything"), lambda: suite_task_names("libero_10")):
        with pytest.raises(libero_pkg.LiberoMissingError, match="make libero"):
            bad()
    workcell = list_all_tasks()
    assert workcell and all(t["world"] == "workcell" for t in workcell)  # everything else works as before
    assert make_task("goal_cube_on_plate").name == "goal_cube_on_plate"
    assert main(["run", "--task", "libero_goal:open_the_middle_drawer_of_the_cabinet", "--out", "/tmp/unused"]) == 2
    assert "LIBERO is not installed" in capsys.readouterr().err


def test_robot_auto_follows_the_task():
    assert RunConfig(task="libero_10:whatever").robot == "libero_panda" == default_robot("libero_goal:x")
    assert RunConfig().robot == "panda"
    assert RunConfig(task="libero_10:whatever", robot="panda").robot == "panda"  # explicit stays explicit
    with pytest.raises(ConfigError, match="shipped, sampled, spread"):
        RunConfig(init="fresh")


def test_every_registered_suite_is_listed(capsys):
    pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"
    assert main(["list", "--json"]) == 0
    tasks = json.loads(capsys.readouterr().out)["tasks"]
    suites = {t["suite"] for t in tasks}
    assert set(STANDARD) <= suites and len(suites) > 20
    for s in STANDARD:
        named = [t for t in tasks if t["suite"] == s]
        assert len(named) == 10 and all(t["name"].startswith(s + ":") and t["instruction"] for t in named)


def test_bad_libero_names_and_init_states(tmp_path, capsys):
    pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"
    with pytest.raises(ConfigError, match="suites: libero_spatial, libero_object"):
        make_task("libero_nope:x")
    with pytest.raises(ConfigError, match="did you mean"):
        make_task("libero_spatial:pick_up_the_black_bowl_next_to_the_ramekin_and_place_it_on_the_plat")
    with pytest.raises(ConfigError, match="suite"):
        suite_task_names("libero_nope")
    assert main(["eval", "--suite", "libero_nope", "--out", str(tmp_path / "e")]) == 2
    assert "libero_nope" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="not available for task 'goal_cube_on_plate'"):
        make_task("goal_cube_on_plate").set_episode(seed=0, init="shipped")
    import dataclasses

    task = make_task(suite_task_names("libero_goal")[0])
    task.info = dataclasses.replace(task.info, init_states_path=Path(tmp_path / "missing.pruned_init"))
    with pytest.raises(ConfigError, match="no usable shipped init states"):
        task.set_episode(seed=0, init="shipped")
    task.set_episode(seed=0, init="sampled")  # a sampled layout needs no init states


def test_a_seed_past_the_shipped_init_states_is_refused_not_wrapped(tmp_path, capsys):
    """Seed 50 of a task with 50 shipped states would be state 0 again: an episode counted twice."""
    pytest.importorskip("libero.libero")
    task = make_task(suite_task_names("libero_goal")[0])
    task.set_episode(seed=49, init="shipped")
    assert task.episode_seed == 49
    for seed in (50, -1):
        with pytest.raises(ConfigError, match=rf"seed {seed} is not a shipped init state .* seeds 0-49"):
            task.set_episode(seed=seed, init="shipped")
    task.set_episode(seed=50, init="sampled")  # sampled layouts take any seed
    # eval checks each cell's last seed before any episode runs: 49 + 2 episodes reach state 50
    args = ["eval", "--tasks", task.name, "--init", "shipped", "--seed-start", "49", "--out", str(tmp_path / "e")]
    assert main(args + ["--episodes", "2"]) == 2
    err = capsys.readouterr().err
    assert "seed 50 is not a shipped init state" in err and "--init sampled" in err
    assert not (tmp_path / "e" / "episodes.jsonl").exists()
    # without --init (the default) a seed past the shipped states is a sampled layout, and says so
    task.set_episode(seed=1001, init=None)
    assert task.init == "sampled" and "seed 1001 is past the 50 shipped init states" in task.init_note
    task.set_episode(seed=3, init=None)
    assert task.init == "shipped" and task.init_note is None
    # ... but an eval cell never mixes the two kinds of layout
    assert main(["eval", "--tasks", task.name, "--seed-start", "49", "--episodes", "2", "--out", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err
    assert "seeds 49-50" in err and "would run shipped layouts and then sampled ones" in err
    assert "give --init shipped or --init sampled" in err


def test_collect_never_takes_libero_test_states_and_keeps_worlds_apart(tmp_path, capsys):
    pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"
    cfg = tmp_path / "shipped.yaml"
    cfg.write_text("init: shipped\n")
    out = str(tmp_path / "d.hdf5")
    assert main(["collect", "--suite", "libero_goal", "--config", str(cfg), "--out", out]) == 2
    assert "test set" in capsys.readouterr().err
    assert main(["collect", "--tasks", "goal_cube_on_plate," + suite_task_names("libero_goal")[0], "--out", out]) == 2
    assert "separate files" in capsys.readouterr().err
    assert main(["collect", "--suite", "libero_goal", "--seed-start", "49990", "--episodes-per-task", "20",
                 "--out", out]) == 2
    assert "< 50000" in capsys.readouterr().err
    assert main(["collect", "--tasks", "goal_cube_on_plate", "--init", "spread", "--out", out]) == 2
    assert "init = 'spread' is not available for task 'goal_cube_on_plate'; choose one of sampled" in \
        capsys.readouterr().err


def test_run_without_init_past_the_shipped_states_records_its_sampled_layout(tmp_path, capsys):
    """`tcot run --task <libero task> --seed 1001` (public seeds run every listed task so): a sampled layout, said on
    stderr and in the record (``init``, ``init_note``), not a refusal."""
    pytest.importorskip("libero.libero")
    task = "libero_goal:open_the_middle_drawer_of_the_cabinet"
    assert main(["run", "--task", task, "--seed", "1001", "--planner", "oracle", "--out", str(tmp_path)]) == 0
    assert "seed 1001 is past the 50 shipped init states" in capsys.readouterr().err
    rec = json.loads((tmp_path / "episode.json").read_text())
    assert rec["init"] == "sampled" and "past the 50 shipped init states" in rec["init_note"]
    assert "fixture_seed" not in rec  # a sampled layout's fixtures are drawn with its own seed
    assert rec["success"] and rec["max_joint_limit_violation_rad"] == 0.0
