"""What GLSR's success verdicts cost under the perturbation families (docs/libero-planner.md, "What is left", item 4):
the same development layout run with the detector as shipped (a verdict of success stops replanning and, held, ends
the episode) and with no verdict ever taken (``--supervisor.success_threshold 1.0``: the arm replans until the
simulator's success or the time limit), sampled development layouts (docs/seeds.md), never the shipped init states:

    .venv/bin/python docs/libero-planner/detector_hold.py --gather   # runs/dev/* -> detector_hold.json
    .venv/bin/python docs/libero-planner/detector_hold.py            # detector_hold.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "detector_hold.json"
SECTION = "libero-detector-hold"
FAMILIES = "object_moved,target_moved,arm_push,camera_noise,camera_shift,init_posture,object_drop,offcenter_grasp"
BASE = (f"tcot eval --suite {dev_runs.S4} --planners learned --modes glsr --init sampled {dev_runs.FOUR_SUITE_MODEL} "
        f"--episodes 1 --seed-start 20040 --perturb {FAMILIES} --supervisor.track.no-releases")
# (run directory under runs/dev, what the detector may do, command); the first is the tracking measurement's own run
RUNS = (
    ("track_families_on", "as shipped", BASE),
    ("nohold_families", "never judged done", f"{BASE} --supervisor.success_threshold 1.0"),
)
KEEP = ("task", "seed", "perturb", "success", "premature_stop", "wall_time_s", "perturbation_fired")


def gather() -> None:
    dev_runs.gather(((name, cmd) for name, _, cmd in RUNS), OUT,
                    lambda name, e: {"run": name, **{k: e.get(k) for k in KEEP}})


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    by: dict = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if r["perturbation_fired"]:
            by[r["perturb"]][r["run"]].append(r)
    (base, _, _), (other, _, _) = RUNS
    out = ["**What the detector's verdicts cost** (GLSR, four-suite checkpoint, sampled development layout 20040, one "
           "episode per task and family whose perturbation fired; stopped early: episodes the detector ended while the "
           "task was not done; won / lost: never judged done against as shipped; wall: the episodes' summed wall "
           "time):", "",
           "| perturbation | as shipped | stopped early | never judged done | won / lost | wall as shipped [s] | "
           "wall never judged done [s] |", "|---|---|---|---|---|---|---|"]

    def row(label: str, a: list[dict], b: list[dict], won_lost: str, bold: str = "") -> str:
        early = sum(bool(e["premature_stop"]) for e in a)
        wa, wb = (sum(e["wall_time_s"] for e in eps) for eps in (a, b))
        fa, fb = (f"{bold}{dev_runs.frac(eps)}{bold}" for eps in (a, b))
        return f"| {label} | {fa} | {early} | {fb} | {won_lost} | {wa:.0f} | {wb:.0f} |"

    for fam in sorted(by):
        a, b = by[fam][base], by[fam][other]
        out.append(row(fam, a, b, dev_runs.won_lost({(e["task"], e["seed"]): e["success"] for e in a}, b)))
    every = [[e for fam in by.values() for e in fam[run]] for run in (base, other)]
    out.append(row("all", *every, "", bold="**"))
    out += dev_runs.command_lines("detector_hold.py", 2, ((name, cmd) for name, _, cmd in RUNS))
    return out


def main() -> None:
    dev_runs.main(__doc__, gather, lines, SECTION)


if __name__ == "__main__":
    main()
