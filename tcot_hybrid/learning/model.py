"""The planner network: one CNN conditioned on a mode prompt, the instruction and the robot state.

Inputs
  image      (B, 3, H, W) float in [0, 1], the planner camera's RGB (H = W = ``image_px``)
  tokens     (B, max_tokens) int64 instruction word ids (0 = padding), see :mod:`tcot_hybrid.learning.vocab`
  mode       (B,) int64: 0 = global, 1 = local, 2 = detect (paper's prompts l_g, l_l, l_f)
  proprio    (B, dof + 1) float: arm joint positions [rad] and the gripper command (1 = closed)

Trajectory model (``kind="trajectory"``) outputs, for every mode's head at once (the caller picks):
  uv_px      (B, n_global + n_local, 2) waypoint pixels [px], soft-argmax of per-waypoint heatmaps
  z_m        (B, n_global + n_local) TCP height above the table per waypoint [m], read out of a
             per-waypoint height map weighted by the same softmax (spatial read-out)
  grip_logit (B, n_global + n_local) gripper-closed logit per waypoint (from pooled features)
  success_logit (B,) task-success logit (detect mode; from pooled features)
  rot6       (B, n_global + n_local, 6) with ``rot_head``: the TCP orientation per waypoint in the planner
             camera's frame (OpenCV: x right, y down, z forward) as its first two columns (x then y axis; the
             "6D" rotation form), read out of six per-waypoint maps with the same softmax as z_m;
             :func:`rot6_to_matrix` makes it a rotation (Gram-Schmidt)
The first ``n_global`` waypoints belong to the global head, the next ``n_local`` to the local head.

Direct model (``kind="direct"``, the paper's no-trajectory baseline) outputs
  delta_m    (B, 3) TCP displacement over the next ``direct_horizon`` planner steps [m, world]
  grip_logit (B, 1) gripper-closed logit at the end of that horizon

Conditioning is FiLM: instruction (mean of word embeddings), mode and proprio embeddings are mixed
by a small MLP into one vector that scales and shifts every residual block's features.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from tcot_hybrid.config import require_choice, require_int, require_positive

MODE_IDS = {"global": 0, "local": 1, "detect": 2}
HEADS = ("heatmap", "fc")
KINDS = ("trajectory", "direct")


@dataclass(frozen=True, kw_only=True)
class ModelConfig:
    """Network shape. Stored in every checkpoint's metadata; loading rebuilds exactly this network.

    kind:        "trajectory" (TCoT planner: waypoints + detect) or "direct" (next-action baseline).
    head:        "heatmap" (per-waypoint heatmaps + soft-argmax, spatial height read-out) or "fc"
                 (flatten + fully connected regression; kept only for the head comparison).
    image_px:    square input image size [px]; must match the planner camera's image.
    width:       channels of the 1/4-resolution stage; the 1/8 and 1/16 stages use 2x and 3x. Up: more
                 accurate, slower (compute grows ~ width^2). Heatmaps are image_px / 4 on a side.
    n_global:    global waypoints L_g; n_local: local waypoints L_l + 1 (from the label windows).
    dof:         arm joints in the proprio input.
    vocab_size:  instruction vocabulary size including <pad> and <unk>.
    max_tokens:  instruction length after padding/truncation [words].
    embed_dim:   word / mode embedding size; cond_dim: FiLM conditioning vector size.
    coord_channels: append normalised x/y coordinate channels to the image (helps localisation).
    readout_radius_cells: 0 = soft-argmax over the whole heatmap; r > 0 = at inference only, soft-argmax
                 over the (2r+1)^2 cells around the peak (picks one mode of a multi-modal heatmap instead of
                 averaging modes, which cuts corners of the path). Training always uses the full map.
    z_offset_m, z_scale_m: height read-out is z_offset_m + z_scale_m * map value [m] (its reference, world z or
                 the camera's height, is the checkpoint's ``height_ref``).
    rot_head:    also predict a TCP orientation per waypoint (``rot6``; LIBERO's tilted and turned grasps); heatmap
                 head only. False = top-down plans (the workcell).
    delta_scale_m: direct model: predicted delta is delta_scale_m * raw output [m].
    detect_head: trajectory model: the success logit comes from its own head (pooled -> 128 -> 1) instead of
                 the last output of the head it shares with the gripper bits. Nothing else reads that head or
                 the detect prompt's mode embedding, so the detector can be fine-tuned alone (``tcot train``
                 ``trainable: detect``) while every waypoint output stays bit-identical.
    """

    kind: str = "trajectory"
    head: str = "heatmap"
    image_px: int = 128
    width: int = 32
    n_global: int = 51
    n_local: int = 9
    dof: int = 7
    vocab_size: int = 2
    max_tokens: int = 24
    embed_dim: int = 32
    cond_dim: int = 64
    coord_channels: bool = True
    readout_radius_cells: int = 0
    z_offset_m: float = 0.15
    z_scale_m: float = 0.10
    delta_scale_m: float = 0.05
    rot_head: bool = False
    detect_head: bool = False

    def __post_init__(self) -> None:
        require_choice("model.kind", self.kind, KINDS)
        require_choice("model.head", self.head, HEADS)
        for name in ("image_px", "width", "n_global", "n_local", "dof", "vocab_size", "max_tokens",
                     "embed_dim", "cond_dim"):
            require_int(f"model.{name}", getattr(self, name), minimum=1)
        if self.image_px % 16:
            from tcot_hybrid.errors import ConfigError

            raise ConfigError(f"model.image_px must be a multiple of 16, got {self.image_px}")
        if self.vocab_size < 2:
            from tcot_hybrid.errors import ConfigError

            raise ConfigError(f"model.vocab_size must be >= 2 (<pad>, <unk>), got {self.vocab_size}")
        require_int("model.readout_radius_cells", self.readout_radius_cells, minimum=0)
        for name in ("z_scale_m", "delta_scale_m"):
            require_positive(f"model.{name}", getattr(self, name))
        if self.rot_head and (self.head != "heatmap" or self.kind != "trajectory"):
            from tcot_hybrid.errors import ConfigError

            raise ConfigError(f"model.rot_head needs kind 'trajectory' and head 'heatmap', got kind {self.kind!r}, "
                              f"head {self.head!r}")
        if self.detect_head and self.kind != "trajectory":
            from tcot_hybrid.errors import ConfigError

            raise ConfigError(f"model.detect_head needs model.kind 'trajectory' (the direct model has no detector), "
                              f"got kind {self.kind!r}")

    @property
    def n_waypoints(self) -> int:
        return self.n_global + self.n_local


def _conv(cin: int, cout: int, k: int = 3, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, k, stride=stride, padding=(k - 1) // 2 if stride == 1 or k == 3 else 0)


class FiLM(nn.Module):
    """Scale and shift of a feature map from the conditioning vector (identity at initialisation)."""

    def __init__(self, ch: int, cond_dim: int):
        super().__init__()
        self.lin = nn.Linear(cond_dim, 2 * ch)
        nn.init.zeros_(self.lin.weight)
        nn.init.zeros_(self.lin.bias)

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        gamma, beta = self.lin(cond).chunk(2, dim=1)
        return x * (1 + gamma[:, :, None, None].to(x.dtype)) + beta[:, :, None, None].to(x.dtype)


class FiLMBlock(nn.Module):
    """Residual block (two 3x3 convs) whose features are scaled/shifted by the conditioning vector.

    No batch norm: measured ~30 % of a training step on CPU, and the zero-initialised second conv
    keeps every block an identity at the start, which trains stably without it.
    """

    def __init__(self, ch: int, cond_dim: int):
        super().__init__()
        self.c1, self.c2 = _conv(ch, ch), _conv(ch, ch)
        nn.init.zeros_(self.c2.weight)
        nn.init.zeros_(self.c2.bias)
        self.film = FiLM(ch, cond_dim)

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        h = self.film(F.relu(self.c1(x)), cond)
        return F.relu(x + self.c2(h))


def spatial_keypoints(f: torch.Tensor) -> torch.Tensor:
    """Per channel expected (x, y) in [-1, 1] under a softmax over the map (robomimic-style keypoints)."""
    b, c, h, w = f.shape
    p = torch.softmax(f.float().flatten(2), dim=-1).view(b, c, h, w)
    ys = torch.linspace(-1, 1, h, device=f.device)
    xs = torch.linspace(-1, 1, w, device=f.device)
    return torch.cat([(p.sum(2) * xs).sum(-1), (p.sum(3) * ys).sum(-1)], dim=1)


def window_readout(prob: torch.Tensor, values: torch.Tensor, h: int, w: int, r: int):
    """Soft-argmax restricted to the (2r+1)^2 cells around each map's peak (cells off the map left out).

    prob, values: (B, n, h*w) softmax probabilities and per-cell values. Returns (u, v, value) per map,
    u/v in cells (cell centres at 0, 1, ...). Gathers the window's cells instead of masking the whole map:
    ~25 cells per map instead of h*w, which matters for batch-1 latency.
    """
    peak = prob.argmax(-1)  # (B, n)
    offs = torch.arange(-r, r + 1, device=prob.device)
    vv = (peak // w)[..., None, None] + offs[:, None]  # (B, n, k, 1)
    uu = (peak % w)[..., None, None] + offs[None, :]  # (B, n, 1, k)
    inside = ((vv >= 0) & (vv < h) & (uu >= 0) & (uu < w)).flatten(2)  # (B, n, k*k)
    cell = (vv.clamp(0, h - 1) * w + uu.clamp(0, w - 1)).flatten(2)
    pw = prob.gather(-1, cell) * inside
    pw = pw / pw.sum(-1, keepdim=True)
    u = (pw * uu.expand(-1, -1, len(offs), -1).flatten(2)).sum(-1)
    v = (pw * vv.expand(-1, -1, -1, len(offs)).flatten(2)).sum(-1)
    return u, v, (pw * values.gather(-1, cell)).sum(-1)


class PlannerNet(nn.Module):
    """U-shaped CNN: 4x4/4 patch stem, FiLM residual stages at 1/4, 1/8, 1/16, decoder back to 1/4.

    The heatmap head reads the 1/4-resolution decoder output (32x32 for 128 px images); soft-argmax
    gives sub-cell pixel coordinates.
    """

    def __init__(self, cfg: ModelConfig):
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        c1, c2, c3 = w, 2 * w, 3 * w
        cin = 3 + (2 if cfg.coord_channels else 0)
        # --- conditioning ---
        self.words = nn.Embedding(cfg.vocab_size, cfg.embed_dim, padding_idx=0)
        self.modes = nn.Embedding(len(MODE_IDS), cfg.embed_dim)
        self.proprio = nn.Sequential(nn.Linear(cfg.dof + 1, cfg.embed_dim), nn.ReLU())
        self.cond = nn.Sequential(nn.Linear(3 * cfg.embed_dim, cfg.cond_dim), nn.ReLU(),
                                  nn.Linear(cfg.cond_dim, cfg.cond_dim), nn.ReLU())
        # proprio normalisation (filled from training data; saved with the weights)
        self.register_buffer("proprio_mean", torch.zeros(cfg.dof + 1))
        self.register_buffer("proprio_std", torch.ones(cfg.dof + 1))
        # --- encoder ---
        self.stem = nn.Conv2d(cin, c1, 4, stride=4)  # 1/4, every pixel seen once (no detail lost)
        self.stem_film = FiLM(c1, cfg.cond_dim)  # early fusion: the instruction shapes features from the start
        self.s4 = FiLMBlock(c1, cfg.cond_dim)
        self.d8, self.s8 = _conv(c1, c2, 3, 2), FiLMBlock(c2, cfg.cond_dim)  # 1/8
        self.d16, self.s16 = _conv(c2, c3, 3, 2), FiLMBlock(c3, cfg.cond_dim)  # 1/16
        self.ctx = nn.Linear(c3 + cfg.cond_dim, c3)  # whole-image context broadcast back into the map
        pooled = 3 * c3 + cfg.cond_dim  # avg pool + spatial-softmax keypoints (x, y) + cond
        if cfg.kind == "direct":
            self.action = nn.Sequential(nn.Linear(pooled, 128), nn.ReLU(), nn.Linear(128, 4))
            return
        n = cfg.n_waypoints
        if cfg.head == "heatmap":
            self.l16, self.u8, self.f8 = nn.Conv2d(c3, c2, 1), _conv(c2, c2), FiLM(c2, cfg.cond_dim)
            self.l8, self.u4, self.f4 = nn.Conv2d(c2, c1, 1), _conv(c1, c1), FiLM(c1, cfg.cond_dim)
            # n heatmaps + n height maps (+ 6n orientation maps)
            self.maps = nn.Conv2d(c1, (8 if cfg.rot_head else 2) * n, 1)
        else:
            side = cfg.image_px // 16
            self.fc = nn.Sequential(nn.Flatten(), nn.Linear(c3 * side * side, 256), nn.ReLU(), nn.Linear(256, 3 * n))
        self.pooled_head = nn.Sequential(nn.Linear(pooled, 128), nn.ReLU(), nn.Linear(128, n + 1))
        if cfg.detect_head:
            self.detect_head = nn.Sequential(nn.Linear(pooled, 128), nn.ReLU(), nn.Linear(128, 1))

    def detect_parameters(self) -> list[tuple[str, nn.Parameter, int | None]]:
        """(name, parameter, row) of every weight only the detect prompt reads: the detect head and the detect
        mode's embedding row (``row``: only that row of the tensor; None: all of it). Training only these
        leaves every global and local output unchanged."""
        if not self.cfg.detect_head:
            from tcot_hybrid.errors import ConfigError

            raise ConfigError("only a model with model.detect_head: true has weights the detector alone reads")
        return [("modes.weight", self.modes.weight, MODE_IDS["detect"]),
                *((f"detect_head.{k}", p, None) for k, p in self.detect_head.named_parameters())]

    def init_detect_head(self) -> None:
        """Copy the shared head's detection path into ``detect_head`` (same outputs as before it existed)."""
        n = self.cfg.n_waypoints
        with torch.no_grad():
            self.detect_head[0].load_state_dict(self.pooled_head[0].state_dict())
            self.detect_head[2].weight.copy_(self.pooled_head[2].weight[n:n + 1])
            self.detect_head[2].bias.copy_(self.pooled_head[2].bias[n:n + 1])

    def load_widened(self, other: "PlannerNet", points_per_segment: int) -> None:
        """Copy ``other``'s weights, which differ from this network's only in ``n_global`` (fewer global
        waypoints), mapping each of this network's waypoints to one of ``other``'s (:func:`widened_source`):
        a warm start for a longer global window on event-spaced labels."""
        src = widened_source(self.cfg.n_global, other.cfg.n_global, self.cfg.n_local, points_per_segment)
        n_new, n_old = self.cfg.n_waypoints, other.cfg.n_waypoints
        theirs = other.state_dict()
        rows_maps = torch.cat([torch.as_tensor(src) + k * n_old for k in range(other.maps.out_channels // n_old)])
        rows_pooled = torch.cat([torch.as_tensor(src), torch.tensor([n_old])])  # + the shared success logit
        state = {}
        for k, v in self.state_dict().items():
            t = theirs[k]
            if k.startswith("maps."):
                t = t[rows_maps]
            elif k.startswith("pooled_head.2."):
                t = t[rows_pooled]
            if t.shape != v.shape:
                raise ValueError(f"{k}: {tuple(t.shape)} does not widen to {tuple(v.shape)} ({n_old} -> {n_new} "
                                 "waypoints)")
            state[k] = t
        self.load_state_dict(state)

    # ------------------------------------------------------------------------------------------------
    def condition(self, tokens: torch.Tensor, mode: torch.Tensor, proprio: torch.Tensor) -> torch.Tensor:
        mask = (tokens > 0).float()
        words = (self.words(tokens) * mask[..., None]).sum(1) / mask.sum(1, keepdim=True).clamp_min(1.0)
        prop = self.proprio((proprio - self.proprio_mean) / self.proprio_std)
        return self.cond(torch.cat([words, self.modes(mode), prop], dim=1))

    def encode(self, image: torch.Tensor, cond: torch.Tensor):
        x = image * 2.0 - 1.0
        if self.cfg.coord_channels:
            b, _, h, w = x.shape
            ys = torch.linspace(-1, 1, h, device=x.device, dtype=x.dtype).view(1, 1, h, 1).expand(b, 1, h, w)
            xs = torch.linspace(-1, 1, w, device=x.device, dtype=x.dtype).view(1, 1, 1, w).expand(b, 1, h, w)
            x = torch.cat([x, xs, ys], dim=1)
        f4 = self.s4(F.relu(self.stem_film(self.stem(x), cond)), cond)
        f8 = self.s8(F.relu(self.d8(f4)), cond)
        f16 = self.s16(F.relu(self.d16(f8)), cond)
        g = f16.float().mean((2, 3))
        f16 = F.relu(f16 + self.ctx(torch.cat([g, cond], dim=1))[:, :, None, None].to(f16.dtype))
        pooled = torch.cat([f16.float().mean((2, 3)), spatial_keypoints(f16), cond.float()], dim=1)
        return f4, f8, f16, pooled

    def forward(self, image, tokens, mode, proprio, *, waypoints: bool | slice = True) -> dict[str, torch.Tensor]:
        """``waypoints=False`` skips the heatmap decoder (the detect prompt needs only the pooled head); a slice of
        the ``n_waypoints`` (heatmap head) computes only those waypoints' maps, and every per-waypoint output then
        covers just them (a planner call needs one head's executed waypoints: a global plan 26 of 60, a local 9)."""
        cfg = self.cfg
        cond = self.condition(tokens, mode, proprio)
        f4, f8, f16, pooled = self.encode(image, cond)
        if cfg.kind == "direct":
            out = self.action(pooled).float()
            return {"delta_m": out[:, :3] * cfg.delta_scale_m, "grip_logit": out[:, 3:4]}
        n_all = cfg.n_waypoints
        sel = waypoints if isinstance(waypoints, slice) else slice(0, n_all)
        if isinstance(waypoints, slice) and cfg.head != "heatmap":
            raise ValueError(f"a waypoint slice needs model.head 'heatmap', got {cfg.head!r}")
        ids = range(n_all)[sel]
        n = len(ids)
        pl = self.pooled_head(pooled).float()
        res = {"grip_logit": pl[:, :n_all][:, sel],
               "success_logit": self.detect_head(pooled).float()[:, 0] if cfg.detect_head else pl[:, n_all]}
        if waypoints is False:
            return res
        if cfg.head == "heatmap":
            x = F.relu(self.f8(self.u8(F.relu(f8 + F.interpolate(self.l16(f16), scale_factor=2, mode="nearest"))), cond))
            x = F.relu(self.f4(self.u4(F.relu(f4 + F.interpolate(self.l8(x), scale_factor=2, mode="nearest"))), cond))
            if n == n_all:
                maps = self.maps(x).float()
            else:  # only the selected waypoints' channels: heatmap, height and (component-major) orientation maps
                rows = torch.as_tensor(list(ids), device=x.device)
                rows = torch.cat([rows + k * n_all for k in range(self.maps.out_channels // n_all)])
                maps = F.conv2d(x, self.maps.weight[rows], self.maps.bias[rows]).float()
            logits, heights = maps[:, :n], maps[:, n:2 * n]
            b, _, h, w = logits.shape
            prob = torch.softmax(logits.flatten(2), dim=-1)  # (B, n, h*w)
            r = cfg.readout_radius_cells
            rot = None
            if cfg.rot_head:  # (B, 6, n, h*w): component-major, so each component reads like the height map
                rot_maps = maps[:, 2 * n:].reshape(b, 6, n, h * w)
            if r > 0 and not self.training:  # mode-seeking read-out: only the cells around the peak
                u, v, z = window_readout(prob, heights.flatten(2), h, w, r)
                if cfg.rot_head:
                    rot = torch.stack([window_readout(prob, rot_maps[:, c], h, w, r)[2] for c in range(6)], -1)
            else:  # expected cell under the whole map
                p2 = prob.view(b, n, h, w)
                u = (p2.sum(2) * torch.arange(w, device=x.device, dtype=torch.float32)).sum(-1)
                v = (p2.sum(3) * torch.arange(h, device=x.device, dtype=torch.float32)).sum(-1)
                z = (prob * heights.flatten(2)).sum(-1)
                if cfg.rot_head:
                    rot = (prob[:, None] * rot_maps).sum(-1).permute(0, 2, 1)  # (B, n, 6)
            if rot is not None:
                res["rot6"] = rot
            s = cfg.image_px / w  # cell c covers pixels c*s .. (c+1)*s: its centre is pixel (c + 0.5) * s - 0.5
            uv = (torch.stack([u, v], dim=-1) + 0.5) * s - 0.5
            res.update(uv_px=uv, z_m=cfg.z_offset_m + cfg.z_scale_m * z, heat_logits=logits)
        else:
            out = self.fc(f16).float().view(-1, n, 3)
            half = cfg.image_px / 2
            res.update(uv_px=half - 0.5 + half * out[..., :2], z_m=cfg.z_offset_m + cfg.z_scale_m * out[..., 2])
        return res


def rot6_to_matrix(r6):
    """(..., 6) first two columns (x axis then y axis) → (..., 3, 3) rotation by Gram-Schmidt (numpy or torch).
    Raises ValueError on a degenerate pair (zero or parallel columns)."""
    import numpy as np

    a = np.asarray(r6, dtype=float)
    x, y = a[..., 0:3], a[..., 3:6]
    nx = np.linalg.norm(x, axis=-1, keepdims=True)
    if not np.isfinite(a).all() or (nx < 1e-6).any():
        raise ValueError("orientation output is not finite or has a zero x column")
    x = x / nx
    y = y - (x * y).sum(-1, keepdims=True) * x
    ny = np.linalg.norm(y, axis=-1, keepdims=True)
    if (ny < 1e-6).any():
        raise ValueError("orientation output has parallel x and y columns")
    y = y / ny
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def matrix_to_rot6(R):
    """(..., 3, 3) rotation → (..., 6): its x column then its y column."""
    import numpy as np

    R = np.asarray(R)
    return np.concatenate([R[..., :, 0], R[..., :, 1]], axis=-1)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def widened_source(n_global: int, n_global_old: int, n_local: int, points_per_segment: int) -> np.ndarray:
    """For each waypoint of a network with ``n_global`` global waypoints, the index of the waypoint of one
    with ``n_global_old`` (< ``n_global``) whose weights start it. Local waypoints map to themselves. A
    global waypoint at offset d from the middle maps to offset d where the old window has it, else to the
    same place in an earlier whole piece of ``points_per_segment`` points (event-spaced windows repeat that
    structure: piece p's i-th point starts from piece p mod m's, m = whole pieces in the old half)."""
    h_new, h_old = n_global // 2, n_global_old // 2
    if n_global <= n_global_old or h_old < points_per_segment:
        raise ValueError(f"widening needs n_global ({n_global}) > n_global_old ({n_global_old}) and at least one "
                         f"whole piece of {points_per_segment} points in the old half ({h_old})")
    period = (h_old // points_per_segment) * points_per_segment
    out = []
    for d in range(-h_new, h_new + 1):
        a = abs(d) if abs(d) <= h_old else (abs(d) - 1) % period + 1
        out.append(h_old + (a if d >= 0 else -a))
    out += [n_global_old + j for j in range(n_local)]
    return np.asarray(out, dtype=np.int64)
