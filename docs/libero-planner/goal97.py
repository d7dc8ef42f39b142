"""libero_goal's own model with the 97-point global window (examples/configs/train_libero_goal97_corner.yaml: v12
widened to 97 global points and trained 8 epochs on the suite, libero_10's recipe) against the goal model shipped
since stop 57 (51 points) and against the four-suite v12 it was continued from, on sampled development layouts
(docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+), all three at the same commit:

    .venv/bin/python docs/libero-planner/goal97.py --gather   # runs/dev/* -> goal97.json
    .venv/bin/python docs/libero-planner/goal97.py            # goal97.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

COMPARISON = dev_runs.SuiteModelComparison(
    prefix="goal97", suite="libero_goal",
    seed_ranges=(20109, 20117),  # fresh for libero_goal (docs/seeds.md), chosen before the run; the second to confirm
    layouts=8,
    models=(("corner", "libero_goal's own (v12 + 6 epochs on the suite, 51 points; shipped at stop 57)",
             "--checkpoint runs/libero/planner_libero_goal_corner.safetensors"),
            ("w97", "97 points (v12 widened + 8 epochs on the suite)",
             "--checkpoint runs/libero/planner_libero_goal97_corner.safetensors"),
            ("v12", "the four-suite v12 (51 points)",
             "--checkpoint tcot_hybrid/checkpoints/libero_panda_default.safetensors")))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-goal-97")
