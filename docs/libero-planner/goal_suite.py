"""The goal suite (libero_goal) on sampled development layouts 20000-20005 (6 per task; docs/seeds.md: never the
shipped init states, never 90000+): the four-suite model with and without the retreat from a release, the 97-point
model, and libero_goal's own model started from either (examples/configs/train_libero_goal97.yaml,
train_libero_goal.yaml), for docs/libero-planner.md, "The goal suite's own model":

    .venv/bin/python docs/libero-planner/goal_suite.py --gather   # runs/dev/* -> goal_suite.json
    .venv/bin/python docs/libero-planner/goal_suite.py            # goal_suite.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path
import long_suite

HERE = Path(__file__).resolve().parent
OUT = HERE / "goal_suite.json"
SECTION = "libero-goal-suite"
GOAL = "tcot eval --suite libero_goal --planners learned --init sampled"
# run directory under runs/dev -> the command that wrote it (the four-suite runs are long_suite.py's)
COMMANDS = {
    **{k: long_suite.COMMANDS[k] for k in ("home1", "v3", "retreat")},
    "goal_r": f"{GOAL} --episodes 4 --seed-start 20002 --modes glsr {dev_runs.FOUR_SUITE_MODEL}",
    "goal_nor": f"{GOAL} --episodes 4 --seed-start 20002 --modes glsr --executor.release-retreat-m None "
                f"{dev_runs.FOUR_SUITE_MODEL}",
    "goal_suite97": f"{GOAL} --episodes 6 --seed-start 20000 --modes glsr,global "
                    "--checkpoint runs/libero/planner_libero_goal97.safetensors",
    "goal_suite51": f"{GOAL} --episodes 6 --seed-start 20000 --modes glsr,global "
                    "--checkpoint runs/libero/planner_libero_goal.safetensors",
}
# (checkpoint, executor, mode, runs whose libero_goal episodes make the row); each mode's first row is the baseline
ROWS = (
    ("shipped (four suites, 51 points)", "retreat from a release", "glsr", ("retreat", "goal_r")),
    ("shipped (four suites, 51 points)", "before the retreat", "glsr", ("home1", "goal_nor")),
    ("v3 (four suites, 97 points)", "before the retreat", "glsr", ("v3",)),
    ("libero_goal's own model, from v3 (97 points)", "retreat from a release", "glsr", ("goal_suite97",)),
    ("libero_goal's own model, from the shipped (51 points)", "retreat from a release", "glsr", ("goal_suite51",)),
    ("shipped (four suites, 51 points)", "retreat from a release", "global", ("retreat",)),
    ("libero_goal's own model, from v3 (97 points)", "retreat from a release", "global", ("goal_suite97",)),
    ("libero_goal's own model, from the shipped (51 points)", "retreat from a release", "global", ("goal_suite51",)),
)


def gather() -> None:
    dev_runs.gather_suite(COMMANDS.items(), OUT, "libero_goal")


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    return dev_runs.model_table(rows, ROWS, "libero_goal") + dev_runs.command_lines("goal_suite.py", 2,
                                                                                   COMMANDS.items())


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
