"""How GLSR's switch tracking (``supervisor.track``, :mod:`tcot_hybrid.anchors`) was measured on sampled development
layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+), docs/libero-planner.md, "Tracking
what the plan grasps":

    .venv/bin/python docs/libero-planner/tracking.py --gather   # runs/dev/* -> tracking.json
    .venv/bin/python docs/libero-planner/tracking.py            # tracking.json -> docs/libero-planner.md

The evaluations it reads (`tcot eval`, the four-suite checkpoint, GLSR) are listed in RUNS with the command that makes
each, in three settings: tracking off, the grasp only (stop 46; `--supervisor.track.no-releases` since the release is
watched too) and the grasp and the placement after it (the LIBERO default since stop 47). A family in which a setting
shifted no plan runs alike with it and without it, episode for episode (the looks render images and change nothing
else), except `camera_noise`, whose noise is drawn per rendered image; so a family was run again with a setting off
only where it shifted a plan, and `camera_noise`.
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
OTHERS = "arm_push,camera_noise,camera_shift,init_posture,object_drop,offcenter_grasp"
FAMILIES = f"object_moved,target_moved,{OTHERS}"
BASE = f"tcot eval --suite {S4} --planners learned --modes glsr --init sampled {dev_runs.FOUR_SUITE_MODEL}"
TWO, ONE = "--episodes 2 --seed-start 20040", "--episodes 1 --seed-start 20040"
OFF, GRASPS = "--supervisor.track.mode off", "--supervisor.track.no-releases"
SETTINGS = ("off", "grasps", "grasps + releases")  # each table row is compared with the one before it
# (run directory under runs/dev, setting, what it measures, command)
RUNS = (
    ("track_nominal_on", "grasps", "none", f"{BASE} {TWO} {GRASPS}"),
    ("release_nominal_on", "grasps + releases", "none", f"{BASE} {TWO}"),
    ("track_moved_off", "off", "object_moved", f"{BASE} {TWO} --perturb object_moved {OFF}"),
    ("track_moved_on", "grasps", "object_moved", f"{BASE} {TWO} --perturb object_moved {GRASPS}"),
    ("release_moved_on", "grasps + releases", "object_moved", f"{BASE} {TWO} --perturb object_moved"),
    ("release_target_off", "grasps", "target_moved", f"{BASE} {TWO} --perturb target_moved {GRASPS}"),
    ("release_target_on", "grasps + releases", "target_moved", f"{BASE} {TWO} --perturb target_moved"),
    ("track_families_off", "off", "families", f"{BASE} {ONE} --perturb camera_noise,init_posture,target_moved {OFF}"),
    ("track_families_on", "grasps", "families", f"{BASE} {ONE} --perturb {FAMILIES} {GRASPS}"),
    # object_moved and target_moved of 20040 with both watched: the two-layout runs above
    ("release_families_on", "grasps + releases", "families", f"{BASE} {ONE} --perturb {OTHERS}"),
)
KEEP = ("task", "suite", "seed", "perturb", "success", "stopped_by", "grasps_tracked", "releases_tracked",
        "perturbation_fired")


def gather() -> None:
    info = {name: (track, what) for name, track, what, _ in RUNS}

    def row(name: str, e: dict) -> dict:
        return {"run": name, "track": info[name][0], "measures": info[name][1], **{k: e.get(k) for k in KEEP}}
    dev_runs.gather(((name, cmd) for name, _, _, cmd in RUNS), OUT, row)


def won_lost(before: list[dict], after: list[dict]) -> str:
    """:func:`dev_runs.won_lost` of ``after`` against ``before`` (both one perturbation family)."""
    return dev_runs.won_lost({(e["task"], e["seed"]): e["success"] for e in before}, after)


def shifted(eps: list[dict]) -> str:
    """Episodes in which a grasp / a release was shifted."""
    return f"{sum(bool(e['grasps_tracked']) for e in eps)} / {sum(bool(e.get('releases_tracked')) for e in eps)}"


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    rows = [r for r in rows if r["perturb"] == "none" or r["perturbation_fired"]]  # a family that could not fire: out
    by: dict = defaultdict(list)
    for r in rows:
        by[(r["measures"], r["track"])].append(r)
    out = ["**Switch tracking under GLSR** (four-suite checkpoint; sampled development layouts; successes / episodes "
           "whose perturbation fired; won / lost: against the row before it on the same layouts; shifted: episodes in "
           "which a grasp / a release was shifted):", "",
           "| perturbation | layouts | tracking | " + " | ".join(SUITES) + " | all four | won / lost | shifted |",
           "|" + "---|" * (len(SUITES) + 6)]
    for what in dict.fromkeys(w for _, _, w, _ in RUNS if w != "families"):
        before: list = []
        for track in SETTINGS:
            eps = by.get((what, track), [])
            if not eps:
                continue
            seeds = sorted({e["seed"] for e in eps})
            out.append(f"| {what} | {seeds[0]}-{seeds[-1]} | {track} | " + " | ".join(dev_runs.per_suite(eps))
                       + f" | **{dev_runs.frac(eps)}** | {won_lost(before, eps) if before else '-'} | {shifted(eps)} |")
            before = eps
    fam = {t: by.get(("families", t), []) for t in SETTINGS}
    # layout 20040's episodes of the two-layout runs stand in for the families run where that setting ran them
    for (what, track), eps in by.items():
        if what != "families" and what != "none":
            have = {(e["task"], e["perturb"]) for e in fam[track]}
            fam[track] = fam[track] + [e for e in eps if e["seed"] == 20040 and (e["task"], e["perturb"]) not in have]
    if fam["grasps"]:
        out += ["", "Every perturbation family, layout 20040 (one episode per task and family whose perturbation fired; "
                "GLSR; \"alike\": the setting shifted no plan, so the episodes run as with the one before; won / lost: "
                "grasps + releases against grasps; shifted: episodes in which a grasp / a release was shifted, grasps + "
                "releases):", "",
                "| perturbation | tracking off | grasps | grasps + releases | won / lost | shifted |",
                "|---|---|---|---|---|---|"]
        for f in sorted({e["perturb"] for e in fam["grasps"]}):
            a, b, c = ([e for e in fam[t] if e["perturb"] == f] for t in SETTINGS)
            first = dev_runs.frac(a) if a else ("alike" if not any(e["grasps_tracked"] for e in b) else "-")
            out.append(f"| {f} | {first} | {dev_runs.frac(b)} | {dev_runs.frac(c)} | "
                       f"{won_lost(b, c) if c else '-'} | {shifted(c) if c else '-'} |")
    out += dev_runs.command_lines("tracking.py", 2, ((name, cmd) for name, _, _, cmd in RUNS))
    return out


def main() -> None:
    dev_runs.main(__doc__, gather, lines, SECTION)


if __name__ == "__main__":
    main()
