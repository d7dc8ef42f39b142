"""How far a side grasp goes past where the planner put it (``learned.side_grasp_depth_m``; docs/libero-planner.md,
"How deep a side grasp goes") for the networks shipped now, which learned the commanded path (v12, libero_10's own
model), on sampled development layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+).
The 12 mm default was measured with an observed-path network whose drawer grasps closed 6 mm short; the tasks are the
ones whose grasps are made with the hand level (a drawer handle, the wine bottle, the ketchup, the microwave mug):

    .venv/bin/python docs/libero-planner/side_depth.py --gather   # runs/dev/* -> side_depth.json
    .venv/bin/python docs/libero-planner/side_depth.py            # side_depth.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "side_depth.json"
SECTION = "libero-side-depth"
FIRST = 20061
BASE = 0.012  # the default the runs are compared with
SIDE_TASKS = ",".join((
    "libero_goal:open_the_middle_drawer_of_the_cabinet", "libero_goal:open_the_top_drawer_and_put_the_bowl_inside",
    "libero_goal:put_the_wine_bottle_on_the_rack", "libero_goal:put_the_wine_bottle_on_top_of_the_cabinet",
    "libero_10:KITCHEN_SCENE6_put_the_yellow_and_white_mug_in_the_microwave_and_close_it",
    "libero_10:KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it",
    "libero_object:pick_up_the_ketchup_and_place_it_in_the_basket"))
LONG_TASKS = ",".join(t for t in SIDE_TASKS.split(",") if t.startswith("libero_10:"))
FOUR = f"tcot eval --tasks {SIDE_TASKS} --planners learned --init sampled --episodes 20 --seed-start {FIRST} " \
       f"--modes global,glsr {dev_runs.FOUR_SUITE_MODEL}"
OWN = f"tcot eval --tasks {LONG_TASKS} --planners learned --init sampled --episodes 12 --seed-start {FIRST} " \
      "--modes global,glsr"
# (run directory under runs/dev, model label, depth [m], command)
RUNS = tuple((f"side_d{d}", "four-suite v12", d, f"{FOUR} --learned.side-grasp-depth-m {d}") for d in (0, 0.006, BASE)) \
    + tuple((f"side10_d{d}", "libero_10's own", d, f"{OWN} --learned.side-grasp-depth-m {d}") for d in (0.006, BASE))
KEEP = ("task", "suite", "mode", "seed", "success")


def gather() -> None:
    dev_runs.gather(((name, cmd) for name, _, _, cmd in RUNS), OUT, lambda name, e: (
        {"run": name, **{k: e.get(k) for k in KEEP}} if e["perturb"] == "none" else None))


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    by: dict = defaultdict(dict)  # (run, mode) -> (task, seed) -> success
    for r in rows:
        by[(r["run"], r["mode"])][(r["task"], r["seed"])] = r["success"]
    out = [f"Sampled development layouts from {FIRST} (20 a task for v12, 12 for libero_10's own model), the tasks whose "
           "grasps are made with the hand level; successes / episodes, won / lost against the "
           f"{BASE * 1000:g} mm default of the same model and mode on the same layouts:", "",
           "| model | depth | mode | episodes | successes | won / lost |", "|---|---|---|---|---|---|"]
    base_run = {label: name for name, label, d, _ in RUNS if d == BASE}
    for name, label, depth, _ in RUNS:
        for mode in ("global", "glsr"):
            eps = by.get((name, mode))
            if not eps:
                continue
            base = by.get((base_run[label], mode), {})
            wl = "-" if depth == BASE else dev_runs.won_lost_keyed(base, eps)
            out.append(f"| {label} | {depth * 1000:g} mm | {mode} | {len(eps)} | **{sum(eps.values())}** | {wl} |")
    out += ["", "Per task:", ""] + dev_runs.per_task_table(
        [(f"{label.split()[0]}, {depth * 1000:g} mm, {mode}", by[(name, mode)])
         for name, label, depth, _ in RUNS for mode in ("global", "glsr") if by.get((name, mode))])
    return out + dev_runs.command_lines("side_depth.py", 2, ((name, cmd) for name, _, _, cmd in RUNS))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
