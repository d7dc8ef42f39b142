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
SUITE, FIRST = "libero_goal", 20081
EVAL = f"tcot eval --suite {SUITE} --planners learned --init sampled --episodes 6 --seed-start {FIRST} --modes global,glsr"
# (run directory under runs/dev, checkpoint label, command)
RUNS = (("goal_v12", "four-suite v12", f"{EVAL} {dev_runs.FOUR_SUITE_MODEL}"),
        ("goal_corner", "libero_goal's own (v12 + 6 epochs on the suite)",
         f"{EVAL} --checkpoint runs/libero/planner_libero_goal_corner.safetensors"))


def gather() -> None:
    dev_runs.gather_suite(((name, cmd) for name, _, cmd in RUNS), OUT, SUITE)


def lines() -> list[str]:
    import json

    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    table_rows = [(label, "side grasps 6 mm", mode, (name,)) for mode in ("global", "glsr") for name, label, _ in RUNS]
    return (dev_runs.model_table(rows, table_rows, SUITE, first_seed=FIRST,
                                 column=lambda ck, how, mode: f"{ck.split(' (')[0]}, {mode}")
            + dev_runs.command_lines("goal_corner.py", 2, ((name, cmd) for name, _, cmd in RUNS)))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
