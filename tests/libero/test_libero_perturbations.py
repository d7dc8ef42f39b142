"""Perturbations on LIBERO scenes: the off-centre grasp nudges the object along the open fingers' closing axis the
moment before they close (LIBERO's grasps are rims, handles and sides), and is refused by name where no skill
picks anything up."""
import numpy as np
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.episode import EpisodeRunner  # noqa: E402
from tcot_hybrid.perturbations import PerturbConfig  # noqa: E402
from tcot_hybrid.run_config import RunConfig  # noqa: E402

BOWL = "libero_spatial:pick_up_the_black_bowl_next_to_the_ramekin_and_place_it_on_the_plate"


def test_offcenter_grasp_shifts_the_bowl_across_the_fingers_before_they_close():
    cfg = RunConfig(task=BOWL, seed=2100, init="sampled", planner="oracle",
                    perturb=PerturbConfig(name="offcenter_grasp"))
    result = EpisodeRunner(cfg).run()
    fired = [e for e in result["events"] if e["kind"] == "perturbation"]
    assert result["perturbation_fired"] and len(fired) == 1
    moved = np.array(fired[0]["moved_m"])
    assert np.linalg.norm(moved) == pytest.approx(cfg.perturb.strength or 0.025, abs=1e-3) and moved[2] == 0.0
    closes = [e["t"] for e in result["events"] if e["kind"] == "gripper" and e["closed"]]
    assert closes and fired[0]["t"] <= closes[0]  # before the fingers first close
    assert result["fault"] is None


def test_offcenter_grasp_is_refused_by_name_where_nothing_is_picked_up():
    cfg = RunConfig(task="libero_goal:open_the_middle_drawer_of_the_cabinet", seed=2100, init="sampled",
                    planner="oracle", perturb=PerturbConfig(name="offcenter_grasp"))
    result = EpisodeRunner(cfg).run()
    assert result["perturbation_fired"] is False
    assert "no pick-and-place" in result["perturbation_note"]
