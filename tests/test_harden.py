"""Hardening round 2 (issue 18; RELIABILITY.md rows 23-28): hostile and careless inputs that used to
crash, hang, eat memory or lose records. Each test failed on the code before the fix."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from tcot_hybrid.config import TIMING_BOUNDS_S, TimingConfig
from tcot_hybrid.errors import ConfigError, short_repr
from tcot_hybrid.run_config import MAX_CONFIG_BYTES, load_config_file

# --- row 23: resource bombs in input files -------------------------------------------------------------

PEAK_RSS_MB = 500
BOMB_SECONDS = 5.0
ERROR_CHARS = 2000


def alias_bomb() -> str:
    """The 422-byte config of issue 18: nine-fold aliases eight deep, 43 million list items expanded."""
    items = ["&a0 [x, x, x, x, x, x, x, x, x]"] + [
        f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 8)]
    return "task: goal_cube_on_plate\nseed: [" + ", ".join(items) + "]\n"


def bomb_files(tmp: Path) -> dict[str, Path]:
    """Every bomb of the row-23 test set, written to ``tmp``."""
    files = {
        "alias_bomb.yaml": alias_bomb(),
        "alias_bomb_mapping.yaml": "a0: &a0 {x: 1, y: 2}\n" + "".join(
            f"a{i}: &a{i} {{{', '.join(f'k{k}: *a{i - 1}' for k in range(10))}}}\n" for i in range(1, 9)),
        "flat_list_under_limit.yaml": "seed: [" + "1, " * (MAX_CONFIG_BYTES // 3 - 10) + "1]\n",
        "deep.yaml": "seed: " + "[" * 60_000 + "]" * 60_000 + "\n",
        "deep.json": '{"seed": ' + "[" * 100_000 + "]" * 100_000 + "}",
        "deep.toml": "seed = " + "[" * 100_000 + "]" * 100_000 + "\n",
        "long_string.yaml": "seed: " + "x" * (MAX_CONFIG_BYTES - 100) + "\n",
    }
    out = {}
    for name, text in files.items():
        (tmp / name).write_text(text)
        out[name] = tmp / name
    big = tmp / "fifty_mb.yaml"  # issue 18: a 50 MB config with a 25M-item list
    with big.open("w") as f:
        f.write("seed: [")
        chunk = "1, " * 100_000
        for _ in range(167):
            f.write(chunk)
        f.write("1]\n")
    out["fifty_mb.yaml"] = big
    return out


def _measure_load(path: Path) -> dict:
    """Load ``path`` in a fresh interpreter; its own peak RSS, load CPU time, error text."""
    code = textwrap.dedent(f"""
        import json, sys, time
        from tcot_hybrid.run_config import load_config_file
        from tcot_hybrid.errors import TcotError
        t0 = time.process_time()  # CPU seconds: wall time doubled on cores shared with other jobs (8.7 s)
        try:
            load_config_file({str(path)!r})
            err, kind = "", None
        except TcotError as exc:
            err, kind = str(exc), type(exc).__name__
        except BaseException as exc:
            err, kind = repr(exc)[:500], "CRASH:" + type(exc).__name__
        dt = time.process_time() - t0
        # VmHWM, not ru_maxrss: ru_maxrss keeps the forking parent's (pytest's) peak across exec
        hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:"))
        print(json.dumps({{"s": dt, "rss_mb": hwm / 1024,
                          "error": err[:100000], "error_len": len(err), "kind": kind}}))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


def test_row23_config_bombs_are_refused_early_with_bounded_memory_time_and_text(tmp_path):
    rows = []
    for name, path in bomb_files(tmp_path).items():
        m = _measure_load(path)
        rows.append((name, path.stat().st_size, m))
        assert m["kind"] == "ConfigError", (name, m)
        assert m["rss_mb"] <= PEAK_RSS_MB, (name, m["rss_mb"])
        assert m["s"] <= BOMB_SECONDS, (name, m["s"])
        assert m["error_len"] <= ERROR_CHARS, (name, m["error_len"])
        assert str(path) in m["error"]
    print("\nrow 23 bombs (file, bytes, peak RSS MB, load s, error chars):")
    for name, size, m in rows:
        print(f"  {name:28s} {size:>10d} {m['rss_mb']:7.0f} {m['s']:6.2f} {m['error_len']:5d}  {m['error'][:90]}")


