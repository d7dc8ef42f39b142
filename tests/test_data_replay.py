"""Label replay: a demo's own eq.-4 label (t = 0, every n_g steps) must solve the task as a frozen plan.

This is the ceiling of frozen-global imitation; the tool task's hook clearance is sized by it.
"""
import dataclasses

import numpy as np
import pytest

from tcot_hybrid.data.collect import collect
from tcot_hybrid.data.replay import LabelReplayPlanner, ReplayConfig, cmd_replay, markdown, replay_file
from tcot_hybrid.errors import ConfigError, DatasetError, PlanningError
from tcot_hybrid.planners.base import Observation
from tcot_hybrid.run_config import RunConfig

TOOL = "tool_pull_cube_with_stick"


@pytest.fixture(scope="module")
def tool_demos(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "tool.hdf5"
    collect(RunConfig(), tasks=[TOOL], seeds=[1, 2], out=path, workers=1, progress=False)
    return path


def test_tool_label_replays_successfully(tool_demos):
    """At the old 1.5 cm hook clearance this failed for every demo (the sampled track cuts the corner)."""
    report = replay_file(tool_demos, workers=1, progress=False)
    assert report["per_task"][TOOL] == {"demos": 2, "successes": 2, "success_rate": 1.0}
    assert all(r["fault"] is None for r in report["demos"])
    assert sorted((r["task"], r["seed"]) for r in report["demos"]) == [(TOOL, 1), (TOOL, 2)]


def test_noise_is_seeded_and_changes_the_plan(tool_demos):
    from tcot_hybrid.data.dataset import open_demos
    from tcot_hybrid.data.labels import TRACK_KEYS, track_from_arrays
    from tcot_hybrid.episode import build_stack

    with open_demos(tool_demos) as f:
        name = f.demos[0]
        tr = track_from_arrays(f.read(name, TRACK_KEYS))
    camera = build_stack(RunConfig(task=TOOL)).camera
    obs = Observation(step=0, image=None, depth_m=None, q=np.zeros(7), gripper_closed=False, instruction="")

    def plan(cfg, seed=1):
        return LabelReplayPlanner(tr, camera, config=cfg, demo_seed=seed).plan(obs, mode="global")

    exact = plan(ReplayConfig())
    w = ReplayConfig().windows
    assert len(exact.uv_px) == w.L_g // 2 + 1
    np.testing.assert_allclose(exact.uv_px[1], tr.uv_px[w.n_g], atol=1e-5)  # point k is sample k * n_g
    events = plan(ReplayConfig(windows=dataclasses.replace(w, global_spacing="events")))
    switch = int(np.flatnonzero(tr.gripper_closed)[0])  # the grasp: first sample with the gripper closed
    per = w.points_per_segment
    np.testing.assert_allclose(events.uv_px[per], tr.uv_px[switch], atol=1e-5)  # the first piece ends on it
    assert events.gripper_closed[per] and not events.gripper_closed[:per].any()
    noisy = ReplayConfig(noise_px=1.0)
    np.testing.assert_array_equal(plan(noisy).uv_px, plan(noisy).uv_px)
    assert not np.allclose(plan(noisy).uv_px, exact.uv_px)
    assert not np.allclose(plan(noisy, seed=2).uv_px, plan(noisy).uv_px)
    with pytest.raises(PlanningError, match="t = 0 global label"):
        LabelReplayPlanner(tr, camera, config=ReplayConfig(), demo_seed=1).plan(
            dataclasses.replace(obs, step=3), mode="global")


def test_commanded_path_and_orientation_reach_the_plan(tool_demos):
    from tcot_hybrid.data.dataset import TCP_TARGET, open_demos
    from tcot_hybrid.data.labels import TRACK_KEYS, global_labels, track_from_arrays
    from tcot_hybrid.episode import build_stack
    from tcot_hybrid.learning.data import quat_wxyz_to_matrix

    with open_demos(tool_demos) as f:
        name = f.demos[0]
        tr = track_from_arrays(f.read(name, TRACK_KEYS))
        a = f.read(name, [TCP_TARGET, "obs/robot0_eef_quat"])
    camera = build_stack(RunConfig(task=TOOL)).camera
    obs = Observation(step=0, image=None, depth_m=None, q=np.zeros(7), gripper_closed=False, instruction="")
    w = dataclasses.replace(ReplayConfig().windows, global_spacing="events", global_path="commanded")
    rot = quat_wxyz_to_matrix(a["obs/robot0_eef_quat"])
    plan = LabelReplayPlanner(tr, camera, config=ReplayConfig(windows=w, orientation=True), demo_seed=1,
                              target_xyz=a[TCP_TARGET], tcp_rot=rot).plan(obs, mode="global")
    from tcot_hybrid.data.labels import commanded_track

    idx = global_labels(commanded_track(tr, a[TCP_TARGET], camera), w).indices[0, w.global_center:]
    pts = camera.unproject(plan.uv_px, plan.depth_m)
    np.testing.assert_allclose(pts, a[TCP_TARGET][idx], atol=1e-4)  # the commanded waypoints, lifted back
    assert not np.allclose(a[TCP_TARGET][idx], tr.xyz_m[idx], atol=1e-3)  # not the observed path
    np.testing.assert_allclose(plan.tcp_rot, rot[idx], atol=1e-6)
    with pytest.raises(Exception, match="commanded waypoints must have shape"):
        commanded_track(tr, a[TCP_TARGET][:-1], camera)


def test_a_file_without_commanded_waypoints_is_named_and_the_cap_keeps_the_first_seeds(tool_demos, tmp_path):
    import shutil

    import h5py

    report = replay_file(tool_demos, workers=1, progress=False, max_per_task=1)
    assert [(r["task"], r["seed"]) for r in report["demos"]] == [(TOOL, 1)]
    old = tmp_path / "old.hdf5"
    shutil.copy(tool_demos, old)
    with h5py.File(old, "a") as h5:
        for g in h5["data"].values():
            del g["obs/tcp_target_pos"]
    with pytest.raises(DatasetError, match="has no obs/tcp_target_pos .*--global-path commanded"):
        cmd_replay(["--data", str(old), "--global-spacing", "events", "--global-path", "commanded", "--workers", "1"])
    with pytest.raises(ConfigError, match="--max-per-task must be >= 1, got 0"):
        cmd_replay(["--data", str(old), "--max-per-task", "0"])


def test_bad_inputs_are_named(tool_demos):
    with pytest.raises(ConfigError, match="noise_px"):
        ReplayConfig(noise_px=-1.0)
    with pytest.raises(ConfigError, match="goal_cube_on_plate.*its tasks: " + TOOL):
        replay_file(tool_demos, tasks=["goal_cube_on_plate"], workers=1, progress=False)
    with pytest.raises(ConfigError, match="--n-g must be >= 2, got 1"):
        cmd_replay(["--data", str(tool_demos), "--n-g", "1"])
    with pytest.raises(ConfigError, match="no <!-- replay:start -->"):
        cmd_replay(["--data", str(tool_demos), "--readme", str(tool_demos.parent / "missing.md")])


def test_markdown_names_the_command_and_every_task():
    report = {"command": "tcot replay --data d.hdf5", "data": "d.hdf5", "L_g": 51, "n_g": 4, "noise_px": 0.0,
              "noise_z_m": 0.0, "success_rate": 0.5, "demos": [{}, {}],
              "per_task": {"a": {"demos": 1, "successes": 1, "success_rate": 1.0},
                           "b": {"demos": 1, "successes": 0, "success_rate": 0.0}}}
    md = markdown(report)
    assert "`tcot replay --data d.hdf5`" in md and "| a | 1 | 1 (100%) |" in md and "| b | 1 | 0 (0%) |" in md
