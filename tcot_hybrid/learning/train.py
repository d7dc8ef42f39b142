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
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import numpy as np
import tyro

from tcot_hybrid.config import require_choice, require_int, require_nonnegative, require_positive
from tcot_hybrid.data.labels import TrajectoryWindowConfig
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.learning.model import MODE_IDS, ModelConfig


@dataclass(frozen=True, kw_only=True)
class MixConfig:
    """Fraction of each sample kind per batch (sums to 1). More of one kind = more of that objective."""

    global_frac: float = 0.6
    local_frac: float = 0.4
    detect_frac: float = 0.0

    def __post_init__(self) -> None:
        for name in ("global_frac", "local_frac", "detect_frac"):
            require_nonnegative(f"mix.{name}", getattr(self, name))
        total = self.global_frac + self.local_frac + self.detect_frac
        if not math.isclose(total, 1.0, abs_tol=1e-6):
            raise ConfigError(f"mix fractions must sum to 1, got {total} ({self})")

    def as_array(self) -> np.ndarray:
        return np.array([self.global_frac, self.local_frac, self.detect_frac])


@dataclass(frozen=True, kw_only=True)
class AugmentConfig:
    """Training-time augmentation (never at inference).

    shift_px:     random image translation in [-shift_px, shift_px] per axis, labels shifted with it [px].
                  Up: more translation invariance; too much teaches the wrong camera.
    brightness:   random brightness scale in [1 - b, 1 + b]. colour: per-channel gain in [1 - c, 1 + c].
    word_dropout: probability that an instruction word is replaced by <unk> (robustness to unseen words).
    """

    shift_px: int = 2
    brightness: float = 0.1
    colour: float = 0.05
    word_dropout: float = 0.1

    def __post_init__(self) -> None:
        require_int("augment.shift_px", self.shift_px, minimum=0)
        for name in ("brightness", "colour", "word_dropout"):
            require_nonnegative(f"augment.{name}", getattr(self, name))
        if self.word_dropout >= 1:
            raise ConfigError(f"augment.word_dropout must be < 1, got {self.word_dropout}")


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """One training run. Stored as YAML/TOML; every field is also a ``tcot train`` flag.

    data:            demonstration file (``tcot collect`` output) [path]
    extra_data:      further demonstration files (``tcot collect`` output, same robot and camera), e.g. more seeds
                     of the tasks a first-plan-at-t = 0 global plan gets wrong most (long, tool); split by seed
                     like ``data`` [paths]
    extra_frame_stride: keep every k-th frame of an ``extra_data`` demo (every t = 0 frame is kept: k divides 0).
                     Up: less memory; the t = 0 scenes, where frozen global plans are made, stay complete.
    online_data:     further files of online episodes (``tcot collect --planner learned`` rollouts, oracle
                     recoveries under ``--perturb``): failure-detection frames from every episode, labelled by
                     the success predicate (paper eq. 7), and recovery trajectories from successful oracle
                     episodes after their perturbation [paths]
    online_frame_stride: keep every k-th frame of an online episode (neighbouring frames are nearly
                     identical; success frames are always kept). Up: less memory and load time, less data.
    init:            start from this checkpoint's weights (same data vocabulary and model shape), e.g. stage 2
                     on online rollouts after a stage-1 run [path]; None = random init.
    out:             checkpoint to write (``.safetensors``; ``.json`` metadata and ``.metrics.jsonl`` next to it)
    kind:            "trajectory" (TCoT planner) or "direct" (next-action baseline)
    seed:            seeds weights, sampling and augmentation; same seed + data + config = same weights
                     (unless ``max_minutes`` cuts the run short)
    threads:         torch CPU threads; 0 = auto: each epoch times a few steps with 2 and with 1 thread
                     and keeps the faster (on a shared, busy machine 1 thread can be several times faster
                     than 2; set a fixed number for bit-reproducible runs)
    global_t0_frac:  fraction of global-mode samples drawn from t = 0 frames, where closed-loop global
                     plans are made. Up: better first plans, less practice on later steps.
    batch_size:      samples per step. Up: smoother gradients, slower steps.
    lr:              peak AdamW learning rate (one-cycle schedule). weight_decay: AdamW decay.
    max_epochs:      epochs (one epoch = ``epoch_samples`` samples). Up: better fit, longer.
    epoch_samples:   samples per epoch; None = as many as training frames. Set it when online data makes the
                     frame count large (fine-tuning needs fewer steps than a pass over every frame).
    max_minutes:     wall-clock cap [min]; stops after the current epoch's validation.
    patience:        stop after this many epochs without a better validation score.
    stage1_epochs:   epochs of stage 1 (trajectory only) before detection joins (trajectory kind only).
    mix_stage1/2:    batch composition per stage.
    recovery_frac:   fraction of local-prompt samples drawn from the recovery frames of ``online_data`` (when
                     there are any). Recovery states (e.g. the arm above an empty bowl after a drop) are a
                     small share of all frames and look like the end of a demonstration, where the local
                     label is "stay": up makes the local prompt recover, down keeps it closer to the demos.
    detect_ignore_before_success: detection negatives exclude the last k frames before an episode's first
                     success frame. The predicate needs the released object to be still, so those frames show
                     the same scene as the first success frames (object in place, gripper open) with the
                     opposite label; the detector learned to wait for the arm to move away and called the first
                     1-4 success steps failures. 0 = use every frame (rounds 1-2). Validation AUROC still
                     counts every frame.
    direct_horizon:  direct kind: predict the TCP displacement over this many planner steps.
    max_train_demos: use only the first N training demos (quick experiments, tests); None = all.
    val_max_frames:  validation frames per epoch (every k-th frame; all t = 0 frames kept). Down: faster epochs.
    bf16:            bf16 autocast + channels_last (measured ~2-3x faster than fp32 on these CPUs).
    heatmap_ce:      weight of a cross-entropy term pulling each heatmap toward a 1-cell Gaussian at its
                     label (a shape prior for soft-argmax; 0 = coordinate loss only).
    max_unknown_fraction: stored in the checkpoint; the planner refuses instructions with more unknown words.
    model:           architecture knobs (vocab_size, dof, n_global, n_local, image_px are filled from the data).
    windows:         label windows (paper eq. 4/5).
    """

    data: str = "data/demos_panda.hdf5"
    extra_data: tuple[str, ...] = ()
    extra_frame_stride: int = 1
    online_data: tuple[str, ...] = ()
    online_frame_stride: int = 2
    init: str | None = None
    out: str = "runs/train/planner.safetensors"
    kind: str = "trajectory"
    seed: int = 0
    threads: int = 0
    batch_size: int = 64
    lr: float = 3e-3
    weight_decay: float = 1e-4
    max_epochs: int = 7
    epoch_samples: int | None = None
    max_minutes: float = 11.0
    patience: int = 4
    stage1_epochs: int = 3
    global_t0_frac: float = 0.25
    mix_stage1: MixConfig = field(default_factory=MixConfig)
    mix_stage2: MixConfig = field(default_factory=lambda: MixConfig(global_frac=0.5, local_frac=0.3, detect_frac=0.2))
    recovery_frac: float = 0.6
    detect_ignore_before_success: int = 0
    direct_horizon: int = 3
    max_train_demos: int | None = None
    val_max_frames: int = 2000
    bf16: bool = True
    heatmap_ce: float = 0.5
    max_unknown_fraction: float = 0.5
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    windows: TrajectoryWindowConfig = field(default_factory=TrajectoryWindowConfig)

    def __post_init__(self) -> None:
        require_choice("kind", self.kind, ("trajectory", "direct"))
        for name in ("seed",):
            require_int(name, getattr(self, name), minimum=0)
        for name in ("batch_size", "max_epochs", "patience", "direct_horizon", "val_max_frames", "online_frame_stride",
                     "extra_frame_stride"):
            require_int(name, getattr(self, name), minimum=1)
        require_int("threads", self.threads, minimum=0)
        require_int("detect_ignore_before_success", self.detect_ignore_before_success, minimum=0)
        for name in ("extra_data", "online_data"):  # YAML gives a list
            object.__setattr__(self, name, tuple(str(p) for p in getattr(self, name)))
        if self.epoch_samples is not None:
            require_int("epoch_samples", self.epoch_samples, minimum=self.batch_size)
        for name in ("global_t0_frac", "recovery_frac"):
            if not 0 <= getattr(self, name) <= 1:
                raise ConfigError(f"{name} must be in [0, 1], got {getattr(self, name)}")
        require_int("stage1_epochs", self.stage1_epochs, minimum=0)
        for name in ("lr", "max_minutes"):
            require_positive(name, getattr(self, name))
        for name in ("weight_decay", "heatmap_ce"):
            require_nonnegative(name, getattr(self, name))
        if not 0 <= self.max_unknown_fraction < 1:
            raise ConfigError(f"max_unknown_fraction must be in [0, 1), got {self.max_unknown_fraction}")
        if not str(self.out).endswith(".safetensors"):
            raise ConfigError(f"out must end in .safetensors, got {self.out!r}")
        if self.kind == "direct" and self.model.kind != "direct":
            object.__setattr__(self, "model", dataclasses.replace(self.model, kind="direct"))
        if self.kind == "trajectory" and self.model.kind != "trajectory":
            raise ConfigError("model.kind must be 'trajectory' when kind is 'trajectory'")


