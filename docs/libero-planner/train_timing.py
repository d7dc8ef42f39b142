"""How long the 50-per-task training run (examples/configs/train_libero50.yaml) takes per epoch on this machine,
measured as a short run of that config on the demonstration file at hand, written to JSON for summarize.py:

    .venv/bin/python docs/libero-planner/train_timing.py [--steps 200] [--out docs/libero-planner/train_timing.json]

Same model, batch, windows, augmentation and bf16 as the real run; only ``epoch_samples`` (= steps x batch),
``max_epochs`` (1), ``stage1_epochs`` (1) and the output path differ, so a step costs what it will cost. The machine's
load average is recorded beside it (2 shared cores), and the loading time of the file measured (it grows with the
number of demonstrations).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
CONFIG = "examples/configs/train_libero50.yaml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=200, help="training steps to time (>= 20)")
    ap.add_argument("--data", default=None, help="demonstration file (default: the config's)")
    ap.add_argument("--out", default=str(HERE / "train_timing.json"))
    ap.add_argument("--summarize", action="store_true", help="rewrite the docs section from --out, run nothing")
    a = ap.parse_args()
    if a.summarize:
        write_section(json.loads(Path(a.out).read_text()))
        return
    if a.steps < 20:
        ap.error(f"--steps must be >= 20, got {a.steps}")
    from tcot_hybrid.learning.train import train
    from tcot_hybrid.learning.train_config import load_train_config

    cfg = load_train_config(ROOT / CONFIG)
    full = cfg
    lines: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        cfg = dataclasses.replace(cfg, data=a.data or str(ROOT / cfg.data), out=str(Path(tmp) / "t.safetensors"),
                                  epoch_samples=a.steps * cfg.batch_size, max_epochs=1, stage1_epochs=1,
                                  val_max_frames=200, max_minutes=600)
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        train(cfg, progress=False, log=lines.append)
        wall = time.perf_counter() - t0
        rec = json.loads((Path(tmp) / "t.metrics.jsonl").read_text().splitlines()[0])
    loaded = next((x for x in lines if x.startswith("data ")), "")
    s_step = rec["epoch_train_s"] / a.steps
    per_epoch = s_step * full.epoch_samples / full.batch_size
    res = {"config": CONFIG, "data": cfg.data, "data_line": loaded, "steps": a.steps, "batch_size": cfg.batch_size,
           "train_s": rec["epoch_train_s"], "s_per_step": round(s_step, 3), "wall_s": round(wall, 1),
           "threads": rec["threads"], "epoch_samples": full.epoch_samples, "max_epochs": full.max_epochs,
           "est_epoch_min": round(per_epoch / 60, 1), "est_run_h": round(per_epoch * full.max_epochs / 3600, 2),
           "load_average_1min": [round(load0, 2), round(os.getloadavg()[0], 2)], "cpus": os.cpu_count(),
           "command": f"python docs/libero-planner/train_timing.py --steps {a.steps}"}
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))
    write_section(res)


def write_section(res: dict) -> None:
    """The figures into docs/libero-planner.md's <!-- libero-train-timing --> section."""
    from tcot_hybrid.markdown import update_readme_section

    import math

    demos = res["data_line"].split(": ", 1)[-1].split(";")[0]  # "309 train demos / 8314 frames, ..."
    parts = math.ceil(res["est_run_h"] * 60 / 50)
    text = (f"- `{res['command']}` on `data/{Path(res['data']).name}` ({demos}): "
            f"{res['steps']} steps of {res['batch_size']} samples in {res['train_s']:.0f} s, **{res['s_per_step']:.2f} s a "
            f"step** ({res['threads']} torch thread(s); load average {res['load_average_1min'][0]:.1f} → "
            f"{res['load_average_1min'][1]:.1f} on {res['cpus']} shared cores).\n"
            f"- So `{res['config']}`: an epoch of {res['epoch_samples']} samples ≈ **{res['est_epoch_min']:.0f} min**, its "
            f"{res['max_epochs']} epochs ≈ **{res['est_run_h']:.1f} h** of training steps (plus loading the 2000-demo "
            f"file, about 5x this one's, and a validation pass per epoch): at this load at least {parts} parts of "
            f"`max_minutes` 50, joined by `--resume` (`make libero-planner` again), over more than one session.")
    update_readme_section(HERE.parent / "libero-planner.md", "libero-train-timing", text)


if __name__ == "__main__":
    main()
