"""Whether the 97-point global window (examples/configs/train_libero_v3.yaml) replaces the shipped checkpoint's 51
(docs/libero-planner.md, "A longer global window"), on sampled development layouts (docs/seeds.md: seeds 20000+,
never the shipped init states, never 90000+):

    .venv/bin/python docs/libero-planner/window_choice.py --gather   # runs/dev/* -> window_choice.json
    .venv/bin/python docs/libero-planner/window_choice.py            # window_choice.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "window_choice.json"
SUITES, S4 = dev_runs.SUITES, dev_runs.S4
SECTION = "libero-window-choice"
EVAL = f"tcot eval --suite {S4} --planners learned --init sampled --episodes 2 --seed-start 20000"
# (run, mode, checkpoint, command); the shipped checkpoint's runs first: the baseline of each mode
RUNS = (
    ("twin2", "global", "shipped (51 points)", f"{EVAL} --modes global {dev_runs.FOUR_SUITE_MODEL}"),
    ("home1", "glsr", "shipped (51 points)", f"{EVAL} --modes glsr --supervisor.home-retries 1 {dev_runs.FOUR_SUITE_MODEL}"),
    ("v3", "global", "v3 (97 points)", f"{EVAL} --modes glsr,global --checkpoint runs/libero/planner_v3.safetensors"),
    ("v3", "glsr", "v3 (97 points)", f"{EVAL} --modes glsr,global --checkpoint runs/libero/planner_v3.safetensors"),
)
KEEP = ("task", "suite", "mode", "seed", "success")


def gather() -> None:
    runs = {name: cmd for name, _, _, cmd in RUNS}
    dev_runs.gather(runs.items(), OUT, lambda name, e: (
        {"run": name, **{k: e.get(k) for k in KEEP}} if e["perturb"] == "none" else None))


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    return (["Sampled development layouts 20000-20001, all 40 tasks (successes / episodes; won and lost against the "
             "shipped checkpoint in the same mode on the same layouts):", ""] + dev_runs.checkpoint_table(rows, RUNS)
            + dev_runs.command_lines("window_choice.py", 2, dict((n, c) for n, _, _, c in RUNS).items()))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
