"""Whether a window of the commanded path, each piece's points at its corners, replaces the shipped checkpoint
(docs/libero-planner.md, "A longer global window" and "100 demonstrations per task"), on sampled development layouts
(docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+): 97 points in v4
(examples/configs/train_libero_v4.yaml, the first 1000 demos) and v5 (train_libero_v5.yaml, all 2000), both continued
from the shipped weights, and v9 (train_libero_v9.yaml, the same labels from nothing); 51 points in v12
(train_libero100_corner.yaml, the 100-demos checkpoint continued on its own 4000 demos). Each trial's checkpoints
run on the same machine at commits whose episodes run alike, so its baseline is not an older model's run:

    .venv/bin/python docs/libero-planner/corner_window.py --gather   # runs/dev/* -> corner_window.json
    .venv/bin/python docs/libero-planner/corner_window.py            # corner_window.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "corner_window.json"
EVAL = (f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start {{seed}} "
        "--modes glsr,global")
SHIPPED_LABEL = "shipped (51 points, observed path)"
SAME_COMMIT = "both checkpoints at the same commit"
# section -> (first of the two layouts, baseline run, candidate run, candidate's label, candidate's checkpoint, where
# the runs ran): each trial's rows, the shipped checkpoint's first (the baseline of each mode)
TRIALS = {
    "libero-corner-window": (20000, "shipped4", "v4", "v4 (97 corner points, commanded path)",
                             "runs/libero/planner_v4.safetensors", SAME_COMMIT),
    "libero-corner-window-v5": (20000, "shipped5", "v5", "v5 (97 corner points, commanded path, 2000 demos)",
                                "runs/libero/planner_v5.safetensors", SAME_COMMIT),
    "libero-corner-window-v9": (20022, "shipped9", "v9", "v9 (97 corner points, commanded path, from nothing)",
                                "runs/libero/planner_v9.safetensors",
                                "the shipped checkpoint at 28817e1 (stop 43's baseline run), v9 at d9d1e0a: between "
                                "them only training code, the checkpoint metadata check and docs changed"),
    "libero-corner-window-v12": (20055, "shipped12", "v12", "v12 (51 corner points, commanded path, 100 demos a task)",
                                 "runs/libero/planner100_corner.safetensors", SAME_COMMIT),
}


def trial_runs(section: str) -> tuple:
    """(run, mode, checkpoint label, command) of one trial, the shipped checkpoint's rows first."""
    seed, base, run, label, checkpoint, _ = TRIALS[section]
    cmd = EVAL.format(seed=seed)
    return dev_runs.per_mode(((base, SHIPPED_LABEL, f"{cmd} {dev_runs.FOUR_SUITE_MODEL}"),
                              (run, label, f"{cmd} --checkpoint {checkpoint}")))


KEEP = ("task", "suite", "mode", "seed", "success")


def gather() -> None:
    runs = {name: cmd for section in TRIALS for name, _, _, cmd in trial_runs(section)}
    dev_runs.gather(runs.items(), OUT, lambda name, e: (
        {"run": name, **{k: e.get(k) for k in KEEP}} if e["perturb"] == "none" else None))


def lines(section: str) -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    seed, base, run, _, _, where = TRIALS[section]
    runs = trial_runs(section)
    return ([f"Sampled development layouts {seed}-{seed + 1}, all 40 tasks, {where} (successes / episodes; won and "
             "lost against the shipped checkpoint in the same mode on the same layouts):", ""]
            + dev_runs.checkpoint_table(rows, runs)
            + ["", dev_runs.changed_tasks(rows, "global", base, run, 2, "shipped"), "",
               dev_runs.changed_tasks(rows, "glsr", base, run, 2, "shipped")]
            + dev_runs.command_lines("corner_window.py", 2, dict((n, c) for n, _, _, c in runs).items()))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, {section: (lambda s=section: lines(s)) for section in TRIALS})
