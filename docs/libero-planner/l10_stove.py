"""libero_10's own model continued on stove demonstrations whose burner is lit (examples/configs/
train_libero10_stove_lit.yaml) against the shipped model, on sampled development layouts (docs/seeds.md: seeds 20000+,
never the shipped init states, never 90000+), both at the same commit:

    .venv/bin/python docs/libero-planner/l10_stove.py --gather   # runs/dev/* -> l10_stove.json
    .venv/bin/python docs/libero-planner/l10_stove.py            # l10_stove.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

COMPARISON = dev_runs.SuiteModelComparison(
    prefix="l10stove", suite="libero_10",
    seed_ranges=(20141, 20149),  # fresh for libero_10 (docs/seeds.md), chosen before the run; the second to confirm
    layouts=8,
    models=(("more", "libero_10's own, six epochs more (shipped at stop 59)",
             "--checkpoint runs/libero/planner_libero10_100_more.safetensors"),
            ("lit", "4 epochs more, stove demos with the burner lit",
             "--checkpoint runs/libero/planner_libero10_stove_lit.safetensors")))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-10-stove")
