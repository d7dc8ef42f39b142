"""Summarise the LIBERO oracle evaluations (docs/libero.md, "Oracle in the paper's protocol") from the eval.json
files the `tcot eval` commands below wrote, into docs/eval-libero/summary.md, docs/libero.md and README.md:

    make libero-oracle-eval            # the three tcot eval runs (docs/eval-libero/*/)
    .venv/bin/tcot bench --quick --out docs/eval-libero/bench-quick   # the LIBERO speed figures
    .venv/bin/python docs/eval-libero/summarize.py
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

from tcot_hybrid.markdown import update_readme_section
from tcot_hybrid.metrics import wilson_interval

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
# which code the controller x IK run measured (docs/libero.md)
CONTROLLERS_IK_WHEN = "commit 145a479, every state with the fixtures at the scene build's draw (before stop 64)"
RUNS = {
    "oracle-shipped": "shipped init states (the paper's protocol: all 50 per task), default controller and IK",
    "oracle-sampled": "sampled layouts, reporting seeds 90000-90004 (5 per task)",
}


def load(name: str) -> dict | None:
    p = HERE / name / "eval.json"
    return json.loads(p.read_text()) if p.is_file() else None


def rate(k: int, n: int) -> str:
    lo, hi = wilson_interval(k, n)
    return f"{k / n:.3f} [{lo:.2f}, {hi:.2f}] n={n}" if n else "-"


def by_suite(cells: list[dict], key=lambda c: ()) -> dict:
    out: dict = defaultdict(lambda: [0, 0])
    for c in cells:
        out[(*key(c), c["suite"])][0] += c["successes"]
        out[(*key(c), c["suite"])][1] += c["episodes"]
    return out


def summary() -> str:
    lines = []
    for name, what in RUNS.items():
        r = load(name)
        if r is None:
            lines += [f"- `{name}`: not run yet", ""]
            continue
        s = by_suite(r["cells"])
        k = sum(v[0] for v in s.values())
        n = sum(v[1] for v in s.values())
        viol = max(c["max_joint_limit_violation_rad"] for c in r["cells"])
        faults = sum(c["faults"] for c in r["cells"])
        lines += [f"**Oracle, {what}** (`docs/eval-libero/{name}/`, {r['episodes']} episodes, "
                  f"{r['wall_time_s'] / 60:.1f} min wall with {r['workers']} workers):", "",
                  "| " + " | ".join(SUITES) + " | all four |", "|" + "---|" * (len(SUITES) + 1),
                  "| " + " | ".join(rate(*s[(su,)]) for su in SUITES) + f" | {rate(k, n)} |", "",
                  f"Worst joint-limit violation {viol:.4f} rad; faulted episodes {faults} (none counted as success).",
                  ""]
    r = load("controllers-ik")
    if r is not None:
        s = by_suite(r["cells"], key=lambda c: (c["controller"], c["ik"]))
        combos = sorted({k[:2] for k in s})
        suites = [su for su in SUITES if any(k[2] == su for k in s)]
        lines += [f"**Every controller and both IK backends**, shipped init states 0-9 of {', '.join(suites)} "
                  f"(`docs/eval-libero/controllers-ik/`, {r['episodes']} episodes, "
                  f"{r['wall_time_s'] / 60:.1f} min wall; {CONTROLLERS_IK_WHEN}):", "",
                  "| controller | ik | " + " | ".join(suites) + " |", "|" + "---|" * (2 + len(suites))]
        for ctrl, ik in combos:
            lines.append(f"| {ctrl} | {ik} | " + " | ".join(rate(*s[(ctrl, ik, su)]) for su in suites) + " |")
        viol = max(c["max_joint_limit_violation_rad"] for c in r["cells"])
        lines += ["", f"Worst joint-limit violation {viol:.4f} rad.", ""]
    b = HERE / "bench-quick" / "bench.json"
    if b.is_file():
        fig = json.loads(b.read_text())["figures"]
        names = {"libero/scene_build_s": "scene build (LIBERO/robosuite compiles it)",
                 "libero/mj_step_us": "bare mj_step",
                 **{k: f"control tick, {k.rsplit('/', 1)[1]} (5 physics steps + controller)"
                    for k in fig if k.startswith("libero/tick_us/")},
                 "libero/render_planner_image_ms": "planner image render (128 px)",
                 "libero/episode_real_time_factor": "oracle episode, real-time factor",
                 "libero/episode_real_time_factor_rendering": "oracle episode rendering every planner step, RTF"}
        lines += ["**Speed on a LIBERO tabletop scene** (`tcot bench --quick --out docs/eval-libero/bench-quick`, "
                  "medians):", "", "| figure | median | unit |", "|---|---|---|"]
        lines += [f"| {label} | {fig[k]['median']:.4g} | {fig[k]['unit']} |" for k, label in names.items() if k in fig]
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    text = summary()
    (HERE / "summary.md").write_text("# LIBERO oracle figures\n\nWritten by `docs/eval-libero/summarize.py`.\n\n" + text)
    update_readme_section(ROOT / "docs" / "libero.md", "libero-oracle", text)
    update_readme_section(ROOT / "README.md", "libero-oracle", text)
    print(text)


if __name__ == "__main__":
    main()
