"""Offline evaluation of a planner checkpoint on demonstrations: held-out ones (validation split by seed,
or a file collected on seeds >= 1000): waypoint pixel error, lifted 3D error, gripper-bit accuracy,
success-detection AUROC, per task; plus how much unseen paraphrases of the instructions cost.

    python -m tcot_hybrid.learning.evaluate --checkpoint CK --data FILE [--split valid] [--out docs/planner-eval]

writes ``planner_eval.json`` and ``planner_eval.md`` into the output directory.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tcot_hybrid.camera import points_at_height
from tcot_hybrid.errors import PlanningError
from tcot_hybrid.metrics import auroc

# One unseen rewording per task instruction (words outside the training vocabulary on purpose).
PARAPHRASES = {
    "put the cube on the left on the plate": "place the left cube onto the plate",
    "put the cube closest to the robot in the bowl": "drop the cube nearest the robot into the bowl",
    "put the blue cube in the basket": "place the blue cube inside the basket",
    "put the green cylinder in the basket": "place the green cylinder inside the basket",
    "put the red cube in the basket": "place the red cube inside the basket",
    "put the cube in the bowl": "place the cube inside the bowl",
    "put the cube on the plate": "place the cube onto the plate",
    "open the drawer": "pull the drawer open",
    "put both cubes in the bowl": "place the two cubes inside the bowl",
    "open the drawer and put the cube in it": "open the drawer then place the cube inside it",
    "stack the green block on the red block and the blue block on the green block":
        "place the green block onto the red block then the blue block onto the green block",
    "use the stick to pull the cube into reach": "grab the stick and drag the cube closer",
    # LIBERO's four suites (docs/libero-planner.md, "Reworded instructions"): verbs, prepositions and word order
    # changed, the objects' names kept
    "open the middle drawer of the cabinet": "pull open the cabinet's middle drawer",
    "open the top drawer and put the bowl inside": "pull the top drawer open and set the bowl in it",
    "pick up the alphabet soup and place it in the basket": "grab the alphabet soup and drop it into the basket",
    "pick up the bbq sauce and place it in the basket": "grab the bbq sauce and drop it into the basket",
    "pick up the black bowl between the plate and the ramekin and place it on the plate":
        "take the black bowl that sits between the plate and the ramekin and set it onto the plate",
    "pick up the black bowl from table center and place it on the plate":
        "take the black bowl in the center of the table and set it onto the plate",
    "pick up the black bowl in the top drawer of the wooden cabinet and place it on the plate":
        "take the black bowl out of the wooden cabinet's top drawer and set it onto the plate",
    "pick up the black bowl next to the cookie box and place it on the plate":
        "take the black bowl beside the cookie box and set it onto the plate",
    "pick up the black bowl next to the plate and place it on the plate":
        "take the black bowl beside the plate and set it onto the plate",
    "pick up the black bowl next to the ramekin and place it on the plate":
        "take the black bowl beside the ramekin and set it onto the plate",
    "pick up the black bowl on the cookie box and place it on the plate":
        "take the black bowl lying on the cookie box and set it onto the plate",
    "pick up the black bowl on the ramekin and place it on the plate":
        "take the black bowl resting on the ramekin and set it onto the plate",
    "pick up the black bowl on the stove and place it on the plate":
        "take the black bowl from the stove and set it onto the plate",
    "pick up the black bowl on the wooden cabinet and place it on the plate":
        "take the black bowl from the top of the wooden cabinet and set it onto the plate",
    "pick up the book and place it in the back compartment of the caddy":
        "grab the book and slide it into the caddy's back compartment",
    "pick up the butter and place it in the basket": "grab the butter and drop it into the basket",
    "pick up the chocolate pudding and place it in the basket": "grab the chocolate pudding and drop it into the basket",
    "pick up the cream cheese and place it in the basket": "grab the cream cheese and drop it into the basket",
    "pick up the ketchup and place it in the basket": "grab the ketchup and drop it into the basket",
    "pick up the milk and place it in the basket": "grab the milk and drop it into the basket",
    "pick up the orange juice and place it in the basket": "grab the orange juice and drop it into the basket",
    "pick up the salad dressing and place it in the basket": "grab the salad dressing and drop it into the basket",
    "pick up the tomato sauce and place it in the basket": "grab the tomato sauce and drop it into the basket",
    "push the plate to the front of the stove": "slide the plate in front of the stove",
    "put both moka pots on the stove": "set the two moka pots onto the stove",
    "put both the alphabet soup and the cream cheese box in the basket":
        "drop the alphabet soup and the cream cheese box into the basket",
    "put both the alphabet soup and the tomato sauce in the basket":
        "drop the alphabet soup and the tomato sauce into the basket",
    "put both the cream cheese box and the butter in the basket": "drop the cream cheese box and the butter into the basket",
    "put the black bowl in the bottom drawer of the cabinet and close it":
        "set the black bowl into the cabinet's bottom drawer then shut it",
    "put the bowl on the plate": "set the bowl onto the plate",
    "put the bowl on the stove": "set the bowl onto the stove",
    "put the bowl on top of the cabinet": "set the bowl on the cabinet's top",
    "put the cream cheese in the bowl": "drop the cream cheese into the bowl",
    "put the white mug on the left plate and put the yellow and white mug on the right plate":
        "set the white mug onto the left plate and the yellow and white mug onto the right plate",
    "put the white mug on the plate and put the chocolate pudding to the right of the plate":
        "set the white mug onto the plate and the chocolate pudding right of the plate",
    "put the wine bottle on the rack": "set the wine bottle onto the rack",
    "put the wine bottle on top of the cabinet": "set the wine bottle on the cabinet's top",
    "put the yellow and white mug in the microwave and close it":
        "set the yellow and white mug inside the microwave then shut it",
    "turn on the stove": "switch the stove on",
    "turn on the stove and put the moka pot on it": "switch the stove on and set the moka pot onto it",
}


def _pct(x: np.ndarray, q: float, scale: float = 1.0) -> float:
    x = x[np.isfinite(x)]
    return round(float(np.percentile(x, q)) * scale, 4) if x.size else float("nan")


def evaluate_trajectory(ck, frames, camera, *, idx: np.ndarray | None = None) -> dict:
    from tcot_hybrid.learning.validation import predict

    model, meta = ck.model, ck.meta
    ng, center = model.cfg.n_global, int(meta["windows"]["L_g"]) // 2
    idx = np.arange(len(frames)) if idx is None else idx
    res: dict = {"frames": int(len(idx)), "demos": len(set(frames.demo[idx].tolist()))}
    per_task: dict[str, dict] = {}
    tasks = np.array(frames.tasks)[frames.demo[idx]]
    t0 = frames.t[idx] == 0
    for mode in ("global", "local"):
        o = predict(model, frames, idx, mode)
        if mode == "global":
            sl = slice(center, ng)
            uvt, zt, gt, xyz = (a[idx][:, center:].numpy() for a in (frames.g_uv, frames.g_z, frames.g_grip, frames.g_xyz))
        else:
            sl = slice(ng, None)
            uvt, zt, gt, xyz = (a[idx].numpy() for a in (frames.l_uv, frames.l_z, frames.l_grip, frames.l_xyz))
        uv, z, grip = o["uv_px"][:, sl], o["z_m"][:, sl], o["grip_logit"][:, sl] > 0
        px = np.linalg.norm(uv - uvt, axis=-1)
        e3 = np.linalg.norm(points_at_height(camera, uv, z) - xyz, axis=-1)
        ok = grip == (gt > 0.5)
        # stop points: where the demo's gripper bit changes (grasp / release) — what decides a grasp
        stop = np.zeros_like(ok)
        stop[:, 1:] = (gt[:, 1:] > 0.5) != (gt[:, :-1] > 0.5)
        r = {"px_median": _pct(px, 50), "px_p90": _pct(px, 90), "3d_cm_median": _pct(e3, 50, 100),
             "3d_cm_p90": _pct(e3, 90, 100), "z_cm_median": _pct(np.abs(z - zt), 50, 100),
             "grip_acc": round(float(ok.mean()), 4),
             "stop_px_median": _pct(px[stop], 50), "stop_3d_cm_median": _pct(e3[stop], 50, 100),
             "stop_3d_cm_p90": _pct(e3[stop], 90, 100)}
        if mode == "global":
            r.update({"t0_px_median": _pct(px[t0], 50), "t0_px_p90": _pct(px[t0], 90),
                      "t0_3d_cm_median": _pct(e3[t0], 50, 100), "t0_3d_cm_p90": _pct(e3[t0], 90, 100),
                      "t0_grip_acc": round(float(ok[t0].mean()), 4),
                      "t0_stop_3d_cm_median": _pct(e3[t0][stop[t0]], 50, 100),
                      "t0_stop_3d_cm_p90": _pct(e3[t0][stop[t0]], 90, 100)})
            for task in sorted(set(tasks.tolist())):
                m = tasks == task
                mt = m & t0
                per_task[task] = {"px_median": _pct(px[m], 50), "3d_cm_median": _pct(e3[m], 50, 100),
                                  "t0_3d_cm_median": _pct(e3[mt], 50, 100),
                                  "t0_stop_3d_cm_max": _pct(e3[mt][stop[mt]], 100, 100),
                                  "grip_acc": round(float(ok[m].mean()), 4)}
        res[mode] = r
    d = predict(model, frames, idx, "detect")
    p = 1 / (1 + np.exp(-d["success_logit"]))
    y = frames.success[idx].numpy()
    a = auroc(p, y)
    res["detect"] = {"auroc": round(a, 4) if a is not None else float("nan"),
                     "acc": round(float(((p > 0.5) == (y > 0.5)).mean()), 4),
                     "positives": int((y > 0.5).sum()), "negatives": int((y <= 0.5).sum())}
    res["per_task"] = per_task
    return res


def stop_sequence(points: np.ndarray, grip: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """Where the executor would switch the gripper along a plan: (position, new state) per stop,
    starting open (a waypoint whose bit differs from the current command is a stop)."""
    out, closed = [], False
    for p, g in zip(points, grip):
        if bool(g) != closed:
            closed = bool(g)
            out.append((p, closed))
    return out


def t0_stop_errors(ck, frames, camera) -> dict:
    """Closed-loop proxy for global plans made at t = 0: compare the gripper-switch positions the executor
    would use on the predicted plan with those of the demonstration (same logic on the true window)."""
    from tcot_hybrid.learning.validation import predict

    ng, center = ck.model.cfg.n_global, int(ck.meta["windows"]["L_g"]) // 2
    idx = np.flatnonzero(frames.t == 0)
    o = predict(ck.model, frames, idx, "global")
    pts = points_at_height(camera, o["uv_px"][:, center:ng], o["z_m"][:, center:ng])
    grip = o["grip_logit"][:, center:ng] > 0
    xyz, gt = frames.g_xyz[idx][:, center:].numpy(), frames.g_grip[idx][:, center:].numpy() > 0.5
    same_count, errs, per_task = 0, [], {}
    tasks = np.array(frames.tasks)[frames.demo[idx]]
    for i in range(len(idx)):
        sp, st = stop_sequence(pts[i], grip[i]), stop_sequence(xyz[i], gt[i])
        ok = len(sp) == len(st) and all(a[1] == b[1] for a, b in zip(sp, st))
        e = [float(np.linalg.norm(a[0] - b[0])) for a, b in zip(sp, st)] if ok else []
        same_count += ok
        errs += e
        worst = max(e) if ok and e else float("inf")
        per_task.setdefault(tasks[i], []).append(worst)
    errs = np.array(errs)
    return {"plans": int(len(idx)), "same_stop_sequence": round(same_count / max(len(idx), 1), 4),
            "stop_err_cm_median": _pct(errs, 50, 100), "stop_err_cm_p90": _pct(errs, 90, 100),
            "plans_all_stops_within_1cm": round(float(np.mean([w <= 0.01 for v in per_task.values() for w in v])), 4),
            "plans_all_stops_within_2cm": round(float(np.mean([w <= 0.02 for v in per_task.values() for w in v])), 4),
            "per_task_within_1_5cm": {k: round(float(np.mean(np.array(v) <= 0.015)), 3) for k, v in sorted(per_task.items())}}


@dataclass
class Rewording:
    """What :func:`reworded_instructions` swapped in: instruction -> rewording, the instructions without one, the
    rewordings the planner would refuse (too many unknown words) and each rewording's unknown-word fraction."""

    pairs: dict[str, str] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)
    unknown_fractions: list[float] = field(default_factory=list)


