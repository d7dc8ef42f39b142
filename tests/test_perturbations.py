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
                                  "camera_noise"])
def test_each_perturbation_fires_once_and_is_reproducible(name):
    recs = []
    for _ in range(2):
        cfg = RunConfig(task="goal_cube_on_plate", seed=4, perturb=PerturbConfig(name=name))
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
