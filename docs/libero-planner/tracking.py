"""How GLSR's grasp tracking (``supervisor.track``, :mod:`tcot_hybrid.anchors`) was measured on sampled development
layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+), docs/libero-planner.md, "Tracking
what the plan grasps":

    .venv/bin/python docs/libero-planner/tracking.py --gather   # runs/dev/* -> tracking.json
    .venv/bin/python docs/libero-planner/tracking.py            # tracking.json -> docs/libero-planner.md

The evaluations it reads (`tcot eval`, the four-suite checkpoint, GLSR) are listed in RUNS with the command that makes
each: the same layouts with tracking on (the LIBERO default) and off. A family in which tracking never shifted a plan
runs alike with it off, episode for episode (the looks render images and change nothing else), except
`camera_noise`, whose noise is drawn per rendered image; so the families were run again with it off only where it
shifted one, and `camera_noise`.
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "tracking.json"
SUITES, S4 = dev_runs.SUITES, dev_runs.S4
SECTION = "libero-tracking"
FAMILIES = "object_moved,target_moved,arm_push,camera_noise,camera_shift,init_posture,object_drop,offcenter_grasp"
BASE = f"tcot eval --suite {S4} --planners learned --modes glsr --init sampled {dev_runs.FOUR_SUITE_MODEL}"
# (run directory under runs/dev, tracking, what it measures, command)
RUNS = (
    ("track_nominal_on", "on", "none", f"{BASE} --episodes 2 --seed-start 20040"),
    ("track_moved_off", "off", "object_moved", f"{BASE} --episodes 2 --seed-start 20040 --perturb object_moved "
                                               "--supervisor.track.mode off"),
    ("track_moved_on", "on", "object_moved", f"{BASE} --episodes 2 --seed-start 20040 --perturb object_moved"),
    ("track_families_off", "off", "families", f"{BASE} --episodes 1 --seed-start 20040 --perturb "
                                              "camera_noise,init_posture,target_moved --supervisor.track.mode off"),
    ("track_families_on", "on", "families", f"{BASE} --episodes 1 --seed-start 20040 --perturb {FAMILIES}"),
)
KEEP = ("task", "suite", "seed", "perturb", "success", "stopped_by", "grasps_tracked", "perturbation_fired")


def gather() -> None:
    info = {name: (track, what) for name, track, what, _ in RUNS}

    def row(name: str, e: dict) -> dict:
        return {"run": name, "track": info[name][0], "measures": info[name][1], **{k: e.get(k) for k in KEEP}}
    dev_runs.gather(((name, cmd) for name, _, _, cmd in RUNS), OUT, row)


def won_lost(off: list[dict], on: list[dict]) -> str:
    """:func:`dev_runs.won_lost` of ``on`` against ``off`` (both one perturbation family)."""
    return dev_runs.won_lost({(e["task"], e["seed"]): e["success"] for e in off}, on)


def tracked(eps: list[dict]) -> int:
    return sum(bool(e["grasps_tracked"]) for e in eps)


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    rows = [r for r in rows if r["perturb"] == "none" or r["perturbation_fired"]]  # a family that could not fire: out
    by: dict = defaultdict(list)
    for r in rows:
        by[r["run"]].append(r)
    out = ["**Grasp tracking under GLSR** (four-suite checkpoint; sampled development layouts; successes / episodes "
           "whose perturbation fired; won / lost: tracking on against off on the same layouts; tracked: episodes in "
           "which a plan was shifted):", "",
           "| perturbation | layouts | tracking | " + " | ".join(SUITES) + " | all four | won / lost | tracked |",
           "|" + "---|" * (len(SUITES) + 6)]
    for name, track, what, _ in RUNS:
        eps = by.get(name, [])
        if not eps or what == "families":
            continue
        seeds = sorted({e["seed"] for e in eps})
        off = by.get(name.replace("_on", "_off"), []) if track == "on" else []
        out.append(f"| {what} | {seeds[0]}-{seeds[-1]} | {track} | " + " | ".join(dev_runs.per_suite(eps))
                   + f" | **{dev_runs.frac(eps)}** | {won_lost(off, eps) if off else '-'} | {tracked(eps)} |")
    on = by.get("track_families_on", [])
    off = by.get("track_families_off", []) + [e for e in by.get("track_moved_off", []) if e["seed"] == 20040]
    if on:
        out += ["", "Every perturbation family, layout 20040 (one episode per task and family whose perturbation fired; "
                "GLSR; \"alike\": tracking shifted no plan, so the episodes run as with it off):", "",
                "| perturbation | tracking off | tracking on | won / lost | tracked |", "|---|---|---|---|---|"]
        for f in sorted({e["perturb"] for e in on}):
            a, b = [e for e in off if e["perturb"] == f], [e for e in on if e["perturb"] == f]
            first = dev_runs.frac(a) if a else ("alike" if not tracked(b) else "-")
            out.append(f"| {f} | {first} | {dev_runs.frac(b)} | {won_lost(a, b) if a else '-'} | {tracked(b)} |")
    out += dev_runs.command_lines("tracking.py", 2, ((name, cmd) for name, _, _, cmd in RUNS))
    return out


def main() -> None:
    dev_runs.main(__doc__, gather, lines, SECTION)


if __name__ == "__main__":
    main()
