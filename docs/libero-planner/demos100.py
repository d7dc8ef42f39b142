"""Whether the 100-demonstrations-per-task checkpoint (examples/configs/train_libero100.yaml, from nothing on today's
oracle's 4000 demonstrations) replaces the four-suite checkpoint shipped before it (docs/libero-planner.md, "100
demonstrations per task"): both on the same fresh sampled development layouts 20053-20054 (docs/seeds.md; never the
shipped init states, never 90000+), all four suites, global-only and GLSR, at the same commit (d72226e's code):

    .venv/bin/python docs/libero-planner/demos100.py --gather   # runs/dev/h100{,base} -> demos100.jsonl
    .venv/bin/python docs/libero-planner/demos100.py            # demos100.jsonl -> docs/libero-planner.md

The baseline's checkpoint is the one shipped until stop 54: `git show d72226e:tcot_hybrid/checkpoints/
libero_panda_default.safetensors` (and its .json beside it) puts it back in a file to pass as --checkpoint.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "demos100.jsonl"
SECTION = "libero-demos100"
EVAL = (f"tcot eval --suite {dev_runs.S4} --planners learned --modes global,glsr --init sampled --episodes 2 "
        "--seed-start 20053")
# run under runs/dev -> (label, --checkpoint), the baseline first
RUNS = {"h100base": ("shipped until stop 54 (2000 demos, a0018e6's oracle)",
                     "the d72226e checkpoint (see the docstring)"),
        "h100": ("100 per task (4000 demos, today's oracle)", "runs/libero/planner100.safetensors")}
KEEP = ("task", "suite", "mode", "seed", "success", "checkpoint_hash", "premature_stop")


def gather() -> None:
    dev_runs.gather(((name, f"{EVAL} --checkpoint {ck}") for name, (_, ck) in RUNS.items()), OUT,
                    lambda name, e: {"run": name, **{k: e.get(k) for k in KEEP}} if e["perturb"] == "none" else None)


def markdown(rows: list[dict]) -> str:
    def label(name: str, mode: str) -> str:
        hashes = ", ".join(sorted({str(r["checkpoint_hash"]) for r in rows if r["run"] == name and r["mode"] == mode}))
        return f"{RUNS[name][0]} (`{hashes}`)"

    runs = [(name, mode, label(name, mode), None) for name in RUNS for mode in ("global", "glsr")]
    lines = [f"`{EVAL}`, each checkpoint by `--checkpoint`, the same stack code (the baseline on 1 worker, the "
             "candidate on 2; `docs/libero-planner/demos100.py` → `demos100.jsonl`); successes per suite, and won / "
             "lost against the first row on the same layouts:", ""] + dev_runs.checkpoint_table(rows, runs)
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gather", action="store_true",
                    help="read runs/dev/h100 and runs/dev/h100base into demos100.jsonl")
    if ap.parse_args().gather:
        gather()
    from tcot_hybrid.markdown import update_readme_section

    rows = [json.loads(line) for line in OUT.read_text().splitlines() if line.strip()]
    text = markdown(rows)
    update_readme_section(Path(dev_runs.ROOT) / "docs" / "libero-planner.md", SECTION, text)
    print(text)


if __name__ == "__main__":
    main()
