"""The paper's-protocol tables (docs/libero-planner/protocol.py): a row cut off midway is carried to another machine
whole (what the detector figures read included), a row still running never reaches the tables, and a row names the
checkpoint it ran."""
import importlib
import json
import sys
from pathlib import Path

import pytest

from tcot_hybrid.evaluation.aggregation import aggregate, detector_metrics

HERE = Path(__file__).resolve().parent.parent / "docs" / "libero-planner"


@pytest.fixture(scope="module")
def protocol():
    sys.path.insert(0, str(HERE))
    try:
        yield importlib.import_module("protocol")
    finally:
        sys.path.remove(str(HERE))


def _episode(suite, task, seed, success, mode="glsr"):
    events = [{"t": 0.1, "kind": "plan_adopted", "step": 0, "waypoints": 26},
              {"t": 1.0, "kind": "supervisor", "step": 3, "p_success": 0.2, "true_success": False, "state": "local"},
              {"t": 1.1, "kind": "stop_check", "step": 4, "p_success": 0.9, "true_success": success, "hold": 1}]
    return {"task": f"{suite}:{task}", "suite": suite, "planner": "learned", "mode": mode, "perturb": "none",
            "seed": seed, "success": success, "fault": None, "stopped_by": "simulator", "steps": 40, "events": events,
            "key": f"{suite}:{task}|learned|{mode}|none|{seed}", "robot": "libero_panda", "controller": "computed_torque",
            "ik": "mink", "sweep": "-", "sim_time_s": 4.0, "wall_time_s": 2.0, "fixture_seed": 2_000_000 + seed}


def test_saved_progress_restores_every_episode_and_the_same_figures(protocol, tmp_path):
    eps = [_episode("libero_10", f"t{i % 3}", i, i % 2 == 0) for i in range(7)]
    (tmp_path / "episodes.jsonl").write_text("".join(json.dumps(e) + "\n" for e in eps))
    protocol.save_progress(tmp_path)
    other = tmp_path / "other_machine"
    other.mkdir()
    (other / "progress.jsonl.gz").write_bytes((tmp_path / "progress.jsonl.gz").read_bytes())
    (other / "episodes.jsonl").write_text(json.dumps(eps[0]) + "\n")  # one episode is there already
    assert protocol.restore_progress(other) == 6
    back = [json.loads(x) for x in (other / "episodes.jsonl").read_text().splitlines()]
    assert sorted(e["key"] for e in back) == sorted(e["key"] for e in eps)
    assert detector_metrics(back) == detector_metrics(eps)
    assert aggregate(back) == aggregate(eps)
    assert all(ev["kind"] != "plan_adopted" for e in back[1:] for ev in e["events"])  # only the detector's calls


