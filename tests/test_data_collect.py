"""``tcot collect`` and the demo reader: layout, invariants, resume, interrupted writes, corrupt files."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import dataclasses  # noqa: E402
import json
import shutil

import h5py
import numpy as np
import pytest

from tcot_hybrid.cli import main
from tcot_hybrid.data.collect import _check_env, collect, write_demo, write_masks
from tcot_hybrid.data.dataset import DemoFile, is_valid_seed, open_demos
from tcot_hybrid.errors import ConfigError, DatasetError
from tcot_hybrid.run_config import RunConfig

TASK = "goal_cube_on_plate"  # short (~5 s simulated) and reliable


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """one.hdf5: seed 0; two.hdf5: one.hdf5 resumed with seeds 0 and 1 (only seed 1 collected)."""
    d = tmp_path_factory.mktemp("demos")
    one, two = d / "one.hdf5", d / "two.hdf5"
    s1 = collect(RunConfig(), tasks=[TASK], seeds=[0], out=one, workers=1, progress=False)
    shutil.copy(one, two)
    s2 = collect(RunConfig(), tasks=[TASK], seeds=[0, 1], out=two, workers=1, progress=False)
    return one, two, s1, s2


def test_layout_and_invariants(files):
    one, _, s1, _ = files
    assert s1.written == 1 and s1.requested == 1
    with open_demos(one) as f:
        assert f.demos == ["demo_0"]
        info = f.info("demo_0")
        assert (info.task, info.seed, info.source, info.planner, info.mode, info.perturb) == (
            TASK, 0, "demo", "oracle", "global", "none")
        assert info.success and 0 < info.t_success < info.num_samples
        a = f.read("demo_0")
        T = info.num_samples
        assert a[f.image_key].shape == (T, 128, 128, 3) and a[f.image_key].dtype == np.uint8
        assert a["obs/robot0_joint_pos"].shape == (T, 7)
        # the exact pixel is the projection of the TCP through the file's camera
        cam = f.camera_model()
        uv, depth = cam.project(a["obs/robot0_eef_pos"].astype(float))
        np.testing.assert_allclose(a["obs/eef_uv_px"], uv, atol=1e-3)
        np.testing.assert_allclose(a["obs/eef_depth_m"], depth, atol=1e-5)
        assert cam.in_image(uv).all()
        # actions: next TCP position minus this one, then the next gripper command; last row holds
        act = a["actions"]
        np.testing.assert_allclose(act[:-1, :3], np.diff(a["obs/robot0_eef_pos"], axis=0), atol=1e-6)
        np.testing.assert_array_equal(act[:-1, 3], a["obs/robot0_gripper_closed"][1:])
        assert np.all(act[-1, :3] == 0)
        # success: t_success is the first true sample, and the demo ends with 5 steps past it
        succ = a["task_success"]
        assert succ[info.t_success] == 1 and not succ[:info.t_success].any()
        assert T - 1 - info.t_success == 5
        # a pick-and-place closes and reopens the gripper
        g = a["obs/robot0_gripper_closed"]
        assert g[0] == 0 and g.max() == 1
        np.testing.assert_allclose(np.linalg.norm(a["obs/robot0_eef_quat"], axis=1), 1, atol=1e-5)
        # the commanded waypoint: the TCP itself before the first plan, then waypoints the hand follows
        tgt, eef = a["obs/tcp_target_pos"], a["obs/robot0_eef_pos"]
        assert tgt.shape == (T, 3) and tgt.dtype == np.float32
        np.testing.assert_array_equal(tgt[0], eef[0])
        gap = np.linalg.norm(tgt - eef, axis=1)
        assert np.median(gap) < 0.05 and gap[1:].min() < 1e-3  # leads the hand by a waypoint, reached at stops
        assert len({tuple(p) for p in tgt}) > 5  # a path of waypoints, not one point
        assert len({im.tobytes() for im in a[f.image_key][::10]}) > 1  # the video changes
        # env args: one camera and config per file
        env = f.env_args
        assert env["robot"] == "panda" and env["camera"] == "agentview" and env["width"] == 128
        assert (env["sim_dt"], env["ctrl_dt"], env["plan_dt"]) == (0.002, 0.01, 0.1)
        assert f.mask("valid") == ["demo_0"] and f.mask("train") == []  # seed 0 % 10 == 0


def test_resume_adds_only_missing_and_keeps_rest_bit_identical(files):
    one, two, _, s2 = files
    assert s2.already_present == 1 and s2.written == 1
    with open_demos(one) as a, open_demos(two) as b:
        assert b.demos == ["demo_0", "demo_1"]
        assert [(i.task, i.seed) for i in b.infos()] == [(TASK, 0), (TASK, 1)]
        ra, rb = a.read("demo_0"), b.read("demo_0")
        assert ra.keys() == rb.keys()
        for k in ra:
            assert ra[k].tobytes() == rb[k].tobytes(), k
        assert a.info("demo_0") == b.info("demo_0")
        assert b.mask("train") == ["demo_1"] and b.mask("valid") == ["demo_0"]
    again = collect(RunConfig(), tasks=[TASK], seeds=[0, 1], out=two, workers=1, progress=False)
    assert again.written == 0 and again.already_present == 2


def test_failed_demo_kept_but_not_in_masks(files, tmp_path):
    _, two, _, _ = files
    p = tmp_path / "f.hdf5"
    shutil.copy(two, p)
    with open_demos(p) as f:
        arrays = f.read("demo_1")
        attrs = dataclasses.asdict(f.info("demo_1"))
    attrs.pop("name")
    attrs.update(seed=11, success=False, t_success=-1)
    from tcot_hybrid.data.collect import DemoRecord
    with h5py.File(p, "a") as h5:
        name = write_demo(h5, DemoRecord(attrs, arrays, {}, 0.0))
        write_masks(h5)
    with open_demos(p) as f:
        assert name in f.demos and not f.info(name).success
        assert name not in f.mask("train") + f.mask("valid")


def test_interrupted_write_is_refused_then_cleaned_on_resume(files, tmp_path):
    _, two, _, _ = files
    p = tmp_path / "i.hdf5"
    shutil.copy(two, p)
    with h5py.File(p, "a") as h5:  # what an interrupt in the middle of a demo leaves behind
        g = h5["data"].create_group("_partial_2")
        g.create_dataset("actions", data=np.zeros((3, 4), np.float32))
    with pytest.raises(DatasetError, match="incomplete") as e:
        open_demos(p)
    assert str(p) in str(e.value)
    s = collect(RunConfig(), tasks=[TASK], seeds=[0, 1], out=p, workers=1, progress=False)
    assert s.written == 0
    with open_demos(p) as f:
        assert f.demos == ["demo_0", "demo_1"]


def test_truncated_file_gives_clear_error(files, tmp_path, capsys):
    _, two, _, _ = files
    data = two.read_bytes()
    for cut in (len(data) // 2, len(data) - 2000):
        p = tmp_path / f"cut{cut}.hdf5"
        p.write_bytes(data[:cut])
        with pytest.raises(DatasetError) as e:
            with open_demos(p) as f:
                f.verify()
        assert str(p) in str(e.value)
        # the CLI reports it as one line, exit code 2, no traceback
        assert main(["collect", "--tasks", TASK, "--episodes-per-task", "1", "--workers", "1", "--quiet",
                     "--out", str(p)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: demo file") and str(p) in err and "Traceback" not in err


def test_missing_dataset_and_bad_attrs_named(files, tmp_path):
    _, two, _, _ = files
    p = tmp_path / "m.hdf5"
    shutil.copy(two, p)
    with h5py.File(p, "a") as h5:
        del h5["data/demo_1/obs/eef_uv_px"]
    with pytest.raises(DatasetError, match="demo_1.*eef_uv_px") as e:
        open_demos(p)
    assert str(p) in str(e.value)
    q = tmp_path / "fmt.hdf5"
    shutil.copy(two, q)
    with h5py.File(q, "a") as h5:
        h5.attrs["format"] = "something-else"
    with pytest.raises(DatasetError, match="format"):
        open_demos(q)
    r = tmp_path / "shape.hdf5"
    shutil.copy(two, r)
    with h5py.File(r, "a") as h5:
        del h5["data/demo_0/actions"]
        h5["data/demo_0"].create_dataset("actions", data=np.zeros((3, 4), np.float32))
    with pytest.raises(DatasetError, match="actions.*shape"):
        open_demos(r)
    with pytest.raises(DatasetError, match="does not exist"):
        open_demos(tmp_path / "nope.hdf5")
    t = tmp_path / "text.hdf5"
    t.write_text("not hdf5")
    with pytest.raises(DatasetError, match="cannot be opened"):
        open_demos(t)


def test_one_robot_and_camera_per_file(files):
    one, _, _, _ = files
    with open_demos(one) as f:
        env = dict(f.env_args)
    with h5py.File(one, "r") as h5:
        _check_env(one, h5, env)  # same settings: fine
        with pytest.raises(DatasetError, match="robot"):
            _check_env(one, h5, {**env, "robot": "ur5e"})
        with pytest.raises(DatasetError, match="config_hash"):
            _check_env(one, h5, {**env, "config_hash": "0000"})


def test_split_rule_and_seed_guard(tmp_path):
    assert [s for s in range(25) if is_valid_seed(s)] == [0, 10, 20]
    with pytest.raises(ConfigError, match="evaluation"):
        from tcot_hybrid.data.collect import cmd_collect
        cmd_collect(["--tasks", TASK, "--seed-start", "990", "--episodes-per-task", "20", "--out",
                     str(tmp_path / "x.hdf5")])
    assert not (tmp_path / "x.hdf5").exists()


def test_reader_exposes_env_json(files):
    one, _, _, _ = files
    with h5py.File(one, "r") as h5:
        env = json.loads(h5["data"].attrs["env_args"])
    assert np.asarray(env["K"]).shape == (3, 3) and np.asarray(env["T_world_cam"]).shape == (4, 4)
    with DemoFile(one) as f:
        assert isinstance(f.dof, int)


def test_collection_that_stopped_before_its_first_demo_resumes(tmp_path):
    p = tmp_path / "empty.hdf5"
    with h5py.File(p, "w") as h5:  # what a run killed before its first demo leaves
        h5.attrs["format"] = "tcot-demos-v1"
        h5.create_group("data").attrs["total"] = 0
    with pytest.raises(DatasetError, match="env_args"):
        open_demos(p)
    s = collect(RunConfig(), tasks=[TASK], seeds=[3], out=p, workers=1, progress=False)
    assert s.written == 1
    with open_demos(p) as f:
        assert [(i.task, i.seed) for i in f.infos()] == [(TASK, 3)] and f.mask("train") == ["demo_0"]


def test_append_with_other_settings_refused_before_any_episode(files, tmp_path):
    one, _, _, _ = files
    p = tmp_path / "o.hdf5"
    shutil.copy(one, p)
    before = p.read_bytes()
    with pytest.raises(DatasetError, match="robot"):
        collect(RunConfig(robot="ur5e"), tasks=[TASK], seeds=[5], out=p, workers=1, progress=False)
    with pytest.raises(DatasetError, match="config_hash"):
        collect(dataclasses.replace(RunConfig(), controller="joint_pd"), tasks=[TASK], seeds=[5], out=p, workers=1,
                progress=False)
    with open_demos(p) as f:
        assert f.demos == ["demo_0"]
    assert p.read_bytes() == before  # not touched


def test_perturbed_episodes_record_when_the_recovery_starts(tmp_path):
    """One file holds one episode per (task, seed, perturbation); the perturbation step and the first plan
    made after it (the start of the recovery) are demo attributes."""
    import dataclasses as dc

    from tcot_hybrid.supervision import SupervisorConfig

    cfg = dc.replace(RunConfig(), supervisor=SupervisorConfig(mode="local", t_l=8))
    path = tmp_path / "rec.hdf5"
    s = collect(cfg, tasks=[TASK], seeds=[3], out=path, workers=1, progress=False,
                perturbs=["none", "object_moved"])
    assert s.written == 2
    again = collect(cfg, tasks=[TASK], seeds=[3], out=path, workers=1, progress=False,
                    perturbs=["none", "object_moved"])
    assert again.written == 0 and again.already_present == 2  # resumable per (task, seed, perturbation)
    with open_demos(path) as f:
        by = {i.perturb: i for i in f.infos()}
    assert by["none"].perturb_step == -1 and by["none"].recover_step == -1
    moved = by["object_moved"]
    assert moved.perturb_step == 5 and moved.recover_step == 8  # local plans every 8 steps
    assert moved.success


def test_collect_refuses_unknown_perturbation(tmp_path, capsys):
    rc = main(["collect", "--tasks", TASK, "--perturb", "earthquake", "--episodes-per-task", "1",
               "--out", str(tmp_path / "x.hdf5")])
    err = capsys.readouterr().err
    assert rc != 0 and "earthquake" in err and "object_moved" in err
    assert not (tmp_path / "x.hdf5").exists()


def test_image_every_renders_only_every_kth_sample_and_loaders_skip_the_rest(tmp_path):
    """LIBERO frames cost 28-80 ms: --image-every renders every k-th sample and the last; the others keep their
    state and track, marked in obs/image_valid, and never become training frames."""
    from tcot_hybrid.learning.data import load_frames
    from tcot_hybrid.data.labels import TrajectoryWindowConfig
    from tcot_hybrid.learning.vocab import Vocabulary

    p = tmp_path / "sparse.hdf5"
    collect(RunConfig(), tasks=[TASK], seeds=[0, 1], out=p, workers=1, progress=False, image_every=4)
    with DemoFile(p) as f:
        name = f.mask("train")[0]
        valid = f.image_valid(name)
        T = f.info(name).num_samples
        expect = (np.arange(T) % 4 == 0)
        expect[-1] = True
        np.testing.assert_array_equal(valid, expect)
        images = f.images(name)
        assert images[~valid].max() == 0 and all(images[t].max() > 0 for t in np.flatnonzero(valid))
        track = f.read(name, ["obs/eef_uv_px"])["obs/eef_uv_px"]
        assert np.isfinite(track).all() and len(track) == T  # labels still see the whole track
        instr = f.info(name).instruction
    frames = load_frames(p, "all", Vocabulary.build([instr]), windows=TrajectoryWindowConfig(), max_tokens=16,
                         direct_horizon=4, frame_stride=2)
    assert len(frames) > 0 and all(t % 4 == 0 or t == T - 1 for t in frames.t[frames.demo == 0])
    assert frames.images.reshape(len(frames), -1).max(dim=1).values.min() > 0  # no black frame is trained on
    with pytest.raises(ConfigError, match="image_every"):
        collect(RunConfig(), tasks=[TASK], seeds=[0], out=tmp_path / "bad.hdf5", workers=1, progress=False,
                image_every=0)