# --- batches --------------------------------------------------------------------------------------------

def steps_to_success(frames) -> np.ndarray:
    """(N,) steps from each frame to its episode's first success frame (<= 0 from then on; a large number in
    episodes that never succeed)."""
    succ = frames.success.numpy() > 0.5
    first = np.full(len(frames.demos), np.iinfo(np.int32).max, dtype=np.int64)
    np.minimum.at(first, frames.demo[succ], frames.t[succ])
    return first[frames.demo] - frames.t


class Batcher:
    """Draws mixed-mode batches with augmentation; deterministic given its numpy Generator."""

    def __init__(self, frames, cfg: TrainConfig, rng: np.random.Generator):
        import torch

        self.f, self.cfg, self.rng, self.torch = frames, cfg, rng, torch
        succ = frames.success.numpy() > 0.5
        self.pos_idx = np.flatnonzero(succ)
        self.neg_idx = np.flatnonzero(~succ & (steps_to_success(frames) > cfg.detect_ignore_before_success))
        self.traj_idx = np.flatnonzero(frames.traj)  # global / local samples imitate these frames only
        self.t0_idx = np.flatnonzero((frames.t == 0) & frames.traj)
        self.recovery_idx = np.flatnonzero(frames.traj & frames.online)

    def indices(self, n: int, mix: MixConfig) -> tuple[np.ndarray, np.ndarray]:
        rng = self.rng
        modes = rng.choice(3, size=n, p=mix.as_array())
        idx = self.traj_idx[rng.integers(0, len(self.traj_idx), size=n)]
        glob = np.flatnonzero(modes == MODE_IDS["global"])
        if glob.size and self.cfg.global_t0_frac > 0 and self.cfg.kind == "trajectory":  # the frames closed-loop global plans are made from
            at0 = glob[rng.random(glob.size) < self.cfg.global_t0_frac]
            idx[at0] = rng.choice(self.t0_idx, size=at0.size)
        loc = np.flatnonzero(modes == MODE_IDS["local"])
        if loc.size and self.recovery_idx.size and self.cfg.recovery_frac > 0:
            rec = loc[rng.random(loc.size) < self.cfg.recovery_frac]
            idx[rec] = rng.choice(self.recovery_idx, size=rec.size)
        det = np.flatnonzero(modes == MODE_IDS["detect"])
        if det.size and self.pos_idx.size and self.neg_idx.size:  # detect: balanced success / not yet
            pos = rng.random(det.size) < 0.5
            idx[det[pos]] = rng.choice(self.pos_idx, size=int(pos.sum()))
            idx[det[~pos]] = rng.choice(self.neg_idx, size=int((~pos).sum()))
        return idx, modes

    def batch(self, idx: np.ndarray, modes: np.ndarray, *, augment: bool) -> dict:
        torch, f, a = self.torch, self.f, self.cfg.augment
        n = len(idx)
        ti = torch.from_numpy(idx)
        img = f.images[ti].permute(0, 3, 1, 2).float().div_(255.0)  # NCHW view of NHWC = channels_last
        shift = np.zeros((n, 2), np.float32)
        tokens = f.tokens[ti].clone()
        if augment:
            s = a.shift_px
            if s > 0:
                shift = self.rng.integers(-s, s + 1, size=(n, 2)).astype(np.float32)
                img = _shift_images(img, shift.astype(int), s)
            if a.brightness > 0 or a.colour > 0:
                gain = (1 + self.rng.uniform(-a.brightness, a.brightness, size=(n, 1, 1, 1))
                        * np.ones((1, 3, 1, 1))) * (1 + self.rng.uniform(-a.colour, a.colour, size=(n, 3, 1, 1)))
                img = (img * torch.from_numpy(gain.astype(np.float32))).clamp_(0, 1)
            if a.word_dropout > 0:
                drop = torch.from_numpy(self.rng.random(tokens.shape) < a.word_dropout) & (tokens > 0)
                tokens[drop] = 1
        img = img.contiguous(memory_format=torch.channels_last)
        sh = torch.from_numpy(shift)
        return {
            "image": img, "tokens": tokens, "mode": torch.from_numpy(modes.astype(np.int64)),
            "proprio": f.proprio[ti],
            "uv": torch.cat([f.g_uv[ti], f.l_uv[ti]], dim=1) + sh[:, None, :],
            "z": torch.cat([f.g_z[ti], f.l_z[ti]], dim=1),
            "grip": torch.cat([f.g_grip[ti], f.l_grip[ti]], dim=1),
            "success": f.success[ti], "d_delta": f.d_delta[ti], "d_grip": f.d_grip[ti],
        }


