"""Whether a leaning hand should come onto its grasp along its approach axis (``executor.grasp_along_approach``;
docs/libero-planner.md, "Grasps along their approach"), judged by the rule set before the runs (docs/seeds.md, stop
66): the 17 tasks with a grasp leaning 5-45 degrees in the t = 0 global plans of training-range layouts 30170-30171,
with and without it, global-only and GLSR at the stack's defaults, on fresh development layouts (10 a task).

    .venv/bin/python docs/libero-planner/grasp_approach.py --gather   # runs/dev/approach_* -> grasp_approach.json
    .venv/bin/python docs/libero-planner/grasp_approach.py            # grasp_approach.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "grasp_approach.json"
SECTION = "libero-grasp-approach"
PER_TASK = 10
FIRST = {"libero_spatial": 20032, "libero_object": 20040, "libero_goal": 20181, "libero_10": 20213}
TASKS = {
    "libero_spatial": ("pick_up_the_black_bowl_next_to_the_cookie_box_and_place_it_on_the_plate",
                       "pick_up_the_black_bowl_on_the_cookie_box_and_place_it_on_the_plate",
                       "pick_up_the_black_bowl_on_the_wooden_cabinet_and_place_it_on_the_plate"),
    "libero_object": ("pick_up_the_alphabet_soup_and_place_it_in_the_basket",
                      "pick_up_the_butter_and_place_it_in_the_basket",
                      "pick_up_the_cream_cheese_and_place_it_in_the_basket",
                      "pick_up_the_milk_and_place_it_in_the_basket",
                      "pick_up_the_orange_juice_and_place_it_in_the_basket",
                      "pick_up_the_salad_dressing_and_place_it_in_the_basket",
                      "pick_up_the_tomato_sauce_and_place_it_in_the_basket"),
    "libero_goal": ("open_the_top_drawer_and_put_the_bowl_inside", "push_the_plate_to_the_front_of_the_stove",
                    "put_the_wine_bottle_on_top_of_the_cabinet"),
    "libero_10": ("KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it",
                  "LIVING_ROOM_SCENE1_put_both_the_alphabet_soup_and_the_cream_cheese_box_in_the_basket",
                  "LIVING_ROOM_SCENE2_put_both_the_cream_cheese_box_and_the_butter_in_the_basket",
                  "STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_back_compartment_of_the_caddy"),
}
# (run prefix, label, tcot eval flag at this commit; both ran with the code of 9924e99, the rule on by default, the
# first row had `--executor.no-grasp-along-approach`: the same two configurations)
SETTINGS = (("approach_off", "straight down onto every grasp (the default)", ""),
            ("approach_on", "a leaning hand along its approach", " --executor.grasp-along-approach"))
KEEP = ("task", "suite", "mode", "seed", "success")


def _command(suite: str, flag: str) -> str:
    tasks = ",".join(f"{suite}:{t}" for t in TASKS[suite])
    return (f"tcot eval --tasks {tasks} --planners learned --modes global,glsr --init sampled --episodes {PER_TASK} "
            f"--seed-start {FIRST[suite]}{flag}")


def _runs() -> list[tuple[str, str, str]]:
    """(run directory under runs/dev, setting, command): one run per suite and setting."""
    return [(f"{name}_{suite}", name, _command(suite, flag)) for name, _, flag in SETTINGS for suite in TASKS]


def gather() -> None:
    setting = {run: name for run, name, _ in _runs()}
    dev_runs.gather(((run, cmd) for run, _, cmd in _runs()), OUT, lambda run, e: (
        {"run": setting[run], **{k: e.get(k) for k in KEEP}} if e["perturb"] == "none" else None))


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    table_rows = dev_runs.per_mode((name, label, "") for name, label, _ in SETTINGS)
    layouts = ", ".join(f"{s} {FIRST[s]}-{FIRST[s] + PER_TASK - 1} ({len(TASKS[s])} tasks)" for s in TASKS)
    return ([f"Sampled development layouts ({layouts}), {PER_TASK} a task; the stack's defaults (no `--checkpoint`); "
             "won / lost against the first row of its mode on the same layouts:", ""]
            + dev_runs.checkpoint_table(rows, table_rows, head="descent onto a grasp")
            + [line for mode in ("global", "glsr")
               for line in ("", dev_runs.changed_tasks(rows, mode, "approach_off", "approach_on", PER_TASK,
                                                       "approach_off"))]
            + dev_runs.command_lines("grasp_approach.py", 1, [(run, cmd) for run, _, cmd in _runs()]))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