@contextlib.contextmanager
def reworded_instructions(frames, vocab, *, max_tokens: int, max_unknown_fraction: float):
    """Inside the block every demo of ``frames`` reads its instruction's rewording (``PARAPHRASES``) as tokens;
    a rewording the planner would refuse is measured anyway (unknown words as <unk>). The original tokens are
    restored afterwards. Yields a :class:`Rewording`."""
    import torch

    saved = frames.tokens.clone()
    r = Rewording()
    try:
        for di, instr in enumerate(frames.instructions):
            para = PARAPHRASES.get(instr)
            if para is None:
                r.missing.append(instr)
                continue
            ids, n_words, n_unknown = vocab.encode(para, max_tokens)
            r.unknown_fractions.append(n_unknown / max(n_words, 1))
            try:
                vocab.encode_checked(para, max_tokens, max_unknown_fraction=max_unknown_fraction)
            except PlanningError:
                r.refused.append(para)
            frames.tokens[frames.demo == di] = torch.from_numpy(ids)
            r.pairs[instr] = para
        yield r
    finally:
        frames.tokens.copy_(saved)


def paraphrase_robustness(ck, frames, camera, vocab) -> dict:
    """Global-plan error at t = 0 with each task's instruction replaced by an unseen rewording."""
    from tcot_hybrid.learning.validation import predict

    ng, center = ck.model.cfg.n_global, int(ck.meta["windows"]["L_g"]) // 2
    idx = np.flatnonzero(frames.t == 0)
    base = predict(ck.model, frames, idx, "global")
    with reworded_instructions(frames, vocab, max_tokens=ck.model.cfg.max_tokens,
                               max_unknown_fraction=float(ck.meta.get("max_unknown_fraction", 0.5))) as r:
        para_out = predict(ck.model, frames, idx, "global")
    rows, refused = r.pairs, r.refused
    xyz = frames.g_xyz[idx][:, center:].numpy()
    e_base = np.linalg.norm(points_at_height(camera, base["uv_px"][:, center:ng], base["z_m"][:, center:ng]) - xyz, axis=-1)
    e_para = np.linalg.norm(points_at_height(camera, para_out["uv_px"][:, center:ng], para_out["z_m"][:, center:ng]) - xyz,
                            axis=-1)
    return {"pairs": rows, "refused": sorted(set(refused)),
            "t0_3d_cm_median_original": _pct(e_base, 50, 100), "t0_3d_cm_p90_original": _pct(e_base, 90, 100),
            "t0_3d_cm_median_paraphrased": _pct(e_para, 50, 100), "t0_3d_cm_p90_paraphrased": _pct(e_para, 90, 100)}


