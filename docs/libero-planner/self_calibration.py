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

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "self_calibration.json"
BASELINE = HERE / "corner_window.json"  # the shipped checkpoint's unperturbed development episodes (run shipped4)
SECTION = "libero-self-calibration"
EVAL = (f"tcot eval --suite {dev_runs.S4} --planners learned --init sampled --episodes 2 --seed-start 20000 "
        f"--modes global,glsr {dev_runs.FOUR_SUITE_MODEL}")
RUNS = (
    ("camshift1", f"{EVAL} --perturb camera_shift --sweep learned.self_calibration.enabled=true,false"),
    ("nominal1", EVAL),
)
TRUE_CAMERA = ("true_camera", ".venv/bin/python docs/libero-planner/true_camera.py --part 0 --parts 2 (and --part 1)")
KEEP = ("task", "suite", "mode", "seed", "success", "perturb", "perturbation_fired", "stopped_by")


def gather() -> None:
    def row(name, e):
        cal = e.get("camera_calibration") or {}
        on = "enabled=false" not in (e.get("sweep") or "")
        how = "the moved camera, known exactly" if name == "true_camera" else "on" if on else "off"
        return {"run": name, "calibration": how, **{k: e.get(k) for k in KEEP},
                "refined": bool(cal.get("refined")), "points": cal.get("points"),
                "nominal_error_px": cal.get("nominal_error_px"), "turn_deg": cal.get("turn_deg")}

    dev_runs.gather(RUNS + (TRUE_CAMERA,), OUT, row)


def _median(xs):
    xs = sorted(xs)
    return xs[len(xs) // 2] if xs else float("nan")


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    out = ["Sampled development layouts 20000-20001, all 40 tasks, the shipped four-suite checkpoint, the same commit "
           "(successes / episodes; won / lost against self-calibration off in the same mode on the same layouts):", "",
           "| perturbation | self-calibration | mode | " + " | ".join(dev_runs.SUITES)
           + " | all four | won / lost | refined | nominal error [px] |", "|" + "---|" * (len(dev_runs.SUITES) + 7)]
    groups: dict = defaultdict(list)
    for r in rows:
        groups[(r["perturb"], r["calibration"], r["mode"])].append(r)
    for pert in ("camera_shift", "none"):
        for mode in ("global", "glsr"):
            base = {(r["task"], r["seed"]): r["success"] for r in groups.get((pert, "off", mode), [])}
            for cal in ("off", "on", "the moved camera, known exactly"):
                eps = groups.get((pert, cal, mode))
                if not eps:
                    continue
                wl = dev_runs.won_lost(base, eps) if cal != "off" and base else "-"
                errs = [r["nominal_error_px"] for r in eps if r["points"]]
                err = f"{_median(errs):.1f}" if errs else "-"
                refined = str(sum(r["refined"] for r in eps)) if errs else "-"
                out.append(f"| {pert} | {cal} | {mode} | " + " | ".join(dev_runs.per_suite(eps))
                           + f" | **{sum(r['success'] for r in eps)}/{len(eps)}** | {wl} | "
                           f"{refined} | {err} |")
    nominal = [r for r in rows if r["perturb"] == "none"]
    if nominal and BASELINE.is_file():  # the same episodes before self-calibration existed (corner_window.py)
        before = {(r["task"], r["seed"], r["mode"]): r["success"] for r in
                  (json.loads(x) for x in BASELINE.read_text().splitlines() if x.strip()) if r["run"] == "shipped4"}
        same = sum(before.get((r["task"], r["seed"], r["mode"])) == r["success"] for r in nominal)
        out += ["", f"Unperturbed, with self-calibration on (the default): {sum(r['refined'] for r in nominal)} of "
                f"{len(nominal)} episodes re-estimated the camera; {same} of {len(nominal)} ended as the same "
                "episodes did before self-calibration existed (`shipped4`, corner_window.json)."]
    turns = [r["turn_deg"] for r in rows if r["perturb"] == "camera_shift" and r["refined"]]
    if turns:
        out += ["", f"Under camera_shift (3 cm, 3 degrees) the fitted turn was {_median(turns):.1f} degrees (median of "
                f"{len(turns)} episodes that re-estimated)."]
    return (out + dev_runs.command_lines("self_calibration.py", 2, RUNS)
            + [f"- `{TRUE_CAMERA[0]}` (runs/dev/true_camera/episodes.jsonl): `{TRUE_CAMERA[1]}`"])


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
