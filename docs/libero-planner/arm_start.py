"""What the arm's start costs the shipped planner (docs/libero-planner.md, "Data and seeds", "The arm's start"): the same
sampled development layouts (docs/seeds.md) with the arm exactly at home, as every sampled layout and demonstration
started before stop 49, and off home by robosuite's default joint noise, as LIBERO's shipped init states start and
sampled layouts now do. The noise has its own generator, so the objects stand alike in both; the runs at home ran at
283b1fb (the commit before the noise), the others at the current code. Never the shipped init states:

    .venv/bin/python docs/libero-planner/arm_start.py --gather   # runs/dev/* -> arm_start.json
    .venv/bin/python docs/libero-planner/arm_start.py            # arm_start.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
import statistics
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "arm_start.json"
SECTION = "libero-arm-start"
BASE = (f"tcot eval --suite {dev_runs.S4} --planners learned --modes glsr --init sampled {dev_runs.FOUR_SUITE_MODEL} "
        "--episodes 2 --seed-start 20047")
AT_HOME = "at home (283b1fb)"
OFF_HOME = "off home, 0.02 rad"
# (run directory under runs/dev, perturbation, the arm's start, command); each perturbation's first run is the
# baseline its won / lost counts against
RUNS = (
    ("home49", "none", AT_HOME, f"{BASE} (at 283b1fb)"),
    ("noise49", "none", OFF_HOME, BASE),
    ("camshift_home49", "camera_shift", AT_HOME, f"{BASE} --perturb camera_shift (at 283b1fb)"),
    ("camshift_noise49", "camera_shift", OFF_HOME, f"{BASE} --perturb camera_shift"),
)
KEEP = ("task", "suite", "seed", "perturb", "success", "premature_stop", "replans", "wall_time_s")


def gather() -> None:
    def row(name: str, e: dict) -> dict:
        cal = e["camera_calibration"]
        return {"run": name, **{k: e.get(k) for k in KEEP}, "refined": cal["refined"],
                "nominal_error_px": cal["nominal_error_px"]}

    dev_runs.gather(((name, cmd) for name, _, _, cmd in RUNS), OUT, row)


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    by: dict = defaultdict(list)
    for r in rows:
        by[r["run"]].append(r)
    out = ["GLSR, four-suite checkpoint, sampled development layouts 20047-20048 (80 per row; won / lost against the "
           "arm at home, layout for layout; re-fitted: episodes whose camera self-calibration took a fit; nominal "
           "error: the median over episodes of the median distance between where the planner saw the hand and where "
           "the nominal camera puts it):", "",
           "| perturbation | arm start | " + " | ".join(dev_runs.SUITES) + " | all four | won / lost | re-fitted | "
           "nominal error [px] |", "|" + "---|" * (len(dev_runs.SUITES) + 6)]
    base: dict = {}
    for name, perturb, start, _ in RUNS:
        eps = by.get(name)
        if not eps:
            continue
        first = perturb not in base
        base.setdefault(perturb, {(e["task"], e["seed"]): e["success"] for e in eps})
        wl = "-" if first else dev_runs.won_lost(base[perturb], eps)
        err = statistics.median(e["nominal_error_px"] for e in eps)
        out.append(f"| {perturb} | {start} | " + " | ".join(dev_runs.per_suite(eps))
                   + f" | **{dev_runs.frac(eps)}** | {wl} | {sum(e['refined'] for e in eps)} | {err:.1f} |")
    out += dev_runs.command_lines("arm_start.py", 1, ((name, cmd) for name, _, _, cmd in RUNS))
    return out


def main() -> None:
    dev_runs.main(__doc__, gather, lines, SECTION)


if __name__ == "__main__":
    main()
