"""``tcot train``: train the TCoT planner (or the direct-action baseline) from a demonstration file.

Recipe (paper Sec. "Trajectory-based Chain-of-Thought Training", adapted):
  stage 1  global + local trajectory planning (batches mixed by ``mix_stage1``);
  stage 2  adds failure detection (``mix_stage2``): demo frames whose task predicate holds vs frames
           before success (online rollouts, ``source="rollout"``, join later through the same file format).
The balance between objectives is the fraction of each sample kind per batch, never a loss weight.
Validation is the file's ``/mask/valid`` split (by seed); the best epoch on validation is kept and
training stops early when it has not improved for ``patience`` epochs.

Every epoch appends one JSON line to ``<out>.metrics.jsonl``: losses, val pixel error median/p90, val
3D error median/p90, gripper accuracy and success AUROC.

Resuming: every epoch also writes ``<out>.resume.pt`` (weights, AdamW and one-cycle scheduler state, the sampling and
torch random states, the best epoch so far and its weights, the config and the data's hash). ``train(cfg,
resume=True)`` (``tcot train --resume``) continues after the last saved epoch: a run cut by ``max_minutes`` (or
killed) goes on where it stopped, and with a fixed ``threads`` it ends with the same weights as one uninterrupted run.
A finished run (all epochs, or early stop) is not trained again. A different config (but for ``max_minutes`` and
``threads``) or data file is refused, naming what differs.
"""
from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tcot_hybrid.errors import ConfigError, DatasetError
from tcot_hybrid.learning.batches import Batcher
from tcot_hybrid.learning.losses import detect_loss, direct_loss, trajectory_loss
from tcot_hybrid.learning.train_config import MixConfig, TrainConfig
from tcot_hybrid.learning.validation import direct_metrics, trajectory_metrics, val_indices


@dataclass
class TrainResult:
    checkpoint: Path
    metrics: dict
    epochs: int
    wall_s: float


RESUME_FREE_FIELDS = ("max_minutes", "threads")  # config fields a resumed run may change


def resume_path(out: str | Path) -> Path:
    """Where a run writing checkpoint ``out`` keeps its per-epoch training state (``--resume``)."""
    return Path(out).with_suffix(".resume.pt")


def load_resume_state(cfg: TrainConfig, data_hash: str) -> dict | None:
    """The saved state of the run writing ``cfg.out`` (None when there is none), after checking that it was written
    with the same config (``RESUME_FREE_FIELDS`` aside) and data; ConfigError naming the difference otherwise."""
    import torch

    path = resume_path(cfg.out)
    if not path.is_file():
        return None
    try:
        st = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - a truncated or foreign file: say which and what to do
        why = str(exc).strip().splitlines()[-1][:160] if str(exc).strip() else type(exc).__name__
        raise ConfigError(f"--resume: cannot read the training state {str(path)!r} ({why}); delete it to start "
                          f"afresh") from exc
    if not isinstance(st, dict) or st.get("format") != RESUME_FORMAT:
        raise ConfigError(f"--resume: {str(path)!r} is not a training state of this version (format "
                          f"{st.get('format') if isinstance(st, dict) else type(st).__name__!r}, expected "
                          f"{RESUME_FORMAT!r}); delete it to start afresh")
    saved, now = _with_new_defaults(json.loads(st["config"])), _jsonable(cfg)
    diff = sorted(k for k in set(saved) | set(now) if k not in RESUME_FREE_FIELDS and saved.get(k) != now.get(k))
    if diff:
        k = diff[0]
        raise ConfigError(f"--resume: {str(path)!r} was written by a run with {k} = {saved.get(k)!r}, this run has "
                          f"{k} = {now.get(k)!r} ({len(diff)} field(s) differ: {', '.join(diff)}); only "
                          f"{', '.join(RESUME_FREE_FIELDS)} may change between the parts of one run. Resume with the "
                          f"same config, or start afresh (--overwrite, without --resume)")
    if st["data_hash"] != data_hash:
        raise ConfigError(f"--resume: {str(path)!r} was trained on data with hash {st['data_hash']}, "
                          f"{cfg.data!r} now has {data_hash} (the file changed, e.g. more demonstrations were "
                          f"collected); start afresh (--overwrite, without --resume)")
    return st


