"""Whether training on spread layouts (`--init spread`, docs/libero-planner.md "Data and seeds") teaches the planner
to look where an object stands: v6 (examples/configs/train_libero_v6.yaml, the shipped checkpoint fine-tuned with the
spread demos added), v7 (train_libero_v7.yaml, the same data for 8 epochs) and v8 (train_libero_v8.yaml, a third of
the spread frames) against the shipped checkpoint, and v10 (train_libero_v10.yaml: v6's recipe without the spread
layouts, the control that tells the new demonstrations' share of the loss from the spread layouts') and v11
(train_libero_v11.yaml: v10 with the tall objects' demonstrations collected again by an oracle that prefers top
grasps),
unperturbed and under `object_moved` and `target_moved`, on sampled development layouts (docs/seeds.md: seeds 20000+,
never the shipped init states, never 90000+). The checkpoints of a table run at the same commit on the same machine:

    .venv/bin/python docs/libero-planner/spread_layouts.py --gather   # runs/dev/* -> spread_layouts.json
    .venv/bin/python docs/libero-planner/spread_layouts.py            # spread_layouts.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path
import long_suite

HERE = Path(__file__).resolve().parent
OUT = HERE / "spread_layouts.json"
SECTION = "libero-spread-layouts-v6"
EVAL = (f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start {{seed}} "
        "--modes glsr,global")
SHIPPED = ("shipped (sampled layouts only)", dev_runs.FOUR_SUITE_MODEL)
V6 = ("v6 (spread layouts added)", "--checkpoint runs/libero/planner_v6.safetensors")
V7 = ("v7 (v6's data, 8 epochs)", "--checkpoint runs/libero/planner_v7.safetensors")
V8 = ("v8 (a third of the spread frames, 12 epochs)", "--checkpoint runs/libero/planner_v8.safetensors")
V10 = ("v10 (no spread frames, 12 epochs)", "--checkpoint runs/libero/planner_v10.safetensors")
V11 = ("v11 (v10 with the tall objects' demos collected again, top grasps preferred)",
       "--checkpoint runs/libero/planner_v11.safetensors")
# (perturbation, the table's heading, its runs: (run, checkpoint), the shipped checkpoint's first, the first of its
# two layouts); each table's runs were made at one commit (the overlap check of a moved object's spot came between
# the two object_moved ones)
TABLES = (("none", "unperturbed (v6 at a46c51e, v7 at a0ea256: nothing is moved, the code between them runs alike)",
           (("shipped6", SHIPPED), ("v6", V6), ("v7", V7)), 20000),
          ("none", "unperturbed, layouts 20020-20021 (the shipped checkpoint in stop 42's runs, global-only from "
           "`shipped8`, GLSR with the put-down rule from `shipped8_pd2` at d25a358; v8 at 28817e1: only training "
           "code and docs changed since)", (("shipped8", SHIPPED, "global"), ("shipped8_pd2", SHIPPED, "glsr"), ("v8", V8)), 20020),
          ("none", "unperturbed, layouts 20024-20025 (the shipped checkpoint in stop 44's baseline run at d9d1e0a, v10 at "
           "ae50039: only docs, a diagnostic script's checkpoint check and training configs changed between)",
           (("shipped10", SHIPPED), ("v10", V10)), 20024),
          ("none", "unperturbed, layouts 20038-20039 (the shipped checkpoint at ae50039, v11 at ec73443: between them "
           "docs, training code and the oracle's side-grasp cost, which a learned episode does not run)",
           (("shipped11", SHIPPED), ("v11", V11)), 20038),
          ("object_moved", "at a46c51e", (("shipped6_objmoved", SHIPPED), ("v6_objmoved", V6)), 20000),
          ("object_moved", "at a0ea256, a moved object's spot checked to overlap nothing",
           (("shipped7_objmoved", SHIPPED), ("v7_objmoved", V7)), 20000),
          ("target_moved", "at a46c51e", (("shipped6_tgtmoved", SHIPPED), ("v6_tgtmoved", V6)), 20000))
KEEP = ("task", "suite", "mode", "seed", "success", "perturb", "perturbation_fired")


def command(perturb: str, checkpoint: str, seed: int) -> str:
    return f"{EVAL.format(seed=seed)} {checkpoint}" + ("" if perturb == "none" else f" --perturb {perturb}")


def trial_runs(table: tuple) -> tuple:
    """(run, mode, checkpoint label, command) of one table, the shipped checkpoint's rows first."""
    perturb, _, runs, seed = table
    rows = dev_runs.per_mode((run, label, long_suite.CORNER_COMMANDS.get(run) or command(perturb, ck, seed))
                             for run, (label, ck), *_ in runs)  # stop 42's runs, as long_suite.py lists them
    only = {run: modes for run, _, *modes in runs if modes}  # the one mode a table takes of a run
    return tuple(r for r in rows if r[0] not in only or r[1] in only[r[0]])


def all_runs() -> dict:
    return {name: cmd for t in TABLES for name, _, _, cmd in trial_runs(t)}


def gather() -> None:
    dev_runs.gather(all_runs().items(), OUT, lambda name, e: {"run": name, **{k: e.get(k) for k in KEEP}})


def fired(rows: list[dict], table: tuple) -> str:
    """How many of each run's episodes the perturbation fired in (a target that is a fixture's region cannot move)."""
    parts = []
    for run, *_ in table[2]:
        eps = [r for r in rows if r["run"] == run]
        parts.append(f"`{run}` {sum(bool(r['perturbation_fired']) for r in eps)} of {len(eps)}")
    return f"The perturbation fired in: {', '.join(parts)} (an episode it did not fire in runs unperturbed)."


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    out = ["Sampled development layouts 20000-20001 unless a table names others, all 40 tasks, the checkpoints of a "
           "table at the same commit on this machine (successes / episodes; won and lost against the shipped "
           "checkpoint in the same mode on the same layouts):"]
    for table in TABLES:
        perturb, heading, runs, _ = table
        names = {run for run, *_ in runs}
        if not any(r["run"] in names for r in rows):
            continue  # not run yet: its commands are listed below
        out += ["", f"Perturbation `{perturb}`, {heading}:", ""]
        out += dev_runs.checkpoint_table([r for r in rows if r["run"] in names], trial_runs(table))
        if perturb != "none":
            out += ["", fired(rows, table)]
    return out + dev_runs.command_lines("spread_layouts.py", 2, all_runs().items())


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
