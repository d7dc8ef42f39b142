"""The long suite (libero_10) on 60 sampled development layouts per mode (seeds 20000-20005, 6 per task; docs/seeds.md:
never the shipped init states, never 90000+): the shipped checkpoint before and after the retreat from a release,
the 97-point model, and libero_10's own model (examples/configs/train_libero10.yaml), for docs/libero-planner.md,
"The long suite: its own model, and leaving a release" (and the section after it, "libero_10's own model on
corner labels": that model against one trained on the commanded corner labels, on fresh layouts 20020-20025):

    .venv/bin/python docs/libero-planner/long_suite.py --gather   # runs/dev/* -> long_suite.json
    .venv/bin/python docs/libero-planner/long_suite.py            # long_suite.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "long_suite.json"
SECTION = "libero-long-suite"
SECTION_CORNER = "libero-long-suite-corner"
SECTION_LOCAL = "libero-long-suite-localcmd"
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
# layouts 20020-20025, which no checkpoint or executor setting was chosen on before (20000-20019 all were looked at)
L10_FRESH = "tcot eval --suite libero_10 --planners learned --init sampled --episodes 6 --seed-start 20020"
ALL4_FRESH = f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start 20020"
CORNER_CK = "--checkpoint runs/libero/planner_libero10_corner.safetensors"
OWN_FILE = "libero10_before_stop42.safetensors"
OWN_CK = f"--checkpoint {OWN_FILE}"
PUT_DOWN_OFF = "--supervisor.empty-grasp-put-down-m None"
CORNER_COMMANDS = {
    "shipped8": f"{ALL4_FRESH} --modes glsr,global {SHIPPED} {PUT_DOWN_OFF} (before the put-down rule)",
    "l10own": f"{L10_FRESH} --modes glsr,global {OWN_CK} {PUT_DOWN_OFF} "
              "(before the put-down rule)",
    "l10corner": f"{L10_FRESH} --modes glsr,global {CORNER_CK} {PUT_DOWN_OFF} (before the put-down rule)",
    "shipped8_pd": f"{ALL4_FRESH} --modes glsr {SHIPPED} (at 455457c: the rule's first version)",
    "l10own_pd": f"{L10_FRESH} --modes glsr {OWN_CK} (at 455457c: the rule's first version)",
    "l10corner_pd": f"{L10_FRESH} --modes glsr {CORNER_CK} (at 455457c: the rule's first version)",
    "l10corner_pd2": f"{L10_FRESH} --modes glsr {CORNER_CK}",
    "shipped8_pd2": f"{ALL4_FRESH} --modes glsr {SHIPPED}",
}
# layouts 20026-20031, fresh again: local plans on the commanded path (stop 43)
L10_FRESH2 = "tcot eval --suite libero_10 --planners learned --init sampled --episodes 6 --seed-start 20026"
LOCAL_COMMANDS = {
    "l10corner_b": f"{L10_FRESH2} --modes glsr,global "
                   "--checkpoint tcot_hybrid/checkpoints/libero_panda_libero_10.safetensors",
    "l10localcmd": f"{L10_FRESH2} --modes glsr,global "
                   "--checkpoint runs/libero/planner_libero10_localcmd.safetensors",
}
LOCALCMD = "the corner model continued with local plans on the commanded path too (not shipped)"
OWN, CORNER, FOUR = ("libero_10's own model before stop 42 (97 points, observed path)",
                     "libero_10's own model on corner labels (97 commanded corner points; shipped at stop 42)",
                     "shipped (four suites, 51 points)")
BEFORE, FIRST, PUT_DOWN = ("empty-grasp check before the put-down rule",
                           "the put-down rule's first version (the plan ahead of the hand, any plan)",
                           "the put-down rule (the closed stretch of the plan that closed the hand)")
CORNER_ROWS = (
    (OWN, BEFORE, "glsr", ("l10own",)),
    (OWN, FIRST, "glsr", ("l10own_pd",)),
    (CORNER, BEFORE, "glsr", ("l10corner",)),
    (CORNER, FIRST, "glsr", ("l10corner_pd",)),
    (CORNER, PUT_DOWN, "glsr", ("l10corner_pd2",)),
    (FOUR, BEFORE, "glsr", ("shipped8",)),
    (FOUR, FIRST, "glsr", ("shipped8_pd",)),
    (FOUR, PUT_DOWN, "glsr", ("shipped8_pd2",)),
    (OWN, "-", "global", ("l10own",)),
    (CORNER, "-", "global", ("l10corner",)),
    (FOUR, "-", "global", ("shipped8",)),
)


LOCAL_ROWS = (
    (CORNER, PUT_DOWN, "glsr", ("l10corner_b",)),
    (LOCALCMD, PUT_DOWN, "glsr", ("l10localcmd",)),
    (CORNER, "-", "global", ("l10corner_b",)),
    (LOCALCMD, "-", "global", ("l10localcmd",)),
)


def _corner_column(ck: str, how: str, mode: str) -> str:
    short = {OWN: "own model before", CORNER: "corner labels", FOUR: "four suites",
             LOCALCMD: "commanded local plans"}[ck]
    rule = {BEFORE: ", before", FIRST: ", put-down v1", PUT_DOWN: ", put-down"}.get(how, "")
    return f"{short}{rule}, {mode}"


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


def gather() -> None:
    dev_runs.gather_suite([*COMMANDS.items(), *CORNER_COMMANDS.items(), *LOCAL_COMMANDS.items()], OUT, "libero_10")


def _rows() -> list[dict]:
    return [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]


def lines() -> list[str]:
    return (dev_runs.model_table(_rows(), ROWS, "libero_10")
            + dev_runs.command_lines("long_suite.py", 2, COMMANDS.items()))


def corner_lines() -> list[str]:
    return (dev_runs.model_table(_rows(), CORNER_ROWS, "libero_10", first_seed=20020, column=_corner_column)
            + dev_runs.command_lines("long_suite.py", 2, CORNER_COMMANDS.items())
            + ["", f"`{OWN_FILE}` is libero_10's own model before stop 42: `git show "
               f"455457c:tcot_hybrid/checkpoints/libero_panda_libero_10.safetensors > {OWN_FILE}`."])


def local_lines() -> list[str]:
    return (dev_runs.model_table(_rows(), LOCAL_ROWS, "libero_10", first_seed=20026, column=_corner_column)
            + dev_runs.command_lines("long_suite.py", 2, LOCAL_COMMANDS.items()))


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, {SECTION: lines, SECTION_CORNER: corner_lines, SECTION_LOCAL: local_lines})
