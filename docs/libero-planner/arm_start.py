"""What the arm's start costs the shipped planner (docs/libero-planner.md, "Data and seeds", "The arm's start"): the same
sampled development layouts (docs/seeds.md) with the arm exactly at home, as every sampled layout and demonstration
started before stop 49, and off home by robosuite's default joint noise, as LIBERO's shipped init states start and
sampled layouts now do. The noise has its own generator, so the objects stand alike in both; the runs at home ran at
283b1fb (the commit before the noise), the others after it; the last two (stop 50) with the arm sent home before the
first plan (``executor.start_home_tol_rad``, on by default since). Never the shipped init states:

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
BASE50 = (f"tcot eval --suite {dev_runs.S4} --planners learned --modes global,glsr --init sampled "
          f"{dev_runs.FOUR_SUITE_MODEL} --episodes 2 --seed-start 20049")
BASE51 = BASE50.replace("--seed-start 20049", "--seed-start 20051")
AT_HOME = "at home (283b1fb)"
OFF_HOME = "off home, 0.02 rad"
HOMED = "off home, then home before the first plan"
L47, L49, L51 = "20047-20048", "20049-20050", "20051-20052"
# (run directory under runs/dev, perturbation, mode, layouts, the arm's start, command); each (perturbation, mode,
# layouts)'s first row is the baseline its won / lost counts against
RUNS = (
    ("home49", "none", "glsr", L47, AT_HOME, f"{BASE} (at 283b1fb)"),
    ("noise49", "none", "glsr", L47, OFF_HOME, BASE),
    ("camshift_home49", "camera_shift", "glsr", L47, AT_HOME, f"{BASE} --perturb camera_shift (at 283b1fb)"),
    ("camshift_noise49", "camera_shift", "glsr", L47, OFF_HOME, f"{BASE} --perturb camera_shift"),
    ("home50", "none", "global", L49, AT_HOME, f"{BASE50} (at 283b1fb)"),
    ("noise50", "none", "global", L49, OFF_HOME, f"{BASE50} (at 3a8c549, before the start from home; now: --executor.start-home-tol-rad None)"),
    ("home50", "none", "glsr", L49, AT_HOME, f"{BASE50} (at 283b1fb)"),
    ("noise50", "none", "glsr", L49, OFF_HOME, f"{BASE50} (at 3a8c549, before the start from home; now: --executor.start-home-tol-rad None)"),
    ("homed50", "none", "global", L49, HOMED, BASE50),
    ("homed50", "none", "glsr", L49, HOMED, BASE50),
    ("noise51", "none", "global", L51, OFF_HOME, f"{BASE51} --executor.start-home-tol-rad None"),
    ("homed51", "none", "global", L51, HOMED, BASE51),
    ("noise51", "none", "glsr", L51, OFF_HOME, f"{BASE51} --executor.start-home-tol-rad None"),
    ("homed51", "none", "glsr", L51, HOMED, BASE51),
)
KEEP = ("task", "suite", "mode", "seed", "perturb", "success", "premature_stop", "replans", "wall_time_s")


def _commands() -> dict:
    return {name: cmd for name, _, _, _, _, cmd in RUNS}  # a run directory holds every mode it ran


def gather() -> None:
    def row(name: str, e: dict) -> dict:
        cal = e["camera_calibration"]
        return {"run": name, **{k: e.get(k) for k in KEEP}, "refined": cal["refined"],
                "nominal_error_px": cal["nominal_error_px"]}

    dev_runs.gather(_commands().items(), OUT, row)


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    by: dict = defaultdict(list)
    for r in rows:
        by[(r["run"], r.get("mode", "glsr"))].append(r)  # stop 49's rows were GLSR only and carry no mode
    out = ["Four-suite checkpoint, sampled development layouts (80 per row; won / lost against the arm at home, layout "
           "for layout; re-fitted: episodes whose camera self-calibration took a fit; nominal error: the median over "
           "episodes of the median distance between where the planner saw the hand and where the nominal camera puts "
           "it):", "",
           "| layouts | mode | perturbation | arm start | " + " | ".join(dev_runs.SUITES) + " | all four | won / lost | "
           "re-fitted | nominal error [px] |", "|" + "---|" * (len(dev_runs.SUITES) + 8)]
    base: dict = {}
    for name, perturb, mode, layouts, start, _ in RUNS:
        eps = by.get((name, mode))
        if not eps:
            continue
        wl = dev_runs.against_first(base, (perturb, mode, layouts), eps)
        err = statistics.median(e["nominal_error_px"] for e in eps)
        out.append(f"| {layouts} | {mode} | {perturb} | {start} | " + " | ".join(dev_runs.per_suite(eps))
                   + f" | **{dev_runs.frac(eps)}** | {wl} | {sum(e['refined'] for e in eps)} | {err:.1f} |")
    out += dev_runs.command_lines("arm_start.py", "1 (stop 49's runs) or 2 (stop 50's)", _commands().items())
    return out


def main() -> None:
    dev_runs.main(__doc__, gather, lines, SECTION)


if __name__ == "__main__":
    main()
