"""Would a local plan made during the carry put the object down nearer its target than the global plan does?
(docs/libero-planner.md, "Where the plans' error is"; a diagnostic, nothing in the stack uses it.)

    MUJOCO_GL=egl .venv/bin/python docs/libero-planner/carry_release.py --measure --seed 20000  # about 35 min, 1 core
    .venv/bin/python docs/libero-planner/carry_release.py     # runs/dev/carry_release/*.jsonl -> carry_release.json, docs

`--measure` runs every task of the four suites whose goal puts an object on or in something once on a sampled
development layout, learned planner (the task's shipped model), global-only, so the executed plan is the t = 0 global
plan. At every planner step while the hand is
closed on a goal object (the one nearest the hand, within 12 cm) it asks the local prompt for a plan from that image
and records the local plan's first release (the last closed point before the first open one, lifted with the plan's
own camera), the global plan's next release, the hand, the object's offset from the hand and the target's centre (the
goal predicate's target body, or its region's site) in runs/dev/carry_release/<seed>.jsonl.

Read as: where the object would land if the hand let go at a release = that release's xy plus the object's offset
from the hand at the look; its error = the horizontal distance from there to the target's centre. Per carry (one
object taken toward one release of the plan), the local release is the median of the first ``k`` looks made at least
``far`` from the global release (the hand still carrying, the target in view); released at the global point, the
local one, or midway. Carries whose two releases are more than 6 cm apart are left out: there the plan's next release
is not a place toward this target (the top drawer's bowl, set aside first).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
RUNS = ROOT / "runs" / "dev" / "carry_release"
OUT = HERE / "carry_release.json"
SECTION = "libero-carry-release"
HELD_WITHIN_M = 0.12  # a goal object this near the hand while it is closed is taken as the one carried
SAME_PLACE_M = 0.06  # releases further apart than this are not two reads of one place
FARS_M = (0.05, 0.08, 0.12)
LOOKS = (1, 3)
WEIGHTS = (0.0, 0.5, 1.0)  # 0: the global release as planned, 1: the local one


def releases(grip) -> list[int]:
    """Index of each point where the hand is last closed before it opens (the release point)."""
    return [i - 1 for i in range(1, len(grip)) if grip[i - 1] and not grip[i]]


def target_xy(data, target) -> np.ndarray:
    """The target's centre in the table plane: a body's position or a region site's."""
    kind, i = target
    return (data.xpos[i] if kind == "body" else data.site_xpos[i])[:2].copy()


def measure(seed: int) -> None:
    import dev_runs  # this folder's: run as a script, the folder is on sys.path

    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.libero.tasks import STANDARD_SUITES, list_libero_tasks
    from tcot_hybrid.lift import lift_waypoints
    from tcot_hybrid.workers import one_torch_thread

    RUNS.mkdir(parents=True, exist_ok=True)
    out = RUNS / f"{seed}.jsonl"
    done = {json.loads(x)["task"] for x in out.read_text().splitlines()} if out.is_file() else set()
    tasks = [f"{t.suite}:{t.task_name}" for t in list_libero_tasks() if t.suite in STANDARD_SUITES]
    for task in tasks:
        if task in done:
            continue
        runner = EpisodeRunner(dev_runs.episode_config(task, seed, "learned", "global"))
        env, m = runner.stack.task.scene.env, runner.stack.task.scene.model
        preds = []  # (object, target, object body, ("body" | "site", id))
        for g in env.parsed_problem["goal_state"]:
            if g[0].lower() not in ("on", "in") or g[1] not in env.objects_dict:
                continue
            ob = m.body(env.objects_dict[g[1]].root_body).id
            if g[2] in env.objects_dict:
                preds.append((g[1], g[2], ob, ("body", m.body(env.objects_dict[g[2]].root_body).id)))
            else:
                sites = [i for i in range(m.nsite) if m.site(i).name.endswith(g[2])]
                if sites:
                    preds.append((g[1], g[2], ob, ("site", sites[0])))
        if not preds:  # nothing is put anywhere (a drawer opened, a knob turned): no carry to read
            continue
        rows: list[dict] = []
        plans: list = []  # (plan, [(executor point index, release point)])

        def look(r, step):  # runs within this task's episode only: preds, rows and plans are this task's
            sim, ex = r.stack.sim, r.stack.executor
            if ex.plan is not None and (not plans or plans[-1][0] is not ex.plan):
                plans.append((ex.plan, [(i, ex.points[i].tolist()) for i in releases(ex.grip)]))
            if not sim.gripper_closed_cmd():
                return
            hand, d = sim.tcp_pos(), sim.data
            obj, _, ob, t = min(preds, key=lambda p: np.linalg.norm(d.xpos[p[2]] - hand))
            if np.linalg.norm(d.xpos[ob] - hand) > HELD_WITHIN_M:
                return
            plan = r.stack.planner.plan(r.observe(step), mode="local")
            pts = lift_waypoints(plan.uv_px, plan.depth_m, plan.lift_camera(ex.camera))
            rel = releases(np.asarray(plan.gripper_closed, bool))
            ahead = [p for i, p in plans[-1][1] if i >= ex.index] if plans else []
            row = {"step": step, "obj": obj, "hand": np.round(hand, 4).tolist(),
                   "obj_off": np.round(d.xpos[ob][:2] - hand[:2], 4).tolist(),
                   "target": np.round(target_xy(d, t), 4).tolist()}
            if rel:
                row["local_release"] = np.round(pts[rel[0]], 4).tolist()
            if ahead:
                row["global_release"] = np.round(ahead[0], 4).tolist()
            rows.append(row)

        runner.frame_hook = look
        with one_torch_thread():  # as `tcot run` and the evaluation's workers
            runner.run()
        rec = {"task": task, "seed": seed, "success": runner.success, "rows": rows}
        with out.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(f"{task} {'ok' if runner.success else 'failed'}: {len(rows)} looks", flush=True)


