"""Whether training on spread layouts (`--init spread`, docs/libero-planner.md "Data and seeds") teaches the planner
to look where an object stands: v6 (examples/configs/train_libero_v6.yaml, the shipped checkpoint fine-tuned with the
spread demos added) and v7 (train_libero_v7.yaml, the same data for 8 epochs) against the shipped checkpoint,
unperturbed and under `object_moved` and `target_moved`, on sampled development layouts (docs/seeds.md: seeds 20000+,
never the shipped init states, never 90000+). The checkpoints of a table run at the same commit on the same machine:

    .venv/bin/python docs/libero-planner/spread_layouts.py --gather   # runs/dev/* -> spread_layouts.json
    .venv/bin/python docs/libero-planner/spread_layouts.py            # spread_layouts.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "spread_layouts.json"
SECTION = "libero-spread-layouts-v6"
EVAL = (f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start 20000 "
        "--modes glsr,global")
SHIPPED = ("shipped (sampled layouts only)", dev_runs.FOUR_SUITE_MODEL)
V6 = ("v6 (spread layouts added)", "--checkpoint runs/libero/planner_v6.safetensors")
V7 = ("v7 (v6's data, 8 epochs)", "--checkpoint runs/libero/planner_v7.safetensors")
# (perturbation, the table's heading, its runs: (run, checkpoint), the shipped checkpoint's first); each table's
# runs were made at one commit (the overlap check of a moved object's spot came between the two object_moved ones)
TABLES = (("none", "unperturbed (v6 at a46c51e, v7 at a0ea256: nothing is moved, the code between them runs alike)",
           (("shipped6", SHIPPED), ("v6", V6), ("v7", V7))),
          ("object_moved", "at a46c51e", (("shipped6_objmoved", SHIPPED), ("v6_objmoved", V6))),
          ("object_moved", "at a0ea256, a moved object's spot checked to overlap nothing",
           (("shipped7_objmoved", SHIPPED), ("v7_objmoved", V7))),
          ("target_moved", "at a46c51e", (("shipped6_tgtmoved", SHIPPED), ("v6_tgtmoved", V6))))
KEEP = ("task", "suite", "mode", "seed", "success", "perturb", "perturbation_fired")


def command(perturb: str, checkpoint: str) -> str:
    return f"{EVAL} {checkpoint}" + ("" if perturb == "none" else f" --perturb {perturb}")


def trial_runs(table: tuple) -> tuple:
    """(run, mode, checkpoint label, command) of one table, the shipped checkpoint's rows first."""
    perturb, _, runs = table
    return dev_runs.per_mode((run, label, command(perturb, ck)) for run, (label, ck) in runs)


def all_runs() -> dict:
    return {name: cmd for t in TABLES for name, _, _, cmd in trial_runs(t)}


def gather() -> None:
    dev_runs.gather(all_runs().items(), OUT, lambda name, e: {"run": name, **{k: e.get(k) for k in KEEP}})


def fired(rows: list[dict], table: tuple) -> str:
    """How many of each run's episodes the perturbation fired in (a target that is a fixture's region cannot move)."""
    parts = []
    for run, _ in table[2]:
        eps = [r for r in rows if r["run"] == run]
        parts.append(f"`{run}` {sum(bool(r['perturbation_fired']) for r in eps)} of {len(eps)}")
    return f"The perturbation fired in: {', '.join(parts)} (an episode it did not fire in runs unperturbed)."


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    out = ["Sampled development layouts 20000-20001, all 40 tasks, the checkpoints of a table at the same commit on "
           "this machine (successes / episodes; won and lost against the shipped checkpoint in the same mode on the "
           "same layouts):"]
    for table in TABLES:
        perturb, heading, runs = table
        names = {run for run, _ in runs}
        if not any(r["run"] in names for r in rows):
            continue  # not run yet: its commands are listed below
        out += ["", f"Perturbation `{perturb}`, {heading}:", ""]
        out += dev_runs.checkpoint_table([r for r in rows if r["run"] in names], trial_runs(table))
        if perturb != "none":
            out += ["", fired(rows, table)]
    return out + dev_runs.command_lines("spread_layouts.py", 2, all_runs().items())


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
