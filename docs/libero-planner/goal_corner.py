"""libero_goal's own model on the commanded corner labels (examples/configs/train_libero_goal_corner.yaml: v12
continued on the suite's demonstrations alone) against the four-suite v12 it starts from, on sampled development
layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+), both at the same commit:

    .venv/bin/python docs/libero-planner/goal_corner.py --gather   # runs/dev/* -> goal_corner.json
    .venv/bin/python docs/libero-planner/goal_corner.py            # goal_corner.json -> docs/libero-planner.md
"""
from __future__ import annotations

from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "goal_corner.json"
SECTION = "libero-goal-corner"
SUITE = "libero_goal"
SEED_RANGES = (20081, 20087)  # 6 layouts a task from each, the second run to confirm the first
EVAL = f"tcot eval --suite {SUITE} --planners learned --init sampled --episodes 6 --modes global,glsr"
MODELS = (("v12", "four-suite v12 (shipped for libero_goal until stop 57)", dev_runs.FOUR_SUITE_MODEL),
          ("corner", "libero_goal's own (v12 + 6 epochs on the suite)",
           "--checkpoint runs/libero/planner_libero_goal_corner.safetensors"))
# (run directory under runs/dev, model label, command)
RUNS = tuple((f"goal_{short}{'b' * k}", label, f"{EVAL} --seed-start {first} {flag}")
             for short, label, flag in MODELS for k, first in enumerate(SEED_RANGES))


def gather() -> None:
    dev_runs.gather_suite(((name, cmd) for name, _, cmd in RUNS), OUT, SUITE)


def lines() -> list[str]:
    import json
    from collections import defaultdict

    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    by: dict = defaultdict(dict)  # (model label, mode) -> (task, seed) -> success
    for r in rows:
        label = next(lab for name, lab, _ in RUNS if name == r["run"])
        by[(label, r["mode"])][(r["task"], r["seed"])] = r["success"]
    labels = list(dict.fromkeys(lab for _, lab, _ in RUNS))
    seeds = sorted({s for eps in by.values() for _, s in eps})
    out = [f"{SUITE} on sampled development layouts {seeds[0]}-{seeds[-1]} ({len(seeds)} a task, in two runs of 6); "
           "successes / episodes per run, won / lost against v12 in the same mode on the same layouts:", "",
           "| model | mode | " + " | ".join(f"{a}-{a + 5}" for a in SEED_RANGES) + " | all | won / lost |",
           "|---|---|" + "---|" * (len(SEED_RANGES) + 2)]
    for mode in ("global", "glsr"):
        base = by[(labels[0], mode)]
        for label in labels:
            eps = by[(label, mode)]
            per_run = [f"{sum(ok for (_, s), ok in eps.items() if a <= s <= a + 5)}/"
                       f"{sum(a <= s <= a + 5 for _, s in eps)}" for a in SEED_RANGES]
            wl = "-" if label == labels[0] else dev_runs.won_lost_keyed(base, eps)
            out.append(f"| {label} | {mode} | " + " | ".join(per_run) + f" | **{sum(eps.values())}/{len(eps)}** | {wl} |")
    out += ["", "Per task (all layouts):", ""] + dev_runs.per_task_table(
        [(f"{label.split(' (')[0]}, {mode}", by[(label, mode)]) for mode in ("global", "glsr") for label in labels])
    return out + dev_runs.command_lines("goal_corner.py", 2, ((name, cmd) for name, _, cmd in RUNS))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