def evaluate_direct(ck, frames, idx=None) -> dict:
    from tcot_hybrid.learning.validation import direct_metrics

    idx = np.arange(len(frames)) if idx is None else idx
    return direct_metrics(ck.model, frames, idx)


def demo_label(meta: dict, data: str | Path, split: str) -> str:
    """What the evaluated demos are to the checkpoint: "held-out" only when it never trained on them (the
    validation split of a file it trained on, or any split of a file it never saw)."""
    from tcot_hybrid.learning.data import file_hash

    trained_on = file_hash(data) in str(meta.get("data_hash", "")).split("+")
    if not trained_on or split == "valid":
        return "held-out demos"
    return "training demos" if split == "train" else "demos (training and validation splits)"


def markdown(r: dict) -> str:
    label = r.get("demos_label", "held-out demos")
    lines = [f"Checkpoint `{r['checkpoint']}` on `{r['data']}` split `{r['split']}` "
             f"({r['result']['demos']} {label}, {r['result']['frames']} frames); command: `{r['command']}`", ""]
    res = r["result"]
    if r["kind"] == "direct":
        lines += ["| metric | value |", "|---|---|"] + [f"| {k} | {v} |" for k, v in res.items()]
        return "\n".join(lines) + "\n"
    lines += ["| mode | px median | px p90 | 3D median [cm] | 3D p90 [cm] | z median [cm] | gripper acc | "
              "stop-point 3D median [cm] |", "|---|---|---|---|---|---|---|---|"]
    for mode in ("global", "local"):
        m = res[mode]
        lines.append(f"| {mode} (all steps) | {m['px_median']} | {m['px_p90']} | {m['3d_cm_median']} | {m['3d_cm_p90']} | "
                     f"{m['z_cm_median']} | {m['grip_acc']} | {m['stop_3d_cm_median']} |")
    g = res["global"]
    lines.append(f"| global at t = 0 | {g['t0_px_median']} | {g['t0_px_p90']} | {g['t0_3d_cm_median']} | "
                 f"{g['t0_3d_cm_p90']} | | {g['t0_grip_acc']} | {g['t0_stop_3d_cm_median']} (p90 {g['t0_stop_3d_cm_p90']}) |")
    d = res["detect"]
    lines += ["", f"Success detection: AUROC {d['auroc']}, accuracy {d['acc']} ({d['positives']} success / "
              f"{d['negatives']} not-yet frames).", "",
              "| task | global px median | global 3D median [cm] | t=0 3D median [cm] | t=0 worst stop point [cm] | gripper acc |",
              "|---|---|---|---|---|---|"]
    for task, m in res["per_task"].items():
        lines.append(f"| {task} | {m['px_median']} | {m['3d_cm_median']} | {m['t0_3d_cm_median']} | "
                     f"{m['t0_stop_3d_cm_max']} | {m['grip_acc']} |")
    if "t0_stops" in r:
        s = r["t0_stops"]
        lines += ["", f"Closed-loop proxy (global plans at t = 0, executor's stop logic on predicted vs demonstrated "
                  f"windows): same gripper-switch sequence in {s['same_stop_sequence']:.1%} of {s['plans']} plans; "
                  f"switch-point error median {s['stop_err_cm_median']} cm, p90 {s['stop_err_cm_p90']} cm; plans with "
                  f"every switch within 1 cm: {s['plans_all_stops_within_1cm']:.1%}, within 2 cm: "
                  f"{s['plans_all_stops_within_2cm']:.1%}.", "",
                  "| task | plans with every switch within 1.5 cm |", "|---|---|"]
        lines += [f"| {k} | {v:.0%} |" for k, v in s["per_task_within_1_5cm"].items()]
    if "paraphrase" in r:
        p = r["paraphrase"]
        lines += ["", f"Unseen paraphrases (global plan at t = 0, 3D error median / p90): original "
                  f"{p['t0_3d_cm_median_original']} / {p['t0_3d_cm_p90_original']} cm, paraphrased "
                  f"{p['t0_3d_cm_median_paraphrased']} / {p['t0_3d_cm_p90_paraphrased']} cm; refused by the "
                  f"unknown-word rule: {', '.join(p['refused']) or 'none'}."]
    return "\n".join(lines) + "\n"


