"""libero_10's own model from v12 (examples/configs/train_libero10_100_corner.yaml: the four-suite v12 widened to 97
global points and continued on the suite's 100-demos demonstrations alone) against the libero_10 model shipped before
it (the 50-demos lineage, train_libero10_corner.yaml), on sampled development layouts (docs/seeds.md: seeds 20000+,
never the shipped init states, never 90000+), both at the same commit:

    .venv/bin/python docs/libero-planner/l10_corner.py --gather   # runs/dev/* -> l10_corner.json
    .venv/bin/python docs/libero-planner/l10_corner.py            # l10_corner.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

# The model these runs judged against, the file shipped as libero_panda_libero_10 before stop 58 (the runs loaded it
# from there)
BEFORE = "runs/libero/libero10_before_stop58.safetensors"
COMPARISON = dev_runs.SuiteModelComparison(
    prefix="l10", suite="libero_10",
    seed_ranges=(20093, 20101),  # fresh for libero_10 (docs/seeds.md), chosen before the run; the second to confirm
    layouts=8,
    models=(("shipped", "libero_10's model of the 50-demos lineage (shipped until stop 58)", f"--checkpoint {BEFORE}"),
            ("v12", "libero_10's own from v12 (97 points, 8 epochs on the suite)",
             "--checkpoint runs/libero/planner_libero10_100_corner.safetensors")))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-10-corner", note=(
        "", f"`{BEFORE}`: `git show 25cd9b9:tcot_hybrid/checkpoints/libero_panda_libero_10.safetensors > {BEFORE}` "
            "(the file the runs loaded, shipped until stop 58)."))
