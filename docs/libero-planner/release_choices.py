"""How the shipped LIBERO checkpoint's last training run was chosen (docs/libero-planner.md, "Demonstrations through
the release"), global-only on sampled development layouts (docs/seeds.md: seeds 20000+, never the shipped init
states, never 90000+):

    .venv/bin/python docs/libero-planner/release_choices.py --gather   # runs/dev/* -> release_choices.json
    .venv/bin/python docs/libero-planner/release_choices.py            # release_choices.json -> docs/libero-planner.md

Each candidate fine-tunes the 2000-demo run (runs/libero/planner50.safetensors) with examples/configs/
train_libero_v2.yaml or a variant of it; the RUNS table names the checkpoint, the data and the windows of each.
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "release_choices.json"
SUITES, S4 = dev_runs.SUITES, dev_runs.S4
SECTION = "libero-release-choices"
EVAL = f"tcot eval --suite {S4} --planners learned --modes global --init sampled --episodes 2 --seed-start 20000"
# (run directory under runs/dev, checkpoint, what it is, command)
RUNS = (
    ("tf16", "2000-demo run", "6 points per piece; demos ending a few steps after success",
     f"{EVAL} (the global rows of glsr_choices.py's tf16)"),
    ("v2_global", "runs/libero/v2a/planner_v2", "4 points per piece; every success reached holding carried through "
     "the plan (recollection part 1 only)", f"{EVAL} --checkpoint runs/libero/v2a/planner_v2.safetensors"),
    ("v2b_global", "runs/libero/v2b/planner_v2", "4 points per piece; demos through the release (both parts)",
     f"{EVAL} --checkpoint runs/libero/v2b/planner_v2.safetensors"),
    ("v2p6_global", "runs/libero/planner_v2p6", "6 points per piece; demos through the release (both parts)",
     f"{EVAL} --checkpoint runs/libero/planner_v2p6.safetensors"),
    ("sidehand_global", "runs/libero/planner_v2p6", "the same, hands without a yaw kept continuous along the plan "
     "(docs/libero-planner.md, \"Side grasps and the wrist\")", f"{EVAL} {dev_runs.FOUR_SUITE_MODEL} (the shipped checkpoint)"),
)
KEEP = ("task", "suite", "mode", "seed", "success", "stopped_by", "steps")


def gather() -> None:
    dev_runs.gather(((name, cmd) for name, _, _, cmd in RUNS), OUT, lambda name, e: (
        {"run": name, **{k: e.get(k) for k in KEEP}} if e["mode"] == "global" and e["perturb"] == "none" else None))


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    by_run: dict = defaultdict(list)
    for r in rows:
        by_run[r["run"]].append(r)
    base = {(r["task"], r["seed"]): r["success"] for r in by_run.get(RUNS[0][0], [])}
    out = ["Global-only, sampled development layouts 20000-20001, all 40 tasks (successes / episodes; won and lost "
           "against the 2000-demo run on the same layouts):", "",
           "| checkpoint | windows and data | " + " | ".join(SUITES) + " | all four | won / lost |",
           "|" + "---|" * (len(SUITES) + 4)]
    for name, ck, what, _ in RUNS:
        eps = by_run.get(name)
        if not eps:
            continue
        per = dev_runs.per_suite(eps)
        wl = "-" if name == RUNS[0][0] else dev_runs.won_lost(base, eps)
        out.append(f"| `{ck}` | {what} | " + " | ".join(per)
                   + f" | {sum(e['success'] for e in eps)}/{len(eps)} | {wl} |")
    out += dev_runs.command_lines("release_choices.py", 2, ((name, cmd) for name, _, _, cmd in RUNS))
    return out


def main() -> None:
    dev_runs.main(__doc__, gather, lines, SECTION)


if __name__ == "__main__":
    main()