RESUME_FORMAT = "tcot-train-resume-1"


def _with_new_defaults(saved: dict) -> dict:
    """A saved run's config with the fields added to TrainConfig since it was written at their defaults (a field
    added with the old behaviour as its default, e.g. windows.segment_points, does not make the run a different one);
    as saved when it no longer reads as a TrainConfig (the comparison then names what differs)."""
    from tcot_hybrid.config import from_mapping

    try:
        return _jsonable(from_mapping(TrainConfig, saved))
    except (ConfigError, TypeError, ValueError):
        return saved


def run_finished(out: str | Path) -> bool:
    """Whether the run writing checkpoint ``out`` has finished (all its epochs, or an early stop) by its saved
    training state; False while a part cut by ``max_minutes`` is left to resume (or no state was saved)."""
    import torch

    path = resume_path(out)
    return path.is_file() and bool(torch.load(path, map_location="cpu", weights_only=True).get("finished"))


def _save_resume_state(cfg: TrainConfig, **state) -> None:
    import os

    import torch

    path = resume_path(cfg.out)
    tmp = path.with_name(path.name + ".tmp")
    torch.save({"format": RESUME_FORMAT, "config": json.dumps(_jsonable(cfg)), **state}, tmp)
    os.replace(tmp, path)  # never a half-written state


