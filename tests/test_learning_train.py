"""Training on a tiny synthetic demo file: the loss goes down, the run is reproducible, the checkpoint and
the metrics log are written; batches, augmentation, config checks and metric helpers."""
import json
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import dataclasses  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
from learning_synth import agentview_camera, make_demo_file  # noqa: E402
from safetensors.torch import load_file  # noqa: E402

from tcot_hybrid.errors import ConfigError, DatasetError  # noqa: E402
from tcot_hybrid.learning.checkpoint import load_checkpoint  # noqa: E402
from tcot_hybrid.learning.data import instructions_of, load_frames  # noqa: E402
from tcot_hybrid.data.labels import TrajectoryWindowConfig, windows_from_meta  # noqa: E402
from tcot_hybrid.learning.model import ModelConfig, PlannerNet  # noqa: E402
from tcot_hybrid.camera import points_at_height  # noqa: E402
from tcot_hybrid.learning.batches import Batcher, steps_to_success  # noqa: E402
from tcot_hybrid.learning.train import train  # noqa: E402
from tcot_hybrid.learning.train_cli import cmd_train  # noqa: E402
from tcot_hybrid.learning.train_config import MixConfig, TrainConfig, load_train_config  # noqa: E402
from tcot_hybrid.metrics import auroc  # noqa: E402
from tcot_hybrid.learning.vocab import Vocabulary  # noqa: E402


@pytest.fixture(scope="module")
def camera():
    return agentview_camera()


@pytest.fixture(scope="module")
def demo_file(tmp_path_factory, camera):
    path = tmp_path_factory.mktemp("synth") / "demos.hdf5"
    make_demo_file(path, camera, seeds=range(12), T=24)
    return path


def _cfg(demo_file, out, **kw):
    base = dict(data=str(demo_file), out=str(out), threads=1, batch_size=16, lr=3e-3, max_epochs=3,
                stage1_epochs=1, patience=10, val_max_frames=64, model=ModelConfig(width=8), bf16=False)
    base.update(kw)
    return TrainConfig(**base)