def run(checkpoint: str | Path, data: str | Path, *, split: str = "valid", out: str | Path | None = None,
        command: str = "", stem: str | None = None) -> dict:
    from tcot_hybrid.data.labels import windows_from_meta
    from tcot_hybrid.learning.checkpoint import load_checkpoint
    from tcot_hybrid.learning.data import env_of, load_frames
    from tcot_hybrid.learning.vocab import Vocabulary

    t0 = time.perf_counter()
    env, camera, _ = env_of(data)
    ck = load_checkpoint(checkpoint, robot=env["robot"], camera=camera)
    vocab = Vocabulary(tuple(ck.meta["vocabulary"]))
    frames = load_frames(data, split, vocab, windows=windows_from_meta(ck.meta["windows"]),
                         max_tokens=ck.model.cfg.max_tokens, direct_horizon=int(ck.meta.get("direct_horizon", 3)))
    report: dict = {"checkpoint": str(checkpoint), "data": str(data), "split": split, "kind": ck.meta["kind"],
                    "demos_label": demo_label(ck.meta, data, split), "command": command}
    if ck.meta["kind"] == "direct":
        report["result"] = {"demos": len(frames.demos), **evaluate_direct(ck, frames)}
    else:
        report["result"] = evaluate_trajectory(ck, frames, camera)
        report["t0_stops"] = t0_stop_errors(ck, frames, camera)
        report["paraphrase"] = paraphrase_robustness(ck, frames, camera, vocab)
    report["wall_s"] = round(time.perf_counter() - t0, 1)
    if out is not None:
        o = Path(out)
        o.mkdir(parents=True, exist_ok=True)
        stem = stem or ("planner_eval" if ck.meta["kind"] != "direct" else "direct_eval")
        (o / f"{stem}.json").write_text(json.dumps(report, indent=1) + "\n")
        (o / f"{stem}.md").write_text(markdown(report))
    return report