def _shift_images(img, shift: np.ndarray, s: int):
    """Translate each image by (dx, dy) whole pixels (content moves right/down), edges replicated."""
    import torch.nn.functional as F

    n, _, h, w = img.shape
    pad = F.pad(img, (s, s, s, s), mode="replicate")
    out = img.new_empty(img.shape)
    for i in range(n):
        dx, dy = int(shift[i, 0]), int(shift[i, 1])
        out[i] = pad[i, :, s - dy:s - dy + h, s - dx:s - dx + w]
    return out


# --- losses ---------------------------------------------------------------------------------------------

def trajectory_loss(out: dict, b: dict, n_global: int, *, heatmap_ce: float = 0.0, image_px: int = 128) -> tuple:
    """Per-sample loss for the sample's own mode; returns (loss, parts dict)."""
    import torch
    import torch.nn.functional as F

    mode = b["mode"]
    n = out["grip_logit"].shape[1]
    wmask = torch.zeros(len(mode), n)
    wmask[mode == 0, :n_global] = 1.0 / n_global
    wmask[mode == 1, n_global:] = 1.0 / (n - n_global)
    traj = (mode <= 1).float()
    px = F.smooth_l1_loss(out["uv_px"], b["uv"], reduction="none", beta=1.0).sum(-1)  # [px]
    zc = F.smooth_l1_loss(out["z_m"] / 0.01, b["z"] / 0.01, reduction="none", beta=1.0)  # [cm]
    gr = F.binary_cross_entropy_with_logits(out["grip_logit"], b["grip"], reduction="none")
    l_px, l_z, l_gr = (px * wmask).sum(1), (zc * wmask).sum(1), (gr * wmask).sum(1)
    det = (mode == 2).float()
    l_det = F.binary_cross_entropy_with_logits(out["success_logit"], b["success"], reduction="none") * det
    total = l_px + l_z + l_gr + l_det
    parts = {"px": l_px.sum() / traj.sum().clamp_min(1), "z_cm": l_z.sum() / traj.sum().clamp_min(1),
             "grip": l_gr.sum() / traj.sum().clamp_min(1), "detect": l_det.sum() / det.sum().clamp_min(1)}
    if heatmap_ce > 0 and "heat_logits" in out:
        logits = out["heat_logits"]
        bsz, k, h, w = logits.shape
        s = image_px / w
        cu = (torch.arange(w) + 0.5) * s - 0.5
        cv = (torch.arange(h) + 0.5) * s - 0.5
        du = (cu[None, None, :] - b["uv"][..., 0:1]) / s
        dv = (cv[None, None, :] - b["uv"][..., 1:2]) / s
        g = torch.exp(-0.5 * (dv[..., :, None] ** 2 + du[..., None, :] ** 2))
        g = g / g.sum((-1, -2), keepdim=True).clamp_min(1e-8)
        ce = -(g * torch.log_softmax(logits.flatten(2), -1).view_as(g)).sum((-1, -2))
        l_ce = (ce * wmask).sum(1)
        total = total + heatmap_ce * l_ce
        parts["heat_ce"] = l_ce.sum() / traj.sum().clamp_min(1)
    return total.mean(), parts


