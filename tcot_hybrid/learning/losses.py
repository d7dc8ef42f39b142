"""Training losses: the TCoT planner's per-mode trajectory / detection loss and the direct baseline's loss."""
from __future__ import annotations


ROT_UNIT = 0.1  # orientation loss unit: a 0.1 rad turn costs about as much as 1-2 px of waypoint error


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
    if "rot6" in out:  # orientation: the two columns' error in units of ROT_UNIT (~ that many rad of turn)
        # parallel-jaw symmetry: the hand turned 180 degrees about its approach axis (x, y columns negated) is the
        # same grasp, so the label is whichever of the two is nearer (no averaging of two equivalent answers)
        pred, lab = out["rot6"] / ROT_UNIT, b["rot"] / ROT_UNIT
        ro = torch.minimum(F.smooth_l1_loss(pred, lab, reduction="none", beta=1.0).sum(-1),
                           F.smooth_l1_loss(pred, -lab, reduction="none", beta=1.0).sum(-1))
        l_rot = (ro * wmask).sum(1)
        total = total + l_rot
        parts["rot"] = l_rot.sum() / traj.sum().clamp_min(1)
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


def detect_loss(out: dict, b: dict) -> tuple:
    """Failure-detection loss alone (every sample a detect prompt; ``trainable: detect``)."""
    import torch.nn.functional as F

    l_det = F.binary_cross_entropy_with_logits(out["success_logit"], b["success"])
    return l_det, {"detect": l_det}


def direct_loss(out: dict, b: dict) -> tuple:
    import torch.nn.functional as F

    d = F.smooth_l1_loss(out["delta_m"] / 0.01, b["d_delta"] / 0.01, reduction="none", beta=1.0).sum(-1)  # [cm]
    g = F.binary_cross_entropy_with_logits(out["grip_logit"][:, 0], b["d_grip"], reduction="none")
    return (d + g).mean(), {"delta_cm": d.mean(), "grip": g.mean()}
