"""What a planner image costs on LIBERO, one full render against the cached backdrop (tcot_hybrid/rendering.py), and
whether the two ever differ: an oracle episode per scene on a development layout (docs/seeds.md), every planner step's
image made both ways and compared, each timed. Writes render_cost.json and the <!-- libero-render-cost --> section of
docs/libero-planner.md:

    .venv/bin/python docs/libero-planner/render_cost.py        # ~2 minutes on one core; run it on an idle machine
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from tcot_hybrid.markdown import update_readme_section

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
# one scene per suite; libero_10's kitchen holds the most static vertices
TASKS = ("libero_spatial:pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate",
         "libero_object:pick_up_the_ketchup_and_place_it_in_the_basket",
         "libero_goal:put_the_wine_bottle_on_top_of_the_cabinet",
         "libero_10:KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it")
SEED = 20000


def measure(task: str, seed: int) -> dict:
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig

    cfg = RunConfig(task=task, seed=seed, init="sampled", planner="oracle")
    cam, px = cfg.scene.planner_camera, cfg.scene.planner_image_px
    full_ms, layered_ms, same = [], [], []

    def both(runner, step):
        sim = runner.stack.sim
        t0 = time.perf_counter()
        layered = sim.render(cam, px, px)
        t1 = time.perf_counter()
        r = sim.renderer(px, px)
        r.update_scene(sim.data, camera=cam, scene_option=sim.render_option)
        full = r.render()
        t2 = time.perf_counter()
        layered_ms.append((t1 - t0) * 1e3)
        full_ms.append((t2 - t1) * 1e3)
        same.append(bool(np.array_equal(layered, full)))

    runner = EpisodeRunner(cfg, frame_hook=both)
    rec = runner.run()
    layer = runner.stack.sim._layered.get((cam, px, px))
    runner.stack.sim.close()
    return {"task": task, "seed": seed, "success": rec["success"], "frames": len(same), "identical": sum(same),
            "full_ms": round(float(np.median(full_ms)), 2), "layered_ms": round(float(np.median(layered_ms)), 2),
            "layered": bool(layer and layer.layered), "backdrop_renders": layer.backdrop_renders if layer else 0,
            "whole_frames": layer.whole_frames if layer else 0}


def section(rows: list[dict]) -> str:
    lines = ["**A planner image on LIBERO, one full render against the cached backdrop** (`docs/libero-planner/"
             "render_cost.py` → `render_cost.json`; an oracle episode per scene, development layout seed "
             f"{rows[0]['seed']}, every planner step's image made both ways; medians on one core, load average "
             f"{rows[0]['load']:.1f} at the start):", "",
             "| scene | frames | identical | full render [ms] | cached backdrop [ms] | backdrop drawn | frames drawn whole |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['task']} | {r['frames']} | {r['identical']} | {r['full_ms']} | {r['layered_ms']} | "
                     f"{r['backdrop_renders']} | {r['whole_frames']} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=SEED, help="development layout seed (default %(default)s)")
    args = ap.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    load = os.getloadavg()[0]
    rows = [{**measure(t, args.seed), "load": load} for t in TASKS]
    (HERE / "render_cost.json").write_text(json.dumps(rows, indent=1) + "\n")
    text = section(rows)
    update_readme_section(ROOT / "docs" / "libero-planner.md", "libero-render-cost", text)
    print(text)
    if any(r["identical"] != r["frames"] for r in rows):
        raise SystemExit("a cached-backdrop image differed from its full render")


if __name__ == "__main__":
    main()