def direct_loss(out: dict, b: dict) -> tuple:
    import torch.nn.functional as F

    d = F.smooth_l1_loss(out["delta_m"] / 0.01, b["d_delta"] / 0.01, reduction="none", beta=1.0).sum(-1)  # [cm]
    g = F.binary_cross_entropy_with_logits(out["grip_logit"][:, 0], b["d_grip"], reduction="none")
    return (d + g).mean(), {"delta_cm": d.mean(), "grip": g.mean()}


# --- validation -----------------------------------------------------------------------------------------

def val_indices(frames, max_frames: int) -> np.ndarray:
    """Every k-th frame plus every t = 0 frame (what a global plan sees in closed loop)."""
    n = len(frames)
    k = max(1, math.ceil(n / max_frames))
    return np.union1d(np.arange(0, n, k), np.flatnonzero(frames.t == 0))


def predict(model, frames, idx: np.ndarray, mode: str, *, batch: int = 256) -> dict:
    """Model outputs for frames ``idx`` in ``mode`` (no augmentation), as numpy arrays."""
    import torch

    outs: dict[str, list] = {}
    model.eval()
    with torch.inference_mode():
        for s in range(0, len(idx), batch):
            ti = torch.from_numpy(idx[s:s + batch])
            img = frames.images[ti].permute(0, 3, 1, 2).float().div_(255.0).contiguous(memory_format=torch.channels_last)
            m = torch.full((len(ti),), MODE_IDS.get(mode, 0), dtype=torch.long)
            o = model(img, frames.tokens[ti], m, frames.proprio[ti], waypoints=mode != "detect")
            for k, v in o.items():
                if k != "heat_logits":
                    outs.setdefault(k, []).append(v.float().numpy())
    return {k: np.concatenate(v) for k, v in outs.items()}


