"""Summarise the LIBERO learned planner (docs/libero-planner.md) from what the commands below wrote, into the
<!-- libero-planner:start/end --> sections of docs/libero-planner.md and README.md:

    make libero-planner        # collection + training: docs/libero-planner/collect.log, train.log,
                               # train.metrics.jsonl, tcot_hybrid/checkpoints/libero_panda_default.*
    make libero-planner-eval   # tcot eval, shipped init states: docs/libero-planner/eval-shipped/
    .venv/bin/python docs/libero-planner/summarize.py
"""
from __future__ import annotations

import json
import re
from collections import defaultdict
from pathlib import Path

from tcot_hybrid.markdown import update_readme_section
from tcot_hybrid.metrics import wilson_interval

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
CKPT = ROOT / "tcot_hybrid" / "checkpoints" / "libero_panda_default"
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")


def rate(k: int, n: int) -> str:
    lo, hi = wilson_interval(k, n)
    return f"{k / n:.3f} [{lo:.2f}, {hi:.2f}] n={n}" if n else "-"


def build_lines() -> list[str]:
    lines = []
    log = HERE / "collect.log"
    m = None
    if log.is_file():
        m = re.search(r"(\d+) demos written \((\d+) already present, (\d+) unsuccessful kept, (\d+) crashed\) in "
                      r"([\d.]+) s .*?([\d.]+) MiB; masks: (\d+) train / (\d+) valid", log.read_text())
    meta_p = CKPT.with_suffix(".json")
    if not meta_p.is_file():
        return ["- the LIBERO planner has not been built yet (`make libero-planner`)"]
    meta = json.loads(meta_p.read_text())
    tc = meta["train_config"]
    size_mb = CKPT.with_suffix(".safetensors").stat().st_size / 1e6
    if m:
        written, present, failed, crashed, wall, mib, ntr, nva = m.groups()
        lines.append(f"- **Collection** (`docs/libero-planner/collect.log`): {written} oracle episodes on sampled "
                     f"layouts (seeds from 0, the four suites' 40 tasks; {present} already in the file), "
                     f"{float(wall) / 60:.1f} min wall with 2 workers on 2 shared cores, a planner image every 3rd "
                     f"step; {failed} unsuccessful (kept, never imitated), {crashed} crashed; {mib} MiB; "
                     f"{ntr} training / {nva} validation demos (split by seed).")
    train_log = HERE / "train.log"
    tm = re.search(r"total time ([\d.]+) min", train_log.read_text()) if train_log.is_file() else None
    epochs = [json.loads(x) for x in (HERE / "train.metrics.jsonl").read_text().splitlines() if x.strip()] \
        if (HERE / "train.metrics.jsonl").is_file() else []
    lines.append(f"- **Training** (`docs/libero-planner/train.log`, `train.metrics.jsonl`): {meta['train_demos']} "
                 f"demos / {meta['train_frames']} frames, {len(epochs)} epochs (best {meta['metrics']['best_epoch']}) "
                 f"of at most {tc['max_epochs']}, cap {tc['max_minutes']} min"
                 + (f", {float(tm.group(1)):.1f} min wall (loading, training, validation, saving)" if tm else "")
                 + f"; checkpoint {size_mb:.1f} MB (`tcot_hybrid/checkpoints/libero_panda_default.safetensors`).")
    v = meta["metrics"]
    lines += ["", "Held-out validation (seeds ≡ 0 mod 10; executed points only: global k ≥ 0, all local; median / p90):",
              "", "| prompt | pixel [px] | 3D [cm] | height [cm] | orientation [deg] | gripper bit |", "|---|---|---|---|---|---|"]
    for name in ("global", "local"):
        lines.append(f"| {name} | {v[f'{name}_px_median']:.2f} / {v[f'{name}_px_p90']:.2f} | "
                     f"{v[f'{name}_3d_cm_median']:.2f} / {v[f'{name}_3d_cm_p90']:.2f} | "
                     f"{v[f'{name}_z_cm_median']:.2f} / {v[f'{name}_z_cm_p90']:.2f} | "
                     f"{v.get(f'{name}_rot_deg_median', float('nan')):.1f} / {v.get(f'{name}_rot_deg_p90', float('nan')):.1f} | "
                     f"{v[f'{name}_grip_acc']:.3f} |")
    lines.append(f"| global at t = 0 | {v['global_t0_px_median']:.2f} / {v['global_t0_px_p90']:.2f} | "
                 f"{v['global_t0_3d_cm_median']:.2f} / {v['global_t0_3d_cm_p90']:.2f} | - | - | {v['global_t0_grip_acc']:.3f} |")
    lines += ["", f"Failure detection on the same frames: AUROC {v['success_auroc']:.3f}, accuracy {v['success_acc']:.3f}."]
    return lines


