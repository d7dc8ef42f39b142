"""How many consecutive "done" calls of the failure detector should end an episode (``--stop-hold-steps``)?

Reads one detector-stopped evaluation run with a hold too long to ever stop (``--stop-on detector
--stop-hold-steps 100000``: every stop check of every step is logged, with the predicate beside it) and replays
the stopping rule for each hold H: where the episode would have stopped, and whether the predicate held there.
The episode is deterministic up to the stop, so one run answers every H.

    python docs/eval-glsr/dev/stop_hold.py docs/eval-glsr/dev/stop-hold [--readme docs/glsr.md]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

HOLDS = (1, 2, 3, 5, 8, 10, 12, 15, 20)


def replay(records: list[dict], hold: int, threshold: float = 0.5) -> dict:
    stops = premature = success = 0
    for r in records:
        h, stop = 0, None
        for e in (e for e in r["events"] if e["kind"] == "stop_check"):
            h = h + 1 if e["p_success"] >= threshold else 0
            if h >= hold:
                stop = e
                break
        if stop is None:  # never stopped: judged at the time limit, as the run was
            success += bool(r["success"])
        else:
            stops += 1
            premature += not stop["true_success"]
            success += bool(stop["true_success"])
    return {"hold": hold, "stops": stops, "premature": premature, "success": success, "n": len(records)}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("run", type=Path)
    p.add_argument("--readme", type=Path)
    args = p.parse_args()
    records = [json.loads(line) for line in (args.run / "episodes.jsonl").read_text().splitlines()]
    seeds = sorted({r["seed"] for r in records})
    lines = [f"Written by `python docs/eval-glsr/dev/stop_hold.py {args.run}` from {len(records)} learned-GLSR "
             f"episodes (all tasks, no perturbation, tuning seeds {seeds[0]}-{seeds[-1]}):", "",
             "| hold [steps] | stopped by the detector | premature stops | success |", "|---|---|---|---|"]
    for h in HOLDS:
        r = replay(records, h)
        lines.append(f"| {h} | {r['stops']} / {r['n']} | {r['premature']} | {r['success']} / {r['n']} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.readme:
        from tcot_hybrid.markdown import update_readme_section

        update_readme_section(args.readme, "stop_hold", text)


if __name__ == "__main__":
    main()
