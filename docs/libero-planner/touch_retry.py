"""Whether a retried grasp should touch down before it closes (``executor.touch_retry_depth_m``; docs/libero-planner.md,
"Touching down on a retry"), judged by the rule set before the runs (docs/seeds.md, stop 67): all 40 tasks under GLSR
at the stack's defaults (the touch acts only after an empty grasp, which GLSR alone looks for), with and without it,
on fresh development layouts (5 a task, 10 on libero_10).

    .venv/bin/python docs/libero-planner/touch_retry.py --gather   # runs/dev/touch_* -> touch_retry.json
    .venv/bin/python docs/libero-planner/touch_retry.py            # touch_retry.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "touch_retry.json"
SECTION = "libero-touch-retry"
FIRST = {"libero_spatial": 20042, "libero_object": 20050, "libero_goal": 20201, "libero_10": 20233}
PER_TASK = {"libero_spatial": 5, "libero_object": 5, "libero_goal": 5, "libero_10": 10}
# (run prefix, label, tcot eval flag); both ran at 450c3e2, where the touch was off by default
SETTINGS = (("touch_off", "closes where planned", ""),
            ("touch_on", "a retried grasp touches down first (8 cm at most)", " --executor.touch-retry-depth-m 0.08"))
KEEP = ("task", "suite", "mode", "seed", "success", "empty_grasps")


def _command(suite: str, flag: str) -> str:
    return (f"tcot eval --suite {suite} --planners learned --modes glsr --init sampled --episodes {PER_TASK[suite]} "
            f"--seed-start {FIRST[suite]}{flag}")


def _runs() -> list[tuple[str, str, str]]:
    """(run directory under runs/dev, setting, command): one run per suite and setting."""
    return [(f"{name}_{suite}", name, _command(suite, flag)) for name, _, flag in SETTINGS for suite in FIRST]


def _row(setting: str, e: dict) -> dict | None:
    if e["perturb"] != "none":
        return None
    touches = [x for x in e["events"] if x["kind"] == "touch"]
    return {"run": setting, **{k: e.get(k) for k in KEEP}, "touches": len(touches),
            "touched": sum(bool(x["touched"]) for x in touches)}


def gather() -> None:
    setting = {run: name for run, name, _ in _runs()}
    dev_runs.gather(((run, cmd) for run, _, cmd in _runs()), OUT, lambda run, e: _row(setting[run], e))


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    table_rows = dev_runs.per_mode((name, label, "") for name, label, _ in SETTINGS)
    layouts = ", ".join(f"{s} {FIRST[s]}-{FIRST[s] + PER_TASK[s] - 1}" for s in FIRST)
    on = [r for r in rows if r["run"] == "touch_on"]
    n_touch = Counter(r["suite"] for r in on if r["touches"])
    fired = (f"With the touch on, {sum(r['touches'] for r in on)} grasps touched down in {sum(n_touch.values())} of "
             f"{len(on)} episodes ({', '.join(f'{s} {n_touch[s]}' for s in FIRST)}); "
             f"{sum(r['touched'] for r in on)} of them felt the touch before their 8 cm were used up.")
    return ([f"Sampled development layouts ({layouts}), all ten tasks of each suite, GLSR at the stack's defaults (no "
             "`--checkpoint`); won / lost against the first row on the same layouts:", ""]
            + dev_runs.checkpoint_table(rows, table_rows, head="a retried grasp")
            + ["", fired, "", dev_runs.changed_tasks(rows, "glsr", "touch_off", "touch_on", "5 or 10", "touch_off")]
            + dev_runs.command_lines("touch_retry.py", 2, [(run, cmd) for run, _, cmd in _runs()]))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