def lift_points(camera, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
    """World points [m] of pixels ``uv`` (..., 2) at heights ``z`` (...) (ray ∩ plane z); NaN where impossible."""
    shape = uv.shape[:-1]
    uv2, z1 = uv.reshape(-1, 2).astype(float), z.reshape(-1).astype(float)
    rays = np.c_[uv2, np.ones(len(uv2))] @ np.linalg.inv(camera.K).T @ camera.T_world_cam[:3, :3].T
    c = camera.T_world_cam[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = (z1 - c[2]) / rays[:, 2]
    depth[~(depth > 0)] = np.nan
    return (c + rays * depth[:, None]).reshape(*shape, 3)


def auroc(scores: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve (rank statistic); NaN when only one class is present."""
    pos, neg = scores[labels > 0.5], scores[labels <= 0.5]
    if not len(pos) or not len(neg):
        return float("nan")
    order = np.argsort(np.concatenate([pos, neg]), kind="mergesort")
    ranks = np.empty(len(order))
    ranks[order] = np.arange(1, len(order) + 1)
    # average ranks of ties
    allv = np.concatenate([pos, neg])
    _, inv, counts = np.unique(allv, return_inverse=True, return_counts=True)
    sums = np.bincount(inv, weights=ranks)
    ranks = (sums / counts)[inv]
    return float((ranks[: len(pos)].sum() - len(pos) * (len(pos) + 1) / 2) / (len(pos) * len(neg)))


def _stats(prefix: str, err: np.ndarray, scale: float = 1.0) -> dict:
    e = err[np.isfinite(err)] * scale
    if not e.size:
        return {f"{prefix}_median": float("nan"), f"{prefix}_p90": float("nan")}
    return {f"{prefix}_median": round(float(np.median(e)), 4), f"{prefix}_p90": round(float(np.percentile(e, 90)), 4)}


def trajectory_metrics(model, frames, idx: np.ndarray, camera, *, n_global: int, center: int) -> dict:
    """Held-out figures: pixel / 3D error, gripper accuracy (executed points: global k >= 0, all local),
    at all steps and at t = 0, plus success-detection AUROC."""
    all_idx, idx = idx, idx[frames.traj[idx]]  # trajectory figures on imitated frames, detection on all
    g = predict(model, frames, idx, "global")
    lo = predict(model, frames, idx, "local")
    ti = idx
    out: dict = {"frames": int(len(idx)), "detect_frames": int(len(all_idx))}
    sel_g = slice(center, n_global)
    for name, o, uv_t, z_t, gr_t, xyz_t, sl in (
            ("global", g, frames.g_uv, frames.g_z, frames.g_grip, frames.g_xyz, sel_g),
            ("local", lo, frames.l_uv, frames.l_z, frames.l_grip, frames.l_xyz, slice(n_global, None))):
        uv = o["uv_px"][:, sl]
        z = o["z_m"][:, sl]
        grip = o["grip_logit"][:, sl] > 0
        if name == "global":
            uvt, zt, grt, xyzt = (a[ti][:, center:].numpy() for a in (uv_t, z_t, gr_t, xyz_t))
        else:
            uvt, zt, grt, xyzt = (a[ti].numpy() for a in (uv_t, z_t, gr_t, xyz_t))
        px = np.linalg.norm(uv - uvt, axis=-1)
        e3 = np.linalg.norm(lift_points(camera, uv, z) - xyzt, axis=-1)
        out.update(_stats(f"{name}_px", px))
        out.update(_stats(f"{name}_3d_cm", e3, 100.0))
        out.update(_stats(f"{name}_z_cm", np.abs(z - zt), 100.0))
        out[f"{name}_grip_acc"] = round(float((grip == (grt > 0.5)).mean()), 4)
        if name == "global":
            t0 = frames.t[ti] == 0
            out.update(_stats("global_t0_px", px[t0]))
            out.update(_stats("global_t0_3d_cm", e3[t0], 100.0))
            out["global_t0_grip_acc"] = round(float((grip[t0] == (grt[t0] > 0.5)).mean()), 4)
            flips = np.diff(grt[t0] > 0.5, axis=1).any(1)
            pf = np.argmax(np.diff(grip[t0].astype(int), axis=1) != 0, axis=1)
            tf = np.argmax(np.diff((grt[t0] > 0.5).astype(int), axis=1) != 0, axis=1)
            out["global_t0_first_flip_exact"] = round(float((pf == tf)[flips].mean()), 4) if flips.any() else float("nan")
    pooled = np.concatenate([np.linalg.norm(g["uv_px"][:, sel_g] - frames.g_uv[ti][:, center:].numpy(), axis=-1).ravel(),
                             np.linalg.norm(lo["uv_px"][:, n_global:] - frames.l_uv[ti].numpy(), axis=-1).ravel()])
    out.update(_stats("px", pooled))
    d = predict(model, frames, all_idx, "detect")
    p = 1 / (1 + np.exp(-d["success_logit"]))
    y = frames.success[all_idx].numpy()
    out["success_auroc"] = round(auroc(p, y), 4)
    out["success_acc"] = round(float(((p > 0.5) == (y > 0.5)).mean()), 4)
    return out


def direct_metrics(model, frames, idx: np.ndarray) -> dict:
    o = predict(model, frames, idx, "global")
    err = np.linalg.norm(o["delta_m"] - frames.d_delta[idx].numpy(), axis=-1)
    out = {"frames": int(len(idx))}
    out.update(_stats("delta_cm", err, 100.0))
    out["grip_acc"] = round(float(((o["grip_logit"][:, 0] > 0) == (frames.d_grip[idx].numpy() > 0.5)).mean()), 4)
    base = np.linalg.norm(frames.d_delta[idx].numpy(), axis=-1)
    out.update(_stats("zero_delta_cm", base, 100.0))
    return out


# --- training -------------------------------------------------------------------------------------------

@dataclass
class TrainResult:
    checkpoint: Path
    metrics: dict
    epochs: int
    wall_s: float


def train(cfg: TrainConfig, *, progress: bool = True, log=print) -> TrainResult:
    """Train per ``cfg``; writes the best-on-validation checkpoint to ``cfg.out``; returns its metrics."""
    import torch
    from tqdm import tqdm

    from tcot_hybrid.learning.checkpoint import camera_meta, save_checkpoint, versions
    from tcot_hybrid.learning.data import concat_frames, env_of, file_hash, instructions_of, load_frames, load_online_frames
    from tcot_hybrid.learning.model import PlannerNet, count_parameters
    from tcot_hybrid.learning.vocab import Vocabulary

    t_start = time.perf_counter()
    torch.set_num_threads(cfg.threads or 2)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    env, camera, dof = env_of(cfg.data)
    vocab = Vocabulary.build(instructions_of(cfg.data, "train"))
    mcfg = dataclasses.replace(cfg.model, vocab_size=len(vocab), dof=dof, n_global=cfg.windows.L_g,
                               n_local=cfg.windows.L_l + 1, image_px=int(env["height"]))
    if int(env["height"]) != int(env["width"]):
        raise ConfigError(f"planner images must be square, data has {env['width']}x{env['height']}")
    load = dict(windows=cfg.windows, max_tokens=mcfg.max_tokens, direct_horizon=cfg.direct_horizon)
    tr = load_frames(cfg.data, "train", vocab, max_demos=cfg.max_train_demos, **load)
    va = load_frames(cfg.data, "valid", vocab, **load)
    log(f"data {cfg.data}: {len(tr.demos)} train demos / {len(tr)} frames, {len(va.demos)} valid demos / "
        f"{len(va)} frames; vocabulary {len(vocab)} words; loaded in {time.perf_counter() - t_start:.1f}s")
    data_files = [cfg.data, *cfg.extra_data, *cfg.online_data]
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
        on_tr, on_va = (load_online_frames(path, split, vocab, frame_stride=cfg.online_frame_stride, **load)
                        for split in ("train", "valid"))
        log(f"online data {path}: {len(on_tr.demos)} train episodes / {len(on_tr)} frames "
            f"({int(on_tr.traj.sum())} with recovery trajectories, {int(on_tr.success.sum())} success), "
            f"{len(on_va.demos)} valid episodes / {len(on_va)} frames")
        trs.append(on_tr)
        vas.append(on_va)
    tr, va = concat_frames(trs), concat_frames(vas)
    del trs, vas
    model = PlannerNet(mcfg)
    if cfg.init is not None:
        _load_init(model, cfg.init, vocab, log)
    else:
        model.proprio_mean.copy_(tr.proprio.mean(0))
        model.proprio_std.copy_(tr.proprio.std(0).clamp_min(1e-3))
    model = model.to(memory_format=torch.channels_last)
    log(f"model {mcfg.kind}/{mcfg.head}: {count_parameters(model) / 1e6:.2f} M parameters")
    steps_per_epoch = math.ceil((cfg.epoch_samples or len(tr)) / cfg.batch_size)
    total_steps = steps_per_epoch * cfg.max_epochs
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=total_steps, pct_start=0.15)
    batcher = Batcher(tr, cfg, rng)
    vidx = val_indices(va, cfg.val_max_frames)
    out = Path(cfg.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    log_path = out.with_suffix(".metrics.jsonl")
    log_path.write_text("")
    best_score, best_state, best_metrics, best_epoch, bad_epochs = math.inf, None, {}, -1, 0
    data_hash = "+".join(file_hash(p) for p in data_files)
    epoch = 0
    for epoch in range(1, cfg.max_epochs + 1):
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
            with torch.autocast("cpu", dtype=torch.bfloat16, enabled=cfg.bf16):
                o = model(b["image"], b["tokens"], b["mode"], b["proprio"])
            if mcfg.kind == "direct":
                loss, parts = direct_loss(o, b)
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
            m = trajectory_metrics(model, va, vidx, camera, n_global=mcfg.n_global, center=cfg.windows.global_center)
            score = m["px_median"] + 0.5 * m["global_t0_px_median"]
            if epoch > cfg.stage1_epochs and math.isfinite(m["success_auroc"]):
                score += DETECT_SCORE_PX * (1.0 - m["success_auroc"])
        rec = {"epoch": epoch, "stage": 1 if epoch <= cfg.stage1_epochs or mcfg.kind == "direct" else 2,
               "train": {k: round(v / steps_per_epoch, 5) for k, v in sums.items()},
               "val": m, "score": round(score, 4), "lr": sched.get_last_lr()[0],
               "epoch_train_s": round(train_s, 1), "elapsed_s": round(time.perf_counter() - t_start, 1),
               "threads": torch.get_num_threads()}
        with open(log_path, "a") as fh:
            fh.write(json.dumps(rec) + "\n")
        log(_epoch_line(rec, mcfg.kind))
        if score < best_score:
            best_score, best_epoch, best_metrics, bad_epochs = score, epoch, m, 0
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        else:
            bad_epochs += 1
        if bad_epochs >= cfg.patience:
            log(f"early stop: no better validation score for {cfg.patience} epochs (best epoch {best_epoch})")
            break
        if (time.perf_counter() - t_start) / 60 >= cfg.max_minutes:
            log(f"time cap: {cfg.max_minutes} min reached after epoch {epoch} (best epoch {best_epoch})")
            break
    model.load_state_dict(best_state)
    model = model.to(memory_format=torch.contiguous_format).eval()
    meta = {
        "robot": env["robot"], "camera": camera_meta(camera), "vocabulary": list(vocab.tokens),
        "windows": dataclasses.asdict(cfg.windows), "direct_horizon": cfg.direct_horizon,
        "max_unknown_fraction": cfg.max_unknown_fraction,
        "data_hash": data_hash, "data_file": str(cfg.data), "extra_data": list(cfg.extra_data),
        "online_data": list(cfg.online_data),
        "init": cfg.init, "data_env_config_hash": env.get("config_hash"),
        "train_demos": len(tr.demos), "train_frames": len(tr),
        "metrics": {"best_epoch": best_epoch, **best_metrics}, "train_config": _jsonable(cfg),
        "versions": versions(), "created_unix": int(time.time()),
    }
    save_checkpoint(out, model, meta)
    wall = time.perf_counter() - t_start
    log(f"wrote {out} (best epoch {best_epoch}) in {wall / 60:.1f} min")
    return TrainResult(checkpoint=out, metrics=best_metrics, epochs=epoch, wall_s=wall)


DETECT_SCORE_PX = 5.0  # stage 2 validation score: 1 - AUROC of the detector costs like this many px of error


def _check_same_env(env: dict, other: dict, path: str, data: str) -> None:
    """Extra and online data must come from the same robot, camera and timing as the demonstrations."""
    from tcot_hybrid.data.dataset import env_difference

    diff = env_difference(other, env, ("robot", "camera", "width", "height", "plan_dt"))
    if diff:
        raise ConfigError(f"data file {path!r} has {diff} (the demonstrations {data!r})")


def _load_init(model, path: str, vocab, log) -> None:
    """Copy a checkpoint's weights into ``model`` (fine-tuning); refuses another shape or vocabulary."""
    from tcot_hybrid.learning.checkpoint import load_checkpoint

    ck = load_checkpoint(path, kind=model.cfg.kind)
    if tuple(ck.meta["vocabulary"]) != tuple(vocab.tokens):
        raise ConfigError(f"init checkpoint {path!r} has vocabulary {ck.meta['vocabulary']}, the data gives "
                          f"{list(vocab.tokens)}")
    mine = dataclasses.replace(model.cfg, readout_radius_cells=0)
    theirs = dataclasses.replace(ck.model.cfg, readout_radius_cells=0)
    if mine != theirs:
        raise ConfigError(f"init checkpoint {path!r} has model {theirs}, this run builds {mine}")
    model.load_state_dict(ck.model.state_dict())
    log(f"initialised from {path}")


_PROBE_STEPS = 6  # per thread count, at the start of every epoch (the first step of each is not timed)


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


# --- CLI --------------------------------------------------------------------------------------------------

def load_train_config(path: str | Path) -> TrainConfig:
    """TrainConfig from YAML/TOML/JSON (unknown keys and wrong types name the field; size, alias expansion,
    nesting and duplicate keys bounded as for run configs)."""
    from tcot_hybrid.run_config import from_mapping, read_config_file

    p = Path(path)
    data = read_config_file(p, what="train config")
    try:
        return from_mapping(TrainConfig, data or {})
    except ConfigError as exc:
        raise ConfigError(f"train config {str(p)!r}: {exc}") from exc


@dataclass(frozen=True, kw_only=True)
class TrainCommand:
    """Train the learned planner (or the direct baseline) and write a checkpoint.

    With --collect, first collects demonstrations with the oracle (``tcot collect``) into --cfg.data when
    the file does not exist yet: nothing → usable checkpoint in one command.
    """

    cfg: Annotated[TrainConfig, tyro.conf.arg(name="")] = field(default_factory=TrainConfig)
    config: Path | None = None
    """YAML/TOML/JSON file with TrainConfig fields; command-line flags override it."""
    collect: bool = False
    """Collect the demonstration file first if it is missing."""
    robot: str = "panda"
    """Robot to collect demonstrations with (only with --collect)."""
    episodes_per_task: int = 50
    """Demonstrations per task to collect (only with --collect); seeds 0 .. N-1."""
    workers: int = 2
    """Collection worker processes (only with --collect)."""
    overwrite: bool = False
    """Replace an existing checkpoint at --out (refused without this flag)."""


def check_train_out(out: str | Path, *, overwrite: bool) -> None:
    """Before any training: refuse to replace an existing checkpoint unless asked, and make sure the
    checkpoint's folder can be written (read-only, a file where the folder belongs, disk full)."""
    from tcot_hybrid.errors import OutputError
    from tcot_hybrid.jsonio import check_output_file

    p = Path(out)
    existing = [x for x in (p, p.with_suffix(".json")) if x.exists() or x.is_symlink()]
    if existing and not overwrite:
        raise OutputError(f"--out {str(p)!r}: {', '.join(repr(str(x)) for x in existing)} already exist(s) (a trained "
                          f"checkpoint?); pass --overwrite to replace it, or choose another --out")
    check_output_file(p, what="--out")


def cmd_train(argv: list[str]) -> int:
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--config", type=Path)
    known, _ = pre.parse_known_args(argv)
    base = load_train_config(known.config) if known.config else TrainConfig()
    cmd = tyro.cli(TrainCommand, args=argv, default=TrainCommand(cfg=base, config=known.config), prog="tcot train")
    t0 = time.perf_counter()
    check_train_out(cmd.cfg.out, overwrite=cmd.overwrite)
    data = Path(cmd.cfg.data)
    if cmd.collect and data.exists():
        from tcot_hybrid.learning.data import env_of

        have = env_of(data)[0].get("robot")
        if have != cmd.robot:
            raise ConfigError(f"--collect --robot {cmd.robot}: {str(data)!r} already holds {have!r} demonstrations; "
                              f"pass --data data/demos_{cmd.robot}.hdf5")
    if cmd.collect and not data.exists():
        from tcot_hybrid.data.collect import cmd_collect

        rc = cmd_collect(["--robot", cmd.robot, "--episodes-per-task", str(cmd.episodes_per_task),
                          "--seed-start", "0", "--workers", str(cmd.workers), "--out", str(data)])
        if rc != 0:
            return rc
        print(f"collection took {(time.perf_counter() - t0) / 60:.1f} min")
    elif not data.exists():
        raise ConfigError(f"demonstration file {str(data)!r} does not exist; run `tcot collect --out {data}` "
                          f"or add --collect")
    os.environ.setdefault("OMP_NUM_THREADS", str(cmd.cfg.threads))
    res = train(cmd.cfg)
    print(f"total time {(time.perf_counter() - t0) / 60:.1f} min -> {res.checkpoint}")
    return 0