def train(cfg: TrainConfig, *, progress: bool = True, log=print, resume: bool = False) -> TrainResult:
    """Train per ``cfg``; writes the best-on-validation checkpoint to ``cfg.out``; returns its metrics.
    ``resume``: continue the run's saved state (``resume_path``) when there is one (see the module doc)."""
    import torch
    from tqdm import tqdm

    from tcot_hybrid.learning.checkpoint import camera_meta, load_checkpoint, save_checkpoint, versions
    from tcot_hybrid.learning.data import (concat_frames, env_of, file_hash, instructions_of, load_frames,
                                           load_online_frames, online_split_size, tasks_of)
    from tcot_hybrid.learning.model import PlannerNet, count_parameters
    from tcot_hybrid.learning.vocab import Vocabulary

    t_start = time.perf_counter()
    data_files = [cfg.data, *cfg.extra_data, *cfg.online_data]
    state, data_hash = None, ""
    if resume and all(Path(p).is_file() for p in data_files):  # a missing file is named by the data load below
        data_hash = "+".join(file_hash(p) for p in data_files)
        state = load_resume_state(cfg, data_hash)  # checked before the (minutes-long) data load
    if state is not None and state["finished"] and Path(cfg.out).is_file():
        # the checkpoint is left as it is, so its recorded training time stays true
        log(f"resumed from {resume_path(cfg.out)}: that run had finished after epoch {state['epoch']} of "
            f"{cfg.max_epochs} (best epoch {state['best_epoch']}); nothing left to train, {cfg.out} left as it is")
        return TrainResult(checkpoint=Path(cfg.out), metrics=json.loads(state["best_metrics"]),
                           epochs=int(state["epoch"]), wall_s=0.0)
    torch.set_num_threads(cfg.threads or 2)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    env, camera, dof = env_of(cfg.data)
    vocab = Vocabulary.build(instructions_of(cfg.data, "train"))
    init = load_checkpoint(cfg.init, kind=cfg.model.kind) if cfg.init else None  # read once: words, then weights
    if init is not None:  # a fine-tune keeps its init's word ids, so a suite's file alone can continue a four-suite model
        vocab = _init_vocabulary(init, cfg.init, vocab)
    mcfg = dataclasses.replace(cfg.model, vocab_size=len(vocab), dof=dof, n_global=cfg.windows.L_g,
                               n_local=cfg.windows.L_l + 1, image_px=int(env["height"]))
    if int(env["height"]) != int(env["width"]):
        raise ConfigError(f"planner images must be square, data has {env['width']}x{env['height']}")
    load = dict(windows=cfg.windows, max_tokens=mcfg.max_tokens, direct_horizon=cfg.direct_horizon,
                height_ref=cfg.height_ref, suites=cfg.suites)
    replaced = frozenset().union(*map(tasks_of, cfg.extra_data)) if cfg.extra_data_replaces_tasks else frozenset()
    tr = load_frames(cfg.data, "train", vocab, max_demos=cfg.max_train_demos, exclude_tasks=replaced, **load)
    va = load_frames(cfg.data, "valid", vocab, exclude_tasks=replaced, **load)
    of = f" (suites {', '.join(cfg.suites)})" if cfg.suites else ""
    if replaced:
        of += f" (without the {len(replaced)} tasks extra_data replaces: {', '.join(sorted(replaced))})"
    log(f"data {cfg.data}{of}: {len(tr.demos)} train demos / {len(tr)} frames, {len(va.demos)} valid demos / "
        f"{len(va)} frames; vocabulary {len(vocab)} words; loaded in {time.perf_counter() - t_start:.1f}s")
    trs, vas = [tr], [va]
    for path in cfg.extra_data:
        _check_same_env(env, env_of(path)[0], path, cfg.data)
        ex_tr, ex_va = (load_frames(path, split, vocab, frame_stride=cfg.extra_frame_stride, **load)
                        for split in ("train", "valid"))
        log(f"extra data {path}: {len(ex_tr.demos)} train demos / {len(ex_tr)} frames, {len(ex_va.demos)} valid "
            f"demos / {len(ex_va)} frames (every {cfg.extra_frame_stride}. frame)")
        trs.append(ex_tr)
        vas.append(ex_va)
    for path in cfg.online_data:
        _check_same_env(env, env_of(path)[0], path, cfg.data)
        if online_split_size(path, "train", cfg.suites) == 0:
            raise DatasetError(f"online data file {path}: no episode falls in the training split (seed % "
                               f"valid_every != 0); collect it with other seeds or another --valid-every")
        on_tr = load_online_frames(path, "train", vocab, frame_stride=cfg.online_frame_stride, **load)
        trs.append(on_tr)
        # a file of one seed per task lies wholly in one split: validation then rests on the other files
        on_va = (load_online_frames(path, "valid", vocab, frame_stride=cfg.online_frame_stride, **load)
                 if online_split_size(path, "valid", cfg.suites) else None)
        log(f"online data {path}: {len(on_tr.demos)} train episodes / {len(on_tr)} frames "
            f"({int(on_tr.traj.sum())} with recovery trajectories, {int(on_tr.success.sum())} success), "
            + (f"{len(on_va.demos)} valid episodes / {len(on_va)} frames" if on_va is not None
               else "no valid episodes"))
        if on_va is not None:
            vas.append(on_va)
    tr, va = concat_frames(trs), concat_frames(vas)
    del trs, vas
    data_hash = data_hash or "+".join(file_hash(p) for p in data_files)
    if resume and state is None:
        log(f"--resume: no training state at {resume_path(cfg.out)}; starting afresh")
    model = PlannerNet(mcfg)
    if state is not None:
        pass  # the weights come from the saved state below
    elif cfg.init is not None:
        _load_init(model, init, cfg.init, log, cfg.windows)
    else:
        model.proprio_mean.copy_(tr.proprio.mean(0))
        model.proprio_std.copy_(tr.proprio.std(0).clamp_min(1e-3))
    model = model.to(memory_format=torch.channels_last)
    log(f"model {mcfg.kind}/{mcfg.head}: {count_parameters(model) / 1e6:.2f} M parameters")
    use_bf16 = cfg.bf16 and native_bf16(torch)
    if cfg.bf16 and not use_bf16:
        log(f"bf16: this CPU ({torch.backends.cpu.get_cpu_capability()}) has no native bf16, so training runs in fp32 "
            "(emulated bf16 measured 3.4x slower than fp32 on an AVX2 CPU)")
    steps_per_epoch = math.ceil((cfg.epoch_samples or len(tr)) / cfg.batch_size)
    total_steps = steps_per_epoch * cfg.max_epochs
    opt = torch.optim.AdamW(_param_groups(model, cfg, log), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=total_steps, pct_start=0.15)
    batcher = Batcher(tr, cfg, rng)
    vidx = val_indices(va, cfg.val_max_frames)
    out = Path(cfg.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    log_path = out.with_suffix(".metrics.jsonl")
    best_score, best_state, best_metrics, best_epoch, bad_epochs = math.inf, None, {}, -1, 0
    start_epoch, elapsed_before, finished = 1, 0.0, False
    if state is not None:
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        sched.load_state_dict(state["scheduler"])
        rng.bit_generator.state = json.loads(state["numpy_rng"])
        torch.set_rng_state(state["torch_rng"])
        best_score, best_state = float(state["best_score"]), state["best_state"]
        best_metrics, best_epoch = json.loads(state["best_metrics"]), int(state["best_epoch"])
        bad_epochs, elapsed_before = int(state["bad_epochs"]), float(state["elapsed_s"])
        start_epoch, finished = int(state["epoch"]) + 1, bool(state["finished"])
        kept = [line for line in (log_path.read_text().splitlines() if log_path.is_file() else [])
                if line.strip() and json.loads(line)["epoch"] < start_epoch]  # an epoch logged after the last save
        log_path.write_text("".join(line + "\n" for line in kept))
        log(f"resumed from {resume_path(out)} after epoch {start_epoch - 1} of {cfg.max_epochs} (best epoch "
            f"{best_epoch}; {elapsed_before / 60:.1f} min of earlier parts)"
            + ("; that run had finished: nothing left to train" if finished else ""))
    else:
        log_path.write_text("")
    epoch = start_epoch - 1
    for epoch in range(start_epoch, cfg.max_epochs + 1 if not finished else start_epoch):
        model.train()
        mix = cfg.mix_stage1 if epoch <= cfg.stage1_epochs else cfg.mix_stage2
        if mcfg.kind == "direct":  # one objective: every frame equally likely
            mix = MixConfig(global_frac=1.0, local_frac=0.0, detect_frac=0.0)
        sums: dict[str, float] = {}
        t_ep = time.perf_counter()
        bar = tqdm(range(steps_per_epoch), desc=f"epoch {epoch}/{cfg.max_epochs}", unit="step", leave=False,
                   disable=not progress)
        probe: dict[int, float] = {}
        for step in bar:
            if cfg.threads == 0:
                step_t0 = _choose_threads(step, probe, torch)
            idx, modes = batcher.indices(cfg.batch_size, mix)
            b = batcher.batch(idx, modes, augment=True)
            with torch.autocast("cpu", dtype=torch.bfloat16, enabled=use_bf16):
                o = model(b["image"], b["tokens"], b["mode"], b["proprio"], waypoints=cfg.trainable != "detect")
            if mcfg.kind == "direct":
                loss, parts = direct_loss(o, b)
            elif cfg.trainable == "detect":
                loss, parts = detect_loss(o, b)
            else:
                loss, parts = trajectory_loss(o, b, mcfg.n_global, heatmap_ce=cfg.heatmap_ce,
                                              image_px=mcfg.image_px)
            if not torch.isfinite(loss):
                raise ConfigError(f"training diverged (loss {loss.item()}) at epoch {epoch}; lower lr (now {cfg.lr})")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 5.0)
            opt.step()
            sched.step()
            for k, v in {"loss": loss, **parts}.items():
                sums[k] = sums.get(k, 0.0) + float(v.detach())
            bar.set_postfix(loss=f"{loss.item():.3f}")
            if cfg.threads == 0 and step < 2 * _PROBE_STEPS and math.isfinite(step_t0):
                probe[torch.get_num_threads()] = probe.get(torch.get_num_threads(), 0.0) + time.perf_counter() - step_t0
        train_s = time.perf_counter() - t_ep
        if mcfg.kind == "direct":
            m = direct_metrics(model, va, vidx)
            score = m["delta_cm_median"]
        else:
            m = trajectory_metrics(model, va, vidx, n_global=mcfg.n_global, center=cfg.windows.global_center)
            score = m["px_median"] + 0.5 * m["global_t0_px_median"]
            if epoch > cfg.stage1_epochs and math.isfinite(m["success_auroc"]):
                score += DETECT_SCORE_PX * (1.0 - m["success_auroc"])
        rec = {"epoch": epoch, "stage": 1 if epoch <= cfg.stage1_epochs or mcfg.kind == "direct" else 2,
               "train": {k: round(v / steps_per_epoch, 5) for k, v in sums.items()},
               "val": m, "score": round(score, 4), "lr": sched.get_last_lr()[0],
               "epoch_train_s": round(train_s, 1),
               "elapsed_s": round(elapsed_before + time.perf_counter() - t_start, 1),
               "threads": torch.get_num_threads()}
        with open(log_path, "a") as fh:
            fh.write(json.dumps(rec) + "\n")
        log(_epoch_line(rec, mcfg.kind))
        if score < best_score:
            best_score, best_epoch, best_metrics, bad_epochs = score, epoch, m, 0
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        else:
            bad_epochs += 1
        finished = bad_epochs >= cfg.patience or epoch == cfg.max_epochs
        _save_resume_state(cfg, model=model.state_dict(), optimizer=opt.state_dict(), scheduler=sched.state_dict(),
                           numpy_rng=json.dumps(rng.bit_generator.state), torch_rng=torch.get_rng_state(),
                           best_score=best_score, best_state=best_state, best_metrics=json.dumps(best_metrics),
                           best_epoch=best_epoch, bad_epochs=bad_epochs, epoch=epoch, finished=finished,
                           elapsed_s=elapsed_before + time.perf_counter() - t_start, data_hash=data_hash)
        if bad_epochs >= cfg.patience:
            log(f"early stop: no better validation score for {cfg.patience} epochs (best epoch {best_epoch})")
            break
        if (time.perf_counter() - t_start) / 60 >= cfg.max_minutes and epoch < cfg.max_epochs:
            log(f"time cap: {cfg.max_minutes} min reached after epoch {epoch} (best epoch {best_epoch}); "
                f"`tcot train --resume` (same config) continues from epoch {epoch + 1}")
            break
    model.load_state_dict(best_state)
    if cfg.trainable == "detect":
        _check_only_detector_changed(model, init)
    model = model.to(memory_format=torch.contiguous_format).eval()
    from tcot_hybrid.data.dataset import camera_per_demo

    cam_meta = camera_meta(camera)
    if camera_per_demo(env):  # trained on several scenes' cameras: runs are checked on name and size only
        cam_meta["per_scene"] = True
    meta = {
        "robot": env["robot"], "world": env.get("world", "workcell"), "height_ref": cfg.height_ref,
        "camera": cam_meta, "vocabulary": list(vocab.tokens),
        "windows": dataclasses.asdict(cfg.windows), "direct_horizon": cfg.direct_horizon,
        "max_unknown_fraction": cfg.max_unknown_fraction,
        "data_hash": data_hash, "data_file": str(cfg.data), "extra_data": list(cfg.extra_data),
        "online_data": list(cfg.online_data),
        "init": cfg.init, "data_env_config_hash": env.get("config_hash"),
        "train_demos": len(tr.demos), "train_frames": len(tr),
        "metrics": {"best_epoch": best_epoch, **best_metrics}, "train_config": _jsonable(cfg),
        "bf16_used": use_bf16,  # of the part that wrote the checkpoint (a resumed run's parts may differ)
        "versions": versions(), "created_unix": int(time.time()),
    }
    if cfg.height_ref == "camera":  # the planner's floor (learned.min_height_m) per training camera
        meta["lowest_tcp_by_camera"] = lowest_tcp_by_camera(tr)
    save_checkpoint(out, model, meta)
    wall = time.perf_counter() - t_start
    log(f"wrote {out} (best epoch {best_epoch}) in {wall / 60:.1f} min"
        + (f" ({(elapsed_before + wall) / 60:.1f} min with the earlier parts)" if elapsed_before else ""))
    return TrainResult(checkpoint=out, metrics=best_metrics, epochs=epoch, wall_s=wall)


