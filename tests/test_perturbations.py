import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

from tcot_hybrid.episode import EpisodeRunner
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.perturbations import PerturbConfig, list_perturbations
from tcot_hybrid.run_config import RunConfig


def test_listing_and_unknown_name():
    names = [p["name"] for p in list_perturbations()]
    assert names[:3] == ["object_moved", "target_moved", "object_drop"]
    assert all(p["description"] for p in list_perturbations())
    with pytest.raises(ConfigError, match="object_moved"):
        PerturbConfig(name="earthquake")


@pytest.mark.parametrize("name", ["object_moved", "target_moved", "object_drop", "offcenter_grasp", "arm_push",
                                  "camera_noise", "camera_shift", "init_posture"])
def test_each_perturbation_fires_once_and_is_reproducible(name):
    recs = []
    for _ in range(2):
        planner = "learned" if name.startswith("camera") else "oracle"  # the oracle never looks at the image
        cfg = RunConfig(task="goal_cube_on_plate", seed=4, planner=planner, perturb=PerturbConfig(name=name))
        recs.append(EpisodeRunner(cfg).run())
    fired = [[e for e in r["events"] if e["kind"] == "perturbation"] for r in recs]
    assert len(fired[0]) == 1, f"{name} should fire exactly once, got {fired[0]}"
    strip = lambda evs: [{k: v for k, v in e.items()} for e in evs]  # noqa: E731
    assert strip(fired[0]) == strip(fired[1]), "same seed must perturb identically"
    assert recs[0]["sim_time_s"] == recs[1]["sim_time_s"]


def test_moved_object_lands_in_workspace_at_the_requested_distance():
    cfg = RunConfig(task="goal_cube_on_plate", seed=2, perturb=PerturbConfig(name="object_moved", strength=0.08))
    rec = EpisodeRunner(cfg).run()
    ev = next(e for e in rec["events"] if e["kind"] == "perturbation")
    assert np.isclose(np.linalg.norm(ev["moved_m"]), 0.08, atol=1e-3)
    assert not rec["success"], "a frozen global plan must not survive a moved object"


def test_camera_noise_changes_only_the_image():
    cfg = RunConfig(task="goal_cube_on_plate", seed=0, planner="oracle", perturb=PerturbConfig(name="camera_noise"))
    r = EpisodeRunner(cfg)
    img = np.full((32, 32, 3), 128, np.uint8)
    assert np.array_equal(r.perturbation.on_image(img), img)  # not fired yet
    r.perturbation.on_step(r, 0)
    noisy = r.perturbation.on_image(img)
    assert noisy.shape == img.shape and noisy.dtype == np.uint8 and not np.array_equal(noisy, img)


def test_camera_shift_moves_the_rendered_view_not_the_calibration_and_is_undone():
    cfg = RunConfig(task="goal_cube_on_plate", seed=0, planner="learned", perturb=PerturbConfig(name="camera_shift"))
    r = EpisodeRunner(cfg)
    sim, cam = r.stack.sim, r.stack.camera
    K, T = cam.K.copy(), cam.T_world_cam.copy()
    cid = sim.model.camera("agentview").id
    pos, quat = sim.model.cam_pos[cid].copy(), sim.model.cam_quat[cid].copy()
    before = r.observe(0).image
    ev = r.perturbation.on_step(r, 0)
    moved = np.linalg.norm(ev["moved_m"])
    assert np.isclose(moved, 0.03, atol=1e-4) and np.isclose(ev["turned_deg"], 3.0)
    after = r.observe(0).image  # the observation of this step is rendered again, from the shifted camera
    assert np.abs(after.astype(int) - before).mean() > 2.0
    np.testing.assert_array_equal(r.stack.camera.K, K)  # the lift keeps the nominal calibration
    np.testing.assert_array_equal(r.stack.camera.T_world_cam, T)
    r.perturbation.undo(r)
    np.testing.assert_array_equal(sim.model.cam_pos[cid], pos)
    np.testing.assert_array_equal(sim.model.cam_quat[cid], quat)


def test_init_posture_starts_inside_the_limits_without_a_reflex():
    cfg = RunConfig(task="goal_cube_on_plate", seed=5, perturb=PerturbConfig(name="init_posture", strength=0.25))
    r = EpisodeRunner(cfg)
    rec = r.run()
    ev = next(e for e in rec["events"] if e["kind"] == "perturbation")
    off = np.abs(ev["offset_rad"])
    assert ev["step"] == 0 and off.max() <= 0.25 and off.max() > 0.05
    assert rec["tracking_reflexes"] == 0 and rec["max_joint_limit_violation_rad"] <= 0.0
    assert rec["success"], "the oracle plans from wherever the arm starts"


@pytest.mark.parametrize("task, name, at_step, reason", [
    ("goal_open_drawer", "target_moved", None, "no target receptacle"),
    ("tool_pull_cube_with_stick", "target_moved", None, "no target receptacle"),
    ("tool_pull_cube_with_stick", "offcenter_grasp", None, "no top-down pick-and-place"),
    ("goal_open_drawer", "offcenter_grasp", None, "no top-down pick-and-place"),
    ("goal_cube_in_bowl", "arm_push", 100000, "after the episode's last planner step 249"),
    ("goal_cube_in_bowl", "camera_noise", None, "does not look at the image"),  # the oracle renders nothing
])
def test_a_perturbation_that_cannot_apply_is_recorded_as_not_fired(task, name, at_step, reason):
    rec = EpisodeRunner(RunConfig(task=task, seed=5, perturb=PerturbConfig(name=name, at_step=at_step))).run()
    assert not [e for e in rec["events"] if e["kind"] == "perturbation"]
    assert rec["perturbation_fired"] is False and reason in rec["perturbation_note"]


def test_fired_perturbation_and_no_perturbation_are_recorded():
    rec = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=5, perturb=PerturbConfig(name="arm_push"))).run()
    assert rec["perturbation_fired"] is True and rec["perturbation_note"] is None
    rec = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=5)).run()
    assert rec["perturbation_fired"] is None and rec["perturbation_note"] is None


def test_run_summary_says_when_a_perturbation_did_not_fire(tmp_path, capsys):
    from tcot_hybrid import cli

    assert cli.main(["run", "--task", "goal_cube_in_bowl", "--seed", "5", "--perturb", "arm_push",
                     "--perturb.at-step", "100000", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "perturbation arm_push did NOT fire: at_step 100000" in out and "not a perturbed one" in out


def test_a_scene_the_oracle_cannot_describe_makes_object_perturbations_wait_not_crash(monkeypatch):
    """target_moved/object_moved watch the task's skills; a scene they cannot be derived from (a LIBERO book lying
    where no grasp fits) used to crash the episode with the oracle's PlanningError. Now the perturbation waits."""
    from tcot_hybrid.errors import PlanningError

    for name in ("object_moved", "target_moved"):
        cfg = RunConfig(task="goal_cube_on_plate", seed=4, perturb=PerturbConfig(name=name))
        runner = EpisodeRunner(cfg)

        def no_skills():
            raise PlanningError("oracle: no grasp for 'black_book_1'")

        monkeypatch.setattr(runner.stack.task, "skills", no_skills)
        assert runner.perturbation.fire(runner, 0) is None
