"""RANSAC fit of an uncalibrated 3x4 projection (normalised DLT) from 3D TCP positions to tracked pixels
(step 3 of the vision label path, :mod:`tcot_hybrid.data.vision_labels`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from tcot_hybrid.config import require_choice, require_in_range, require_int, require_positive
from tcot_hybrid.errors import DatasetError

# --- 3. RANSAC fit of an uncalibrated projection ------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class RansacConfig:
    """RANSAC over normalised-DLT 3x4 projections (3D TCP [m] → tracked pixel [px]).

    threshold_px: inlier reprojection error [px]. Down: stricter, needs a more accurate tracker.
    iterations:   random minimal samples (6 points each). Up: more robust to many outliers, slower.
    fit:          "file" = one matrix for every demo of a file (fixed camera, best conditioned);
                  "demo" = one matrix per demo (falls back to "file" when a demo's 3D track is degenerate).
    min_inliers:  fewer inliers than this = no fit (status reported) [-].
    min_inlier_fraction: fewer inliers than this fraction of the tracked points = no fit [-]. Down:
                  accepts fits that explain only a part of the track (a degenerate subset can fit well).
    min_thickness: smallest / largest principal extent of the tracked 3D points below which the track
                  counts as planar ("degenerate": a 3x4 projection is not determined) [-]. Measured: drawer
                  demos at 0.002-0.003 fitted their few visible points but reprojected the rest 21 px off.
    seed:         RNG seed of the sampling (results are reproducible).
    """

    threshold_px: float = 2.0
    iterations: int = 300
    fit: str = "file"
    min_inliers: int = 12
    min_inlier_fraction: float = 0.5
    min_thickness: float = 0.01
    seed: int = 0

    def __post_init__(self) -> None:
        require_positive("ransac.threshold_px", self.threshold_px)
        require_int("ransac.iterations", self.iterations, minimum=1)
        require_choice("ransac.fit", self.fit, ("file", "demo"))
        require_int("ransac.min_inliers", self.min_inliers, minimum=6)
        require_positive("ransac.min_thickness", self.min_thickness)
        require_in_range("ransac.min_inlier_fraction", self.min_inlier_fraction, 0.0, 1.0, low_closed=False)
        require_int("ransac.seed", self.seed, minimum=0)


class RansacResult(NamedTuple):
    """P (3, 4) projection (NaN if not ok); inliers (N,) bool; ok; status ("ok", "too_few_points",
    "degenerate", "too_few_inliers", "points_behind_camera"); rms_px over inliers."""

    P: np.ndarray
    inliers: np.ndarray
    ok: bool
    status: str
    rms_px: float


def _normaliser(x: np.ndarray) -> np.ndarray:
    """Similarity moving the centroid to 0 and the mean distance to sqrt(dim) (Hartley)."""
    d = x.shape[1]
    c = x.mean(axis=0)
    s = np.sqrt(d) / max(np.mean(np.linalg.norm(x - c, axis=1)), 1e-12)
    T = np.eye(d + 1)
    T[:d, :d] *= s
    T[:d, d] = -s * c
    return T


def _dlt_rows(Xn: np.ndarray, un: np.ndarray) -> np.ndarray:
    """(..., 2N, 12) DLT design matrix from normalised homogeneous 3D (…, N, 4) and 2D (…, N, 2) points."""
    z = np.zeros_like(Xn)
    u, v = un[..., 0:1], un[..., 1:2]
    r1 = np.concatenate([Xn, z, -u * Xn], axis=-1)
    r2 = np.concatenate([z, Xn, -v * Xn], axis=-1)
    return np.concatenate([r1, r2], axis=-2)


def fit_projection_dlt(X: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Least-squares 3x4 projection (normalised DLT) with ``uv ~ P [X; 1]``; needs N >= 6 points not all
    on one plane. Returns P scaled so ``||P[2, :3]|| = 1`` and points in front have positive w."""
    X, uv = np.asarray(X, float), np.asarray(uv, float)
    if X.ndim != 2 or X.shape[1] != 3 or uv.shape != (X.shape[0], 2) or X.shape[0] < 6:
        raise DatasetError(f"DLT needs (N>=6, 3) points and (N, 2) pixels, got {X.shape} and {uv.shape}")
    T3, T2 = _normaliser(X), _normaliser(uv)
    Xn = np.c_[X, np.ones(len(X))] @ T3.T
    un = (np.c_[uv, np.ones(len(uv))] @ T2.T)[:, :2]
    _, _, vt = np.linalg.svd(_dlt_rows(Xn, un), full_matrices=False)
    return _denormalise(vt[-1].reshape(3, 4), T2, T3, X)


def _denormalise(Pn: np.ndarray, T2: np.ndarray, T3: np.ndarray, X: np.ndarray) -> np.ndarray:
    P = np.linalg.inv(T2) @ Pn @ T3
    n = np.linalg.norm(P[2, :3])
    P = P / (n if n > 0 else 1.0)
    if np.median(np.c_[X, np.ones(len(X))] @ P[2]) < 0:
        P = -P
    return P


def project(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(N, 3) points → (N, 2) pixels through P (NaN where w <= 0, i.e. behind the fitted camera)."""
    h = np.c_[np.asarray(X, float), np.ones(len(X))] @ np.asarray(P).T
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = h[:, :2] / h[:, 2:3]
    uv[h[:, 2] <= 0] = np.nan
    return uv


def reprojection_errors(P: np.ndarray, X: np.ndarray, uv: np.ndarray) -> np.ndarray:
    e = np.linalg.norm(project(P, X) - uv, axis=1)
    return np.where(np.isfinite(e), e, np.inf)


def ransac_projection(X: np.ndarray, uv: np.ndarray, cfg: RansacConfig = RansacConfig()) -> RansacResult:
    """Robust fit of ``uv ~ P [X; 1]``: RANSAC over 6-point DLTs, then refit on the inliers (twice).

    Rows with a NaN pixel (tracker lost) are ignored. Never raises for bad geometry: the status says why.
    """
    X, uv = np.asarray(X, float), np.asarray(uv, float)
    n = len(X)
    nan_P = np.full((3, 4), np.nan)
    valid = np.isfinite(uv).all(axis=1) & np.isfinite(X).all(axis=1)
    idx = np.flatnonzero(valid)
    if len(idx) < max(6, cfg.min_inliers):
        return RansacResult(nan_P, np.zeros(n, bool), False, "too_few_points", float("nan"))
    Xv, uvv = X[idx], uv[idx]
    sv = np.linalg.svd(Xv - Xv.mean(axis=0), compute_uv=False)
    if sv[2] < cfg.min_thickness * sv[0]:  # (nearly) planar or collinear 3D track: the DLT is not determined
        return RansacResult(nan_P, np.zeros(n, bool), False, "degenerate", float("nan"))
    rng = np.random.default_rng(cfg.seed)
    T3, T2 = _normaliser(Xv), _normaliser(uvv)
    Xn = np.c_[Xv, np.ones(len(Xv))] @ T3.T
    un = (np.c_[uvv, np.ones(len(uvv))] @ T2.T)[:, :2]
    samples = np.stack([rng.choice(len(idx), 6, replace=False) for _ in range(cfg.iterations)])
    _, _, vt = np.linalg.svd(_dlt_rows(Xn[samples], un[samples]))  # batched: (iters, 12, 12)
    Pn = vt[:, -1].reshape(-1, 3, 4)
    scale = T2[0, 0]  # normalised → pixel distances
    best_score, mask = -np.inf, None
    block = max(1, 2_000_000 // len(idx))  # hypotheses scored per block: bounded memory on whole files
    for k0 in range(0, len(Pn), block):
        h = np.einsum("kij,nj->kni", Pn[k0:k0 + block], Xn)  # (block, N, 3) normalised pixels
        with np.errstate(divide="ignore", invalid="ignore"):
            err = np.linalg.norm(h[..., :2] / h[..., 2:3] - un[None], axis=-1) / scale
        err = np.where(np.isfinite(err), err, np.inf)
        inl = err <= cfg.threshold_px
        score = inl.sum(axis=1) - 1e-6 * np.where(inl, err, 0).sum(axis=1)  # most inliers, then smallest error
        j = int(np.argmax(score))
        if score[j] > best_score:
            best_score, mask = score[j], inl[j]
    for _ in range(2):  # refit on the inliers, re-select
        if mask.sum() < cfg.min_inliers:
            break
        P = fit_projection_dlt(Xv[mask], uvv[mask])
        e = reprojection_errors(P, Xv, uvv)
        mask = e <= cfg.threshold_px
    if mask.sum() < max(cfg.min_inliers, cfg.min_inlier_fraction * len(idx)):
        return RansacResult(nan_P, np.zeros(n, bool), False, "too_few_inliers", float("nan"))
    P = fit_projection_dlt(Xv[mask], uvv[mask])
    Xf = X[np.isfinite(X).all(axis=1)]
    if not (np.c_[Xf, np.ones(len(Xf))] @ P[2] > 0).all():
        # every 3D point (tracked or not) must lie in front of the fitted camera, else its reprojection
        # is meaningless: the fit only explains a degenerate subset
        return RansacResult(nan_P, np.zeros(n, bool), False, "points_behind_camera", float("nan"))
    e = reprojection_errors(P, Xv, uvv)
    inliers = np.zeros(n, bool)
    inliers[idx] = e <= cfg.threshold_px
    rms = float(np.sqrt(np.mean(e[e <= cfg.threshold_px] ** 2))) if inliers.any() else float("nan")
    return RansacResult(P, inliers, True, "ok", rms)
