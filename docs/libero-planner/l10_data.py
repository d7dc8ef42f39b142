"""libero_10's own model on twice the demonstrations (examples/configs/train_libero10_200_more.yaml: the shipped
model continued on seeds 0-99 and 100-199 of the oracle) against the shipped model, on sampled development layouts
(docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+), both at the same commit:

    .venv/bin/python docs/libero-planner/l10_data.py --gather   # runs/dev/* -> l10_data.json
    .venv/bin/python docs/libero-planner/l10_data.py            # l10_data.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

COMPARISON = dev_runs.SuiteModelComparison(
    prefix="l10data", suite="libero_10",
    seed_ranges=(20125, 20133),  # fresh for libero_10 (docs/seeds.md), chosen before the run; the second to confirm
    layouts=8,
    models=(("more", "libero_10's own, six epochs more (100 demos a task; shipped at stop 59)",
             "--checkpoint runs/libero/planner_libero10_100_more.safetensors"),
            ("data", "8 epochs more on 200 demos a task",
             "--checkpoint runs/libero/planner_libero10_200_more.safetensors")))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-10-data")
