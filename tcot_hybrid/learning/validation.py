"""Validation figures of a planner network on held-out frames: pixel / 3D / height errors, gripper accuracy
and success-detection AUROC (trajectory kind), displacement error (direct kind)."""
from __future__ import annotations

import math

import numpy as np

from tcot_hybrid.camera import points_at_height
from tcot_hybrid.learning.model import MODE_IDS
from tcot_hybrid.metrics import auroc, error_stats


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


def _stats(prefix: str, err: np.ndarray, scale: float = 1.0) -> dict:
    s = error_stats(err, scale=scale, digits=4, empty=float("nan"))
    return {f"{prefix}_median": s["median"], f"{prefix}_p90": s["p90"]}


def lift_frames(frames, rows: np.ndarray, uv: np.ndarray, z: np.ndarray, camera=None) -> np.ndarray:
    """(n, K, 3) world points of predicted pixels ``uv`` (n, K, 2) at label-frame heights ``z`` (n, K) of frames
    ``rows``: each frame through its own planner camera and height reference (``camera``: one camera for all,
    for frame sets without per-frame cameras)."""
    z_world = z + frames.z_ref[rows][:, None]
    if camera is not None or not getattr(frames, "cameras", None):
        return points_at_height(camera, uv, z_world)
    out = np.empty((*uv.shape[:-1], 3))
    cam = frames.cam[rows]
    for c in np.unique(cam):
        sel = cam == c
        out[sel] = points_at_height(frames.cameras[c], uv[sel], z_world[sel])
    return out


def rotation_error_deg(rot6_pred: np.ndarray, rot6_true: np.ndarray) -> np.ndarray:
    """Angle [deg] between predicted (made a rotation by Gram-Schmidt) and labelled orientations (both (..., 6)),
    up to the parallel-jaw symmetry: the labelled hand or the same hand turned 180 degrees about its approach
    axis, whichever is nearer (at most 90 degrees of turn about that axis)."""
    from tcot_hybrid.learning.model import rot6_to_matrix

    Rp, Rt = rot6_to_matrix(rot6_pred), rot6_to_matrix(rot6_true)
    cos = (np.einsum("...ij,...ij->...", Rp, Rt) - 1.0) / 2.0
    cos_flip = (np.einsum("...ij,...ij->...", Rp, Rt * np.array([-1.0, -1.0, 1.0])) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(np.maximum(cos, cos_flip), -1.0, 1.0)))


def trajectory_metrics(model, frames, idx: np.ndarray, camera=None, *, n_global: int, center: int) -> dict:
    """Held-out figures: pixel / 3D error, gripper accuracy (executed points: global k >= 0, all local),
    at all steps and at t = 0, orientation error with a rotation head, plus success-detection AUROC. Points are
    lifted through each frame's own camera (``camera`` overrides it for all)."""
    all_idx, idx = idx, idx[frames.traj[idx]]  # trajectory figures on imitated frames, detection on all
    g = predict(model, frames, idx, "global")
    lo = predict(model, frames, idx, "local")
    ti = idx
    out: dict = {"frames": int(len(idx)), "detect_frames": int(len(all_idx))}
    sel_g = slice(center, n_global)
    for name, o, uv_t, z_t, gr_t, xyz_t, rot_t, sl in (
            ("global", g, frames.g_uv, frames.g_z, frames.g_grip, frames.g_xyz, frames.g_rot, sel_g),
            ("local", lo, frames.l_uv, frames.l_z, frames.l_grip, frames.l_xyz, frames.l_rot, slice(n_global, None))):
        uv = o["uv_px"][:, sl]
        z = o["z_m"][:, sl]
        grip = o["grip_logit"][:, sl] > 0
        if name == "global":
            uvt, zt, grt, xyzt, rott = (a[ti][:, center:].numpy() for a in (uv_t, z_t, gr_t, xyz_t, rot_t))
        else:
            uvt, zt, grt, xyzt, rott = (a[ti].numpy() for a in (uv_t, z_t, gr_t, xyz_t, rot_t))
        px = np.linalg.norm(uv - uvt, axis=-1)
        e3 = np.linalg.norm(lift_frames(frames, ti, uv, z, camera) - xyzt, axis=-1)
        if "rot6" in o:
            out.update(_stats(f"{name}_rot_deg", rotation_error_deg(o["rot6"][:, sl], rott)))
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
    a = auroc(p, y)
    out["success_auroc"] = round(a, 4) if a is not None else float("nan")
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