def test_row23_alias_bomb_through_the_cli_is_short_and_fast(tmp_path):
    f = tmp_path / "bomb.yaml"
    f.write_text(alias_bomb())
    r = subprocess.run([sys.executable, "-m", "tcot_hybrid.cli", "run", "--config", str(f), "--out",
                        str(tmp_path / "o")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr) <= ERROR_CHARS and "expands to more than" in r.stderr


def test_short_repr_never_expands_shared_or_deep_values():
    x: list = [1, 2]
    for _ in range(8):
        x = [x] * 9  # 43M leaves, shared
    assert len(short_repr(x)) < 260
    deep: list = []
    for _ in range(100_000):
        deep = [deep]
    assert len(short_repr(deep)) < 260
    assert short_repr([1, "a", {"k": (2, 3)}]) == repr([1, "a", {"k": (2, 3)}])


def test_row23_error_echo_of_a_huge_value_is_bounded():
    with pytest.raises(ConfigError) as exc:
        TimingConfig(sim_dt=[1.0] * 1_000_000)  # type: ignore[arg-type]
    assert len(str(exc.value)) < 400


def test_duplicate_yaml_key_refused(tmp_path):
    f = tmp_path / "dup.yaml"
    f.write_text("seed: 1\ntask: goal_cube_in_bowl\nseed: 2\n")
    with pytest.raises(ConfigError, match=r"key 'seed' appears twice \(line 1 and line 3\)"):
        load_config_file(f)
    f.write_text("timing:\n  sim_dt: 0.002\n  sim_dt: 0.001\n")
    with pytest.raises(ConfigError, match="sim_dt' appears twice"):
        load_config_file(f)
    f.write_text("a: &x {seed: 1}\n")  # an anchor alone is fine syntax (then an unknown key)
    with pytest.raises(ConfigError, match="unknown key"):
        load_config_file(f)


def test_config_path_that_is_a_directory_or_device_is_named_as_such(tmp_path):
    with pytest.raises(ConfigError, match="is a directory"):
        load_config_file(tmp_path)
    with pytest.raises(ConfigError, match="not a regular file"):
        load_config_file("/dev/zero")
    with pytest.raises(ConfigError, match="does not exist"):
        load_config_file(tmp_path / "nope.yaml")


# --- row 26: physically absurd timings ----------------------------------------------------------------

@pytest.mark.parametrize("field", ["sim_dt", "ctrl_dt", "plan_dt"])
@pytest.mark.parametrize("value", [1e-300, 1e-7, 5.0, 1e6])
def test_row26_time_steps_out_of_range_refused_with_the_bound(field, value):
    kw = {"sim_dt": value, "ctrl_dt": value, "plan_dt": value}
    lo, hi = TIMING_BOUNDS_S["sim_dt"]
    with pytest.raises(ConfigError) as exc:
        TimingConfig(**kw)
    msg = str(exc.value)
    assert "sim_dt" in msg and f"[{lo:g}, {hi:g}]" in msg
    base = {"sim_dt": 0.002, "ctrl_dt": 0.01, "plan_dt": 0.1}
    base[field] = value
    lo, hi = TIMING_BOUNDS_S[field]
    with pytest.raises(ConfigError, match=field):
        TimingConfig(**base)


def test_row26_time_step_bounds_keep_the_defaults_and_the_tested_settings():
    TimingConfig()
    TimingConfig(sim_dt=0.001, ctrl_dt=0.002, plan_dt=0.1)
    TimingConfig(sim_dt=0.002, ctrl_dt=0.004, plan_dt=0.2)


# --- row 25: relabelled or mismatched checkpoints -----------------------------------------------------

def _copy_checkpoint(tmp: Path, stem: str = "panda_default") -> Path:
    from tcot_hybrid.learning.checkpoint import checkpoints_dir

    src = checkpoints_dir() / f"{stem}.safetensors"
    dst = tmp / src.name
    dst.write_bytes(src.read_bytes())
    dst.with_suffix(".json").write_text(src.with_suffix(".json").read_text())
    return dst


def _edit_meta(path: Path, edit, *, restamp: bool) -> None:
    from tcot_hybrid.learning.checkpoint import meta_path, stamp_metadata

    meta = json.loads(meta_path(path).read_text())
    edit(meta)
    meta_path(path).write_text(json.dumps(stamp_metadata(meta) if restamp else meta))


def _robot_copy(tmp: Path, bundled: str, name: str) -> Path:
    """The bundled robot's folder copied to ``tmp/<name>`` with ``name = <name>`` in its robot.toml."""
    from tcot_hybrid.robot import load_robot_spec

    spec = load_robot_spec(bundled)
    folder = tmp / f"{name}_from_{bundled}"
    folder.mkdir()
    toml = (spec.mjcf_path.parent / "robot.toml").read_text()
    (folder / "robot.toml").write_text(toml.replace(f'name = "{bundled}"', f'name = "{name}"'))
    (folder / spec.mjcf_path.name).write_text(spec.mjcf_path.read_text())
    return folder / "robot.toml"


@pytest.fixture()
def count_steps(monkeypatch):
    import tcot_hybrid.sim as sim_module

    steps: list[int] = []
    real = sim_module.Simulation.step1
    monkeypatch.setattr(sim_module.Simulation, "step1", lambda self: steps.append(1) or real(self))
    return steps


def test_row25_relabelled_checkpoint_refused_before_the_first_step(tmp_path, count_steps):
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.errors import CheckpointError
    from tcot_hybrid.run_config import RunConfig

    def relabel(meta):
        meta["robot"] = "ur5e"

    cases = {}
    for restamp in (False, True):  # edited by hand; edited and the metadata digest recomputed too
        folder = tmp_path / f"restamp_{restamp}"
        folder.mkdir()
        path = _copy_checkpoint(folder)
        _edit_meta(path, relabel, restamp=restamp)
        with pytest.raises(CheckpointError) as exc:
            EpisodeRunner(RunConfig(task="goal_cube_on_plate", robot="ur5e", planner="learned", checkpoint=str(path)))
        cases[restamp] = str(exc.value)
    assert "metadata_sha256" in cases[False]
    assert "model digest" in cases[True]
    assert not count_steps
    print(f"\nrow 25: relabelled: {cases[False][-120:]}\nrow 25: relabelled + re-hashed: {cases[True][-160:]}")


def test_row25_other_arm_named_panda_refused_same_arm_renamed_accepted(tmp_path, count_steps):
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.errors import CheckpointError
    from tcot_hybrid.run_config import RunConfig

    fake = _robot_copy(tmp_path, "ur5e", "panda")  # a UR5e whose robot.toml says "panda"
    with pytest.raises(CheckpointError, match="model digest"):
        EpisodeRunner(RunConfig(task="goal_cube_on_plate", robot=str(fake), planner="learned"))
    assert not count_steps
    same = _robot_copy(tmp_path, "panda", "my_panda")  # the Panda model under another name
    ck = _copy_checkpoint(tmp_path)
    EpisodeRunner(RunConfig(task="goal_cube_on_plate", robot=str(same), planner="learned", checkpoint=str(ck)))


def test_row25_network_shapes_checked_against_the_run(tmp_path):
    from tcot_hybrid.errors import CheckpointError
    from tcot_hybrid.learning.checkpoint import load_checkpoint
    from tcot_hybrid.robot import load_robot_spec, robot_model_digest

    path = _copy_checkpoint(tmp_path)
    ur5e = load_robot_spec("ur5e")

    def for_ur5e(meta):  # a careful relabelling: the digest of the UR5e model, hashes recomputed
        meta["robot"], meta["robot_model_digest"] = "ur5e", robot_model_digest(ur5e)

    _edit_meta(path, for_ur5e, restamp=True)
    with pytest.raises(CheckpointError, match="network takes 7 joints, robot 'ur5e' has 6"):
        load_checkpoint(path, robot_spec=ur5e)

    def image_size(meta):
        meta["camera"]["width"] = meta["camera"]["height"] = 96

    path = _copy_checkpoint(tmp_path)
    _edit_meta(path, image_size, restamp=True)
    with pytest.raises(CheckpointError, match="96x96 px but the network takes 128x128"):
        load_checkpoint(path)

    def windows(meta):
        meta["windows"]["L_g"] = 31

    path = _copy_checkpoint(tmp_path)
    _edit_meta(path, windows, restamp=True)
    with pytest.raises(CheckpointError, match="do not match the network"):
        load_checkpoint(path)


METADATA_CRASHES = {
    "200k-deep nested JSON": None,  # written raw below
    "windows as a list": lambda m: m.update(windows=[51, 4, 8, 2]),
    "vocabulary of ints": lambda m: m.update(vocabulary=list(range(len(m["vocabulary"])))),
    "vocabulary with None": lambda m: m["vocabulary"].__setitem__(3, None),
    "string where a number belongs (windows)": lambda m: m["windows"].update(L_g="fifty-one"),
    "string where a number belongs (model)": lambda m: m["model"].update(width="wide"),
    "camera K of strings": lambda m: m["camera"].update(K=[["a"] * 3] * 3),
    "camera width as a string": lambda m: m["camera"].update(width="128"),
    "robot as a list": lambda m: m.update(robot=["panda"]),
    "model as a list": lambda m: m.update(model=[1, 2]),
    "max_unknown_fraction a string": lambda m: m.update(max_unknown_fraction="half"),
    "global_spacing unknown": lambda m: m["windows"].update(global_spacing="sometimes"),
}


@pytest.mark.parametrize("restamp", [False, True])
def test_row25_metadata_crashes_become_checkpoint_errors(tmp_path, restamp):
    """Each used to escape as RecursionError / AttributeError / TypeError / ValueError (issue 18 item 7);
    with the digest recomputed the type checks themselves refuse it."""
    from tcot_hybrid.errors import CheckpointError
    from tcot_hybrid.learning.checkpoint import load_checkpoint, meta_path
    from tcot_hybrid.planners.learned import LearnedPlanner

    for what, edit in METADATA_CRASHES.items():
        path = _copy_checkpoint(tmp_path)
        if edit is None:
            meta_path(path).write_text('{"format": ' + "[" * 200_000 + "]" * 200_000 + "}")
        else:
            _edit_meta(path, edit, restamp=restamp)
        try:
            ck = load_checkpoint(path)
            LearnedPlanner(ck, None)  # type: ignore[arg-type]  # what the planner reads at construction
        except CheckpointError as exc:
            assert len(str(exc)) < ERROR_CHARS, what
            continue
        pytest.fail(f"{what}: accepted")


# --- row 24: output locations and records ----------------------------------------------------------------

@pytest.fixture()
def mount_tmpfs(tmp_path):
    """Mount a small tmpfs (a real full or read-only disk); skipped where mounting is not permitted."""
    import shutil as _sh

    mounted: list[Path] = []

    def mount(name: str, size: str = "1m", ro: bool = False) -> Path:
        d = tmp_path / name
        d.mkdir()
        opts = f"size={size}" + (",ro" if ro else "")
        if _sh.which("mount") is None or subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(d)],
                                                       capture_output=True).returncode != 0:
            pytest.skip("cannot mount a tmpfs here (needs root); the monkeypatched tests cover the same paths")
        mounted.append(d)
        return d

    yield mount
    for d in mounted:
        subprocess.run(["umount", "-l", str(d)], capture_output=True)


