"""The label ceiling of LIBERO's global windows: each demonstration's own t = 0 global label run as a frozen plan
(`tcot replay`, with the demo's TCP orientation, as a planner with a rotation head plans, on the demo's own sampled
layout), written into docs/libero-planner.md:

    MUJOCO_GL=egl .venv/bin/python docs/libero-planner/label_ceiling.py [--variants ...] [--summarize]
    MUJOCO_GL=egl .venv/bin/python docs/libero-planner/label_ceiling.py --all-tasks [--summarize]

Default: the six hard tasks below, training seeds 0-4, every variant, into the <!-- libero-label-ceiling -->
section. --all-tasks: all 40 tasks of the four suites, training seeds 0-1, the shipped window against the commanded
corner points, into <!-- libero-label-ceiling-40 -->. Demonstrations: `tcot collect` (never the shipped init states,
docs/seeds.md) into runs/dev/cmd_demos.hdf5 or runs/dev/cmd_demos40.hdf5 (collected when missing; they record
obs/tcp_target_pos, which the 'commanded' windows label from). Each variant's report goes to
docs/libero-planner/label-ceiling[-40]/<variant>.json and is reused when there (delete it to run that variant again).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
OUT = HERE / "label-ceiling"
DATA = ROOT / "runs/dev/cmd_demos.hdf5"
OUT40 = HERE / "label-ceiling-40"
DATA40 = ROOT / "runs/dev/cmd_demos40.hdf5"
TASKS = [
    "libero_10:KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it",
    "libero_10:KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it",
    "libero_10:KITCHEN_SCENE6_put_the_yellow_and_white_mug_in_the_microwave_and_close_it",
    "libero_10:LIVING_ROOM_SCENE2_put_both_the_alphabet_soup_and_the_tomato_sauce_in_the_basket",
    "libero_10:LIVING_ROOM_SCENE2_put_both_the_cream_cheese_box_and_the_butter_in_the_basket",
    "libero_goal:open_the_top_drawer_and_put_the_bowl_inside",
]
SHORT = ["stove + moka", "bottom drawer + bowl", "microwave", "soup + tomato sauce", "cream cheese + butter",
         "top drawer + bowl"]
# (L_g, global_path, segment_points, points_per_segment); the first two: the shipped window and the v3 one
SHIPPED, COMMANDED_CORNERS = (51, "observed", "length", 6), (97, "commanded", "corners", 6)
VARIANTS = [(51, "observed", "length", 6), (97, "observed", "length", 6), (97, "observed", "length", 8),
            (97, "observed", "corners", 6), (97, "observed", "corners", 8), (97, "commanded", "length", 6),
            (97, "commanded", "length", 8), (97, "commanded", "corners", 6), (97, "commanded", "corners", 8)]


def name(v) -> str:
    return f"L{v[0]}_{v[1]}_{v[2]}_{v[3]}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--summarize", action="store_true", help="rewrite the docs section from the reports, run nothing")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--all-tasks", action="store_true",
                    help="all 40 tasks, seeds 0-1, the shipped window against the commanded corner points")
    ap.add_argument("--variants", default=None,
                    help=f"comma-separated variants to run (default all: {', '.join(name(v) for v in VARIANTS)})")
    a = ap.parse_args()
    chosen = VARIANTS if a.variants is None else [v for v in VARIANTS if name(v) in a.variants.split(",")]
    unknown = set((a.variants or "").split(",")) - {name(v) for v in VARIANTS} - {""}
    if unknown:
        ap.error(f"unknown variants {sorted(unknown)}; choose from {', '.join(name(v) for v in VARIANTS)}")
    if a.all_tasks and a.variants is not None:
        ap.error(f"--all-tasks replays its own two variants ({name(SHIPPED)}, {name(COMMANDED_CORNERS)}); "
                 "give --variants without it")
    if a.all_tasks:
        from dev_runs import S4

        data, out, chosen = DATA40, OUT40, [SHIPPED, COMMANDED_CORNERS]
        collect = ["--suite", S4, "--episodes-per-task", "2"]
    else:
        data, out, collect = DATA, OUT, ["--tasks", ",".join(TASKS), "--episodes-per-task", "5"]
    if not a.summarize:
        replay_variants(data, out, chosen, collect, a.workers)
    write_section_40() if a.all_tasks else write_section()


def replay_variants(data: Path, out: Path, variants, collect: list[str], workers: int) -> None:
    out.mkdir(exist_ok=True)
    if not data.is_file():
        subprocess.run([sys.executable, "-m", "tcot_hybrid.cli", "collect", *collect, "--seed-start", "0",
                        "--image-every", "30", "--workers", str(workers), "--quiet", "--out", str(data)],
                       check=True, cwd=ROOT)
    from tcot_hybrid.data.labels import TrajectoryWindowConfig
    from tcot_hybrid.data.replay import ReplayConfig, replay_file

    for v in variants:
        path = out / f"{name(v)}.json"
        if path.is_file():
            continue
        w = TrajectoryWindowConfig(L_g=v[0], L_l=1, n_l=1, global_spacing="events", global_path=v[1],
                                   segment_points=v[2], points_per_segment=v[3])
        report = replay_file(data, config=ReplayConfig(windows=w, orientation=True), workers=workers)
        report["command"] = (f"tcot replay --data {data.relative_to(ROOT)} --global-spacing events --L-g {v[0]} "
                             f"--orientation --global-path {v[1]} --segment-points {v[2]} "
                             f"--points-per-segment {v[3]} --workers {workers}")
        path.write_text(json.dumps(report, indent=1) + "\n")
        print(f"{name(v)}: {report['success_rate']:.3f} ({report['wall_s']} s)")


def write_section_40() -> None:
    from dev_runs import SUITES, per_suite

    from tcot_hybrid.markdown import update_readme_section

    reps = {v: json.loads((OUT40 / f"{name(v)}.json").read_text()) for v in (SHIPPED, COMMANDED_CORNERS)
            if (OUT40 / f"{name(v)}.json").is_file()}
    rows = []
    for v, rep in reps.items():
        eps = [{**d, "suite": d["task"].split(":")[0]} for d in rep["demos"]]
        rows.append(f"| {v[0]} | {v[1]} | {v[2]} | {v[3]} | " + " | ".join(per_suite(eps))
                    + f" | **{sum(e['success'] for e in eps)}/{len(eps)}** |")
    diff = ""
    if len(reps) == 2:
        base, new = (reps[v]["per_task"] for v in (SHIPPED, COMMANDED_CORNERS))
        changed = [f"{t.split(':')[1]} {base[t]['successes']} -> {new[t]['successes']}" for t in sorted(base)
                   if base[t]["successes"] != new[t]["successes"]]
        diff = "\n\nTasks whose count differs (of 2): " + "; ".join(changed) + "."
    text = ("Label replays over all 40 tasks (`python docs/libero-planner/label_ceiling.py --all-tasks`; as above, "
            "2 demos a task, training seeds 0-1; reports in `docs/libero-planner/label-ceiling-40/`):\n\n"
            "| L_g | path labelled | points placed by | points a piece | " + " | ".join(SUITES) + " | all |\n"
            "|---|---|---|---|" + "---|" * (len(SUITES) + 1) + "\n" + "\n".join(rows) + diff)
    update_readme_section(HERE.parent / "libero-planner.md", "libero-label-ceiling-40", text)


def write_section() -> None:
    from tcot_hybrid.markdown import update_readme_section

    rows = []
    for v in VARIANTS:
        path = OUT / f"{name(v)}.json"
        if not path.is_file():
            continue
        rep = json.loads(path.read_text())
        cells = [f"{rep['per_task'][t]['successes']}/{rep['per_task'][t]['demos']}" if t in rep["per_task"] else "-"
                 for t in TASKS]
        n = sum(rep["per_task"][t]["successes"] for t in TASKS if t in rep["per_task"])
        d = sum(rep["per_task"][t]["demos"] for t in TASKS if t in rep["per_task"])
        rows.append(f"| {v[0]} | {v[1]} | {v[2]} | {v[3]} | " + " | ".join(cells) + f" | **{n}/{d}** |")
    text = ("Label replays (`python docs/libero-planner/label_ceiling.py`; each demo's own t = 0 global label with its "
            "orientation, one frozen global plan, no local replanning, on the demo's own sampled layout; the successful ones "
            "of 5 demos a task, training seeds 0-4; reports in `docs/libero-planner/label-ceiling/`):\n\n"
            "| L_g | path labelled | points placed by | points a piece | " + " | ".join(SHORT) + " | all |\n"
            "|---|---|---|---|" + "---|" * (len(SHORT) + 1) + "\n" + "\n".join(rows))
    update_readme_section(HERE.parent / "libero-planner.md", "libero-label-ceiling", text)


if __name__ == "__main__":
    main()
