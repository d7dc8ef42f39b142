"""Does the learned global prompt follow an object that is not where the layouts put it? (docs/libero-planner.md,
"Where the global prompt looks"), written to follow.json:

    .venv/bin/python docs/libero-planner/follow.py [--seed 20000] [--move 0.05] [--out docs/libero-planner/follow.json]

For every task of the four suites, on a sampled development layout (docs/seeds.md): the shipped checkpoint's global
plan at t = 0 (its first grasp g0); then the object of the first skill not yet done is moved ``--move`` metres on its
support, as the object_moved perturbation moves it (tcot_hybrid.perturbations), and the global plan is asked again
from the same posture (g1). ``follow`` is the grasp's shift along the object's, as a fraction of it: 1 when the grasp
moves with the object, 0 when it stays where the layouts usually put it. ``layout_spread_cm``: how far that object
stands from its mean position over ``--spread-layouts`` sampled layouts from the same seed on (the largest distance):
how much LIBERO's layouts move it.
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")


def first_grasp(runner, step: int) -> np.ndarray | None:
    """World position [m] of the first closed-gripper waypoint of a fresh global plan, or None (no grasp planned)."""
    from tcot_hybrid.lift import lift_waypoints

    runner.invalidate_observation()
    plan = runner.stack.planner.plan(runner.observe(step), mode="global")
    points = lift_waypoints(plan.uv_px, plan.depth_m, runner.stack.camera, config=runner.cfg.lift)
    closed = np.flatnonzero(plan.gripper_closed)
    return points[closed[0]] if len(closed) else None


def layout_spread_cm(task: str, obj: str, seeds: range) -> float:
    """Largest distance [cm] of ``obj`` from its mean table position over the sampled layouts ``seeds``."""
    import mujoco

    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig

    xy = []
    for seed in seeds:
        world = EpisodeRunner(RunConfig(task=task, seed=seed, init="sampled", planner="oracle")).stack.sim.world
        mujoco.mj_forward(world.model, world.data)
        xy.append(world.pos(obj)[:2])
    xy = np.array(xy)
    return round(100 * float(np.linalg.norm(xy - xy.mean(0), axis=1).max()), 1)


def probe(task: str, seed: int, move_m: float, spread_layouts: int) -> dict | None:
    import mujoco

    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.perturbations import _first_open_skill, _relocate
    from tcot_hybrid.run_config import RunConfig

    from tcot_hybrid.learning.checkpoint import default_checkpoint

    runner = EpisodeRunner(RunConfig(task=task, seed=seed, init="sampled", planner="learned",
                                     checkpoint=str(default_checkpoint("libero_panda"))))  # the four-suite model
    runner.settle()
    world = runner.stack.sim.world
    g0, skill = first_grasp(runner, 0), _first_open_skill(runner)
    if g0 is None or skill is None or skill.obj not in world.objects:
        return None  # nothing to grasp first, or a fixture (a drawer, the stove): nothing to move
    o0 = world.pos(skill.obj)
    if _relocate(runner, skill.obj, move_m, np.random.default_rng(seed)) is None:
        return None
    mujoco.mj_forward(world.model, world.data)
    o1 = world.pos(skill.obj)
    d = o1[:2] - o0[:2]
    if np.linalg.norm(d) < 0.5 * move_m:  # a drawer shifts at most 6 cm sideways, and only when it fits
        return None
    g1 = first_grasp(runner, 1)
    if g1 is None:
        return None
    s = g1[:2] - g0[:2]
    return {"task": task, "object": skill.obj, "moved_cm": round(100 * float(np.linalg.norm(d)), 1),
            "grasp_shift_cm": round(100 * float(np.linalg.norm(s)), 1), "follow": round(float(s @ d / (d @ d)), 3),
            "grasp_to_object_before_cm": round(100 * float(np.linalg.norm(g0[:2] - o0[:2])), 1),
            "grasp_to_object_after_cm": round(100 * float(np.linalg.norm(g1[:2] - o1[:2])), 1),
            "layout_spread_cm": layout_spread_cm(task, skill.obj, range(seed, seed + spread_layouts))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=20000, help="sampled development layout (docs/seeds.md)")
    ap.add_argument("--move", type=float, default=0.05, help="how far the object is moved [m]")
    ap.add_argument("--spread-layouts", type=int, default=10, help="sampled layouts the object's spread is taken over")
    ap.add_argument("--out", default=str(HERE / "follow.json"))
    a = ap.parse_args()
    if not 0.0 < a.move <= 0.2:
        ap.error(f"--move must be in (0, 0.2] m, got {a.move}")
    if a.spread_layouts < 2:
        ap.error(f"--spread-layouts must be >= 2, got {a.spread_layouts}")
    os.environ.setdefault("MUJOCO_GL", "egl")
    from tcot_hybrid.tasks.registry import list_all_tasks

    rows = []
    for t in list_all_tasks():
        if t["world"] == "libero" and t["suite"] in SUITES:
            row = probe(t["name"], a.seed, a.move, a.spread_layouts)
            if row is not None:
                rows.append(row)
                print(json.dumps(row), flush=True)
    follow = [r["follow"] for r in rows]
    spread = [r["layout_spread_cm"] for r in rows]
    summary = {"seed": a.seed, "move_m": a.move, "tasks": len(rows), "median_follow": round(float(np.median(follow)), 3),
               "quartiles": [round(float(q), 3) for q in np.percentile(follow, [25, 75])],
               "spread_layouts": a.spread_layouts, "median_layout_spread_cm": round(float(np.median(spread)), 1),
               "max_layout_spread_cm": max(spread), "rows": rows}
    Path(a.out).write_text(json.dumps(summary, indent=1) + "\n")
    print(f"{len(rows)} tasks: median follow {summary['median_follow']} (quartiles {summary['quartiles']}); objects' "
          f"layout spread median {summary['median_layout_spread_cm']} cm, largest {summary['max_layout_spread_cm']} cm "
          f"-> {a.out}")


if __name__ == "__main__":
    main()
