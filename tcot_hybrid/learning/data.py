"""Training frames: every sample of every demo of one split, with its labels, held in memory.

One row per demo sample t (the state at the start of planner step t). Labels per row:
  global window (paper eq. 4) and local window (eq. 5) from the data package's label helpers: pixel,
  TCP height z_m and gripper bit per point, plus the ground-truth 3D TCP point (for the 3D error);
  success (task predicate at t) for detect; direct action (TCP displacement over ``direct_horizon``
  steps and the gripper bit at the end of it) for the direct baseline.
Images stay uint8 (T, H, W, 3); batches are converted on the fly.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from tcot_hybrid.data import open_demos
from tcot_hybrid.data.labels import TrajectoryWindowConfig, global_labels, local_labels, track_from_arrays
from tcot_hybrid.errors import DatasetError
from tcot_hybrid.learning.vocab import Vocabulary

_KEYS = ("obs/robot0_joint_pos", "obs/robot0_eef_pos", "obs/robot0_gripper_closed", "obs/eef_uv_px",
         "task_success")


@dataclass
class FrameSet:
    """All frames of one split. Arrays share the first dimension N (frames)."""

    images: torch.Tensor  # (N, H, W, 3) uint8
    tokens: torch.Tensor  # (N, max_tokens) int64
    proprio: torch.Tensor  # (N, dof + 1) float32: joints [rad] + gripper command
    g_uv: torch.Tensor  # (N, L_g, 2) [px]
    g_z: torch.Tensor  # (N, L_g) [m]
    g_grip: torch.Tensor  # (N, L_g) float 0/1
    g_xyz: torch.Tensor  # (N, L_g, 3) [m] ground-truth TCP points
    l_uv: torch.Tensor
    l_z: torch.Tensor
    l_grip: torch.Tensor
    l_xyz: torch.Tensor
    success: torch.Tensor  # (N,) float 0/1
    d_delta: torch.Tensor  # (N, 3) [m] TCP displacement over direct_horizon steps
    d_grip: torch.Tensor  # (N,) float 0/1 gripper command direct_horizon steps ahead
    demo: np.ndarray  # (N,) demo index into ``demos``
    t: np.ndarray  # (N,) sample index within the demo
    demos: list[str]
    tasks: list[str]
    instructions: list[str]

    def __len__(self) -> int:
        return int(self.images.shape[0])


def file_hash(path: str | Path, *, chunk: int = 1 << 22) -> str:
    """SHA-256 of a data file (first 16 hex digits); recorded in checkpoints."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while b := f.read(chunk):
            h.update(b)
    return h.hexdigest()[:16]


def load_frames(path: str | Path, split: str, vocab: Vocabulary, *, windows: TrajectoryWindowConfig,
                max_tokens: int, direct_horizon: int, max_demos: int | None = None,
                successful_only: bool = True) -> FrameSet:
    """Read split ``train``/``valid`` (or ``all``: both) of demo file ``path`` into memory with every label
    computed. Only successful demos carry trajectory labels worth imitating; ``successful_only`` drops the rest.
    """
    with open_demos(path) as f:
        names = f.mask("train") + f.mask("valid") if split == "all" else f.mask(split)
        infos = [f.info(n) for n in names]
        if successful_only:
            names = [i.name for i in infos if i.success]
        if max_demos is not None:
            names = names[:max_demos]
        if not names:
            raise DatasetError(f"demo file {path}: split {split!r} has no usable demos")
        cols: dict[str, list] = {k: [] for k in ("img", "tok", "prop", "g", "l", "gx", "lx", "succ", "dd", "dg",
                                                 "demo", "t")}
        tasks, instrs = [], []
        for di, name in enumerate(names):
            info = f.info(name)
            arr = f.read(name, _KEYS)
            img = f.images(name)
            T = info.num_samples
            track = track_from_arrays(arr)
            gl, ll = global_labels(track, windows), local_labels(track, windows)
            pos = arr["obs/robot0_eef_pos"].astype(np.float32)
            grip = arr["obs/robot0_gripper_closed"].astype(np.float32)
            ids, _, _ = vocab.encode(info.instruction, max_tokens)
            ahead = np.minimum(np.arange(T) + direct_horizon, T - 1)
            cols["img"].append(img)
            cols["tok"].append(np.repeat(ids[None], T, axis=0))
            cols["prop"].append(np.c_[arr["obs/robot0_joint_pos"], grip].astype(np.float32))
            cols["g"].append((gl.uv_px, gl.z_m, gl.gripper_closed.astype(np.float32)))
            cols["l"].append((ll.uv_px, ll.z_m, ll.gripper_closed.astype(np.float32)))
            cols["gx"].append(pos[gl.indices])
            cols["lx"].append(pos[ll.indices])
            cols["succ"].append(arr["task_success"].astype(np.float32))
            cols["dd"].append(pos[ahead] - pos)
            cols["dg"].append(grip[ahead])
            cols["demo"].append(np.full(T, di))
            cols["t"].append(np.arange(T))
            tasks.append(info.task)
            instrs.append(info.instruction)

    def cat(key, j=None):
        xs = cols[key] if j is None else [c[j] for c in cols[key]]
        return torch.from_numpy(np.ascontiguousarray(np.concatenate(xs, axis=0)))

    return FrameSet(
        images=cat("img"), tokens=cat("tok"), proprio=cat("prop"),
        g_uv=cat("g", 0).float(), g_z=cat("g", 1).float(), g_grip=cat("g", 2), g_xyz=cat("gx"),
        l_uv=cat("l", 0).float(), l_z=cat("l", 1).float(), l_grip=cat("l", 2), l_xyz=cat("lx"),
        success=cat("succ"), d_delta=cat("dd"), d_grip=cat("dg"),
        demo=np.concatenate(cols["demo"]), t=np.concatenate(cols["t"]), demos=names, tasks=tasks,
        instructions=instrs)


def instructions_of(path: str | Path, split: str = "train") -> list[str]:
    with open_demos(path) as f:
        return sorted({f.info(n).instruction for n in f.mask(split)})


def env_of(path: str | Path) -> tuple[dict, object, int]:
    """(env_args, planner CameraModel, dof) of a demo file."""
    with open_demos(path) as f:
        return dict(f.env_args), f.camera_model(), int(f.dof or 0)
