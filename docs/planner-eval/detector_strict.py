"""Round 8 against round 10 on held-out frames labelled by the strict success predicates (issue 17).

Frames: the validation split (seed 450) of round 10's data (oracle demonstrations and round 8's own GLSR
episodes with and without every perturbation, labelled per step by the strict predicates). Waypoint figures on
the demonstration frames, detection on every frame. Round 10 trained the detector alone (``trainable: detect``),
so its waypoint figures must equal round 8's.

    python docs/planner-eval/detector_strict.py runs/train/stage2_round8.safetensors \
        runs/train/stage2_round10.safetensors [--readme docs/planner.md]
"""
from __future__ import annotations

import argparse
from pathlib import Path

DATA = "data/demos_strict_panda.hdf5"
ONLINE = "data/online_learned_glsr_strict.hdf5"
MAX_FRAMES = 4000


def figures(checkpoint: str) -> dict:
    import torch

    from tcot_hybrid.data.labels import windows_from_meta
    from tcot_hybrid.learning.checkpoint import load_checkpoint
    from tcot_hybrid.learning.data import concat_frames, env_of, load_frames, load_online_frames
    from tcot_hybrid.learning.validation import trajectory_metrics, val_indices
    from tcot_hybrid.learning.vocab import Vocabulary

    torch.set_num_threads(2)
    ck = load_checkpoint(checkpoint)
    vocab = Vocabulary(tuple(ck.meta["vocabulary"]))
    windows = windows_from_meta(ck.meta["windows"])
    load = dict(windows=windows, max_tokens=ck.model.cfg.max_tokens, direct_horizon=int(ck.meta["direct_horizon"]))
    va = concat_frames([load_frames(DATA, "valid", vocab, **load),
                        load_online_frames(ONLINE, "valid", vocab, frame_stride=1, **load)])
    _, camera, _ = env_of(DATA)
    m = trajectory_metrics(ck.model, va, val_indices(va, MAX_FRAMES), camera, n_global=ck.model.cfg.n_global,
                           center=windows.global_center)
    m["episodes"] = len(va.demos)
    m["positives"] = int(va.success[val_indices(va, MAX_FRAMES)].sum())
    return m


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("checkpoints", nargs="+")
    p.add_argument("--readme", type=Path)
    args = p.parse_args()
    rows = []
    for ck in args.checkpoints:
        m = figures(ck)
        rows.append(f"| `{ck}` | {m['detect_frames']} ({m['positives']}) | {m['success_auroc']:.4f} | "
                    f"{m['success_acc']:.4f} | {m['global_px_median']:.2f} / {m['global_px_p90']:.2f} | "
                    f"{m['global_t0_px_median']:.2f} / {m['global_t0_px_p90']:.2f} | "
                    f"{m['local_px_median']:.2f} / {m['local_px_p90']:.2f} | "
                    f"{m['global_3d_cm_median']:.2f} / {m['global_3d_cm_p90']:.2f} | "
                    f"{m['global_grip_acc']:.4f} / {m['local_grip_acc']:.4f} |")
    text = "\n".join([
        f"Written by `python docs/planner-eval/detector_strict.py {' '.join(args.checkpoints)}` from the held-out "
        f"split (seed 450, {m['episodes']} episodes) of `{DATA}` and `{ONLINE}`, labelled by the strict "
        "predicates:", "",
        "| checkpoint | detect frames (success) | detect AUROC | detect accuracy | global px median / p90 | "
        "global t = 0 px | local px | global 3D [cm] | gripper acc global / local |",
        "|---|---|---|---|---|---|---|---|---|", *rows]) + "\n"
    print(text)
    if args.readme:
        from tcot_hybrid.markdown import update_readme_section

        update_readme_section(args.readme, "detector_strict", text)


if __name__ == "__main__":
    main()