def eval_lines() -> list[str]:
    """Success per suite and mode from the episodes `tcot eval` recorded (episodes.jsonl; eval.json adds the wall
    time once the run has finished), beside the oracle on the same shipped init states."""
    ep_path = HERE / "eval-shipped" / "episodes.jsonl"
    if not ep_path.is_file():
        return ["- not evaluated yet (`make libero-planner-eval`)"]
    eps = [json.loads(x) for x in ep_path.read_text().splitlines() if x.strip()]
    got: dict = defaultdict(lambda: [0, 0])
    for e in eps:
        got[(e["mode"], e["suite"])][0] += bool(e["success"])
        got[(e["mode"], e["suite"])][1] += 1
    seeds = sorted({e["seed"] for e in eps})
    pairs = {(e["task"], e["seed"]) for e in eps}  # the oracle on exactly the same (task, init state) pairs
    oracle: dict = defaultdict(lambda: [0, 0])
    op = ROOT / "docs" / "eval-libero" / "oracle-shipped" / "episodes.jsonl"
    if op.is_file():
        for line in op.read_text().splitlines():
            e = json.loads(line)
            if (e["task"], e["seed"]) in pairs:
                oracle[e["suite"]][0] += bool(e["success"])
                oracle[e["suite"]][1] += 1
    order = ("global", "local", "glsr", "glsr_reset")
    modes = sorted({m for m, _ in got}, key=lambda m: order.index(m) if m in order else len(order))
    r = json.loads((HERE / "eval-shipped" / "eval.json").read_text()) if (HERE / "eval-shipped" / "eval.json").is_file() else None
    how = (f"{r['wall_time_s'] / 60:.1f} min wall with {r['workers']} workers" if r
           else "the run was stopped before it finished: these are the episodes it completed")
    lines = [f"**Learned planner, shipped init states {seeds[0]}-{seeds[-1]} of every task** "
             f"(`docs/libero-planner/eval-shipped/`, {len(eps)} episodes, {how}), beside the oracle on the same init "
             f"states (`docs/eval-libero/oracle-shipped/`):", "",
             "| planner | " + " | ".join(SUITES) + " | all four |", "|" + "---|" * (len(SUITES) + 2)]
    for mode in modes:
        k = sum(got[(mode, s)][0] for s in SUITES)
        n = sum(got[(mode, s)][1] for s in SUITES)
        lines.append(f"| learned, {mode} | " + " | ".join(rate(*got[(mode, s)]) for s in SUITES) + f" | {rate(k, n)} |")
    if oracle:
        k = sum(oracle[s][0] for s in SUITES)
        n = sum(oracle[s][1] for s in SUITES)
        lines.append("| oracle (privileged) | " + " | ".join(rate(*oracle[s]) for s in SUITES) + f" | {rate(k, n)} |")
    faults = sum(bool(e["fault"]) for e in eps)
    viol = max(e["max_joint_limit_violation_rad"] for e in eps)
    replans = [e["replans"] for e in eps if e["mode"] == "glsr"]
    lines += ["", f"Worst joint-limit violation {viol:.4f} rad; faulted episodes {faults} (none counted as success)"
              + (f"; GLSR replanned {sum(replans) / len(replans):.1f} times per episode on average." if replans else ".")]
    return lines


def main() -> None:
    text = "\n".join(build_lines() + [""] + eval_lines()) + "\n"
    (HERE / "summary.md").write_text(text)
    for target in (ROOT / "docs" / "libero-planner.md", ROOT / "README.md"):
        update_readme_section(target, "libero-planner", text)
    print(text)


if __name__ == "__main__":
    main()
