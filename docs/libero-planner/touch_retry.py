"""Whether a retried grasp should touch down before it closes (``executor.touch_retry_depth_m``; docs/libero-planner.md,
"Touching down on a retry"), judged by the rule set before the runs (docs/seeds.md, stop 67): all 40 tasks under GLSR
at the stack's defaults (the touch acts only after an empty grasp, which GLSR alone looks for), with and without it,
on fresh development layouts (5 a task, 10 on libero_10), twice: the second time with the touch's steps slowed.

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
PER_TASK = {"libero_spatial": 5, "libero_object": 5, "libero_goal": 5, "libero_10": 10}
# (run prefix, what ran, the fresh layouts' first seed per suite); both rules were set before their runs (docs/seeds.md,
# stop 67). The first ran at 450c3e2, its touch at the smoother's full speed; the second at bc783f4, its touch's steps
# planned TOUCH_SLOWER times slower. The first's libero_goal runs were stopped unfinished once libero_10 had failed
# its rule; the table leaves libero_goal out of it.
JUDGEMENTS = (("touch", "first judgement: the touch at full speed (450c3e2)",
               {"libero_spatial": 20042, "libero_object": 20050, "libero_goal": 20201, "libero_10": 20233}),
              ("touch2", "second judgement: the touch four times slower (bc783f4)",
               {"libero_spatial": 20047, "libero_object": 20055, "libero_goal": 20206, "libero_10": 20243}))
SETTINGS = (("off", "closes where planned", ""),
            ("on", "a retried grasp touches down first (8 cm at most)", " --executor.touch-retry-depth-m 0.08"))
KEEP = ("task", "suite", "mode", "seed", "success", "empty_grasps")


def _command(suite: str, first: int, flag: str) -> str:
    return (f"tcot eval --suite {suite} --planners learned --modes glsr --init sampled --episodes {PER_TASK[suite]} "
            f"--seed-start {first}{flag}")


def _runs() -> list[tuple[str, str, str]]:
    """(run directory under runs/dev, its judgement's prefix and setting, command): one run per judgement, suite and
    setting."""
    return [(f"{prefix}_{name}_{suite}", f"{prefix}_{name}", _command(suite, first[suite], flag))
            for prefix, _, first in JUDGEMENTS for name, _, flag in SETTINGS for suite in first]


def _row(setting: str, e: dict) -> dict | None:
    if e["perturb"] != "none":
        return None
    touches = [x for x in e["events"] if x["kind"] == "touch"]
    return {"run": setting, **{k: e.get(k) for k in KEEP}, "touches": len(touches),
            "touched": sum(bool(x["touched"]) for x in touches)}


def gather() -> None:
    setting = {run: name for run, name, _ in _runs()}
    dev_runs.gather(((run, cmd) for run, _, cmd in _runs()), OUT, lambda run, e: _row(setting[run], e))


def _judgement(rows: list[dict], prefix: str, label: str, first: dict) -> list[str]:
    ran = Counter((r["run"], r["suite"]) for r in rows)
    done = {s for s in first if all(ran[(f"{prefix}_{n}", s)] == 10 * PER_TASK[s] for n, _, _ in SETTINGS)}
    rows = [r for r in rows if r["run"].startswith(prefix + "_") and r["suite"] in done]
    layouts = ", ".join(f"{s} {first[s]}-{first[s] + PER_TASK[s] - 1}" for s in first if s in done)
    on = [r for r in rows if r["run"] == f"{prefix}_on"]
    n_touch = Counter(r["suite"] for r in on if r["touches"])
    fired = (f"With the touch on, {sum(r['touches'] for r in on)} grasps touched down in {sum(n_touch.values())} of "
             f"{len(on)} episodes ({', '.join(f'{s} {n_touch[s]}' for s in first if s in done)}); "
             f"{sum(r['touched'] for r in on)} of them felt the touch before their 8 cm were used up.")
    table_rows = tuple((f"{prefix}_{name}", "glsr", text, "") for name, text, _ in SETTINGS)
    return ([f"**{label[0].upper() + label[1:]}.** Sampled development layouts ({layouts}), all ten tasks of each "
             "suite, GLSR at the stack's defaults (no `--checkpoint`); won / lost against the first row on the same "
             "layouts:", ""]
            + dev_runs.checkpoint_table(rows, table_rows, head="a retried grasp")
            + ["", fired, "", dev_runs.changed_tasks(rows, "glsr", f"{prefix}_off", f"{prefix}_on", "5 or 10",
                                                     f"{prefix}_off"), ""])


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    return ([line for prefix, label, first in JUDGEMENTS for line in _judgement(rows, prefix, label, first)]
            + dev_runs.command_lines("touch_retry.py", 2, [(run, cmd) for run, _, cmd in _runs()]))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
