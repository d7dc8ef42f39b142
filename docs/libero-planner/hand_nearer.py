"""Whether the executor should also solve a hand's half-turned twin when a plan asks the hand to turn more than 90
degrees from the hand of the previous waypoint's IK answer (``executor.TWIN_TURN_RAD``; docs/libero-planner.md, "The
hand the arm stands nearer"), on sampled development layouts (docs/seeds.md: seeds 20000+, never the shipped init
states, never 90000+).
Then the same with a margin: the twin taken for less joint travel alone only when it saves more than 0.5 rad
(``executor.TWIN_TRAVEL_MARGIN_RAD``). Same checkpoints (the stack's defaults: the four-suite v12 and libero_10's own
model), same machine; the baseline ran at 867c9b2, the commit before the first rule, the first rule alone at a27107c:

    .venv/bin/python docs/libero-planner/hand_nearer.py --gather   # runs/dev/* -> hand_nearer.json
    .venv/bin/python docs/libero-planner/hand_nearer.py            # hand_nearer.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "hand_nearer.json"
SECTION = "libero-hand-nearer"
FIRST, PER_TASK = 20057, 4
EVAL = f"tcot eval --suite {dev_runs.S4} --init sampled --episodes {PER_TASK} --seed-start {FIRST}"
BEFORE, AFTER = "twin on a miss or a limit (867c9b2)", "and on a turn over 90 degrees (a27107c)"
MARGIN = "and a 0.5 rad travel margin"
# (run directory under runs/dev, mode, executor label, command); each mode's first row is its baseline
LEARNED = dev_runs.per_mode((
    ("twin_base", f"learned, {BEFORE}", f"{EVAL} --planners learned --modes glsr,global (at 867c9b2)"),
    ("twin_turn", f"learned, {AFTER}", f"{EVAL} --planners learned --modes glsr,global (at a27107c)"),
    ("twin_margin", f"learned, {MARGIN}", f"{EVAL} --planners learned --modes glsr,global")))
ORACLE = (("twin_base_oracle", "global", f"oracle, {BEFORE}", f"{EVAL} --planners oracle --modes global (at 867c9b2)"),
          ("twin_turn_oracle", "global", f"oracle, {AFTER}", f"{EVAL} --planners oracle --modes global (at a27107c)"),
          ("twin_margin_oracle", "global", f"oracle, {MARGIN}", f"{EVAL} --planners oracle --modes global"))
KEEP = ("task", "suite", "mode", "seed", "success")


def _commands() -> dict:
    return {name: cmd for name, _, _, cmd in LEARNED + ORACLE}


def gather() -> None:
    dev_runs.gather(_commands().items(), OUT, lambda name, e: (
        {"run": name, **{k: e.get(k) for k in KEEP}, "hand_turned": sum(
            x["kind"] == "hand_turned" for x in e.get("events", []))} if e["perturb"] == "none" else None))


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    oracle = [r for r in rows if r["run"].endswith("_oracle")]
    learned = [r for r in rows if not r["run"].endswith("_oracle")]
    counts = Counter((r["run"], r["mode"]) for r in rows if r["hand_turned"])
    return ([f"Sampled development layouts {FIRST}-{FIRST + PER_TASK - 1}, all 40 tasks ({PER_TASK * 40} episodes a "
             "row; won / lost against the first row of its mode on the same layouts):", ""]
            + dev_runs.checkpoint_table(learned, LEARNED, head="planner, executor")
            + dev_runs.checkpoint_table(oracle, ORACLE, head="planner, executor")[2:]
            + ["", "Episodes with a `hand_turned` event: " + "; ".join(
                f"{label}, {mode}: {counts.get((run, mode), 0)}" for run, mode, label, _ in LEARNED + ORACLE) + "."]
            + [line for rows_, mode, base, run in ((learned, "global", "twin_base", "twin_turn"),
                                                   (learned, "glsr", "twin_base", "twin_turn"),
                                                   (learned, "global", "twin_turn", "twin_margin"),
                                                   (learned, "glsr", "twin_turn", "twin_margin"),
                                                   (oracle, "global", "twin_base_oracle", "twin_margin_oracle"))
               for line in ("", dev_runs.changed_tasks(rows_, mode, base, run, PER_TASK, base))]
            + dev_runs.command_lines("hand_nearer.py", 2, _commands().items()))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