def _fill(folder: Path) -> None:
    """Fill the file system holding ``folder`` to the last byte."""
    with (folder / "filler").open("wb", buffering=0) as f:
        for size in (65536, 4096, 512, 1):
            try:
                while True:
                    f.write(b"\0" * size)
            except OSError:
                pass


def _record(n_events: int = 3) -> dict:
    return {"task": "t", "seed": 1, "success": True, "fault": None,
            "events": [{"t": i * 0.1, "kind": "gripper", "closed": bool(i % 2)} for i in range(n_events)]}


def test_row24_record_on_a_full_disk_keeps_the_previous_record(mount_tmpfs):
    from tcot_hybrid.episode import write_record
    from tcot_hybrid.errors import OutputError

    disk = mount_tmpfs("full", size="256k")
    path = write_record(_record(), disk)
    before = path.read_bytes()
    _fill(disk)
    with pytest.raises(OutputError, match="disk is full.*previous file is left as it was"):
        write_record(_record(n_events=20_000), disk)  # a much bigger record than the space left
    assert path.read_bytes() == before and json.loads(before)["success"] is True
    assert sorted(p.name for p in disk.iterdir()) == ["episode.json", "filler"]  # no temp file left
    (disk / "filler").unlink()
    path.unlink()
    _fill(disk)
    with pytest.raises(OutputError, match="disk is full"):
        write_record(_record(n_events=20_000), disk)
    assert not path.exists()  # never a 0-byte or cut-off record


