"""Whether a plan's long segments should be cut so the hand follows the planned line (``executor.max_segment_m``;
docs/libero-planner.md, "Straight segments"): first the book, where it was found (training-range layouts), then the
judgement by the rule set before its runs (docs/seeds.md, stop 68): all 40 tasks, global-only and GLSR at the stack's
defaults, with and without the cut, on fresh development layouts (5 a task, 10 on libero_10).

    .venv/bin/python docs/libero-planner/straight_segments.py --gather   # runs/dev/cut* -> straight_segments.json
    .venv/bin/python docs/libero-planner/straight_segments.py            # the .json -> docs/libero-planner.md
"""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "straight_segments.json"
SECTION = "libero-straight-segments"
BOOK = "libero_10:STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_back_compartment_of_the_caddy"
SCREEN_FIRST, SCREEN_LAYOUTS = 30192, 20  # training-range layouts (docs/seeds.md): where the bow was found
PER_TASK = {"libero_spatial": 5, "libero_object": 5, "libero_goal": 5, "libero_10": 10}
OFF = " --executor.max-segment-m None"
ALL, VERTICAL, CLOSED, HOLDING = (f" --executor.max-segment-m 0.04 --executor.cut-segments {w}"
                                  for w in ("all", "vertical", "closed_descents", "holding_descents"))
# (run prefix, what ran, the cut's flags, the fresh layouts' first seed per suite); each rule was set before its runs
# (docs/seeds.md, stop 68). The first ran at 5e03de3 (every long segment cut, a cut point's orientation slerped along
# its segment); the second at 85b7765 (every long segment, a cut point at its segment end's orientation, as a squared
# corner; stopped once libero_10 had failed); the third at a218b8b (a closed hand's vertical descents alone).
JUDGEMENTS = (("cut", "first judgement: every long segment cut, orientations slerped (5e03de3)", ALL,
               {"libero_spatial": 20052, "libero_object": 20060, "libero_goal": 20221, "libero_10": 20253}),
              ("cut2", "second judgement: every long segment cut, at its end's orientation (85b7765; stopped once "
               "libero_10 had failed, its other suites' layouts libero_spatial 20057, libero_object 20065, libero_goal "
               "20226 on)", ALL, {"libero_10": 20263}),
              ("cut3", "third judgement: a closed hand's vertical descents cut (a218b8b)", CLOSED,
               {"libero_spatial": 20062, "libero_object": 20070, "libero_goal": 20231, "libero_10": 20273}),
              ("cut4", "fourth judgement: the vertical descents of a hand holding something cut (1b8a012)", HOLDING,
               {"libero_spatial": 20067, "libero_object": 20075, "libero_goal": 20236, "libero_10": 20283}))
SETTINGS = (("off", "as planned (no cut)"), ("on", "cut to 4 cm"))
SCREENS = (("off", "as planned (no cut)", OFF),
           ("on", "every long segment, orientations slerped (5e03de3)", ALL),
           ("on2", "every long segment, at its end's orientation (85b7765)", ALL),
           ("on3", "vertical segments (a218b8b)", VERTICAL),
           ("on4", "a closed hand's vertical descents (a218b8b)", CLOSED),
           ("on5", "a holding hand's vertical descents (1b8a012)", HOLDING))
# the five libero_10 tasks the second judgement lost on, with the narrower cuts, on its layouts and on the third's
# (both development ones by then): (run, label, flags, first layout, the uncut run they are counted against)
LOSERS = ("KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it",
          "KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it",
          "KITCHEN_SCENE6_put_the_yellow_and_white_mug_in_the_microwave_and_close_it",
          "KITCHEN_SCENE8_put_both_moka_pots_on_the_stove",
          "LIVING_ROOM_SCENE2_put_both_the_cream_cheese_box_and_the_butter_in_the_basket")
LOSER_RUNS = (("cutlosers_vertical", "vertical segments", VERTICAL, 20263, "cut2_off"),
              ("cutlosers_closed", "a closed hand's vertical descents", CLOSED, 20263, "cut2_off"),
              ("cutlosers3_holding", "a holding hand's vertical descents", HOLDING, 20273, "cut3_off"))
MODES = ("global", "glsr")
KEEP = ("task", "suite", "mode", "seed", "success", "steps", "tracking_reflexes")


def _command(which: str, episodes: int, first: int, flag: str) -> str:
    return (f"tcot eval {which} --planners learned --modes global,glsr --init sampled --episodes {episodes} "
            f"--seed-start {first}{flag}")


def _runs() -> list[tuple[str, str, str]]:
    """(run directory under runs/dev, setting, command): the book's screens, the second judgement's losers again, then
    one run per judgement, suite and setting. (Uncut runs made before "--executor.max-segment-m None" existed ran
    without the flag: the same thing.)"""
    screen = [(f"cutscreen_{name}", f"cutscreen_{name}",
               _command(f"--tasks {BOOK}", SCREEN_LAYOUTS, SCREEN_FIRST, flag)) for name, _, flag in SCREENS]
    losers = ",".join(f"libero_10:{t}" for t in LOSERS)
    again = [(name, name, _command(f"--tasks {losers}", 10, first, flag)) for name, _, flag, first, _ in LOSER_RUNS]
    return screen + again + [(f"{prefix}_{name}_{suite}", f"{prefix}_{name}",
                              _command(f"--suite {suite}", PER_TASK[suite], first[suite], on if name == "on" else OFF))
                             for prefix, _, on, first in JUDGEMENTS for suite in first for name, _ in SETTINGS]