def test_a_row_still_running_is_left_out_of_the_tables(protocol, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(protocol, "PER_SUITE", 2)
    whole = [_episode(s, "t", seed, True, mode="global") for s in protocol.SUITES for seed in (0, 1)]
    running = [_episode("libero_10", "t", 0, False)]
    got = protocol._complete_rows(whole + running, tmp_path)
    assert sorted(e["key"] for e in got) == sorted(e["key"] for e in whole)
    assert "the learned glsr row is in progress in episodes.jsonl (1 of 8 episodes)" in capsys.readouterr().out


def test_a_task_model_folder_is_whole_with_every_init_state_of_the_tasks_routed_to_its_model(protocol, tmp_path,
                                                                                                monkeypatch, capsys):
    folder = tmp_path / "eval-protocol-task" / "libero_panda_tasks_wide"
    monkeypatch.setattr(protocol, "TASK_EVAL", folder.parent)
    monkeypatch.setattr(protocol, "PER_TASK", 2)
    monkeypatch.setattr(protocol, "routed_tasks", lambda stem: ["libero_goal:a", "libero_goal:b"])
    eps = [_episode("libero_goal", t, seed, True) for t in ("a", "b") for seed in (0, 1)]
    assert protocol._complete_rows(eps[:3], folder) == []
    assert "the learned glsr row is in progress in episodes.jsonl (3 of 4 episodes)" in capsys.readouterr().out
    assert len(protocol._complete_rows(eps, folder)) == 4


def test_a_rerun_half_done_is_in_progress_and_not_mixed_with_the_run_before(protocol, tmp_path, capsys):
    """A complete row, then a rerun (other defaults or code: other keys) of part of it: the tables keep the first run
    whole until the rerun has every init state, then take the rerun whole."""
    protocol.PER_SUITE, saved = 2, protocol.PER_SUITE
    try:
        first = [_episode(s, "t", seed, True) for s in protocol.SUITES for seed in (0, 1)]
        rerun = [{**e, "key": e["key"] + "|new", "success": False} for e in first]
        assert protocol._complete_rows(first + rerun[:3], tmp_path) == []
        assert "the learned glsr row is in progress in episodes.jsonl (3 of 8 episodes)" in capsys.readouterr().out
        got = protocol._complete_rows(first + rerun, tmp_path)
        assert sorted(e["key"] for e in got) == sorted(e["key"] for e in rerun)
        # resumed in parts (no episode twice), and the first run alone: each is one run
        assert len(protocol._complete_rows(first[:5] + first[5:], tmp_path)) == 8
    finally:
        protocol.PER_SUITE = saved


def test_a_row_run_with_one_fixture_draw_never_replaces_one_run_with_each_states_own(protocol, tmp_path, monkeypatch,
                                                                                        capsys):
    monkeypatch.setattr(protocol, "PER_SUITE", 2)
    new = [_episode(s, "t", seed, seed == 0) for s in protocol.SUITES for seed in (0, 1)]
    old = [{**e, "fixture_seed": None, "success": True} for e in new]  # left in an older checkout's episodes.jsonl
    (tmp_path / "records.jsonl").write_text("".join(json.dumps({k: e.get(k) for k in protocol.RECORD_FIELDS}) + "\n"
                                                    for e in new))
    (tmp_path / "episodes.jsonl").write_text("".join(json.dumps(e) + "\n" for e in old))
    got = protocol._records(tmp_path)
    assert sorted((r["suite"], r["seed"], r["success"], r["fixture_seed"]) for r in got) == sorted(
        (e["suite"], e["seed"], e["success"], e["fixture_seed"]) for e in new)
    assert "the learned glsr row in episodes.jsonl ran with the fixtures at the build's one draw" in capsys.readouterr().out
    # a row with a state records.jsonl does not hold yet is left out whole too, not merged around the kept ones
    (tmp_path / "episodes.jsonl").write_text("".join(json.dumps(e) + "\n" for e in old + [{**old[0], "seed": 7}]))
    monkeypatch.setattr(protocol, "_complete_rows", lambda eps, folder: eps)
    assert sorted(r["seed"] for r in protocol._records(tmp_path)) == sorted(e["seed"] for e in new)
    # the other way round, a run with each state's own draw replaces one with the build's draw
    (tmp_path / "episodes.jsonl").write_text("".join(json.dumps(e) + "\n" for e in new))
    (tmp_path / "records.jsonl").write_text("".join(json.dumps({k: e.get(k) for k in protocol.RECORD_FIELDS}) + "\n"
                                                    for e in old))
    assert sum(r["success"] for r in protocol._records(tmp_path)) == 4


def test_restoring_without_saved_progress_restores_nothing(protocol, tmp_path):
    assert protocol.restore_progress(tmp_path) == 0
    assert not (tmp_path / "episodes.jsonl").exists()


def test_a_row_already_complete_keeps_the_commit_and_wall_time_it_ran_with(protocol, tmp_path):
    (tmp_path / "eval-learned-local.json").write_text(json.dumps({"episodes": 2000, "ran_now": 1104}))
    (tmp_path / "eval-learned-local.commit").write_text("1ea9f6f\n")
    (tmp_path / "eval.json").write_text(json.dumps({"episodes": 2000, "ran_now": 0}))
    assert not protocol.keep_row(tmp_path, "learned", "local", "a30ff97")
    assert (tmp_path / "eval-learned-local.commit").read_text() == "1ea9f6f\n"
    assert json.loads((tmp_path / "eval-learned-local.json").read_text())["ran_now"] == 1104

    (tmp_path / "eval.json").write_text(json.dumps({"episodes": 2000, "ran_now": 12}))
    assert protocol.keep_row(tmp_path, "learned", "local", "a30ff97")
    assert (tmp_path / "eval-learned-local.commit").read_text() == "a30ff97\n"
    assert json.loads((tmp_path / "eval-learned-local.json").read_text())["ran_now"] == 12


def test_a_row_resumed_at_another_commit_names_every_commit_its_parts_started_at(protocol, tmp_path):
    protocol.start_row(tmp_path, "learned", "glsr", "1ea9f6f")  # cut off with the session: never kept
    protocol.start_row(tmp_path, "learned", "glsr", "a30ff97")
    (tmp_path / "eval.json").write_text(json.dumps({"episodes": 2000, "ran_now": 1104}))
    assert protocol.keep_row(tmp_path, "learned", "glsr", "a30ff97")
    assert (tmp_path / "eval-learned-glsr.commit").read_text() == "1ea9f6f, then a30ff97\n"
    assert not (tmp_path / "eval-learned-glsr.started").exists()

    # a later run in one part names its own commit alone
    protocol.start_row(tmp_path, "learned", "glsr", "b00c0de")
    (tmp_path / "eval.json").write_text(json.dumps({"episodes": 2000, "ran_now": 2000}))
    assert protocol.keep_row(tmp_path, "learned", "glsr", "b00c0de")
    assert (tmp_path / "eval-learned-glsr.commit").read_text() == "b00c0de\n"


def test_the_stack_defaults_row_names_the_four_suite_checkpoint_it_borrows(protocol, monkeypatch, tmp_path):
    monkeypatch.setattr(protocol, "ORACLE", tmp_path / "no_oracle_run.jsonl")
    def with_hash(e, checkpoint):
        return {**e, "checkpoint_hash": checkpoint, "max_reference_limit_excess_rad": 0.0}

    glsr = [with_hash(_episode(s, "t", i, True), "0ld0ld0ld0ld0ld0")
            for s in ("libero_spatial", "libero_object", "libero_goal", "libero_10") for i in range(2)]
    own = [with_hash(_episode("libero_10", "t", i, True), "5u1te5u1te5u1te5") for i in range(2)]
    lines = protocol.table1_lines({("learned", "glsr"): glsr}, own, {})
    note = [x for x in lines if x.startswith(f"- {protocol.DEFAULTS_ROW.split(' (')[0]}:")]
    assert len(note) == 1
    assert protocol.ONE_DRAW_NOTE not in lines  # every episode drew its fixtures
    # a row any of whose episodes kept the fixtures at the scene build's placement (before stop 64) is marked
    glsr[0] = {k: v for k, v in glsr[0].items() if k != "fixture_seed"}
    lines = protocol.table1_lines({("learned", "glsr"): glsr}, own, {})
    assert sum(x.startswith("| ours: GLSR (Algorithm 1)") and x.split(" | ")[0].endswith(" °") for x in lines) == 1
    assert sum(x.startswith(f"| ours: {protocol.DEFAULTS_ROW} °") for x in lines) == 1  # it borrows the marked one
    assert protocol.ONE_DRAW_NOTE in lines
    assert "libero_10 from the suite models' rows" in note[0]
    assert "`0ld0ld0ld0ld0ld0`, **not the one shipped now**" in note[0]


def test_the_defaults_rows_take_each_task_from_the_row_of_the_model_it_loads(protocol, tmp_path, monkeypatch):
    """A task routed in task_models.json to the four-suite model comes from the four-suite row, one routed to a
    model shipped for routed tasks alone from that model's row (left out while it has none), its suite's other tasks
    from the suite model's row, a suite without its own model from the four-suite row; the global-only defaults row
    is put together the same way from the global-only rows."""
    import tcot_hybrid.learning.checkpoint as ck

    monkeypatch.setattr(ck, "checkpoints_dir", lambda: tmp_path)
    for stem in ("libero_panda_default", "libero_panda_libero_10", "libero_panda_tasks_wide"):
        (tmp_path / f"{stem}.safetensors").write_bytes(b"")
    (tmp_path / ck.TASK_MODELS_FILE).write_text(json.dumps({"routes": {"libero_panda": {
        "libero_10:stove": "libero_panda_default", "libero_10:mug": "libero_panda_tasks_wide"}}}))
    multi = [_episode(s, t, 0, ok) for s, t, ok in (("libero_10", "stove", True), ("libero_10", "book", False),
                                                   ("libero_10", "mug", False), ("libero_goal", "knob", True))]
    own = [_episode("libero_10", t, 0, ok) for t, ok in (("stove", False), ("book", True), ("mug", False))]
    picked = protocol.defaults_episodes(multi, own)
    assert sorted((e["task"], e["success"]) for e in picked) == [
        ("libero_10:book", True), ("libero_10:stove", True), ("libero_goal:knob", True)]
    wide = {"libero_panda_tasks_wide": [_episode("libero_10", "mug", 0, True)]}
    picked = protocol.defaults_episodes(multi, own, wide)
    assert sorted((e["task"], e["success"]) for e in picked) == [
        ("libero_10:book", True), ("libero_10:mug", True), ("libero_10:stove", True), ("libero_goal:knob", True)]
    assert protocol.routed_tasks("libero_panda_tasks_wide") == ["libero_10:mug"]
    by = {("learned", m): [{**e, "mode": m, "checkpoint_hash": "c", "max_reference_limit_excess_rad": 0.0} for e in multi]
          for m in ("global", "glsr")}
    own_both = [{**e, "mode": m, "checkpoint_hash": "o"} for e in own for m in ("global", "glsr")]
    lines = protocol.table1_lines(by, own_both, {})
    assert sum(x.startswith(f"| ours: {protocol.DEFAULTS_GLOBAL_ROW} |") for x in lines) == 1
    assert sum(x.startswith(f"| ours: {protocol.DEFAULTS_ROW} |") for x in lines) == 1
