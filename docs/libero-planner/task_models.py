"""A model per task: which shipped model plans each libero_10 and libero_goal task (docs/libero-planner.md, "A model
per task"). The rule, set before the runs (docs/seeds.md, stop 63): training-range layouts 30000-30019 of every task,
global-only, with the four-suite model and the suite's own, screen the tasks (a candidate: the other model wins by at
least 5 of 20), and a second screen under GLSR on 30020-30039; fresh development layouts judge each candidate, both
models, global-only and GLSR: it is routed to the other model (tcot_hybrid/checkpoints/task_models.json) if its GLSR gains at least 3 of 20 and its
global-only loses none. Stop 64: two candidates from stop 60's runs, for libero_goal's 97-point model, judged the
same way with either mode allowed to carry the gain (JUDGE3_GOAL).

    .venv/bin/python docs/libero-planner/task_models.py --gather   # runs/dev/* -> task_models*.json
    .venv/bin/python docs/libero-planner/task_models.py            # those -> docs/libero-planner.md
"""
from __future__ import annotations

from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

OWN = "--checkpoint tcot_hybrid/checkpoints/libero_panda_{}.safetensors"
MULTI = ("multi", "the four-suite model", "--checkpoint tcot_hybrid/checkpoints/libero_panda_default.safetensors")
SCREENS = {suite: dev_runs.SuiteModelComparison(
    prefix=f"screen_{short}", suite=suite, seed_ranges=(30000,), layouts=20, modes=("global",),
    layouts_kind="training-range",
    models=((short, f"{suite}'s own model", OWN.format(suite)), MULTI))
    for suite, short in (("libero_10", "l10"), ("libero_goal", "goal"))}
# the second screen, under GLSR (a task GLSR recovers and global-only never solves is invisible to the first)
SCREENS_GLSR = {suite: dev_runs.SuiteModelComparison(
    prefix=f"screen2_{short}", suite=suite, seed_ranges=(30020,), layouts=20, modes=("glsr",),
    layouts_kind="training-range", models=((short, f"{suite}'s own model", OWN.format(suite)), MULTI))
    for suite, short in (("libero_10", "l10"), ("libero_goal", "goal"))}
STOVE = "libero_10:KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it"
PUDDING = "libero_10:LIVING_ROOM_SCENE6_put_the_white_mug_on_the_plate_and_put_the_chocolate_pudding_to_the_right_of_the_plate"
JUDGE = dev_runs.SuiteModelComparison(
    prefix="taskm", suite="libero_10", seed_ranges=(20173,), layouts=20, tasks=(STOVE, PUDDING),
    models=(("l10", "libero_10's own model", OWN.format("libero_10")), MULTI))

# the second screen's candidates (GLSR wins by at least 5 of 20), judged by the same rule on fresh layouts
TOP_DRAWER = "libero_goal:open_the_top_drawer_and_put_the_bowl_inside"
JUDGE2_GOAL = dev_runs.SuiteModelComparison(
    prefix="taskm2", suite="libero_goal", seed_ranges=(20141,), layouts=20, tasks=(TOP_DRAWER,),
    models=(("goal", "libero_goal's own model", OWN.format("libero_goal")), MULTI))

# stop 64: the 97-point goal model's two tasks of stop 60's runs (docs/libero-planner.md, "The goal suite's own
# model"), judged against the model the stack's defaults give them, either mode allowed to carry the gain
WINE_CABINET = "libero_goal:put_the_wine_bottle_on_top_of_the_cabinet"
JUDGE3_GOAL = dev_runs.SuiteModelComparison(
    prefix="taskm3", suite="libero_goal", seed_ranges=(20161,), layouts=20, tasks=(TOP_DRAWER, WINE_CABINET),
    models=(("defaults", "the stack's defaults (the four-suite model for the top drawer, libero_goal's own for the "
             "wine bottle)", ""),
            ("goal97", "the 97-point goal model", "--checkpoint runs/libero/planner_libero_goal97_corner.safetensors")))


def main() -> None:
    here = Path(__file__)
    parts = [(f"task-models-screen-{s}", c, here.with_name(f"task_models_screen_{s}.json")) for s, c in SCREENS.items()]
    parts += [(f"task-models-screen2-{s}", c, here.with_name(f"task_models_screen2_{s}.json"))
              for s, c in SCREENS_GLSR.items()]
    parts.append(("task-models-judge", JUDGE, here.with_suffix(".json")))
    parts.append(("task-models-judge2-libero_goal", JUDGE2_GOAL, here.with_name("task_models_judge2_libero_goal.json")))
    parts.append(("task-models-judge3-libero_goal", JUDGE3_GOAL, here.with_name("task_models_judge3_libero_goal.json")))
    dev_runs.main(__doc__,
                  lambda: [dev_runs.gather_suite(((n, cmd) for n, _, cmd in c.runs), out, c.suite) for _, c, out in parts],
                  {section: (lambda c=c, out=out: c.lines(out, here.name)) for section, c, out in parts})


if __name__ == "__main__":
    main()
