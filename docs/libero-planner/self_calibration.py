"""Whether re-estimating the planner camera's pose from where the network sees the hand (tcot_hybrid/calibration.py,
`learned.self_calibration`) carries the learned planner through a knocked camera (`camera_shift`), and whether it
leaves undisturbed episodes alone, on sampled development layouts (docs/seeds.md: seeds 20000+, never the shipped
init states, never 90000+) (docs/libero-planner.md, "A knocked camera"):

    .venv/bin/python docs/libero-planner/self_calibration.py --gather   # runs/dev/* -> self_calibration.json
    .venv/bin/python docs/libero-planner/self_calibration.py            # self_calibration.json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from statistics import median_high

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "self_calibration.json"
SECTION = "libero-self-calibration"
EVAL = (f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start 20000 "
        f"--modes global,glsr {dev_runs.FOUR_SUITE_MODEL}")
FIRST = "on, first version (no consistency check)"
SECOND = "on, second version (one sighting anywhere is enough)"
# (run, the command that makes it, the commit it ran at); every run on the same machine
RUNS = (
    ("camshift1", f"{EVAL} --perturb camera_shift --sweep learned.self_calibration.enabled=true,false", "fb5a3a2"),
    ("nominal0", EVAL, "6e5e613, before self-calibration"),
    ("nominal1", EVAL, "dcc912c"),
    ("selfcal2", f"{EVAL} --perturb none,camera_shift", "4fd3d65"),
    ("posture3", f"{EVAL} --perturb init_posture --sweep learned.self_calibration.enabled=true,false", "8595588"),
    ("camshift3", f"{EVAL} --perturb camera_shift", "8595588"),
)
TRUE_CAMERA = ("true_camera", ".venv/bin/python docs/libero-planner/true_camera.py --part 0 --parts 2 (and --part 1)",
               "fb5a3a2")
KEEP = ("task", "suite", "mode", "seed", "success", "perturb", "perturbation_fired", "stopped_by")
# the label of a run's episodes, in table order; the first of each perturbation is the baseline of won / lost
LABELS = ("off", FIRST, SECOND, "on", "the moved camera, known exactly")


def _label(run: str, e: dict) -> str:
    if run == "true_camera":
        return LABELS[-1]
    if run == "nominal0" or "enabled=false" in (e.get("sweep") or ""):
        return "off"
    return {"selfcal2": SECOND, "posture3": "on", "camshift3": "on"}.get(run, FIRST)


def gather() -> None:
    def row(name, e):
        cal = e.get("camera_calibration") or {}
        return {"run": name, "calibration": _label(name, e), **{k: e.get(k) for k in KEEP},
                "refined": bool(cal.get("refined")), "points": cal.get("points"),
                "nominal_error_px": cal.get("nominal_error_px"), "rejected_fits": cal.get("rejected_fits")}

    dev_runs.gather([(n, c) for n, c, _ in RUNS + (TRUE_CAMERA,)], OUT, row)


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    commits = {n: c for n, _, c in RUNS + (TRUE_CAMERA,)}
    out = ["Sampled development layouts 20000-20001, all 40 tasks, the shipped four-suite checkpoint, one machine "
           "(successes / episodes; won / lost against self-calibration off in the same mode on the same layouts; "
           "refined: episodes that lifted with a re-fitted camera; nominal error: the median over episodes of the "
           "median pixel distance between the network's hand and the nominal camera's projection of the TCP):", "",
           "| perturbation | self-calibration | run (commit) | mode | " + " | ".join(dev_runs.SUITES)
           + " | all four | won / lost | refined | nominal error [px] |", "|" + "---|" * (len(dev_runs.SUITES) + 8)]
    groups: dict = defaultdict(list)
    for r in rows:
        groups[(r["perturb"], r["mode"], r["calibration"], r["run"])].append(r)
    for pert in ("camera_shift", "init_posture", "none"):
        for mode in ("global", "glsr"):
            base = {(r["task"], r["seed"]): r["success"] for (p, m, c, _), eps in groups.items()
                    if (p, m, c) == (pert, mode, "off") for r in eps}
            keys = sorted((k for k in groups if k[:2] == (pert, mode)), key=lambda k: LABELS.index(k[2]))
            for key in keys:
                eps, cal, run = groups[key], key[2], key[3]
                wl = dev_runs.won_lost(base, eps) if cal != "off" and base else "-"
                errs = [r["nominal_error_px"] for r in eps if r["points"]]
                err = f"{median_high(errs):.1f}" if errs else "-"
                refined = str(sum(r["refined"] for r in eps)) if errs else "-"
                out.append(f"| {pert} | {cal} | {run} ({commits[run]}) | {mode} | " + " | ".join(dev_runs.per_suite(eps))
                           + f" | **{sum(r['success'] for r in eps)}/{len(eps)}** | {wl} | {refined} | {err} |")
    return (out + dev_runs.command_lines("self_calibration.py", 2, [(n, c) for n, c, _ in RUNS])
            + [f"- `{TRUE_CAMERA[0]}` (runs/dev/true_camera/episodes.jsonl): `{TRUE_CAMERA[1]}`"])


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
