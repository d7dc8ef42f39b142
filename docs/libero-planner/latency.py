"""Learned-planner latency on a LIBERO scene (docs/libero-planner.md), written to JSON for summarize.py:

    .venv/bin/python docs/libero-planner/latency.py [--calls 200] [--out docs/libero-planner/latency.json]

Batch-1 image-to-plan time per call of the shipped LIBERO checkpoint (global plan, local plan, success probability)
with 2 torch threads and with 1 (what each `tcot eval` worker uses), at the planner image size the checkpoint takes,
on the first libero_spatial task's sampled layout (seed 0): :func:`tcot_hybrid.bench.planner_inference_ms`, the
figure `tcot bench` reports for the workcell. The machine's load average is recorded beside it (2 shared cores).
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calls", type=int, default=200, help="timed calls per mode and thread count (>= 5)")
    ap.add_argument("--out", default=str(HERE / "latency.json"))
    a = ap.parse_args()
    if a.calls < 5:
        ap.error(f"--calls must be >= 5, got {a.calls}")
    from tcot_hybrid.bench import LIBERO_BENCH_TASK, planner_inference_ms
    from tcot_hybrid.libero import libero_available
    from tcot_hybrid.run_config import RunConfig

    if not libero_available():
        raise SystemExit("LIBERO is not installed (make libero)")
    cfg = RunConfig(task=LIBERO_BENCH_TASK, seed=0)
    load_before = os.getloadavg()
    t = time.perf_counter()
    figures = planner_inference_ms(cfg, a.calls)
    res = {"task": LIBERO_BENCH_TASK, "seed": 0, "calls": a.calls, "image_px": cfg.scene.planner_image_px,
           "figures": figures, "load_average_1min": [round(load_before[0], 2), round(os.getloadavg()[0], 2)],
           "cpus": os.cpu_count(), "wall_s": round(time.perf_counter() - t, 1),
           "command": f"python docs/libero-planner/latency.py --calls {a.calls}"}
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
