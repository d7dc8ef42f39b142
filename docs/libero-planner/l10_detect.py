"""libero_10's failure detector trained alone on its own GLSR episodes and stove demonstrations whose burner is lit
(examples/configs/train_libero10_detect_stove.yaml) against the shipped model, on sampled development layouts
(docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+), both at the same commit. Its global and
local plans are bit-identical to the shipped model's (the training checks it), so only GLSR can differ and only GLSR
runs:

    .venv/bin/python docs/libero-planner/l10_detect.py --gather   # runs/dev/* -> l10_detect.json
    .venv/bin/python docs/libero-planner/l10_detect.py            # l10_detect.json -> docs/libero-planner.md
"""
from __future__ import annotations

import dev_runs  # this folder's: run as a script, the folder is on sys.path

COMPARISON = dev_runs.SuiteModelComparison(
    prefix="l10detect", suite="libero_10",
    seed_ranges=(20157, 20165),  # fresh for libero_10 (docs/seeds.md), chosen before the run; the second to confirm
    layouts=8,
    models=(("more", "libero_10's own, six epochs more (shipped at stop 59)",
             "--checkpoint runs/libero/planner_libero10_100_more.safetensors"),
            ("detect", "its detector alone trained on its GLSR episodes and the stove lit",
             "--checkpoint runs/libero/planner_libero10_detect_stove.safetensors")),
    modes=("glsr",))

if __name__ == "__main__":
    COMPARISON.main(__doc__, __file__, "libero-10-detect")
