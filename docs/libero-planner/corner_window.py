"""Whether v4 (examples/configs/train_libero_v4.yaml: 97 global points on the commanded path, each piece's points at
its corners) replaces the shipped checkpoint (docs/libero-planner.md, "A longer global window"), on sampled
development layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+). Both checkpoints
run at the same commit, so the baseline is not an older run's:

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
SECTION = "libero-corner-window"
EVAL = (f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start 20000 "
        "--modes glsr,global")
SHIPPED = f"{EVAL} {dev_runs.FOUR_SUITE_MODEL}"
V4 = f"{EVAL} --checkpoint runs/libero/planner_v4.safetensors"
# (run, mode, checkpoint, command); the shipped checkpoint's rows first: the baseline of each mode
RUNS = (
    ("shipped4", "global", "shipped (51 points, observed path)", SHIPPED),
    ("shipped4", "glsr", "shipped (51 points, observed path)", SHIPPED),
    ("v4", "global", "v4 (97 corner points, commanded path)", V4),
    ("v4", "glsr", "v4 (97 corner points, commanded path)", V4),
)
KEEP = ("task", "suite", "mode", "seed", "success")


def gather() -> None:
    runs = {name: cmd for name, _, _, cmd in RUNS}
    dev_runs.gather(runs.items(), OUT, lambda name, e: (
        {"run": name, **{k: e.get(k) for k in KEEP}} if e["perturb"] == "none" else None))


def changed_tasks(rows: list[dict], mode: str) -> str:
    """Tasks whose successes differ between the shipped checkpoint and v4 in ``mode``."""
    count: dict = defaultdict(lambda: defaultdict(int))
    for r in rows:
        if r["mode"] == mode:
            count[r["task"].split(":", 1)[1]][r["run"]] += r["success"]
    diff = [f"{t} {c['shipped4']} -> {c['v4']}" for t, c in sorted(count.items()) if c["shipped4"] != c["v4"]]
    return f"Tasks whose count differs in {mode} (of 2, shipped -> v4): " + ("; ".join(diff) or "none") + "."


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    return (["Sampled development layouts 20000-20001, all 40 tasks, both checkpoints at the same commit (successes / "
             "episodes; won and lost against the shipped checkpoint in the same mode on the same layouts):", ""]
            + dev_runs.checkpoint_table(rows, RUNS) + ["", changed_tasks(rows, "global"), "",
                                                       changed_tasks(rows, "glsr")]
            + dev_runs.command_lines("corner_window.py", 2, dict((n, c) for n, _, _, c in RUNS).items()))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
