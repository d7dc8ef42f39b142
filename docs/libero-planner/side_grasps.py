"""How deep a side grasp goes (``--learned.side-grasp-depth-m``), chosen on sampled development layouts (docs/seeds.md:
seeds 20000+, never the shipped init states, never 90000+), GLSR, for docs/libero-planner.md, "Side grasps":

    .venv/bin/python docs/libero-planner/side_grasps.py --gather   # runs/dev/* -> side_grasps.json
    .venv/bin/python docs/libero-planner/side_grasps.py            # side_grasps.json -> docs/libero-planner.md

Every depth ran the same layouts; the libero_10 task loads libero_10's own model, the others the four-suite one.
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "side_grasps.json"
SECTION = "libero-side-grasps"
EVAL = "tcot eval --planners learned --init sampled --modes glsr"
OTHER = ("libero_object:pick_up_the_ketchup_and_place_it_in_the_basket,"
         "libero_10:KITCHEN_SCENE6_put_the_yellow_and_white_mug_in_the_microwave_and_close_it,"
         "libero_goal:put_the_wine_bottle_on_the_rack,libero_goal:put_the_wine_bottle_on_top_of_the_cabinet")
DEPTHS = ("0", "0.008", "0.012")
# run directory under runs/dev -> (depth, command)
RUNS = {
    **{f"side10_goal_{d}": (d, f"{EVAL} --suite libero_goal --episodes 10 --seed-start 20000 "
                               f"--learned.side-grasp-depth-m {d} {dev_runs.FOUR_SUITE_MODEL}") for d in DEPTHS},
    **{f"side_other_{d}": (d, f"{EVAL} --tasks {OTHER} --episodes 10 --seed-start 20000 "
                              f"--learned.side-grasp-depth-m {d}") for d in ("0", "0.012")},
    **{f"side_{short}_{d}": (d, f"{EVAL} --suite {suite} --episodes 5 --seed-start 20000 "
                                 f"--learned.side-grasp-depth-m {d}")
       for short, suite in (("obj", "libero_object"), ("spa", "libero_spatial")) for d in ("0", "0.012")},
    **{f"side_mid_{d}": (d, f"{EVAL} --tasks libero_goal:open_the_middle_drawer_of_the_cabinet --episodes 10 "
                            f"--seed-start 20010 --learned.side-grasp-depth-m {d}") for d in ("0", "0.012")},
}
KEEP = ("task", "suite", "mode", "seed", "success")


def gather() -> None:
    dev_runs.gather(((name, cmd) for name, (_, cmd) in RUNS.items()), OUT,
                    lambda name, e: {"run": name, "depth_m": RUNS[name][0], **{k: e.get(k) for k in KEEP}})


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    # (task, depth) -> {seed: success}; a task run twice at one depth adds its layouts (the wine bottles ran in
    # two runs on the same seeds: one seed and config replay bit-identically, so the second is the same episode)
    got: dict = defaultdict(dict)
    for r in rows:
        got[(r["task"], r["depth_m"])][r["seed"]] = bool(r["success"])
    tasks = sorted({t for t, _ in got})
    out = ["Successes per task and side-grasp depth (GLSR; a cell that ran fewer layouts than its row ran the first "
           "ones; `-`: not run):",
           "", "| task | layouts | " + " | ".join(f"{d} m" for d in DEPTHS) + " |", "|---|---|" + "---|" * len(DEPTHS)]
    totals = defaultdict(lambda: [0, 0])
    for task in tasks:
        seeds = sorted(set().union(*(got[(task, d)] for d in DEPTHS if (task, d) in got)))
        cells = []
        for d in DEPTHS:
            s = got.get((task, d))
            cells.append("-" if s is None else f"{sum(s.values())}/{len(s)}")
        out.append(f"| {task} | {seeds[0]}-{seeds[-1]} ({len(seeds)}) | " + " | ".join(cells) + " |")
        for d in ("0", "0.012"):  # the pair every task ran
            s = got.get((task, d), {})
            totals[d][0] += sum(s.values())
            totals[d][1] += len(s)
    out += ["", "All tasks: " + ", ".join(f"{d} m {k}/{n}" for d, (k, n) in totals.items()) + "."]
    return out + dev_runs.command_lines("side_grasps.py", 2, ((n, c) for n, (_, c) in RUNS.items()))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
