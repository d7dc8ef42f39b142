"""Whether training on spread layouts (`--init spread`, docs/libero-planner.md "Data and seeds") teaches the planner
to look where an object stands: v6 (examples/configs/train_libero_v6.yaml, the shipped checkpoint fine-tuned with the
spread demos added) against the shipped checkpoint, unperturbed and under `object_moved` and `target_moved`, on
sampled development layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+). Both
checkpoints run at the same commit on the same machine:

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
# perturbation -> (shipped checkpoint's run, v6's run)
RUNS = {"none": ("shipped6", "v6"),
        "object_moved": ("shipped6_objmoved", "v6_objmoved"),
        "target_moved": ("shipped6_tgtmoved", "v6_tgtmoved")}
KEEP = ("task", "suite", "mode", "seed", "success", "perturb", "perturbation_fired")


def command(perturb: str, checkpoint: str) -> str:
    return f"{EVAL} {checkpoint}" + ("" if perturb == "none" else f" --perturb {perturb}")


def trial_runs(perturb: str) -> tuple:
    """(run, mode, checkpoint label, command) of one perturbation, the shipped checkpoint's rows first."""
    return tuple((run, mode, label, command(perturb, ck))
                 for run, (label, ck) in zip(RUNS[perturb], (SHIPPED, V6)) for mode in ("global", "glsr"))


def gather() -> None:
    runs = {name: cmd for p in RUNS for name, _, _, cmd in trial_runs(p)}
    dev_runs.gather(runs.items(), OUT, lambda name, e: {"run": name, **{k: e.get(k) for k in KEEP}})


def fired(rows: list[dict], perturb: str) -> str:
    """How many of each run's episodes the perturbation fired in (a target that is a fixture's region cannot move)."""
    parts = []
    for run in RUNS[perturb]:
        eps = [r for r in rows if r["run"] == run]
        parts.append(f"`{run}` {sum(bool(r['perturbation_fired']) for r in eps)} of {len(eps)}")
    return f"The perturbation fired in: {', '.join(parts)} (an episode it did not fire in runs unperturbed)."


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    out = ["Sampled development layouts 20000-20001, all 40 tasks, both checkpoints at the same commit (successes / "
           "episodes; won and lost against the shipped checkpoint in the same mode on the same layouts):"]
    for perturb in RUNS:
        out += ["", f"Perturbation `{perturb}`:", ""]
        out += dev_runs.checkpoint_table([r for r in rows if r["perturb"] == perturb], trial_runs(perturb))
        if perturb != "none":
            out += ["", fired(rows, perturb)]
    runs = [(n, c) for p in RUNS for n, _, _, c in trial_runs(p)]
    return out + dev_runs.command_lines("spread_layouts.py", 2, dict(runs).items())


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
