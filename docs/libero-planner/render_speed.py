"""What leaving unseen meshes out of a render saved on LIBERO (tcot_hybrid/frustum.py at 1261862, since removed), and
whether an image ever changed: an oracle episode per scene on a development layout (docs/seeds.md), every planner
step's image rendered with and without the culling, each timed; and whole episodes: the GLSR protocol row's first
episodes run again at 1261862 (culling on, workers with LP_NUM_THREADS=0; `render-speed/rerun_1261862.jsonl`)
against the same episodes of the row at db26995 (`eval-protocol/records.jsonl`), both with 2 workers on idle cores.
Writes render_speed.json and the <!-- libero-render-speed --> section of docs/libero-planner.md:

    .venv/bin/python docs/libero-planner/render_speed.py      # ~3 minutes on one core, at 1261862
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
TASKS = ("libero_spatial:pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate",
         "libero_object:pick_up_the_ketchup_and_place_it_in_the_basket",
         "libero_goal:put_the_wine_bottle_on_top_of_the_cabinet",
         "libero_10:KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it")
SEED = 20000


def measure(task: str, seed: int) -> dict:
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.frustum import outside_frustum
    from tcot_hybrid.run_config import RunConfig

    cfg = RunConfig(task=task, seed=seed, init="sampled", planner="oracle")
    cam, px = cfg.scene.planner_camera, cfg.scene.planner_image_px
    culled_ms, full_ms, same, hidden_share = [], [], [], []

    def both(runner, step):
        sim = runner.stack.sim
        m, d = sim.model, sim.data
        cid = m.camera(cam).id
        meshes = sim._culling.meshes[m.geom_rgba[sim._culling.meshes, 3] > 0]
        verts = 3 * m.mesh_facenum[m.geom_dataid[meshes]]
        out = outside_frustum(d.cam_xpos[cid], d.cam_xmat[cid].reshape(3, 3), float(m.cam_fovy[cid]), 1.0,
                              d.geom_xpos[meshes], m.geom_rbound[meshes])
        hidden_share.append(float(verts[out].sum() / verts.sum()))
        t0 = time.perf_counter()
        culled = sim.render(cam, px, px)
        t1 = time.perf_counter()
        applies = sim._culling.applies
        sim._culling.applies = lambda *_: False
        try:
            full = sim.render(cam, px, px)
        finally:
            sim._culling.applies = applies
        t2 = time.perf_counter()
        culled_ms.append((t1 - t0) * 1e3)
        full_ms.append((t2 - t1) * 1e3)
        same.append(bool(np.array_equal(culled, full)))

    runner = EpisodeRunner(cfg, frame_hook=both)
    rec = runner.run()
    n_vert = int(3 * runner.stack.sim.model.mesh_facenum.sum())
    runner.stack.sim.close()
    return {"task": task, "seed": seed, "success": rec["success"], "frames": len(same), "identical": sum(same),
            "mesh_vertices": n_vert, "hidden_share": round(float(np.mean(hidden_share)), 3),
            "full_ms": round(float(np.median(full_ms)), 2), "culled_ms": round(float(np.median(culled_ms)), 2)}


def rerun() -> dict:
    """Whole episodes: the rerun's wall time per episode against the protocol row's, same (task, init state)."""
    rows = [json.loads(x) for x in (HERE / "render-speed" / "rerun_1261862.jsonl").read_text().splitlines()]
    row = {}
    for x in (HERE / "eval-protocol" / "records.jsonl").read_text().splitlines():
        r = json.loads(x)
        if r["planner"] == "learned" and r["mode"] == "glsr" and r["perturb"] == "none":
            row[(r["task"], r["seed"])] = r
    by_task: dict[str, list[float]] = {}
    same = 0
    for r in rows:
        o = row[(r["task"], r["seed"])]
        same += o["success"] == r["success"] and o["steps"] == r["steps"]
        if o["wall_time_s"] > 10:  # the short ones are dominated by the scene's first frames
            by_task.setdefault(r["task"].split(":")[1], []).append(r["wall_time_s"] / o["wall_time_s"])
    return {"episodes": len(rows), "same_outcome_and_steps": same,
            "wall_ratio": {t: {"episodes": len(v), "p10": round(float(np.percentile(v, 10)), 3),
                               "median": round(float(np.median(v)), 3), "p90": round(float(np.percentile(v, 90)), 3)}
                           for t, v in by_task.items()}}


def section(rows: list[dict], ab_: dict) -> str:
    lines = ["**Meshes out of sight, left out** (`docs/libero-planner/render_speed.py` → `render_speed.json`; an oracle "
             f"episode per scene, development layout seed {rows[0]['seed']}, every planner step's image rendered with and "
             f"without the culling; medians on one core, load average {rows[0]['load']:.1f} at the start, "
             f"LP_NUM_THREADS={rows[0]['lp_num_threads']}):", "",
             "| scene | frames | identical | vertices drawn (3 a triangle) | share outside the view | all drawn [ms] | "
             "unseen left out [ms] |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['task']} | {r['frames']} | {r['identical']} | {r['mesh_vertices']:,} | "
                     f"{r['hidden_share']:.2f} | {r['full_ms']} | {r['culled_ms']} |")
    lines += ["", f"Whole episodes: {ab_['episodes']} episodes of the GLSR protocol row run again at 1261862, "
              f"{ab_['same_outcome_and_steps']} with the same outcome and step count as the row at db26995; wall time "
              "against the row's, per episode over 10 s (p10 / median / p90):", "",
              "| task | episodes | wall time, 1261862 / db26995 |", "|---|---|---|"]
    for t, w in ab_["wall_ratio"].items():
        lines.append(f"| {t} | {w['episodes']} | {w['p10']:.2f} / **{w['median']:.2f}** / {w['p90']:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=SEED, help="development layout seed (default %(default)s)")
    ap.add_argument("--gather", action="store_true", help="only re-read the episodes and rewrite the section")
    args = ap.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    out = HERE / "render_speed.json"
    if args.gather:
        rows = json.loads(out.read_text())["scenes"]
    else:
        load = os.getloadavg()[0]
        lp = os.environ.get("LP_NUM_THREADS", "unset")
        rows = [{**measure(t, args.seed), "load": load, "lp_num_threads": lp} for t in TASKS]
    ab_ = rerun()
    out.write_text(json.dumps({"scenes": rows, "ab": ab_}, indent=1) + "\n")
    text = section(rows, ab_)
    update_readme_section(ROOT / "docs" / "libero-planner.md", "libero-render-speed", text)
    print(text)
    if any(r["identical"] != r["frames"] for r in rows):
        raise SystemExit("an image with unseen meshes left out differed from drawing everything")


if __name__ == "__main__":
    main()
