"""Whether a 97-point window of the commanded path, each piece's points at its corners, replaces the shipped
checkpoint (docs/libero-planner.md, "A longer global window"), on sampled development layouts (docs/seeds.md: seeds
20000+, never the shipped init states, never 90000+): v4 (examples/configs/train_libero_v4.yaml, the first 1000
demos) and v5 (train_libero_v5.yaml, all 2000). Each trial's checkpoints run at the same commit on the same machine,
so its baseline is not an older run's:

    .venv/bin/python docs/libero-planner/corner_window.py --gather   # runs/dev/* -> corner_window.json
    .venv/bin/python docs/libero-planner/corner_window.py            # corner_window.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "corner_window.json"
EVAL = (f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start 20000 "
        "--modes glsr,global")
SHIPPED = f"{EVAL} {dev_runs.FOUR_SUITE_MODEL}"
SHIPPED_LABEL = "shipped (51 points, observed path)"
# section -> (baseline run, candidate run, candidate's label, candidate's command): each trial's rows, the shipped
# checkpoint's first (the baseline of each mode)
TRIALS = {
    "libero-corner-window": ("shipped4", "v4", "v4 (97 corner points, commanded path)",
                             f"{EVAL} --checkpoint runs/libero/planner_v4.safetensors"),
    "libero-corner-window-v5": ("shipped5", "v5", "v5 (97 corner points, commanded path, 2000 demos)",
                                f"{EVAL} --checkpoint runs/libero/planner_v5.safetensors"),
}


def trial_runs(section: str) -> tuple:
    """(run, mode, checkpoint label, command) of one trial, the shipped checkpoint's rows first."""
    base, run, label, cmd = TRIALS[section]
    return dev_runs.per_mode(((base, SHIPPED_LABEL, SHIPPED), (run, label, cmd)))


KEEP = ("task", "suite", "mode", "seed", "success")


def gather() -> None:
    runs = {name: cmd for section in TRIALS for name, _, _, cmd in trial_runs(section)}
    dev_runs.gather(runs.items(), OUT, lambda name, e: (
        {"run": name, **{k: e.get(k) for k in KEEP}} if e["perturb"] == "none" else None))


def changed_tasks(rows: list[dict], mode: str, base: str, run: str) -> str:
    """Tasks whose successes differ between the shipped checkpoint (run ``base``) and the candidate in ``mode``."""
    count: dict = defaultdict(lambda: defaultdict(int))
    for r in rows:
        if r["mode"] == mode:
            count[r["task"].split(":", 1)[1]][r["run"]] += r["success"]
    diff = [f"{t} {c[base]} -> {c[run]}" for t, c in sorted(count.items()) if c[base] != c[run]]
    return f"Tasks whose count differs in {mode} (of 2, shipped -> {run}): " + ("; ".join(diff) or "none") + "."


def lines(section: str) -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    base, run, _, _ = TRIALS[section]
    runs = trial_runs(section)
    return (["Sampled development layouts 20000-20001, all 40 tasks, both checkpoints at the same commit (successes / "
             "episodes; won and lost against the shipped checkpoint in the same mode on the same layouts):", ""]
            + dev_runs.checkpoint_table(rows, runs)
            + ["", changed_tasks(rows, "global", base, run), "", changed_tasks(rows, "glsr", base, run)]
            + dev_runs.command_lines("corner_window.py", 2, dict((n, c) for n, _, _, c in runs).items()))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, {section: (lambda s=section: lines(s)) for section in TRIALS})