def lowest_tcp_by_camera(frames) -> list[dict]:
    """Per planner camera of ``frames`` (its position), the lowest labelled TCP height of its imitated frames (global
    and local labels, measured like the network's heights) and, where the demonstrations recorded it, the support
    surface under that camera (``support_z_m``, from the camera like the heights): where ``learned.min_height_m`` is
    counted from on a ``height_ref: camera`` checkpoint (:func:`tcot_hybrid.planners.learned.lowest_plan_height`)."""
    out = []
    supports = getattr(frames, "camera_support_z", None) or [None] * len(frames.cameras)
    for c in np.unique(frames.cam[frames.traj]):
        sel = np.flatnonzero(frames.traj & (frames.cam == c))
        low = min(float(frames.g_z.numpy()[sel].min()), float(frames.l_z.numpy()[sel].min()))
        pos = np.asarray(frames.cameras[c].T_world_cam, dtype=float)[:3, 3]
        entry = {"camera_pos_m": [round(float(x), 4) for x in pos], "lowest_z_m": round(low, 4)}
        if supports[c] is not None:
            entry["support_z_m"] = round(float(supports[c]) - float(pos[2]), 4)
        out.append(entry)
    return out


DETECT_SCORE_PX = 5.0  # stage 2 validation score: 1 - AUROC of the detector costs like this many px of error