def test_tiny_training_lowers_loss_and_writes_checkpoint(demo_file, tmp_path, camera):
    cfg = _cfg(demo_file, tmp_path / "p.safetensors", max_epochs=4)
    res = train(cfg, progress=False, log=lambda *_: None)
    lines = [json.loads(x) for x in (tmp_path / "p.metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in lines] == list(range(1, 5))
    first, last = lines[0]["train"], lines[-1]["train"]
    assert last["loss"] < 0.8 * first["loss"] and last["px"] < first["px"]
    assert lines[0]["stage"] == 1 and lines[-1]["stage"] == 2 and lines[-1]["train"]["detect"] > 0
    for key in ("px_median", "px_p90", "global_3d_cm_median", "global_grip_acc", "success_auroc"):
        assert key in lines[-1]["val"]
    ck = load_checkpoint(res.checkpoint, robot="panda", camera=camera, kind="trajectory")
    assert ck.meta["metrics"]["best_epoch"] >= 1 and ck.meta["train_demos"] == 10
    assert ck.meta["vocabulary"][:2] == ["<pad>", "<unk>"]
    # the held-out report command, written to a named section and file stem (e.g. a training-split report)
    from tcot_hybrid.learning.evaluate import main as evaluate_main

    md = tmp_path / "report.md"
    md.write_text("# report\n<!-- planner_eval_train:start -->\n<!-- planner_eval_train:end -->\n")
    assert evaluate_main(["--checkpoint", str(res.checkpoint), "--data", str(demo_file), "--split", "train",
                          "--out", str(tmp_path / "ev"), "--threads", "1", "--readme", str(md),
                          "--section", "planner_eval_train", "--stem", "train_split"]) == 0
    report = json.loads((tmp_path / "ev" / "train_split.json").read_text())
    assert report["split"] == "train" and 0.0 <= report["result"]["detect"]["auroc"] <= 1.0
    section = md.read_text().split("<!-- planner_eval_train:start -->")[1].split("<!-- planner_eval_train:end -->")[0]
    assert "Success detection: AUROC" in section and str(res.checkpoint) in section
    assert "training demos" in section and "held-out" not in section  # it trained on them
    for bad in (["--stem", "../escape"], ["--section", "nowhere"]):  # refused before any evaluation
        with pytest.raises(SystemExit):
            evaluate_main(["--checkpoint", str(res.checkpoint), "--data", str(demo_file), "--readme", str(md), *bad])


def test_same_seed_same_weights(demo_file, tmp_path):
    a = train(_cfg(demo_file, tmp_path / "a.safetensors", max_epochs=1), progress=False, log=lambda *_: None)
    b = train(_cfg(demo_file, tmp_path / "b.safetensors", max_epochs=1), progress=False, log=lambda *_: None)
    wa, wb = load_file(a.checkpoint), load_file(b.checkpoint)
    assert all(torch.equal(wa[k], wb[k]) for k in wa)


def test_resumed_run_ends_with_the_weights_of_an_uninterrupted_one(demo_file, tmp_path):
    from tcot_hybrid.learning.train import resume_path, run_finished

    quiet = dict(progress=False, log=lambda *_: None)
    whole = train(_cfg(demo_file, tmp_path / "whole.safetensors", max_epochs=3), **quiet)
    out = tmp_path / "parts.safetensors"
    lines: list[str] = []
    # the time cap stops the first part after its first epoch: a checkpoint (best so far) and the training state
    train(_cfg(demo_file, out, max_epochs=3, max_minutes=1e-6), log=lines.append, progress=False)
    assert any("time cap" in x and "--resume" in x for x in lines) and resume_path(out).is_file()
    assert not run_finished(out)
    assert [json.loads(x)["epoch"] for x in out.with_suffix(".metrics.jsonl").read_text().splitlines()] == [1]
    # a stray metrics line of an epoch whose state was never saved (killed in between) is dropped on resume
    with out.with_suffix(".metrics.jsonl").open("a") as fh:
        fh.write(json.dumps({"epoch": 2, "stray": True}) + "\n")
    # a different config is refused, naming the field; max_minutes may change
    with pytest.raises(ConfigError, match=r"lr = 0.003.*lr = 0.001"):
        train(_cfg(demo_file, out, max_epochs=3, lr=1e-3), resume=True, **quiet)
    lines.clear()
    res = train(_cfg(demo_file, out, max_epochs=3, max_minutes=1e-6), resume=True, log=lines.append, progress=False)
    assert any("resumed" in x and "after epoch 1 of 3" in x for x in lines) and res.epochs == 2
    res = train(_cfg(demo_file, out, max_epochs=3), resume=True, **quiet)  # the rest
    recs = [json.loads(x) for x in out.with_suffix(".metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in recs] == [1, 2, 3] and not any(r.get("stray") for r in recs)
    wa, wb = load_file(whole.checkpoint), load_file(res.checkpoint)
    assert all(torch.equal(wa[k], wb[k]) for k in wa)  # same weights as the run that was never cut
    whole_recs = [json.loads(x) for x in (tmp_path / "whole.metrics.jsonl").read_text().splitlines()]
    assert [r["val"] for r in recs] == [r["val"] for r in whole_recs]
    # a finished run is not trained again, nor its checkpoint rewritten (its recorded training time stays)
    lines.clear()
    written = out.stat().st_mtime_ns
    again = train(_cfg(demo_file, out, max_epochs=3), resume=True, log=lines.append, progress=False)
    assert any("nothing left to train" in x for x in lines) and again.epochs == 3 and run_finished(out)
    assert out.stat().st_mtime_ns == written and not any("wrote" in x for x in lines) and again.metrics == res.metrics
    # ... but a finished run whose checkpoint was deleted writes it again from the saved best weights
    best = load_file(out)
    out.unlink()
    train(_cfg(demo_file, out, max_epochs=3), resume=True, **quiet)
    rewritten = load_file(out)
    assert rewritten.keys() == best.keys() and all(torch.equal(rewritten[k], best[k]) for k in best)
    assert len(out.with_suffix(".metrics.jsonl").read_text().splitlines()) == 3
    # the command line: --resume continues over an existing checkpoint without --overwrite
    assert cmd_train(["--data", str(demo_file), "--out", str(out), "--threads", "1", "--batch-size", "16",
                      "--max-epochs", "3", "--stage1-epochs", "1", "--patience", "10", "--val-max-frames", "64",
                      "--model.width", "8", "--no-bf16", "--resume"]) == 0


def test_resume_refuses_changed_data_and_unreadable_state(demo_file, tmp_path, camera):
    out = tmp_path / "r.safetensors"
    train(_cfg(demo_file, out, max_epochs=2, max_minutes=1e-6), progress=False, log=lambda *_: None)
    other = tmp_path / "more.hdf5"
    make_demo_file(other, camera, seeds=range(14), T=24)
    with pytest.raises(ConfigError, match=r"data = .*demos.hdf5.*more.hdf5"):
        train(_cfg(other, out, max_epochs=2), resume=True, progress=False, log=lambda *_: None)
    from tcot_hybrid.learning.train import resume_path

    # a state written before a config field existed (one added with the old behaviour as its default) resumes
    st = torch.load(resume_path(out), map_location="cpu", weights_only=True)
    saved = json.loads(st["config"])
    del saved["windows"]["segment_points"], saved["windows"]["global_path"]
    st["config"] = json.dumps(saved)
    torch.save(st, resume_path(out))
    lines = []
    train(_cfg(demo_file, out, max_epochs=2), resume=True, progress=False, log=lines.append)
    assert any("resumed" in x and "after epoch 1 of 2" in x for x in lines)
    resume_path(out).write_bytes(b"not a state")
    with pytest.raises(ConfigError, match="cannot read the training state.*delete it"):
        train(_cfg(demo_file, out, max_epochs=2), resume=True, progress=False, log=lambda *_: None)


def test_direct_kind_trains(demo_file, tmp_path, camera):
    cfg = _cfg(demo_file, tmp_path / "d.safetensors", kind="direct", max_epochs=2)
    assert cfg.model.kind == "direct"
    res = train(cfg, progress=False, log=lambda *_: None)
    assert "delta_cm_median" in res.metrics
    load_checkpoint(res.checkpoint, robot="panda", camera=camera, kind="direct")


def test_commanded_labels_come_from_the_recorded_waypoints(demo_file, tmp_path, camera):
    import shutil

    import h5py

    vocab = Vocabulary.build(instructions_of(demo_file))
    observed = TrajectoryWindowConfig(global_spacing="events")
    commanded = dataclasses.replace(observed, global_path="commanded")
    local = dataclasses.replace(observed, local_path="commanded")
    for w in (commanded, local):
        with pytest.raises(DatasetError, match="has no obs/tcp_target_pos .*windows.global_path or windows.local_path "
                                               "'commanded'"):
            load_frames(demo_file, "train", vocab, windows=w, max_tokens=24, direct_horizon=3)
    ahead = tmp_path / "ahead.hdf5"
    shutil.copy(demo_file, ahead)
    lead = np.array([0.0, 0.02, 0.0], np.float32)  # the command runs 2 cm ahead of the hand along y
    with h5py.File(ahead, "a") as h5:
        for g in h5["data"].values():
            g.create_dataset("obs/tcp_target_pos", data=g["obs/robot0_eef_pos"][:] + lead)
    a = load_frames(ahead, "train", vocab, windows=observed, max_tokens=24, direct_horizon=3)
    b = load_frames(ahead, "train", vocab, windows=commanded, max_tokens=24, direct_horizon=3)
    # same points, each 2 cm ahead (the float32 sum may move a path-length fraction onto the adjacent sample)
    same = ((b.g_xyz - torch.from_numpy(lead) - a.g_xyz).abs() < 1e-5).all(-1)
    assert same.float().mean() > 0.99
    assert not torch.allclose(b.g_uv, a.g_uv, atol=0.5)  # pixels through the demo's camera moved with them
    torch.testing.assert_close(b.g_z[same], a.g_z[same])  # a sideways lead leaves the heights
    torch.testing.assert_close(b.l_xyz, a.l_xyz)  # local labels stay the observed path
    c = load_frames(ahead, "train", vocab, windows=local, max_tokens=24, direct_horizon=3)
    torch.testing.assert_close(c.l_xyz, a.l_xyz + torch.from_numpy(lead))  # local_path: the same steps, 2 cm ahead
    torch.testing.assert_close(c.l_z, a.l_z)
    assert not torch.allclose(c.l_uv, a.l_uv, atol=0.5)
    torch.testing.assert_close(c.g_xyz, a.g_xyz)  # and the global labels stay observed


def test_shift_augmentation_moves_labels_with_pixels(demo_file):
    vocab = Vocabulary.build(instructions_of(demo_file))
    fs = load_frames(demo_file, "train", vocab, windows=TrainConfig().windows, max_tokens=24, direct_horizon=3)
    cfg = TrainConfig(data=str(demo_file))
    b = Batcher(fs, dataclasses.replace(cfg, augment=dataclasses.replace(cfg.augment, brightness=0.0, colour=0.0,
                                                                          shift_px=2)),
                np.random.default_rng(0))
    idx = np.arange(0, len(fs), 7)
    modes = np.zeros(len(idx), int)
    plain = b.batch(idx, modes, augment=False)
    aug = b.batch(idx, modes, augment=True)
    center = 25  # current step's point of the global window = the gripper disc in this frame

    def magenta_centroid(img):
        m = (img[0] > 0.8) & (img[1] < 0.3) & (img[2] > 0.75)
        ys, xs = np.nonzero(m.numpy())
        return np.array([xs.mean(), ys.mean()])
    moved = 0
    for i in range(len(idx)):
        d_img = magenta_centroid(aug["image"][i]) - magenta_centroid(plain["image"][i])
        d_lbl = (aug["uv"][i, center] - plain["uv"][i, center]).numpy()
        if np.all(np.abs(magenta_centroid(plain["image"][i]) - 64) < 55):  # away from the replicated border
            assert np.allclose(d_img, d_lbl, atol=0.5)
            moved += bool(np.any(d_lbl != 0))
    assert moved > 0


def test_detect_samples_are_balanced(demo_file):
    vocab = Vocabulary.build(instructions_of(demo_file))
    fs = load_frames(demo_file, "train", vocab, windows=TrainConfig().windows, max_tokens=24, direct_horizon=3)
    b = Batcher(fs, TrainConfig(data=str(demo_file)), np.random.default_rng(0))
    idx, modes = b.indices(4000, MixConfig(global_frac=0.0, local_frac=0.0, detect_frac=1.0))
    share = fs.success[idx].mean().item()
    assert 0.45 < share < 0.55 and fs.success.mean().item() < 0.2


def test_detect_negatives_skip_the_frames_just_before_success(demo_file):
    vocab = Vocabulary.build(instructions_of(demo_file))
    fs = load_frames(demo_file, "train", vocab, windows=TrainConfig().windows, max_tokens=24, direct_horizon=3)
    to_go = steps_to_success(fs)
    succ = fs.success.numpy() > 0.5
    assert np.all(to_go[succ] <= 0) and np.all(to_go[~succ] > 0)
    first = {d: fs.t[(fs.demo == d) & succ].min() for d in np.unique(fs.demo[succ])}
    i = np.flatnonzero(~succ)[0]
    assert to_go[i] == first[fs.demo[i]] - fs.t[i]
    cfg = TrainConfig(data=str(demo_file))
    every = Batcher(fs, cfg, np.random.default_rng(0)).neg_idx
    skip = Batcher(fs, dataclasses.replace(cfg, detect_ignore_before_success=3), np.random.default_rng(0)).neg_idx
    assert set(skip) == {j for j in every if to_go[j] > 3}
    assert 0 < len(every) - len(skip) <= 3 * len(first)
    with pytest.raises(ConfigError, match="detect_ignore_before_success"):
        TrainConfig(detect_ignore_before_success=-1)


def test_config_validation_and_files(tmp_path):
    with pytest.raises(ConfigError, match="sum to 1"):
        MixConfig(global_frac=0.5, local_frac=0.4, detect_frac=0.0)
    with pytest.raises(ConfigError, match="out must end"):
        TrainConfig(out="x.pt")
    with pytest.raises(ConfigError, match="kind"):
        TrainConfig(kind="diffusion")
    p = tmp_path / "t.yaml"
    p.write_text("max_epochs: 2\nmix_stage2: {global_frac: 0.5, local_frac: 0.25, detect_frac: 0.25}\n")
    assert load_train_config(p).mix_stage2.detect_frac == 0.25
    p.write_text("max_epoch: 2\n")
    with pytest.raises(ConfigError, match="unknown key"):
        load_train_config(p)
    p.write_text("lr: !!python/object/apply:os.system ['touch pwned']\n")
    with pytest.raises(ConfigError):
        load_train_config(p)
    assert not (tmp_path / "pwned").exists()


def test_example_train_configs_load_and_chain():
    """The shipped pipeline's configs are valid, and each round starts from the previous round's output."""
    root = Path(__file__).resolve().parent.parent / "examples" / "configs"
    stage2 = load_train_config(root / "train_stage2.yaml")
    round2 = load_train_config(root / "train_stage2_round2.yaml")
    assert stage2.init == "runs/train/stage1.safetensors" and round2.init == stage2.out
    assert set(stage2.online_data) < set(round2.online_data)  # round 2 adds data, drops none
    round4 = load_train_config(root / "train_stage2_round4.yaml")
    assert round4.init == round2.out and set(round2.online_data) < set(round4.online_data)
    round5 = load_train_config(root / "train_stage2_round5.yaml")
    assert round5.init == round4.out and set(round5.online_data) == set(round4.online_data)
    round6 = load_train_config(root / "train_stage2_round6.yaml")
    assert round6.init == round5.out and set(round6.online_data) == set(round5.online_data)
    assert round6.extra_data == ("data/demos_extra_panda.hdf5",) and round6.data == round5.data
    round8 = load_train_config(root / "train_stage2_round8.yaml")  # same data, event-spaced global windows
    assert round8.init == round6.out and round8.extra_data == round6.extra_data
    assert set(round8.online_data) == set(round6.online_data) and round8.windows.global_spacing == "events"
    # round 10: the detector alone, from round 8, on new strict-labelled data; same label windows as round 8
    round10 = load_train_config(root / "train_stage2_round10.yaml")
    assert round10.init == round8.out and round10.trainable == "detect" and round10.model.detect_head
    assert round10.windows == round8.windows and round10.model.readout_radius_cells == round8.model.readout_radius_cells
    # the shipped checkpoint is the last round's output, with that round's config
    shipped = json.loads((root.parent.parent / "tcot_hybrid" / "checkpoints" / "panda_default.json").read_text())
    assert shipped["train_config"]["out"] == round10.out
    assert shipped["model"]["readout_radius_cells"] == round10.model.readout_radius_cells
    assert shipped["model"]["detect_head"] is True
    assert windows_from_meta(shipped["windows"]) == round10.windows


def test_libero_configs_share_model_windows_and_height_reference():
    """The 50-per-task run (one resumable run from nothing) builds the same network as the two 400-demo runs."""
    root = Path(__file__).resolve().parent.parent / "examples" / "configs"
    first, ft, fifty = (load_train_config(root / f"train_libero{x}.yaml") for x in ("", "_finetune", "50"))
    assert ft.init == first.out and fifty.init is None and fifty.out not in (first.out, ft.out)
    for c in (ft, fifty):
        assert (c.model, c.windows, c.height_ref, c.data) == (first.model, first.windows, first.height_ref, first.data)
    assert fifty.epoch_samples and fifty.max_epochs * fifty.epoch_samples > 3 * ft.max_epochs * 8314
    # the 100-per-task run: the same network from nothing, at least as many samples as the shipped two runs together
    hundred, v2 = (load_train_config(root / f"train_libero{x}.yaml") for x in ("100", "_v2"))
    assert hundred.init is None and hundred.out not in (fifty.out, v2.out) and hundred.data != fifty.data
    assert (hundred.model, hundred.windows, hundred.height_ref) == (fifty.model, fifty.windows, fifty.height_ref)
    assert (hundred.max_epochs * hundred.epoch_samples
            >= fifty.max_epochs * fifty.epoch_samples + v2.max_epochs * v2.epoch_samples)


@pytest.mark.parametrize("suite, stem, base", [("libero_10", "10", "_v3"), ("libero_goal", "_goal97", "_v3"),
                                                ("libero_goal", "_goal", "_v2")])
def test_suite_models_continue_a_four_suite_model_on_their_suite_alone(suite, stem, base):
    root = Path(__file__).resolve().parent.parent / "examples" / "configs"
    four, own, v3 = (load_train_config(root / f"train_libero{x}.yaml") for x in (base, stem, "_v3"))
    assert own.suites == (suite,) and four.suites == ()
    assert own.init == four.out and own.out not in (four.out, four.init)
    assert (own.model, own.windows, own.height_ref) == (four.model, four.windows, four.height_ref)
    assert own.data == v3.data  # the demonstrations collected through the release


@pytest.mark.parametrize("suite, stems, window_change", [("libero_goal", ("_goal_corner", "_goal_stove_lit"), {}),
                                                          ("libero_10", ("10_100_corner", "10_100_more"), {"L_g": 97})])
def test_the_suites_corner_models_continue_the_shipped_four_suite_model_on_the_same_file(suite, stems, window_change):
    """libero_goal's and libero_10's shipped models are v12 (the shipped four-suite checkpoint, train_libero100_corner's
    output) continued on their suite's demonstrations of v12's own file, with v12's network, labels and height
    reference; libero_10's global window is widened to 97 points (its long tasks replay best from it); each suite's run
    is continued once more (libero_goal's with its stove knob's demonstrations recollected with the burner lit in
    place of the old ones), each run starting from the one before (``stems`` in order; the last is shipped)."""
    root = Path(__file__).resolve().parent.parent
    v12, *runs = (load_train_config(root / "examples" / "configs" / f"train_libero{x}.yaml")
                  for x in ("100_corner", *stems))
    assert v12.suites == () and runs[0].init == "tcot_hybrid/checkpoints/libero_panda_default.safetensors"
    for before, run in zip([None, *runs], runs):
        assert run.suites == (suite,) and run.data == v12.data
        assert (run.model, run.height_ref) == (v12.model, v12.height_ref)
        assert run.windows == dataclasses.replace(v12.windows, **window_change)
        if before is not None:
            assert run.init == before.out and run.out not in (before.out, before.init)
    shipped = {stem: json.loads((root / "tcot_hybrid" / "checkpoints" / f"libero_panda_{stem}.json").read_text())
               for stem in ("default", suite)}
    assert shipped["default"]["train_config"]["out"] == v12.out
    assert shipped[suite]["train_config"]["out"] == runs[-1].out
    assert shipped[suite]["vocabulary"] == shipped["default"]["vocabulary"]  # reads every suite's words


@pytest.mark.parametrize("name", ["suites", "extra_data", "online_data"])
def test_a_bare_string_for_a_list_field_is_refused(name):
    with pytest.raises(ConfigError, match=f"{name} must be a list.*write \\[x\\]"):
        TrainConfig(**{name: "x"})  # would otherwise be read as its letters


def test_extra_data_replaces_tasks_needs_extra_data():
    with pytest.raises(ConfigError, match="extra_data_replaces_tasks needs extra_data"):
        TrainConfig(extra_data_replaces_tasks=True)


def test_cmd_train_missing_data_is_clear(tmp_path):
    with pytest.raises(ConfigError, match="does not exist.*--collect"):
        cmd_train(["--data", str(tmp_path / "none.hdf5"), "--out", str(tmp_path / "x.safetensors")])


def test_auroc_and_lift_helpers(camera):
    assert auroc(np.array([0.1, 0.2, 0.8, 0.9]), np.array([0, 0, 1, 1])) == 1.0
    assert auroc(np.array([0.9, 0.8, 0.2, 0.1]), np.array([0, 0, 1, 1])) == 0.0
    assert auroc(np.array([0.5, 0.5]), np.array([0, 1])) == 0.5
    assert auroc(np.array([0.5]), np.array([1])) is None
    pts = np.array([[0.5, 0.1, 0.05], [0.4, -0.2, 0.3]])
    uv, _ = camera.project(pts)
    assert np.allclose(points_at_height(camera, uv, pts[:, 2]), pts, atol=1e-9)


@pytest.fixture(scope="module")
def online_file(tmp_path_factory, camera):
    """Online episodes: failed learned rollouts (seeds 20-25) and oracle recoveries (26-31) whose recovery
    starts at step 8."""
    path = tmp_path_factory.mktemp("online") / "online.hdf5"

    def episode(seed):
        if seed < 26:
            return {"source": "rollout", "planner": "learned", "success": False, "perturb": "object_moved",
                    "perturb_step": 5, "recover_step": -1}
        return {"perturb": "object_drop", "perturb_step": 5, "recover_step": 8}
    make_demo_file(path, camera, seeds=range(20, 32), T=24, episode=episode)
    return path


def test_online_frames_detect_everywhere_imitate_only_recoveries(online_file, demo_file):
    from tcot_hybrid.learning.data import concat_frames, load_online_frames

    vocab = Vocabulary.build(instructions_of(demo_file))
    kw = dict(windows=TrainConfig().windows, max_tokens=24, direct_horizon=3)
    on = load_online_frames(online_file, "train", vocab, frame_stride=3, **kw)
    seeds = {20, 30}  # validation seeds (seed % 10 == 0) stay out of the train split
    assert len(on.demos) == 12 - len(seeds)
    rollout = np.isin(on.demo, [i for i, n in enumerate(on.demos) if i < 5])  # demos of seeds 21-25
    assert not on.traj[rollout].any() and not on.success[torch.from_numpy(rollout)].any()
    assert set(on.t[rollout]) == set(range(0, 24, 3))  # every 3rd frame kept
    rec = ~rollout
    assert set(on.t[rec & on.traj]) == set(range(8, 18)) | {18, 21, 22, 23}  # dense where the recovery starts
    assert set(on.t[rec & ~on.traj]) == {0, 3, 6}
    assert set(on.t[rec & (on.success.numpy() > 0.5)]) == {21, 22, 23}  # success frames always kept
    demos = load_frames(demo_file, "train", vocab, **kw)
    both = concat_frames([demos, on])
    assert len(both) == len(demos) + len(on) and both.demos == demos.demos + on.demos
    assert both.demo.max() == len(both.demos) - 1 and both.traj[: len(demos)].all()
    b = Batcher(both, TrainConfig(data=str(demo_file)), np.random.default_rng(0))
    idx, modes = b.indices(2000, MixConfig(global_frac=0.5, local_frac=0.3, detect_frac=0.2))
    assert both.traj[idx[modes <= 1]].all()  # trajectories only from imitated frames
    assert (~both.traj[idx[modes == 2]]).any()  # detection also sees failed rollouts
    assert not both.online[: len(demos)].any() and both.online[len(demos):].all()
    share = both.online[idx[modes == 1]].mean()  # recovery_frac 0.6 + their share of the rest
    natural = (both.traj & both.online).sum() / both.traj.sum()
    assert abs(share - (0.6 + 0.4 * natural)) < 0.06


@pytest.fixture(scope="module")
def extra_demo_file(tmp_path_factory, camera):
    path = tmp_path_factory.mktemp("extra") / "extra.hdf5"
    make_demo_file(path, camera, seeds=range(40, 46), T=24)
    return path


def test_extra_demos_keep_every_kth_frame_with_whole_track_labels(extra_demo_file, demo_file):
    vocab = Vocabulary.build(instructions_of(demo_file))
    kw = dict(windows=TrainConfig().windows, max_tokens=24, direct_horizon=3)
    full = load_frames(extra_demo_file, "train", vocab, **kw)
    sparse = load_frames(extra_demo_file, "train", vocab, frame_stride=4, **kw)
    assert sparse.demos == full.demos and set(sparse.t) == set(range(0, 24, 4))  # t = 0 always kept
    rows = np.flatnonzero(full.t % 4 == 0)
    for name in ("g_uv", "g_z", "g_grip", "l_uv", "d_delta", "success"):  # labels from the whole track
        assert torch.equal(getattr(sparse, name), getattr(full, name)[rows]), name
    assert np.array_equal(sparse.demo, full.demo[rows]) and sparse.traj.all() and not sparse.online.any()


def test_stage2_finetune_from_checkpoint_with_extra_and_online_data(demo_file, extra_demo_file, online_file, tmp_path):
    first = train(_cfg(demo_file, tmp_path / "s1.safetensors", max_epochs=1, stage1_epochs=1),
                  progress=False, log=lambda *_: None)
    cfg = _cfg(demo_file, tmp_path / "s2.safetensors", max_epochs=1, stage1_epochs=0, init=str(first.checkpoint),
               extra_data=[str(extra_demo_file)], extra_frame_stride=4,  # a list, as YAML gives it
               online_data=(str(online_file),), epoch_samples=64,
               windows=TrajectoryWindowConfig(global_spacing="events"))  # as round 8: eq.-4 init, event labels
    logs = []
    res = train(cfg, progress=False, log=logs.append)
    assert any("initialised from" in line for line in logs)
    assert any(line.startswith(f"extra data {extra_demo_file}: 5 train demos / 30 frames") for line in logs)
    lines = [json.loads(x) for x in (tmp_path / "s2.metrics.jsonl").read_text().splitlines()]
    assert lines[0]["stage"] == 2 and lines[0]["train"]["detect"] > 0
    assert lines[0]["val"]["detect_frames"] > lines[0]["val"]["frames"]  # failed rollouts scored for detection
    meta = load_checkpoint(res.checkpoint).meta
    assert meta["online_data"] == [str(online_file)] and meta["init"] == str(first.checkpoint)
    assert meta["extra_data"] == [str(extra_demo_file)] and meta["data_hash"].count("+") == 2
    assert windows_from_meta(meta["windows"]) == cfg.windows
    with pytest.raises(ConfigError, match="init checkpoint .* has model"):
        train(_cfg(demo_file, tmp_path / "s3.safetensors", max_epochs=1, init=str(first.checkpoint),
                   model=ModelConfig(width=16)), progress=False, log=lambda *_: None)


def test_a_finetune_keeps_its_inits_vocabulary_and_refuses_words_it_lacks(demo_file, tmp_path, camera):
    """A suite's demonstrations alone continue a model trained on more instructions: the run keeps the init's word
    ids (every instruction it read still encodes as before); a word the init never saw is refused, named."""
    first = train(_cfg(demo_file, tmp_path / "v1.safetensors", max_epochs=1), progress=False, log=lambda *_: None)
    words = load_checkpoint(first.checkpoint).meta["vocabulary"]
    assert {"cube", "drawer"} <= set(words)
    one_task = tmp_path / "drawer.hdf5"
    make_demo_file(one_task, camera, seeds=range(12), T=24, instructions=("open the drawer",))
    assert "cube" not in Vocabulary.build(instructions_of(one_task, "train")).tokens
    res = train(_cfg(one_task, tmp_path / "v2.safetensors", max_epochs=1, stage1_epochs=0, init=str(first.checkpoint)),
                progress=False, log=lambda *_: None)
    assert load_checkpoint(res.checkpoint).meta["vocabulary"] == words
    new_word = tmp_path / "close.hdf5"
    make_demo_file(new_word, camera, seeds=range(12), T=24, instructions=("close the drawer",))
    with pytest.raises(ConfigError, match=r"has no word for \['close'\]"):
        train(_cfg(new_word, tmp_path / "v3.safetensors", max_epochs=1, init=str(first.checkpoint)),
              progress=False, log=lambda *_: None)


def test_a_longer_global_window_starts_from_a_shorter_windows_checkpoint(demo_file, tmp_path):
    ev = TrajectoryWindowConfig(global_spacing="events", L_g=25, points_per_segment=4)
    first = train(_cfg(demo_file, tmp_path / "w1.safetensors", max_epochs=1, windows=ev),
                  progress=False, log=lambda *_: None)
    logs = []
    wide = dataclasses.replace(ev, L_g=41)
    res = train(_cfg(demo_file, tmp_path / "w2.safetensors", max_epochs=1, stage1_epochs=0, windows=wide,
                     init=str(first.checkpoint)), progress=False, log=logs.append)
    assert any("global waypoints widened 25 -> 41" in line for line in logs)
    ck = load_checkpoint(res.checkpoint)
    assert ck.model.cfg.n_global == 41 and windows_from_meta(ck.meta["windows"]) == wide
    with pytest.raises(ConfigError, match="widening needs windows.global_spacing 'events', got 'time'"):
        train(_cfg(demo_file, tmp_path / "w3.safetensors", max_epochs=1, init=str(first.checkpoint),
                   windows=dataclasses.replace(wide, global_spacing="time")), progress=False, log=lambda *_: None)
    with pytest.raises(ConfigError, match="init checkpoint .* has model"):  # a shorter window is not a widening
        train(_cfg(demo_file, tmp_path / "w4.safetensors", max_epochs=1, init=str(first.checkpoint),
                   windows=dataclasses.replace(ev, L_g=21)), progress=False, log=lambda *_: None)


def test_bf16_without_native_support_trains_in_fp32_and_says_so(demo_file, tmp_path, monkeypatch):
    import tcot_hybrid.learning.train as train_mod

    monkeypatch.setattr(train_mod, "native_bf16", lambda torch: False)
    logs = []
    res = train(_cfg(demo_file, tmp_path / "b.safetensors", max_epochs=1, bf16=True), progress=False,
                log=logs.append)
    assert any("has no native bf16, so training runs in fp32" in line for line in logs)
    assert load_checkpoint(res.checkpoint).meta["bf16_used"] is False


def test_detect_only_finetune_leaves_every_plan_output_bit_identical(demo_file, online_file, tmp_path, camera):
    """``trainable: detect`` on a shared-head checkpoint: the new detect head starts as the old detector, training
    changes the detector's outputs, and every global/local output (waypoints, heights, gripper bits) stays the
    same bit for bit."""
    first = train(_cfg(demo_file, tmp_path / "s1.safetensors", max_epochs=2, stage1_epochs=1),
                  progress=False, log=lambda *_: None)
    before = load_checkpoint(first.checkpoint).model.eval()
    model_cfg = ModelConfig(width=8, detect_head=True)
    cfg = _cfg(demo_file, tmp_path / "det.safetensors", max_epochs=2, stage1_epochs=0, init=str(first.checkpoint),
               online_data=(str(online_file),), epoch_samples=64, lr=1e-2, trainable="detect", model=model_cfg,
               mix_stage2=MixConfig(global_frac=0.0, local_frac=0.0, detect_frac=1.0))
    logs = []
    res = train(cfg, progress=False, log=logs.append)
    assert any("detect head copied from its shared head" in line for line in logs)
    assert any(line.startswith("trainable: detect") for line in logs)
    after = load_checkpoint(res.checkpoint, robot="panda", camera=camera).model.eval()
    assert after.cfg.detect_head and not before.cfg.detect_head
    g = torch.Generator().manual_seed(0)
    img = torch.rand(4, 3, 128, 128, generator=g)
    tokens = torch.randint(2, after.cfg.vocab_size, (4, 24), generator=g)
    proprio = torch.randn(4, after.cfg.dof + 1, generator=g)
    with torch.no_grad():
        for mode in (0, 1):  # global, local: identical
            m = torch.full((4,), mode)
            a, b = after(img, tokens, m, proprio), before(img, tokens, m, proprio)
            for k in ("uv_px", "z_m", "grip_logit"):
                assert torch.equal(a[k], b[k]), (mode, k)
        m = torch.full((4,), 2)  # detect: trained
        assert not torch.equal(after(img, tokens, m, proprio)["success_logit"],
                               before(img, tokens, m, proprio)["success_logit"])
        # the copied head reproduces the shared head's detector exactly before any step
        fresh = PlannerNet(after.cfg)
        fresh.load_state_dict(before.state_dict(), strict=False)
        fresh.init_detect_head()
        fresh.eval()
        assert torch.allclose(fresh(img, tokens, m, proprio)["success_logit"],
                              before(img, tokens, m, proprio)["success_logit"], atol=1e-6)


def test_detect_only_finetune_config_is_checked(demo_file, tmp_path):
    with pytest.raises(ConfigError, match="trainable = 'frozen' is not valid; choose one of all, detect"):
        _cfg(demo_file, tmp_path / "x.safetensors", trainable="frozen")
    with pytest.raises(ConfigError, match=r"model.detect_head = False \(needs True\).*stage1_epochs = 1 \(needs 0\)"
                                          r".*mix_stage2.detect_frac = 0.2 \(needs 1.0\)"):
        _cfg(demo_file, tmp_path / "x.safetensors", trainable="detect", init="x.safetensors")
    with pytest.raises(ConfigError, match="set init"):
        _cfg(demo_file, tmp_path / "x.safetensors", trainable="detect", stage1_epochs=0,
             model=ModelConfig(width=8, detect_head=True),
             mix_stage2=MixConfig(global_frac=0.0, local_frac=0.0, detect_frac=1.0))
    with pytest.raises(ConfigError, match="model.detect_head needs model.kind 'trajectory'"):
        ModelConfig(kind="direct", detect_head=True)


def test_online_split_sizes_follow_the_seed_rule(online_file, tmp_path, camera):
    from tcot_hybrid.learning.data import online_split_size

    assert online_split_size(online_file, "train") == 10 and online_split_size(online_file, "valid") == 2
    one_seed = tmp_path / "one_seed.hdf5"  # one rollout per task at seed 200: the whole file is validation
    make_demo_file(one_seed, camera, seeds=[200], T=24)
    assert online_split_size(one_seed, "train") == 0 and online_split_size(one_seed, "valid") == 1
    with pytest.raises(DatasetError, match="split must be"):
        online_split_size(online_file, "test")
