"""The long suite (libero_10) on 60 sampled development layouts per mode (seeds 20000-20005, 6 per task; docs/seeds.md:
never the shipped init states, never 90000+): the shipped checkpoint before and after the retreat from a release,
the 97-point model, and libero_10's own model (examples/configs/train_libero10.yaml), for docs/libero-planner.md,
"The long suite: its own model, and leaving a release":

    .venv/bin/python docs/libero-planner/long_suite.py --gather   # runs/dev/* -> long_suite.json
    .venv/bin/python docs/libero-planner/long_suite.py            # long_suite.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "long_suite.json"
SECTION = "libero-long-suite"
ALL4 = f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start 20000"
L10 = "tcot eval --suite libero_10 --planners learned --init sampled --episodes 4 --seed-start 20002"
SHIPPED = dev_runs.FOUR_SUITE_MODEL  # the rows' "shipped (four suites)"
SUITE_CK = "--checkpoint runs/libero/planner_libero10.safetensors"
# run directory under runs/dev -> the command that wrote it (at the commit named in the row)
COMMANDS = {
    "home1": f"{ALL4} --modes glsr --supervisor.home-retries 1 {SHIPPED} (before the retreat)",
    "l10_v2": f"{L10} --modes glsr {SHIPPED} (before the retreat)",
    "l10_v2_sim": f"{L10} --modes glsr --stop-on simulator {SHIPPED} (before the retreat)",
    "v3": f"{ALL4} --modes glsr,global --checkpoint runs/libero/planner_v3.safetensors (before the retreat)",
    "l10_v3": f"{L10} --modes glsr --checkpoint runs/libero/planner_v3.safetensors (before the retreat)",
    "twin2": f"{ALL4} --modes global {SHIPPED} (before the retreat)",
    "retreat": f"{ALL4} --modes glsr,global {SHIPPED}",
    "l10_v2r": f"{L10} --modes glsr {SHIPPED}",
    "l10_v2r_global": f"{L10} --modes global {SHIPPED}",
    "l10_suite": f"tcot eval --suite libero_10 --planners learned --init sampled --episodes 6 --seed-start 20000 "
                 f"--modes glsr,global {SUITE_CK}",
}
# (checkpoint, executor and stop rule, mode, runs whose libero_10 episodes make the row); each mode's first row is the
# baseline its won / lost count against
ROWS = (
    ("shipped (four suites, 51 points)", "before the retreat", "glsr", ("home1", "l10_v2")),
    ("shipped (four suites, 51 points)", "before the retreat, stop on the simulator only", "glsr", ("l10_v2_sim",)),
    ("v3 (four suites, 97 points)", "before the retreat", "glsr", ("v3", "l10_v3")),
    ("shipped (four suites, 51 points)", "retreat from a release", "glsr", ("retreat", "l10_v2r")),
    ("libero_10's own model (97 points)", "retreat from a release", "glsr", ("l10_suite",)),
    ("shipped (four suites, 51 points)", "before the retreat", "global", ("twin2",)),
    ("shipped (four suites, 51 points)", "retreat from a release", "global", ("retreat", "l10_v2r_global")),
    ("libero_10's own model (97 points)", "retreat from a release", "global", ("l10_suite",)),
)
KEEP = ("task", "suite", "mode", "seed", "success", "stopped_by", "premature_stop")


def gather() -> None:
    dev_runs.gather(COMMANDS.items(), OUT, lambda name, e: (
        {"run": name, **{k: e.get(k) for k in KEEP}} if e["perturb"] == "none" and e["suite"] == "libero_10"
        else None))


def _row_episodes(rows: list[dict], runs: tuple[str, ...], mode: str) -> dict:
    return {(r["task"], r["seed"]): r for r in rows if r["run"] in runs and r["mode"] == mode}


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    out = ["libero_10 on sampled development layouts 20000-20005 (6 per task; a row that ran only 20002-20005 says so; "
           "won / lost against the first row of its mode on the layouts both ran):", "",
           "| checkpoint | executor | mode | layouts | successes | won / lost |", "|---|---|---|---|---|---|"]
    base: dict = {}
    per_task: dict = defaultdict(dict)
    for ck, how, mode, runs in ROWS:
        eps = _row_episodes(rows, runs, mode)
        if not eps:
            continue
        seeds = sorted({s for _, s in eps})
        first = mode not in base
        base.setdefault(mode, {k: e["success"] for k, e in eps.items()})
        wl = "-" if first else dev_runs.won_lost(base[mode], list(eps.values()))
        k = sum(e["success"] for e in eps.values())
        out.append(f"| {ck} | {how} | {mode} | {seeds[0]}-{seeds[-1]} ({len(eps)}) | **{k}/{len(eps)}** | {wl} |")
        if len(seeds) == 6:
            name = f"{ck.split(' (')[0]}, {'retreat' if how.startswith('retreat') else 'no retreat'}, {mode}"
            for (task, _), e in eps.items():
                got = per_task[task].setdefault(name, [0, 0])
                got[0] += bool(e["success"])
                got[1] += 1
    cols = list(dict.fromkeys(c for t in per_task.values() for c in t))
    out += ["", "Per task (rows over all six layouts):", "", "| task | " + " | ".join(cols) + " |",
            "|" + "---|" * (len(cols) + 1)]
    for task in sorted(per_task):
        out.append(f"| {task.split(':', 1)[1]} | " + " | ".join(
            "%d/%d" % tuple(per_task[task][c]) if c in per_task[task] else "-" for c in cols) + " |")
    return out + dev_runs.command_lines("long_suite.py", 2, COMMANDS.items())


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