def _check_same_env(env: dict, other: dict, path: str, data: str) -> None:
    """Extra and online data must come from the same robot, camera and timing as the demonstrations."""
    from tcot_hybrid.data.dataset import env_difference

    diff = env_difference(other, env, ("robot", "camera", "width", "height", "plan_dt"))
    if diff:
        raise ConfigError(f"data file {path!r} has {diff} (the demonstrations {data!r})")


def _init_vocabulary(ck, path: str, data_vocab):
    """The vocabulary of init checkpoint ``ck`` (loaded from ``path``; its word embeddings are indexed by it), which
    a fine-tune keeps, when it holds every word of the run's training instructions (``data_vocab``): a model continued
    on one suite's demonstrations still reads the instructions of the others. ConfigError naming the words it lacks
    otherwise."""
    from tcot_hybrid.learning.vocab import Vocabulary

    tokens = tuple(ck.meta["vocabulary"])
    missing = sorted(set(data_vocab.tokens) - set(tokens))
    if missing:
        raise ConfigError(f"init checkpoint {path!r} has no word for {missing} of the training instructions (its "
                          f"vocabulary: {list(tokens)}); train from nothing, or from a checkpoint that knows them")
    return Vocabulary(tokens)


def _load_init(model, ck, path: str, log, windows) -> None:
    """Copy checkpoint ``ck``'s weights (loaded from ``path``) into ``model`` (fine-tuning); its vocabulary is the
    run's (:func:`_init_vocabulary`). Refuses another shape, but for a longer global window on event-spaced labels
    (more global waypoints, each started from the checkpoint's waypoint at the same place in its piece:
    ``PlannerNet.load_widened``)."""
    mine = dataclasses.replace(model.cfg, readout_radius_cells=0)
    theirs = dataclasses.replace(ck.model.cfg, readout_radius_cells=0)
    add_head = mine.detect_head and not theirs.detect_head  # a shared-head checkpoint gains its own detect head
    widen = mine.n_global > theirs.n_global and not add_head
    if mine != dataclasses.replace(theirs, detect_head=theirs.detect_head or add_head,
                                   n_global=mine.n_global if widen else theirs.n_global):
        raise ConfigError(f"init checkpoint {path!r} has model {theirs}, this run builds {mine}")
    if widen:  # a longer global window: every new waypoint starts from one of the checkpoint's
        if windows.global_spacing != "events":
            raise ConfigError(f"init checkpoint {path!r} has {theirs.n_global} global waypoints, this run "
                              f"{mine.n_global}: widening needs windows.global_spacing 'events', got "
                              f"{windows.global_spacing!r}")
        model.load_widened(ck.model, windows.points_per_segment)
    else:
        model.load_state_dict(ck.model.state_dict(), strict=not add_head)
    if add_head:
        model.init_detect_head()
    log(f"initialised from {path}" + (" (detect head copied from its shared head)" if add_head else "")
        + (f" (global waypoints widened {theirs.n_global} -> {mine.n_global})" if widen else ""))


