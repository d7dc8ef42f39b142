"""Why libero_10's book task fails under the learned planner (docs/libero-planner.md, "The book: a grasp 1-2 cm off"):
each development layout run global-only once with the oracle and once with the learned planner (libero_10's shipped
model), recording where the hand first closed, the first tracking reflex, and success. The learned grasp's offset
from the oracle's (which grasps the book at its centre) is the network's grasp error on that layout.

    MUJOCO_GL=egl .venv/bin/python docs/libero-planner/book_grasp.py   # layouts 20026-20031 -> book_grasp.json, table
    .venv/bin/python docs/libero-planner/book_grasp.py --show     # book_grasp.json -> table
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

import dev_runs  # this folder's: run as a script, the folder is on sys.path

HERE = Path(__file__).resolve().parent
OUT = HERE / "book_grasp.json"
TASK = "libero_10:STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_back_compartment_of_the_caddy"
SEEDS = range(20026, 20032)  # development layouts (docs/seeds.md), never the shipped init states


def run(planner: str, seed: int) -> dict:
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.workers import one_torch_thread

    cfg = dev_runs.episode_config(TASK, seed, planner)
    seen = {"grasp": None}

    def hook(runner, step):  # the hand where the gripper was first commanded closed
        sim = runner.stack.sim
        if seen["grasp"] is None and sim.gripper_closed_cmd():
            seen["grasp"] = [round(float(v), 4) for v in sim.tcp_pos()]

    r = EpisodeRunner(cfg, frame_hook=hook)
    with one_torch_thread():  # as `tcot run` and the evaluation's workers: an episode can turn on the last bits
        r.run()
    reflex = next((e for e in r.stack.executor.events if e["kind"] == "tracking_reflex"), None)
    return {"planner": planner, "seed": seed, "success": bool(r.success), "grasp": seen["grasp"],
            "reflex": None if reflex is None else {k: reflex[k] for k in ("t", "joint", "error_rad", "waypoint")}}


def table(rows: list[dict]) -> list[str]:
    by = {(r["planner"], r["seed"]): r for r in rows}
    out = ["| layout | oracle | learned | learned grasp - oracle grasp (x, y, z) [cm] | horizontal [cm] | learned: "
           "first tracking reflex |", "|---|---|---|---|---|---|"]
    for seed in sorted({r["seed"] for r in rows}):
        o, lr = by[("oracle", seed)], by[("learned", seed)]
        d = np.subtract(lr["grasp"], o["grasp"]) * 100 if lr["grasp"] and o["grasp"] else None
        off = "-" if d is None else ", ".join(f"{v:+.1f}" for v in d)
        hor = "-" if d is None else f"{np.hypot(d[0], d[1]):.1f}"
        rf = lr["reflex"]
        rfs = "-" if rf is None else f"{rf['joint']} at {rf['t']:.1f} s (waypoint {rf['waypoint']})"
        out.append(f"| {seed} | {'success' if o['success'] else 'failure'} | "
                   f"{'success' if lr['success'] else 'failure'} | {off} | {hor} | {rfs} |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--show", action="store_true", help="print the table of the saved JSON, run nothing")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    if not a.show:
        jobs = [(p, s) for s in SEEDS for p in ("oracle", "learned")]
        with ProcessPoolExecutor(a.workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            rows = list(pool.map(run, *zip(*jobs)))
        OUT.write_text(json.dumps(rows, indent=1) + "\n")
    print("\n".join(table(json.loads(OUT.read_text()))))


if __name__ == "__main__":
    main()
