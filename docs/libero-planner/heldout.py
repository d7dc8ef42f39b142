"""Held-out errors of a LIBERO planner checkpoint (docs/libero-planner.md), by suite and by read-out, written to JSON
for docs/libero-planner/summarize.py:

    .venv/bin/python docs/libero-planner/heldout.py [--checkpoint CK] [--out docs/libero-planner/heldout.json]

The validation split of the demonstration file (seeds ≡ 0 mod 10, sampled layouts; never the shipped init states),
the figures training logs (:func:`tcot_hybrid.learning.validation.trajectory_metrics`: executed points, each frame
through its own camera), once per heatmap read-out: ``readout_radius_cells`` 0 (soft-argmax over the whole map, what
training optimises) and 2 (soft-argmax around the peak, the workcell's). Per suite: the global plan's pixel error at
every step and at t = 0, and at t = 0 the error of the plan's first grasp point (the first waypoint whose labelled
gripper bit is closed: is the plan going to the right object?). And the same t = 0 errors with every instruction
reworded (:func:`reworded`).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
KEYS = ("global_px_median", "global_px_p90", "global_t0_px_median", "global_t0_px_p90", "local_px_median",
        "local_px_p90", "global_3d_cm_median", "global_t0_3d_cm_median", "local_3d_cm_median", "global_z_cm_median",
        "global_rot_deg_median", "local_rot_deg_median", "global_grip_acc", "success_auroc")


def first_grasp_errors(uv: np.ndarray, uv_true: np.ndarray, grip_true: np.ndarray) -> np.ndarray:
    """Pixel error at the first waypoint whose labelled gripper bit is closed, per plan (NaN: no grasp in it)."""
    out = np.full(len(uv), np.nan)
    for i in range(len(uv)):
        k = np.flatnonzero(grip_true[i] > 0.5)
        if k.size:
            out[i] = float(np.linalg.norm(uv[i, k[0]] - uv_true[i, k[0]]))
    return out


def reworded(ck, frames, traj: np.ndarray, uv_true: np.ndarray, grip_true: np.ndarray, center: int) -> dict:
    """t = 0 global plans with each instruction replaced by its rewording (``PARAPHRASES``: verbs, prepositions and
    word order changed, objects' names kept): first-grasp and whole-plan pixel errors beside the original wording's,
    and the rewordings the planner would refuse (more unknown words than the checkpoint's ``max_unknown_fraction``;
    measured anyway, with the unknown words as <unk>)."""
    from tcot_hybrid.learning.evaluate import reworded_instructions
    from tcot_hybrid.learning.validation import predict
    from tcot_hybrid.learning.vocab import Vocabulary

    ng = ck.model.cfg.n_global
    t0 = frames.t[traj] == 0
    rows = traj[t0]

    def errors() -> dict:
        uv = predict(ck.model, frames, rows, "global")["uv_px"][:, center:ng]
        px = np.linalg.norm(uv - uv_true[t0], axis=-1)
        grasp = first_grasp_errors(uv, uv_true[t0], grip_true[t0])
        grasp = grasp[np.isfinite(grasp)]
        return {"t0_px_median": round(float(np.median(px)), 2),
                "t0_first_grasp_px_median": round(float(np.median(grasp)), 2),
                "t0_first_grasp_within_5px": round(float((grasp < 5).mean()), 3)}

    original = errors()
    with reworded_instructions(frames, Vocabulary(tuple(ck.meta["vocabulary"])), max_tokens=ck.model.cfg.max_tokens,
                               max_unknown_fraction=float(ck.meta.get("max_unknown_fraction", 0.5))) as r:
        changed = errors()
    return {"original": original, "reworded": changed, "instructions": len(set(frames.instructions)),
            "without_rewording": sorted(set(r.missing)), "refused": sorted(set(r.refused)),
            "unknown_word_fraction_median": round(float(np.median(r.unknown_fractions)), 3),
            "t0_plans": int(t0.sum())}


def _rel(path: str) -> str:
    p = Path(path).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(path)


def load_validation(checkpoint: str, data: str) -> tuple:
    """(checkpoint, validation frames of ``data`` labelled with its windows, the windows, the frames training
    validates on: :func:`val_indices` with its ``val_max_frames``), torch on 2 threads (precision.py shares it)."""
    import torch

    from tcot_hybrid.data.labels import windows_from_meta
    from tcot_hybrid.learning.checkpoint import load_checkpoint
    from tcot_hybrid.learning.data import load_frames
    from tcot_hybrid.learning.validation import val_indices
    from tcot_hybrid.learning.vocab import Vocabulary

    torch.set_num_threads(2)
    ck = load_checkpoint(checkpoint)
    meta, model = ck.meta, ck.model
    win = windows_from_meta(meta["windows"])
    frames = load_frames(data, "valid", Vocabulary(tuple(meta["vocabulary"])), windows=win,
                         max_tokens=model.cfg.max_tokens, direct_horizon=int(meta["direct_horizon"]),
                         height_ref=meta.get("height_ref", "world"))
    idx = val_indices(frames, int(meta.get("train_config", {}).get("val_max_frames", 2000)))
    return ck, frames, win, idx


def evaluate(checkpoint: str, data: str, radii: tuple[int, ...]) -> dict:
    from tcot_hybrid.learning.validation import predict, trajectory_metrics

    ck, frames, win, idx = load_validation(checkpoint, data)
    meta, model = ck.meta, ck.model
    ng, c = model.cfg.n_global, win.global_center
    traj = idx[frames.traj[idx]]
    suite = np.array([t.split(":")[0] for t in frames.tasks])[frames.demo[traj]]
    t0 = frames.t[traj] == 0
    res = {"checkpoint": _rel(checkpoint), "data": _rel(data), "valid_demos": len(frames.demos),
           "frames": int(len(traj)), "t0_plans": int(t0.sum()), "shipped_readout_radius_cells":
           int(model.cfg.readout_radius_cells), "by_readout": {}}
    for r in radii:
        model.cfg = dataclasses.replace(model.cfg, readout_radius_cells=r)
        m = trajectory_metrics(model, frames, idx, n_global=ng, center=c)
        g = predict(model, frames, traj, "global")
        uv, uvt = g["uv_px"][:, c:ng], frames.g_uv[traj][:, c:].numpy()
        px = np.linalg.norm(uv - uvt, axis=-1)
        grasp = first_grasp_errors(uv, uvt, frames.g_grip[traj][:, c:].numpy())
        per_suite = {}
        for s in SUITES:
            sel = suite == s
            gs = grasp[sel & t0]
            gs = gs[np.isfinite(gs)]
            per_suite[s] = {"plans_t0": int((sel & t0).sum()), "global_px_median": round(float(np.median(px[sel])), 2),
                            "global_t0_px_median": round(float(np.median(px[sel & t0])), 2),
                            "t0_first_grasp_px_median": round(float(np.median(gs)), 2) if gs.size else None,
                            "t0_first_grasp_within_5px": round(float((gs < 5).mean()), 3) if gs.size else None,
                            "t0_first_grasp_over_20px": round(float((gs >= 20).mean()), 3) if gs.size else None}
        ga = grasp[t0][np.isfinite(grasp[t0])]
        res["by_readout"][str(r)] = {**{k: m[k] for k in KEYS},
                                     "t0_first_grasp_px_median": round(float(np.median(ga)), 2),
                                     "t0_first_grasp_within_5px": round(float((ga < 5).mean()), 3),
                                     "t0_first_grasp_over_20px": round(float((ga >= 20).mean()), 3),
                                     "t0_first_grasp_plans": int(ga.size), "per_suite": per_suite}
    model.cfg = dataclasses.replace(model.cfg, readout_radius_cells=int(meta["model"]["readout_radius_cells"]))
    res["reworded"] = reworded(ck, frames, traj, frames.g_uv[traj][:, c:].numpy(), frames.g_grip[traj][:, c:].numpy(), c)
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--checkpoint", default=str(ROOT / "tcot_hybrid" / "checkpoints" / "libero_panda_default.safetensors"))
    ap.add_argument("--data", default=str(ROOT / "data" / "demos_libero_panda.hdf5"))
    ap.add_argument("--out", default=str(HERE / "heldout.json"))
    ap.add_argument("--radii", default="0,2", help="heatmap read-out radii [cells], comma-separated")
    a = ap.parse_args()
    try:
        radii = tuple(int(x) for x in a.radii.split(","))
    except ValueError:
        ap.error(f"--radii must be comma-separated integers, got {a.radii!r}")
    if any(r < 0 for r in radii):
        ap.error(f"--radii must be >= 0, got {a.radii!r}")
    t = time.perf_counter()
    res = evaluate(a.checkpoint, a.data, radii)
    res["wall_s"] = round(time.perf_counter() - t, 1)
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps({k: v for k, v in res.items() if k != "by_readout"}))
    for r, v in res["by_readout"].items():
        print(f"readout {r}: global px {v['global_px_median']} / t0 {v['global_t0_px_median']}, local px "
              f"{v['local_px_median']}, t0 first grasp {v['t0_first_grasp_px_median']} px")


if __name__ == "__main__":
    main()