def _param_groups(model, cfg: TrainConfig, log) -> list[dict]:
    """AdamW parameter groups: every weight, or (``trainable: detect``) only those nothing but the detect prompt
    reads. A weight of which only one row is the detector's (the detect mode's embedding row) gets a gradient
    mask and no weight decay, so Adam never moves its other rows (zero gradient, zero update)."""
    if cfg.trainable == "all":
        return [{"params": list(model.parameters())}]
    for p in model.parameters():
        p.requires_grad_(False)
    whole, rows = [], []
    for name, p, row in model.detect_parameters():
        p.requires_grad_(True)
        if row is None:
            whole.append(p)
        else:
            mask = _row_mask(p, row)
            p.register_hook(lambda g, m=mask: g * m)
            rows.append(p)
    n = sum(p.numel() for p in whole) + sum(p.shape[-1] for p in rows)
    log(f"trainable: detect — {n} weights (detect head + the detect mode's embedding row); the rest frozen")
    return [{"params": whole}, {"params": rows, "weight_decay": 0.0}]


def _row_mask(p, row: int):
    """A 0/1 mask shaped like ``p``: ones on row ``row`` only."""
    import torch

    mask = torch.zeros_like(p)
    mask[row] = 1.0
    return mask


def _check_only_detector_changed(model, init) -> None:
    """After ``trainable: detect``: every weight a global or local output reads equals the init checkpoint's
    (``init``, as loaded before training: :func:`_load_init` copied its weights, so its own are untouched), bit for
    bit."""
    import torch

    ref = init.model.state_dict()
    detect = {name: row for name, _, row in model.detect_parameters()}
    for k, v in model.state_dict().items():
        if k not in ref or (k in detect and detect[k] is None):
            continue  # the detect head (new, or the one being trained)
        a, b = v.detach().cpu(), ref[k]
        if k in detect:  # only the detect row may differ
            a, b = torch.cat([a[:detect[k]], a[detect[k] + 1:]]), torch.cat([b[:detect[k]], b[detect[k] + 1:]])
        if not torch.equal(a, b):
            raise RuntimeError(f"trainable 'detect' changed {k!r}, which a trajectory output reads")


