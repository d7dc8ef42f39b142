"""Training batches: mixed-mode sample indices (global / local / detect, per the batch mix) and augmentation."""
from __future__ import annotations

import numpy as np

from tcot_hybrid.learning.model import MODE_IDS
from tcot_hybrid.learning.train_config import MixConfig, TrainConfig


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
            "rot": torch.cat([f.g_rot[ti], f.l_rot[ti]], dim=1),
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
