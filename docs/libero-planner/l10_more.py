"""libero_10's own model six epochs more (examples/configs/train_libero10_100_more.yaml: the model of
train_libero10_100_corner.yaml continued on the same demonstrations with a fresh one-cycle at half its peak rate)
against that model, on sampled development layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never
90000+), both at the same commit:

    .venv/bin/python docs/libero-planner/l10_more.py --gather   # runs/dev/* -> l10_more.json
    .venv/bin/python docs/libero-planner/l10_more.py            # l10_more.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

COMPARISON = dev_runs.SuiteModelComparison(
    prefix="l10more", suite="libero_10",
    seed_ranges=(20109, 20117),  # fresh for libero_10 (docs/seeds.md), chosen before the run; the second to confirm
    layouts=8,
    models=(("v12", "libero_10's own from v12 (8 epochs on the suite; shipped at stop 58)",
             "--checkpoint runs/libero/planner_libero10_100_corner.safetensors"),
            ("more", "six epochs more (14 on the suite)",
             "--checkpoint runs/libero/planner_libero10_100_more.safetensors")))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-10-more")
