"""How GLSR's retry from home (``supervisor.home_retries``) was measured on sampled development layouts
(docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+), docs/libero-planner.md, "Retries from
home":

    .venv/bin/python docs/libero-planner/home_retries.py --gather   # runs/dev/* -> home_retries.json
    .venv/bin/python docs/libero-planner/home_retries.py            # home_retries.json -> docs/libero-planner.md

The evaluations it reads (`tcot eval`, shipped checkpoint) are listed in RUNS with the command that makes each; the
same layouts with 0 retries (Algorithm 1 with the empty-grasp check) and with 1.
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "home_retries.json"
SUITES, S4 = dev_runs.SUITES, dev_runs.S4
SECTION = "libero-home-retries"
PERTURBS = "object_drop,object_moved"
S3 = "libero_spatial,libero_object,libero_goal"  # under perturbation: the suites whose tasks start with one object
# (run directory under runs/dev, home retries, command)
RUNS = tuple(
    (f"{prefix}home{n}", n, f"tcot eval --suite {suites} --planners learned --modes glsr --init sampled {extra} "
                            f"--seed-start 20000 --supervisor.home-retries {n} {dev_runs.FOUR_SUITE_MODEL}")
    for prefix, suites, extra in (("", S4, "--episodes 2"), ("pert_", S3, f"--perturb {PERTURBS} --episodes 1"))
    for n in (0, 1))
KEEP = ("task", "suite", "seed", "perturb", "success", "stopped_by", "homes", "empty_grasps", "perturbation_fired")


def gather() -> None:
    retries = {name: n for name, n, _ in RUNS}
    dev_runs.gather(((name, cmd) for name, _, cmd in RUNS), OUT,
                    lambda name, e: {"run": name, "home_retries": retries[name], **{k: e.get(k) for k in KEEP}})


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    rows = [r for r in rows if r["perturb"] == "none" or r["perturbation_fired"]]  # a family that could not fire: out
    by: dict = defaultdict(list)
    for r in rows:
        by[(r["perturb"], r["home_retries"])].append(r)
    families = sorted({r["perturb"] for r in rows} - {"none"})
    out = ["**Retries from home** (GLSR, shipped checkpoint; no perturbation: development layouts 20000-20001, all 40 "
           f"tasks; {', '.join(families)}: layout 20000, one episode per task of {S3.replace(',', ', ')}, those "
           "whose perturbation fired; "
           "successes / episodes, and the retries used per episode):", "",
           "| home retries | " + " | ".join(SUITES) + " | all four | " + " | ".join(families) + " |",
           "|" + "---|" * (len(SUITES) + len(families) + 2)]
    for n in sorted({r["home_retries"] for r in rows}):
        clean = by[("none", n)]
        homes = sum(e["homes"] or 0 for e in clean) / len(clean) if clean else 0.0
        cols = [dev_runs.frac([e for e in clean if e["suite"] == s]) for s in SUITES]
        cols.append(f"{dev_runs.frac(clean)} ({homes:.2f})")
        for f in families:
            eps = by[(f, n)]
            cols.append(dev_runs.frac(eps)
                        + (f" ({sum(e['homes'] or 0 for e in eps) / len(eps):.2f})" if eps else ""))
        out.append(f"| {n} | " + " | ".join(cols) + " |")
    out.append("")
    base = {(r["perturb"], r["task"], r["seed"]): r["success"] for r in rows if r["home_retries"] == 0}
    for n in sorted({r["home_retries"] for r in rows} - {0}):
        for f in ["none"] + families:
            paired = [(base[(f, r["task"], r["seed"])], r["success"]) for r in by[(f, n)]
                      if (f, r["task"], r["seed"]) in base]
            what = "no perturbation" if f == "none" else f
            out.append(f"- {n} retr{'y' if n == 1 else 'ies'} against 0, {what}, the same {len(paired)} layouts: won "
                       f"{sum(b and not a for a, b in paired)}, lost {sum(a and not b for a, b in paired)}.")
    out += dev_runs.command_lines("home_retries.py", 1, ((name, cmd) for name, _, cmd in RUNS))
    return out


def main() -> None:
    dev_runs.main(__doc__, gather, lines, SECTION)


if __name__ == "__main__":
    main()