def test_row24_atomic_write_failure_midway_leaves_old_file(tmp_path, monkeypatch):
    """Same as the full-disk test without a mount: the write fails after the bytes went out."""
    import errno
    import os

    import tcot_hybrid.jsonio as jsonio
    from tcot_hybrid.episode import write_record
    from tcot_hybrid.errors import OutputError

    path = write_record(_record(), tmp_path)
    before = path.read_bytes()

    def no_space(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(jsonio.os, "fsync", no_space)
    with pytest.raises(OutputError, match="disk is full"):
        write_record(_record(n_events=50), tmp_path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["episode.json"]


def test_row24_symlinked_record_is_replaced_never_followed(tmp_path):
    from tcot_hybrid.episode import write_record

    precious = tmp_path / "precious.txt"
    precious.write_text("do not overwrite")
    out = tmp_path / "run"
    out.mkdir()
    (out / "episode.json").symlink_to(precious)
    path = write_record(_record(), out)
    assert precious.read_text() == "do not overwrite"
    assert not path.is_symlink() and json.loads(path.read_text())["task"] == "t"


def _cli(argv: list[str], monkeypatch=None) -> tuple[int, str]:
    """Run ``tcot`` in-process; returns (exit code, stderr)."""
    import contextlib
    import io

    from tcot_hybrid.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            rc = main(argv)
        except SystemExit as exc:  # tyro/argparse usage errors
            rc = int(exc.code or 0)
    return rc, err.getvalue()


@pytest.fixture()
def no_episode(monkeypatch):
    """Fail the test if an episode is built (the output checks must come first)."""
    import tcot_hybrid.episode as episode

    def boom(*a, **k):
        raise AssertionError("an episode was built before the output location was checked")

    monkeypatch.setattr(episode.EpisodeRunner, "__init__", boom)


def test_row24_unusable_out_refused_before_the_episode(tmp_path, no_episode):
    afile = tmp_path / "afile"
    afile.write_text("")
    rc, err = _cli(["run", "--task", "goal_cube_on_plate", "--out", str(afile)])
    assert rc == 2 and "is an existing file, not a folder" in err
    assert afile.read_text() == ""
    out = tmp_path / "run"
    (out / "episode.json").mkdir(parents=True)
    rc, err = _cli(["run", "--task", "goal_cube_on_plate", "--out", str(out)])
    assert rc == 2 and "directory named episode.json" in err
    vdir = tmp_path / "v"
    vdir.mkdir()
    rc, err = _cli(["run", "--task", "goal_cube_on_plate", "--out", str(tmp_path / "ok"), "--video", str(vdir)])
    assert rc == 2 and "--video" in err and "is a directory" in err
    rc, err = _cli(["run", "--task", "goal_cube_on_plate", "--out", str(tmp_path / "ok"), "--video",
                    str(afile / "x.mp4")])
    assert rc == 2 and "--video folder" in err


def test_row24_read_only_and_full_outputs_refused_before_work(mount_tmpfs, no_episode, tmp_path):
    ro = mount_tmpfs("ro", ro=True)
    full = mount_tmpfs("full", size="128k")
    _fill(full)
    for where, why in ((ro, "read-only"), (full, "disk is full")):
        rc, err = _cli(["run", "--task", "goal_cube_on_plate", "--out", str(where / "run")])
        assert rc == 2 and why in err, err
        rc, err = _cli(["run", "--task", "goal_cube_on_plate", "--out", str(tmp_path / "ok"),
                        "--video", str(where / "v.mp4")])
        assert rc == 2 and "--video" in err and why in err, err
        rc, err = _cli(["eval", "--tasks", "goal_cube_on_plate", "--episodes", "1", "--out", str(where / "ev")])
        assert rc == 2 and why in err, err
        rc, err = _cli(["collect", "--tasks", "goal_cube_on_plate", "--episodes-per-task", "1", "--quiet",
                        "--out", str(where / "d.hdf5")])
        assert rc == 2 and why in err, err
        rc, err = _cli(["train", "--data", str(tmp_path / "none.hdf5"), "--out", str(where / "p.safetensors")])
        assert rc == 2 and why in err, err


def test_train_refuses_to_overwrite_a_checkpoint_without_flag(tmp_path):
    from tcot_hybrid.errors import OutputError
    from tcot_hybrid.learning.train_cli import check_train_out

    ck = tmp_path / "planner.safetensors"
    ck.write_bytes(b"trained")
    ck.with_suffix(".json").write_text("{}")
    rc, err = _cli(["train", "--data", str(tmp_path / "none.hdf5"), "--out", str(ck)])
    assert rc == 2 and "--overwrite" in err and ck.read_bytes() == b"trained"
    with pytest.raises(OutputError):
        check_train_out(ck, overwrite=False)
    check_train_out(ck, overwrite=True)  # allowed with the flag
    check_train_out(tmp_path / "new.safetensors", overwrite=False)
    rc, err = _cli(["train", "--data", str(tmp_path / "none.hdf5"), "--out", str(ck), "--overwrite"])
    assert rc == 2 and "none.hdf5" in err  # got past the overwrite check to the missing data


def test_collect_stops_cleanly_on_a_full_disk_keeping_its_demos(mount_tmpfs, tmp_path):
    from tcot_hybrid.data.collect import MIN_FREE_BYTES
    from tcot_hybrid.data.dataset import open_demos

    disk = mount_tmpfs("disk", size=f"{(MIN_FREE_BYTES + 6 * 2**20) // 1024}k")
    out = disk / "demos.hdf5"
    r = subprocess.run([sys.executable, "-m", "tcot_hybrid.cli", "collect", "--tasks", "goal_cube_on_plate",
                        "--episodes-per-task", "30", "--workers", "1", "--quiet", "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2, r.stderr[-2000:]
    assert "Traceback" not in r.stderr and len(r.stderr) < ERROR_CHARS
    assert "(nearly) full" in r.stderr and "re-run the same command to resume" in r.stderr
    with open_demos(out) as f:
        kept = len(f.demos)
    assert 0 < kept < 30
    print(f"\ncollect on a {disk} of {MIN_FREE_BYTES // 2**20 + 6} MiB: stopped after {kept} demos: "
          f"{r.stderr.strip()[:200]}")


def test_collect_write_error_is_a_dataset_error(tmp_path, monkeypatch):
    """An HDF5 write that fails anyway (the free-space check passed) stops with DatasetError, no more writes."""
    import errno

    import tcot_hybrid.data.collect as collect_mod
    from tcot_hybrid.errors import DatasetError
    from tcot_hybrid.run_config import RunConfig

    def failing(h5, rec, **kw):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(collect_mod, "write_demo", failing)
    with pytest.raises(DatasetError, match="writing a demo to .* failed.*resume"):
        collect_mod.collect(RunConfig(), tasks=["goal_cube_on_plate"], seeds=[0], out=tmp_path / "d.hdf5",
                            workers=1, progress=False)


def test_huge_video_and_planner_image_sizes_refused():
    from tcot_hybrid.scene import SceneConfig

    for kw in ({"video_width": 100_000}, {"video_height": 100_000}, {"planner_image_px": 100_000}):
        with pytest.raises(ConfigError, match=f"{next(iter(kw))} = 100000 px is above"):
            SceneConfig(**kw)
    rc, err = _cli(["run", "--task", "goal_cube_on_plate", "--scene.video-width", "100000", "--video", "/tmp/x.mp4"])
    assert rc == 2 and "Traceback" not in err


def test_nan_joint_data_caught_when_the_dataset_is_read(tmp_path):
    import h5py

    from tcot_hybrid.data.collect import collect
    from tcot_hybrid.data.dataset import open_demos
    from tcot_hybrid.errors import DatasetError
    from tcot_hybrid.run_config import RunConfig

    out = tmp_path / "d.hdf5"
    collect(RunConfig(), tasks=["goal_cube_on_plate"], seeds=[0], out=out, workers=1, progress=False)
    with h5py.File(out, "a") as h5:
        q = h5["data/demo_0/obs/robot0_joint_pos"]
        arr = q[()]
        arr[3, 2] = np.nan
        q[...] = arr
    with open_demos(out) as f, pytest.raises(DatasetError, match=r"demo_0/obs/robot0_joint_pos holds a non-finite value \(nan at sample 3\)"):
        f.read("demo_0")
    from tcot_hybrid.data.labels import TrajectoryWindowConfig
    from tcot_hybrid.learning.data import load_frames
    from tcot_hybrid.learning.vocab import Vocabulary

    with pytest.raises(DatasetError, match="non-finite"):
        load_frames(out, "all", Vocabulary.build(["put the cube on the plate"]), windows=TrajectoryWindowConfig(),
                    max_tokens=24, direct_horizon=4)


# --- smaller items -----------------------------------------------------------------------------------------

def test_one_line_summary_names_the_fault():
    from tcot_hybrid.cli import outcome

    assert outcome({"success": True, "fault": None}) == "SUCCESS"
    assert outcome({"success": False, "fault": None}) == "failure"
    assert outcome({"success": False, "fault": "sim_fault:mjWARN_BADQACC"}) == "FAULT sim_fault:mjWARN_BADQACC"


def test_sim_time_keeps_counting_after_mujoco_resets_a_diverged_state():
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0))
    s = r.stack
    r.settle()
    for _ in range(30):
        s.executor.tick()
    t_before = s.sim.time_s
    hand = s.sim.model.site_bodyid[s.sim.ee_site]
    s.sim.data.xfrc_applied[hand, :3] = [1e9, 0, 0]  # issue 18: a 1e9 N push
    for _ in range(5):
        s.executor.tick()
    assert s.sim.fault is not None
    ticks = 5 * r.cfg.timing.substeps * r.cfg.timing.sim_dt
    assert s.sim.data.time < t_before  # MuJoCo restarted its clock
    assert s.sim.time_s == pytest.approx(t_before + ticks, abs=1e-9)
    assert r.record(0.0)["sim_time_s"] == pytest.approx(t_before + ticks, abs=1e-4)


# --- row 26: physically absurd robot specs -----------------------------------------------------------------

def _edited_robot(tmp: Path, name: str, *, toml_edit=None, xml_edit=None) -> Path:
    folder = _robot_copy(tmp, "panda", name).parent
    if toml_edit:
        t = folder / "robot.toml"
        t.write_text(toml_edit(t.read_text()))
    if xml_edit:
        x = folder / "panda.xml"
        x.write_text(xml_edit(x.read_text()))
    return folder / "robot.toml"


@pytest.mark.parametrize("field, line, value", [
    ("v_max", "v_max = [2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]", "1e12"),
    ("a_max", "a_max = [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0]", "1e9"),
    ("j_max", "j_max = [7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0]", "1e15"),
    ("v_max", "v_max = [2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]", "1e-9"),
    ("kp", "kp = [400.0, 400.0, 400.0, 400.0, 400.0, 400.0, 400.0]", "1e12"),
    ("q_max", "q_max = [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973]", "1e6"),
])
def test_row26_absurd_spec_values_refused_with_the_bound(tmp_path, field, line, value):
    from tcot_hybrid.errors import RobotModelError
    from tcot_hybrid.robot import SPEC_BOUNDS, load_robot_spec

    def edit(text):
        assert line in text
        n = line.count(",") + 1
        return text.replace(line, f"{field} = [{', '.join([value] * n)}]")

    toml = _edited_robot(tmp_path, "absurd", toml_edit=edit)
    lo, hi, unit = SPEC_BOUNDS[field]
    with pytest.raises(RobotModelError) as exc:
        load_robot_spec(toml)
    assert field in str(exc.value) and f"[{lo:g}, {hi:g}] {unit}" in str(exc.value)


def test_row26_tau_max_beyond_any_arm_refused_even_with_a_matching_mjcf(tmp_path):
    """tau_max 1e9 with the MJCF motors' ctrlrange raised to match: torque saturation would be off."""
    import re

    from tcot_hybrid.errors import RobotModelError
    from tcot_hybrid.robot import load_robot_spec

    toml = _edited_robot(
        tmp_path, "strong",
        toml_edit=lambda t: t.replace("tau_max = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]",
                                      "tau_max = [1e9, 1e9, 1e9, 1e9, 1e9, 1e9, 1e9]"),
        xml_edit=lambda x: re.sub(r'(<motor[^>]*ctrlrange=")[^"]*(")', r"\g<1>-1e9 1e9\g<2>", x))
    with pytest.raises(RobotModelError, match=r"tau_max: joint 'joint1' has 1e\+09 N m, outside the sanity range"):
        load_robot_spec(toml)


# --- row 28: an arm that cannot reach part of the workspace --------------------------------------------------

def _short_panda(tmp: Path) -> Path:
    """The Panda mounted 30 cm further back (first joint body moved): the far half of the workspace is
    out of reach."""
    toml = _edited_robot(tmp, "short_panda", xml_edit=lambda x: x.replace(
        '<body name="link1" pos="0 0 0.333">', '<body name="link1" pos="-0.3 0 0.333">'))
    return toml.parent


def test_row28_robot_check_bundled_panda_reaches_the_workspace(tmp_path):
    from tcot_hybrid.robot_check import check_robot

    rep = check_robot("panda", tasks=["goal_cube_on_plate", "long_stack_three_blocks"], seeds=3, step_m=0.05,
                      png=tmp_path / "panda.png")
    assert rep["ok"] and rep["reachable_fraction"] >= 0.95
    assert {c["name"] for c in rep["checks"]} >= {"spec and MJCF", "Pinocchio vs MuJoCo", "gripper opening",
                                                  "finger actuators", "reach"}
    assert [t["task"] for t in rep["tasks"]] == ["goal_cube_on_plate", "long_stack_three_blocks"]
    assert all(t["reachable_fraction"] == 1.0 for t in rep["tasks"])
    assert (tmp_path / "panda.png").stat().st_size > 10_000


def test_row28_short_reach_arm_mapped_warned_before_stepping_and_named_in_the_record(tmp_path):
    from tcot_hybrid.robot_check import check_robot

    folder = _short_panda(tmp_path)
    rep = check_robot(folder, tasks=["object_red_cube_in_basket"], seeds=4, step_m=0.05, png=None)
    assert rep["ok"]  # a usable robot, with a reach warning
    assert 0.2 < rep["reachable_fraction"] < 0.8
    reach = next(c for c in rep["checks"] if c["name"] == "reach")
    assert not reach["ok"] and reach["severity"] == "warning"
    assert rep["tasks"][0]["reachable_fraction"] < 1.0
    print(f"\nrow 28: short-reach panda: reachable_fraction {rep['reachable_fraction']}, "
          f"object_red_cube_in_basket {rep['tasks'][0]}")
    # the run: warned before the first step, the unreachable grasp named in the record
    out = tmp_path / "run"
    steps: list = []
    import tcot_hybrid.sim as sim_module

    real = sim_module.Simulation.step1

    def counting(self):
        if not steps:  # what `tcot run` had printed to stderr when the first physics step came
            steps.append(sys.stderr.getvalue())
        real(self)

    sim_module.Simulation.step1 = counting
    try:
        rc, _ = _cli(["run", "--robot", str(folder), "--task", "object_red_cube_in_basket", "--seed", "3",
                      "--out", str(out)])
    finally:
        sim_module.Simulation.step1 = real
    assert rc == 0
    assert "warning: robot 'short_panda' cannot reach the grasp point" in steps[0]  # printed before stepping
    assert f"tcot robot check {folder}" in steps[0]
    rec = json.loads((out / "episode.json").read_text())
    kinds = [e["kind"] for e in rec["events"]]
    assert not rec["success"] and "unreachable_target" in kinds and "unreachable_grasp" in kinds
    assert kinds.index("unreachable_target") < kinds.index("gripper")


def test_robot_check_cli_json_and_exit_codes(tmp_path):
    r = subprocess.run([sys.executable, "-m", "tcot_hybrid.cli", "robot", "check", "ur5e", "--json", "--tasks",
                        "goal_cube_in_bowl", "--seeds", "2", "--step", "0.1", "--png", str(tmp_path / "u.png")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-1000:]
    rep = json.loads(r.stdout)
    assert 0.0 <= rep["reachable_fraction"] <= 1.0 and rep["tasks"][0]["task"] == "goal_cube_in_bowl"
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "robot.toml").write_text('name = "bad"\n')
    r = subprocess.run([sys.executable, "-m", "tcot_hybrid.cli", "robot", "check", str(bad), "--png", "none"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and "[FAIL] spec and MJCF" in r.stdout and "missing key" in r.stdout


def test_robot_check_gripper_findings(tmp_path):
    """Pads in a child body of the finger, a second finger actuator, a short opening: each named."""
    from tcot_hybrid.robot import load_robot_spec
    from tcot_hybrid.robot_check import gripper_checks

    spec = load_robot_spec("panda")
    xml = spec.mjcf_path.read_text()
    assert 'range="0 0.04"' in xml
    short = _edited_robot(tmp_path, "narrow", xml_edit=lambda x: x.replace('range="0 0.04"', 'range="0 0.015"')
                          .replace('ctrlrange="0 0.04"', 'ctrlrange="0 0.015"'),
                          toml_edit=lambda t: t.replace("gripper_open = 0.04", "gripper_open = 0.015"))
    checks = {c.name: c for c in gripper_checks(load_robot_spec(short))}
    assert not checks["gripper opening"].ok and "3.0 cm" in checks["gripper opening"].detail
    two = _edited_robot(tmp_path, "two", xml_edit=lambda x: x.replace(
        "</actuator>", '  <position name="finger2_drive" joint="finger_joint2" ctrlrange="0 0.04" kp="100"/>\n'
                       "  </actuator>"))
    checks = {c.name: c for c in gripper_checks(load_robot_spec(two))}
    assert not checks["finger actuators"].ok and "finger2_drive" in checks["finger actuators"].detail
    lib = {c.name: c for c in gripper_checks(load_robot_spec("libero_panda"))}  # mirrored actuator, pads in tip bodies
    assert lib["finger actuators"].ok
    pads = [c for n, c in lib.items() if n.startswith("finger pads")]
    assert len(pads) == 2 and all(c.ok for c in pads)


def test_compute_home_handles_continuous_joints(tmp_path):
    """A wrist with no range (continuous) used to be clamped to 0 and the pose missed."""
    import re

    from tcot_hybrid.robot import load_robot_spec
    from tcot_hybrid.robots.compute_home import solve_home

    spec = load_robot_spec("ur5e")
    xml = spec.mjcf_path.read_text()
    xml2 = re.sub(r'(<joint name="wrist_3_joint"[^>]*?) range="[^"]*"', r"\1", xml)
    assert xml2 != xml
    mjcf = tmp_path / "ur5e.xml"
    mjcf.write_text(xml2)
    seed = np.array(spec.home_q) + 0.3
    seed[-1] = 2.5  # the continuous joint starts far from 0
    q, pe, re_ = solve_home(mjcf, list(spec.arm_joints), spec.ee_site, seed, np.array([0.45, 0.0, 0.35]))
    assert pe < 1e-3 and re_ < 1e-2
    assert -np.pi <= q[-1] < np.pi


def test_eval_records_keep_every_event_tcot_run_keeps():
    """`tcot eval` used to drop gripper, plan_adopted and slow_arrival events (a failure then needed a re-run)."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.evaluation import Job, run_job
    from tcot_hybrid.run_config import RunConfig

    cfg = RunConfig(task="goal_cube_on_plate", seed=1000)
    rec = run_job(Job(cfg))
    run_rec = EpisodeRunner(cfg).run()
    kinds = [e["kind"] for e in rec["events"]]
    assert {"gripper", "plan_adopted"} <= set(kinds)
    assert kinds == [e["kind"] for e in run_rec["events"]]
