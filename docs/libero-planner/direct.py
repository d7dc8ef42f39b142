"""Summarise the direct (next-action) baseline on LIBERO into the <!-- libero-direct:start/end --> section of
docs/libero-planner.md, from what these commands wrote (``make libero-planner`` runs the first and this script):

    tcot train --config examples/configs/train_libero_direct.yaml    # runs/libero/direct.* → the shipped
        # tcot_hybrid/checkpoints/libero_panda_direct_default.*, its log docs/libero-planner/direct_train.log
    tcot eval --suite libero_object --planners direct --init sampled --episodes 3 --seed-start 20000 --workers 1 \\
        --out docs/libero-planner/eval-direct                          # development layouts (docs/seeds.md)
    .venv/bin/python docs/libero-planner/direct.py
"""
from __future__ import annotations

import json
import re
from collections import Counter, defaultdict
from pathlib import Path

from tcot_hybrid.markdown import update_readme_section
from tcot_hybrid.metrics import wilson_interval

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
CKPT = ROOT / "tcot_hybrid" / "checkpoints" / "libero_panda_direct_default"
EVAL = HERE / "eval-direct"
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")


def rate(k: int, n: int) -> str:
    lo, hi = wilson_interval(k, n)
    return f"{k / n:.3f} [{lo:.2f}, {hi:.2f}] n={n}" if n else "-"


def train_lines() -> list[str]:
    meta_p = CKPT.with_suffix(".json")
    if not meta_p.is_file():
        return ["- the LIBERO direct checkpoint has not been trained yet (`make libero-planner`)"]
    meta = json.loads(meta_p.read_text())
    tc, m = meta["train_config"], meta["metrics"]
    size_mb = CKPT.with_suffix(".safetensors").stat().st_size / 1e6
    log = HERE / "direct_train.log"
    wall = loaded = None
    if log.is_file():
        text = log.read_text()
        w = re.search(r"wrote \S+ \(best epoch \d+\) in ([\d.]+) min", text)
        d = re.search(r"loaded in ([\d.]+)s", text)
        wall, loaded = (float(w.group(1)) if w else None), (float(d.group(1)) if d else None)
    epochs_run = 0
    met = HERE / "direct_train.metrics.jsonl"
    if met.is_file():
        epochs_run = sum(1 for x in met.read_text().splitlines() if x.strip())
    return [
        f"- **Checkpoint** `tcot_hybrid/checkpoints/libero_panda_direct_default.*` ({size_mb:.2f} MB; world "
        f"`{meta['world']}`, robot `{meta['robot']}`, per-scene camera: {meta['camera'].get('per_scene', False)}), "
        f"trained by `tcot train --config examples/configs/train_libero_direct.yaml` on `{Path(tc['data']).name}` "
        f"({meta['train_demos']} training demos / {meta['train_frames']} imaged frames, the same oracle "
        f"demonstrations as the LIBERO planner): {epochs_run} epochs of {tc['epoch_samples']} samples on "
        f"{tc['threads']} torch thread(s), " + (f"{wall:.1f} min wall including {loaded / 60:.1f} min loading the "
                                                f"file (`docs/libero-planner/direct_train.log`)" if wall and loaded
                                                else "wall time not logged") + ".",
        f"- **Held-out frames** (validation split, best epoch {m['best_epoch']}, {m['frames']} frames): TCP "
        f"displacement over {meta['direct_horizon']} planner steps off by **{m['delta_cm_median']:.2f} cm median / "
        f"{m['delta_cm_p90']:.2f} cm p90** (predicting no motion at all: {m['zero_delta_cm_median']:.2f} / "
        f"{m['zero_delta_cm_p90']:.2f} cm); gripper bit right on {m['grip_acc']:.3f} of the frames.",
    ]


