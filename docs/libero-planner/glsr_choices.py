"""How GLSR's two LIBERO settings were chosen (docs/libero-planner.md, "Choosing t_f on LIBERO" and "Empty grasps"),
on sampled development layouts (docs/seeds.md: seeds 20000+, never the shipped init states, never 90000+):

    .venv/bin/python docs/libero-planner/glsr_choices.py --gather   # runs/dev/* -> glsr_choices.json (one line each)
    .venv/bin/python docs/libero-planner/glsr_choices.py            # glsr_choices.json -> docs/libero-planner.md

The evaluations it reads (`tcot eval`, shipped checkpoint, 2 workers) are listed in RUNS with the command that makes
each; the first runs were made before the two settings existed, when t_f = 16 and no empty-grasp check were the
defaults, and the commands below name those values explicitly (the episodes replay identically). `t_f` = 1000 steps is
longer than any episode: like `plan`, the global plan is followed until it has been carried out, but `--stop-on
either` asks the detector only from step t_f on, so no episode of that run was ended by a detector verdict (with
`plan` the stop checks start when the plan has run out; a verdict the local plan confirms then ends the episode
instead of leaving the arm idle until the time limit, the same outcome sooner). "First version" of
the empty-grasp check: the lift was measured from the TCP height at the first planner step the gripper was commanded
closed, by a plan or by anything else; the shipped one measures it from where a plan closed it (`grasp_tcp_z`), so an
`object_drop` (which reopens and recloses the gripper in the air) no longer resets it. With no perturbation the two
differ by the hand's motion within one planner step; under `object_drop` the shipped one reopens where the first
did not. Its figures on the shipped init states and under every perturbation are in `summarize.py`'s tables.
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "glsr_choices.json"
SUITES, S4 = dev_runs.SUITES, dev_runs.S4
SECTION = "libero-glsr-choices"

OLD = f"--sweep supervisor.t_f=16 --supervisor.empty-grasp off {dev_runs.FOUR_SUITE_MODEL}"
# (run directory under runs/dev, setting label, command)
RUNS = (
    ("tf16", "t_f = 16, no empty-grasp check",
     f"tcot eval --suite {S4} --planners learned --modes global,glsr --init sampled --episodes 2 --seed-start 20000 {OLD}"),
    ("tf1000", "t_f = 1000, no empty-grasp check",
     f"tcot eval --suite {S4} --planners learned --modes glsr --init sampled --episodes 2 --seed-start 20000 "
     f"--sweep supervisor.t_f=1000 --supervisor.empty-grasp off {dev_runs.FOUR_SUITE_MODEL}"),
    ("eg3_goal10", "t_f = plan, empty-grasp check (first version)",
     "tcot eval --suite libero_goal,libero_10 --planners learned --modes glsr --init sampled --episodes 2 "
     f"--seed-start 20000 {dev_runs.FOUR_SUITE_MODEL}"),
    ("pert_tf16", "t_f = 16, no empty-grasp check",
     "tcot eval --suite libero_spatial,libero_object --planners learned --modes global,glsr "
     f"--perturb object_moved,object_drop --init sampled --episodes 1 --seed-start 20000 {OLD}"),
    ("pert_eg3", "t_f = plan, empty-grasp check (first version)",
     "tcot eval --suite libero_spatial,libero_object --planners learned --modes glsr "
     "--perturb object_moved,object_drop,offcenter_grasp --init sampled --episodes 1 --seed-start 20000"),
)
SETTINGS = {name: setting for name, setting, _ in RUNS}
KEEP = ("task", "suite", "mode", "seed", "perturb", "success", "stopped_by", "steps", "replans", "empty_grasps",
        "perturbation_fired")


def gather() -> None:
    dev_runs.gather(((name, cmd) for name, _, cmd in RUNS), OUT, lambda name, e: {
        "run": name, "setting": "-" if e["mode"] == "global" else SETTINGS[name], **{k: e.get(k) for k in KEEP}})


def frac(k: int, n: int) -> str:
    return f"{k}/{n}" if n else "-"


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    out = ["**No perturbation** (sampled development layouts 20000-20001, all 40 tasks; successes / episodes):", "",
           "| mode | setting | " + " | ".join(SUITES) + " | all four | ended on a detector verdict, not done |",
           "|" + "---|" * (len(SUITES) + 4)]
    clean = [r for r in rows if r["perturb"] == "none"]
    cells: dict = defaultdict(list)
    for r in clean:
        cells[(r["mode"], r["setting"])].append(r)
    for (mode, setting), eps in sorted(cells.items(), key=lambda kv: (kv[0][0] != "global", kv[0][1])):
        per = [frac(sum(e["success"] for e in eps if e["suite"] == s), sum(e["suite"] == s for e in eps))
               for s in SUITES]
        stops = sum(e["stopped_by"] == "detector" and not e["success"] for e in eps)
        out.append(f"| {mode} | {setting} | " + " | ".join(per)
                   + f" | {frac(sum(e['success'] for e in eps), len(eps))} | {stops} |")
    glob = {(r["task"], r["seed"]): r["success"] for r in clean if r["mode"] == "global"}
    out.append("")
    for (mode, setting), eps in sorted(cells.items()):
        if mode != "glsr":
            continue
        paired = [(glob[(e["task"], e["seed"])], e["success"]) for e in eps if (e["task"], e["seed"]) in glob]
        out.append(f"- GLSR ({setting}) against global-only on the same {len(paired)} layouts: only GLSR "
                   f"{sum(b and not a for a, b in paired)}, only global-only {sum(a and not b for a, b in paired)}.")
    pert = [r for r in rows if r["perturb"] != "none"]
    if pert:
        names = sorted({r["perturb"] for r in pert})
        out += ["", "**Perturbations** (libero_spatial and libero_object, development layout 20000, one episode per task "
                "and perturbation; successes / episodes, and the empty-grasp reopenings per episode):", "",
                "| mode | setting | " + " | ".join(names) + " |", "|" + "---|" * (len(names) + 2)]
        pc: dict = defaultdict(list)
        for r in pert:
            pc[(r["mode"], r["setting"])].append(r)
        for (mode, setting), eps in sorted(pc.items(), key=lambda kv: (kv[0][0] != "global", kv[0][1])):
            cols = []
            for nm in names:
                sel = [e for e in eps if e["perturb"] == nm]
                eg = sum(e.get("empty_grasps") or 0 for e in sel)
                cols.append(f"{frac(sum(e['success'] for e in sel), len(sel))}"
                            + (f" ({eg / len(sel):.1f})" if sel and "no empty-grasp" not in setting
                               and mode == "glsr" else ""))
            out.append(f"| {mode} | {setting} | " + " | ".join(cols) + " |")
    out += dev_runs.command_lines("glsr_choices.py", 2, ((name, cmd) for name, _, cmd in RUNS))
    return out


def main() -> None:
    dev_runs.main(__doc__, gather, lines, SECTION)


if __name__ == "__main__":
    main()
