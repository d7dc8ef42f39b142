"""libero_goal's own model six epochs more (examples/configs/train_libero_goal_more.yaml: the model of
train_libero_goal_corner.yaml continued on the same demonstrations with a fresh one-cycle at half its peak rate)
against that model, on sampled development layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never
90000+), both at the same commit:

    .venv/bin/python docs/libero-planner/goal_more.py --gather   # runs/dev/* -> goal_more.json
    .venv/bin/python docs/libero-planner/goal_more.py            # goal_more.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

COMPARISON = dev_runs.SuiteModelComparison(
    prefix="goalmore", suite="libero_goal",
    seed_ranges=(20093, 20101),  # fresh for libero_goal (docs/seeds.md), chosen before the run; the second to confirm
    layouts=8,
    models=(("corner", "libero_goal's own (v12 + 6 epochs on the suite; shipped at stop 57)",
             "--checkpoint runs/libero/planner_libero_goal_corner.safetensors"),
            ("more", "six epochs more (12 on the suite)",
             "--checkpoint runs/libero/planner_libero_goal_more.safetensors")))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-goal-more")