def eval_lines() -> list[str]:
    p = EVAL / "episodes.jsonl"
    if not p.is_file():
        return ["- not evaluated yet (the `tcot eval` command in `docs/libero-planner/direct.py`)"]
    eps = [json.loads(x) for x in p.read_text().splitlines() if x.strip()]
    r = json.loads((EVAL / "eval.json").read_text()) if (EVAL / "eval.json").is_file() else None
    seeds = sorted({e["seed"] for e in eps})
    got: dict = defaultdict(lambda: [0, 0])
    for e in eps:
        got[e["suite"]][0] += bool(e["success"])
        got[e["suite"]][1] += 1
    suites = [s for s in SUITES if s in got]
    k, n = sum(v[0] for v in got.values()), sum(v[1] for v in got.values())
    events = Counter(ev["kind"] for e in eps for ev in e["events"])
    reasons = Counter(re.split(r"[-\d\[(]", ev.get("reason", ""), maxsplit=1)[0].strip()[:60]
                      for e in eps for ev in e["events"] if ev["kind"] == "plan_rejected")
    steps = sum(e["steps"] for e in eps)
    stopped = Counter(e["stopped_by"] for e in eps)
    tasks = len({e["task"] for e in eps})
    how = (f"{len(eps)} episodes on {tasks} tasks, {r['wall_time_s'] / 60:.1f} min wall with {r['workers']} worker(s)"
           if r and r["ran_now"] == r["episodes"] == len(eps)
           else f"{len(eps)} episodes on {tasks} tasks: the run was stopped before it finished (CPU shared with longer "
                f"jobs), these are the episodes it completed, in its task order")
    walls = sorted(e["wall_time_s"] for e in eps)
    how += f"; {walls[0]:.0f}-{walls[-1]:.0f} s wall per episode"
    lines = [f"**Direct baseline, sampled development layouts, seeds {seeds[0]}-{seeds[-1]}** "
             f"(`docs/libero-planner/eval-direct/`, {how}; development seeds, docs/seeds.md: not a reporting "
             f"figure):", "",
             "| planner | " + " | ".join(suites) + (" | all |" if len(suites) > 1 else " |"),
             "|" + "---|" * (len(suites) + 1 + (len(suites) > 1)),
             "| direct | " + " | ".join(rate(*got[s]) for s in suites) + (f" | {rate(k, n)} |" if len(suites) > 1
                                                                          else " |"), ""]
    faults = sum(bool(e["fault"]) for e in eps)
    viol = max(e["max_joint_limit_violation_rad"] for e in eps)
    ik = sorted(ev["pos_err_m"] for e in eps for ev in e["events"] if ev["kind"] == "ik_not_converged")
    sat = [e["safety"]["saturations"] / max(e["safety"]["ticks"], 1) for e in eps]
    lines.append(
        f"- Every planner step asked the network (a one-waypoint plan, lifted, solved by IK, timed by Ruckig, tracked "
        f"by the controller): {steps} steps, {events['plan_adopted']} plans adopted, {events['plan_rejected']} "
        f"refused by the planner or the lift, {events.get('plan_stale', 0)} over the latency budget; IK left "
        f"{len(ik)} waypoints unconverged" + (f" (position error median {1e3 * ik[len(ik) // 2]:.1f} mm, at most "
                                               f"{1e3 * ik[-1]:.1f} mm)" if ik else "")
        + f"; a torque at its limit on {100 * sum(sat) / len(sat):.0f} % of control ticks (mean over episodes); "
        f"faulted episodes {faults} (none counted as success); worst joint-limit violation {viol:.4f} rad; episodes "
        f"ended by " + ", ".join(f"{k}: {v}" for k, v in sorted(stopped.items())) + ".")
    if reasons:
        lines.append("- Refusals: " + "; ".join(f"{v}x \"{k}\"" for k, v in reasons.most_common(3)) + ".")
    return lines


def main() -> None:
    text = "\n".join(train_lines() + [""] + eval_lines()) + "\n"
    update_readme_section(ROOT / "docs" / "libero-planner.md", "libero-direct", text)
    print(text)


if __name__ == "__main__":
    main()