def main(argv: list[str] | None = None) -> int:
    import sys

    p = argparse.ArgumentParser(prog="python -m tcot_hybrid.learning.evaluate", description=__doc__)
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--data", required=True)
    p.add_argument("--split", default="valid", choices=["train", "valid", "all"])
    p.add_argument("--out", default="docs/planner-eval")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--readme", type=Path, default=None,
                   help="also write the report into this Markdown file's <!-- planner_eval:start/end --> "
                        "(direct checkpoints: direct_eval) section")
    p.add_argument("--section", default=None,
                   help="name of that Markdown section instead (e.g. planner_eval_train for a training-split report)")
    p.add_argument("--stem", default=None,
                   help="file name stem in --out (default planner_eval / direct_eval)")
    args = p.parse_args(argv)
    if args.stem is not None and (not args.stem or Path(args.stem).name != args.stem or args.stem in (".", "..")):
        p.error(f"--stem must be a plain file name inside --out, got {args.stem!r}")
    if args.section is not None and args.readme is None:
        p.error("--section names a section of the --readme file; give --readme too")
    if args.readme is not None:  # fail before the evaluation, not after it
        from tcot_hybrid.markdown import has_readme_section

        names = [args.section] if args.section else ["planner_eval", "direct_eval"]
        if not any(has_readme_section(args.readme, n) for n in names):
            p.error(f"{str(args.readme)!r} has no <!-- {'/'.join(names)}:start/end --> section to write into")
    import torch

    torch.set_num_threads(args.threads)
    cmdline = "python -m tcot_hybrid.learning.evaluate " + " ".join(sys.argv[1:] if argv is None else argv)
    r = run(args.checkpoint, args.data, split=args.split, out=args.out, command=cmdline, stem=args.stem)
    print(markdown(r))
    if args.readme:
        from tcot_hybrid.markdown import update_readme_section

        section = args.section or ("direct_eval" if r["kind"] == "direct" else "planner_eval")
        update_readme_section(args.readme, section, markdown(r))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