_PROBE_STEPS = 6  # per thread count, at the start of every epoch (the first step of each is not timed)


def native_bf16(torch) -> bool:
    """True if oneDNN computes bf16 natively here (AVX512-BF16 or AMX); elsewhere bf16 autocast is emulated."""
    return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())


def _choose_threads(step: int, probe: dict, torch) -> float:
    """threads = 0: steps 0..5 run on 2 threads, 6..11 on 1, then the faster count for the rest of the epoch."""
    if step == 0:
        torch.set_num_threads(2)
    elif step == _PROBE_STEPS:
        torch.set_num_threads(1)
    elif step == 2 * _PROBE_STEPS:
        torch.set_num_threads(min(probe, key=probe.get) if probe else 2)
    if step in (0, _PROBE_STEPS):  # first step after a switch: warm-up, not timed
        return math.inf
    return time.perf_counter()


def _epoch_line(rec: dict, kind: str) -> str:
    v = rec["val"]
    if kind == "direct":
        return (f"epoch {rec['epoch']}: loss {rec['train']['loss']:.3f} | val delta {v['delta_cm_median']:.2f}/"
                f"{v['delta_cm_p90']:.2f} cm (median/p90), grip acc {v['grip_acc']:.3f} | {rec['epoch_train_s']}s")
    return (f"epoch {rec['epoch']} (stage {rec['stage']}): loss {rec['train']['loss']:.3f} | val px "
            f"{v['px_median']:.2f}/{v['px_p90']:.2f}, t0 {v['global_t0_px_median']:.2f}/{v['global_t0_px_p90']:.2f}, "
            f"3D global {v['global_3d_cm_median']:.2f}/{v['global_3d_cm_p90']:.2f} cm, grip {v['global_grip_acc']:.3f}/"
            f"{v['local_grip_acc']:.3f}, AUROC {v['success_auroc']:.3f} | {rec['epoch_train_s']}s")


def _jsonable(cfg) -> dict:
    return json.loads(json.dumps(dataclasses.asdict(cfg), default=str))
