"""How far the LIBERO planner's local plans reach on success frames and on the others (held-out), the figure behind
``supervisor.confirm_motion_m`` (docs/glsr.md, "A success verdict the planner contradicts"), written to JSON for
docs/libero-planner/summarize.py:

    .venv/bin/python docs/libero-planner/confirm.py [--checkpoint CK] [--out docs/libero-planner/confirm.json]

The validation split of the demonstration file (seeds ≡ 0 mod 10, sampled layouts), every 2nd frame: the local plan
from each frame (its waypoints lifted through the frame's own camera), its reach (largest distance of a waypoint from
the first) and whether it switches the gripper, against the frame's success label; and the detector's verdicts
(p >= 0.5) the check would overrule. Held-out demonstration frames only: in-episode states after a failed grasp are
not among them (the failure analysis measures those).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
REACHES_M = (0.03, 0.05, 0.08)


def evaluate(checkpoint: str, data: str) -> dict:
    import torch

    from tcot_hybrid.data.labels import windows_from_meta
    from tcot_hybrid.learning.checkpoint import load_checkpoint
    from tcot_hybrid.learning.data import load_frames
    from tcot_hybrid.learning.validation import lift_frames, predict
    from tcot_hybrid.learning.vocab import Vocabulary
    from tcot_hybrid.metrics import auroc
    from tcot_hybrid.supervision import SupervisorConfig

    torch.set_num_threads(2)
    ck = load_checkpoint(checkpoint)
    meta, model = ck.meta, ck.model.eval()
    frames = load_frames(data, "valid", Vocabulary(tuple(meta["vocabulary"])), windows=windows_from_meta(meta["windows"]),
                         max_tokens=model.cfg.max_tokens, direct_horizon=int(meta["direct_horizon"]),
                         height_ref=meta.get("height_ref", "world"))
    idx = np.arange(len(frames))[::2]
    succ = np.asarray(frames.success)[idx] > 0.5
    ng = model.cfg.n_global
    loc = predict(model, frames, idx, "local")
    p = 1.0 / (1.0 + np.exp(-predict(model, frames, idx, "detect")["success_logit"]))
    pts = lift_frames(frames, idx, loc["uv_px"][:, ng:], loc["z_m"][:, ng:])
    reach = np.linalg.norm(pts - pts[:, :1], axis=-1).max(1)
    grip = 1.0 / (1.0 + np.exp(-loc["grip_logit"][:, ng:])) > 0.5
    switch = (grip != grip[:, :1]).any(1)
    thr = SupervisorConfig().success_threshold
    fp, tp = (p >= thr) & ~succ, (p >= thr) & succ
    res = {"checkpoint": str(Path(checkpoint).resolve().relative_to(ROOT)) if Path(checkpoint).resolve().is_relative_to(ROOT)
           else checkpoint, "frames": int(len(idx)), "success_frames": int(succ.sum()),
           "reach_cm_median_success": round(float(np.median(reach[succ])) * 100, 1),
           "reach_cm_median_other": round(float(np.median(reach[~succ])) * 100, 1),
           "reach_auroc": round(float(auroc(-reach, succ)), 3), "detector_auroc": round(float(auroc(p, succ)), 3),
           "detector_false_verdicts": int(fp.sum()), "detector_true_verdicts": int(tp.sum()), "by_reach": {}}
    for r in REACHES_M:
        still = (reach <= r) & ~switch
        res["by_reach"][f"{r:.2f}"] = {"still_success": round(float(still[succ].mean()), 3),
                                        "still_other": round(float(still[~succ].mean()), 3),
                                        "false_verdicts_overruled": int((fp & ~still).sum()),
                                        "true_verdicts_overruled": int((tp & ~still).sum())}
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--checkpoint", default=str(ROOT / "tcot_hybrid" / "checkpoints" / "libero_panda_default.safetensors"))
    ap.add_argument("--data", default=str(ROOT / "data" / "demos_libero_panda.hdf5"))
    ap.add_argument("--out", default=str(HERE / "confirm.json"))
    a = ap.parse_args()
    t = time.perf_counter()
    res = evaluate(a.checkpoint, a.data)
    res["wall_s"] = round(time.perf_counter() - t, 1)
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