def carries(episodes: list[dict], far_m: float, k: int) -> list[dict]:
    """One record per carry: the landing error [m] for each release weight, and whether it was left out."""
    out = []
    for ep in episodes:
        groups: dict = {}
        for r in ep["rows"]:
            if "global_release" in r:
                groups.setdefault((r["obj"], tuple(r["global_release"])), []).append(r)
        for (obj, _), rs in groups.items():
            far = [r for r in rs if "local_release" in r
                   and np.linalg.norm(np.subtract(r["hand"][:2], r["global_release"][:2])) >= far_m]
            if len(far) < k:
                continue
            last = far[k - 1]
            g = np.array(last["global_release"][:2])
            local = np.median([r["local_release"][:2] for r in far[:k]], axis=0)
            off, target = np.array(last["obj_off"]), np.array(last["target"])
            apart = float(np.linalg.norm(local - g))
            errs = [float(np.linalg.norm(g + w * (local - g) + off - target)) for w in WEIGHTS]
            out.append({"task": ep["task"], "seed": ep["seed"], "obj": obj, "apart_m": apart, "errors_m": errs,
                        "left_out": apart > SAME_PLACE_M})
    return out


def summarize() -> dict:
    files = sorted(RUNS.glob("*.jsonl"))
    if not files:
        sys.exit(f"no {RUNS.relative_to(ROOT)}/*.jsonl: run --measure --seed 20000 (and 20001) first")
    episodes = [json.loads(x) for f in files for x in f.read_text().splitlines() if x.strip()]
    rows = []
    for far in FARS_M:
        for k in LOOKS:
            cs = carries(episodes, far, k)
            kept = [c for c in cs if not c["left_out"]]
            e = np.array([c["errors_m"] for c in kept]) * 100
            rows.append({"far_m": far, "looks": k, "carries": len(kept), "left_out": len(cs) - len(kept),
                         "median_cm": np.round(np.median(e, axis=0), 2).tolist(),
                         "over_2cm": (e > 2).sum(axis=0).tolist(), "over_3cm": (e > 3).sum(axis=0).tolist(),
                         "local_nearer": int((e[:, 2] < e[:, 0]).sum()),
                         "global_nearer": int((e[:, 2] > e[:, 0]).sum())})
    return {"seeds": sorted({ep["seed"] for ep in episodes}), "episodes": len(episodes),
            "successes": sum(ep["success"] for ep in episodes), "weights": list(WEIGHTS), "rows": rows}


def markdown(res: dict) -> str:
    seeds = ", ".join(str(s) for s in res["seeds"])
    lines = [f"Sampled development layouts {seeds}, every task of the four suites with an On or In goal, the task's "
             f"shipped model, global-only ({res['episodes']} episodes, {res['successes']} successful); "
             "`docs/libero-planner/carry_release.py` → `carry_release.json`. Landing error: the carried object's "
             "would-be landing (release xy plus the object's offset from the hand) to the target's centre, median [cm] "
             "and carries over 2 / 3 cm:", "",
             "| looks made at least | looks | carries | global release | midway | local release | local nearer / "
             "further |", "|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        cells = [f"{m:.2f} ({a}, {b})" for m, a, b in zip(r["median_cm"], r["over_2cm"], r["over_3cm"])]
        lines.append(f"| {r['far_m'] * 100:.0f} cm from the release | {r['looks']} | {r['carries']} "
                     f"({r['left_out']} left out) | " + " | ".join(cells)
                     + f" | {r['local_nearer']} / {r['global_nearer']} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--measure", action="store_true", help="run the episodes of --seed (resumable, task by task)")
    ap.add_argument("--seed", type=int, help="the development layout to measure on")
    a = ap.parse_args()
    if a.measure:
        if a.seed is None:
            ap.error("--measure needs --seed (a development layout, e.g. 20000)")
        measure(a.seed)
        return
    from tcot_hybrid.markdown import update_readme_section

    res = summarize()
    OUT.write_text(json.dumps(res, indent=1) + "\n")
    update_readme_section(ROOT / "docs" / "libero-planner.md", SECTION, markdown(res))
    print(markdown(res))


if __name__ == "__main__":
    main()
