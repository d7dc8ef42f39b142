"""The generic LIBERO oracle: one task of each skill family solved on a fixed sampled layout (development
seeds, docs/seeds.md), and a goal predicate without a skill refused with a clear error."""
from types import SimpleNamespace

import pytest

from tcot_hybrid.errors import ConfigError

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.episode import EpisodeRunner  # noqa: E402
from tcot_hybrid.libero.oracle import SUPPORTED_PREDICATES, goal_predicates  # noqa: E402
from tcot_hybrid.run_config import RunConfig  # noqa: E402

# (family, task, sampled-layout seed): one task per skill family, on a development seed.
FAMILIES = [
    ("on: rim pinch, bowl onto a plate",
     "libero_spatial:pick_up_the_black_bowl_next_to_the_ramekin_and_place_it_on_the_plate", 3),
    ("in: top grasp, carton into the basket", "libero_object:pick_up_the_ketchup_and_place_it_in_the_basket", 3),
    ("open: drawer handle pinched and pulled", "libero_goal:open_the_middle_drawer_of_the_cabinet", 0),
    ("turnon: stove knob pushed along its arc", "libero_goal:turn_on_the_stove", 0),
    ("in + close: bowl into an open drawer, drawer pushed shut",
     "libero_10:KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it", 0),
]


@pytest.mark.parametrize("family,task,seed", FAMILIES, ids=[f[0].split(":")[0] + "-" + f[1].split(":")[0]
                                                            for f in FAMILIES])
def test_oracle_solves_each_skill_family(family, task, seed):
    result = EpisodeRunner(RunConfig(task=task, seed=seed, init="sampled", planner="oracle")).run()
    assert result["fault"] is None, (family, result["fault"])
    assert result["success"], (family, [e for e in result["events"] if e["kind"] in ("plan_rejected", "tracking_reflex")])
    assert result["max_joint_limit_violation_rad"] == 0.0


def test_a_predicate_without_a_skill_is_refused_by_name():
    fake = SimpleNamespace(name="libero_x:lift_the_bowl",
                           scene=SimpleNamespace(env=SimpleNamespace(parsed_problem={
                               "goal_state": [["on", "bowl_1", "plate_1"], ["up", "bowl_1"]]})))
    with pytest.raises(ConfigError) as err:
        goal_predicates(fake)
    msg = str(err.value)
    assert "'up'" in msg and "lift_the_bowl" in msg
    assert all(p in msg for p in SUPPORTED_PREDICATES)
