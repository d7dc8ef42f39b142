"""libero_goal's own model continued on stove demonstrations whose burner is lit (examples/configs/
train_libero_goal_stove_lit.yaml) against the shipped model, on sampled development layouts (docs/seeds.md: seeds
20000+, never the shipped init states, never 90000+), both at the same commit:

    .venv/bin/python docs/libero-planner/goal_stove.py --gather   # runs/dev/* -> goal_stove.json
    .venv/bin/python docs/libero-planner/goal_stove.py            # goal_stove.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

COMPARISON = dev_runs.SuiteModelComparison(
    prefix="goalstove", suite="libero_goal",
    seed_ranges=(20125, 20133),  # fresh for libero_goal (docs/seeds.md), chosen before the run; the second to confirm
    layouts=8,
    models=(("corner", "libero_goal's own (v12 + 6 epochs on the suite; shipped at stop 57)",
             "--checkpoint runs/libero/planner_libero_goal_corner.safetensors"),
            ("lit", "4 epochs more, stove demos with the burner lit",
             "--checkpoint runs/libero/planner_libero_goal_stove_lit.safetensors")))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-goal-stove")
