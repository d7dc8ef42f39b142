"""libero_goal's own model on the commanded corner labels (examples/configs/train_libero_goal_corner.yaml: v12
continued on the suite's demonstrations alone) against the four-suite v12 it starts from, on sampled development
layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+), both at the same commit:

    .venv/bin/python docs/libero-planner/goal_corner.py --gather   # runs/dev/* -> goal_corner.json
    .venv/bin/python docs/libero-planner/goal_corner.py            # goal_corner.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

COMPARISON = dev_runs.SuiteModelComparison(
    prefix="goal", suite="libero_goal",
    seed_ranges=(20081, 20087),  # 6 layouts a task from each, the second run to confirm the first
    layouts=6,
    models=(("v12", "four-suite v12 (shipped for libero_goal until stop 57)", dev_runs.FOUR_SUITE_MODEL),
            ("corner", "libero_goal's own (v12 + 6 epochs on the suite)",
             "--checkpoint runs/libero/planner_libero_goal_corner.safetensors")))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-goal-corner")