def _row(setting: str, e: dict) -> dict | None:
    if e["perturb"] != "none":
        return None
    return {"run": setting, **{k: e.get(k) for k in KEEP}}


def gather() -> None:
    setting = {run: name for run, name, _ in _runs()}
    dev_runs.gather(((run, cmd) for run, _, cmd in _runs()), OUT, lambda run, e: _row(setting[run], e))


def _screen(rows: list[dict]) -> list[str]:
    rows = [r for r in rows if r["run"].startswith("cutscreen_")]
    out = [f"**Where it was found.** The book (libero_10), training-range layouts {SCREEN_FIRST}-"
           f"{SCREEN_FIRST + SCREEN_LAYOUTS - 1}, the stack's defaults otherwise:", "",
           "| segments | mode | successes | episodes with a tracking reflex | median planner steps of the successes |",
           "|---|---|---|---|---|"]
    for name, text, _ in SCREENS:
        for mode in MODES:
            eps = [r for r in rows if r["run"] == f"cutscreen_{name}" and r["mode"] == mode]
            if not eps:
                continue
            won = sorted(r["steps"] for r in eps if r["success"])
            median = won[len(won) // 2] if won else "-"
            out.append(f"| {text} | {mode} | {sum(r['success'] for r in eps)}/{len(eps)} | "
                       f"{sum(bool(r['tracking_reflexes']) for r in eps)} | {median} |")
    return out + [""]


def _losers(rows: list[dict]) -> list[str]:
    out = ["**The second judgement's losers again** (the five libero_10 tasks it lost on, on its layouts "
           "20263-20272 and on the third's 20273-20282, by then development ones), with the narrower cuts; won / lost "
           "against the uncut run on the same layouts:", "", "| segments | layouts | mode | successes | won / lost |",
           "|---|---|---|---|---|"]
    def by_layout(run: str, mode: str) -> dict:
        return {(r["task"], r["seed"]): r["success"] for r in rows if r["run"] == run and r["mode"] == mode}

    for first, base_run in sorted({(f, b) for _, _, _, f, b in LOSER_RUNS}):
        runs = [x for x in LOSER_RUNS if x[3] == first]
        for mode in MODES:
            base, keys = by_layout(base_run, mode), by_layout(runs[0][0], mode).keys()
            out.append(f"| as planned (no cut) | {first}-{first + 9} | {mode} | "
                       f"{sum(base.get(k, False) for k in keys)}/{len(keys)} | - |")
            for name, text, _, _, _ in runs:
                eps = by_layout(name, mode)
                out.append(f"| {text} | {first}-{first + 9} | {mode} | {sum(eps.values())}/{len(eps)} | "
                           f"{dev_runs.won_lost_keyed(base, eps)} |")
    return out + [""]


def _judgement(rows: list[dict], prefix: str, label: str, first: dict) -> list[str]:
    ran = Counter((r["run"], r["suite"], r["mode"]) for r in rows)
    done = [s for s in first if all(ran[(f"{prefix}_{n}", s, m)] == 10 * PER_TASK[s] for n, _ in SETTINGS
                                    for m in MODES)]
    rows = [r for r in rows if r["run"].startswith(prefix + "_") and r["suite"] in done]
    layouts = ", ".join(f"{s} {first[s]}-{first[s] + PER_TASK[s] - 1}" for s in done)
    table_rows = tuple((f"{prefix}_{name}", mode, text, "") for mode in MODES for name, text in SETTINGS)
    lines = [f"**{label[0].upper() + label[1:]}.** Sampled development layouts ({layouts}), all ten tasks of each "
             "suite, the stack's defaults otherwise (no `--checkpoint`); won / lost against the uncut row in the same "
             "mode on the same layouts:", ""] + dev_runs.checkpoint_table(rows, table_rows, head="segments")
    for mode in MODES:
        lines += ["", dev_runs.changed_tasks(rows, mode, f"{prefix}_off", f"{prefix}_on", "5 or 10", f"{prefix}_off")]
    return lines + [""]


def lines() -> list[str]:
    rows = [json.loads(x) for x in OUT.read_text().splitlines() if x.strip()]
    judged = [line for prefix, label, _, first in JUDGEMENTS for line in _judgement(rows, prefix, label, first)]
    return _screen(rows) + _losers(rows) + judged + dev_runs.command_lines("straight_segments.py", 2,
                                                           [(run, cmd) for run, _, cmd in _runs()])


if __name__ == "__main__":
    dev_runs.main(__doc__, gather, lines, SECTION)
