"""Gripper-track labels without camera calibration (the paper's pipeline, with OpenCV instead of big models).

1. **Detect** the gripper in the first frame only, from the image: the fingers and pads are magenta in
   both robot models (nothing else in the workcell is), so a colour threshold gives a mask; its
   centroid (the two fingers' blobs merged) is the tracked point.
2. **Track** it through the video with pyramidal Lucas-Kanade (``cv2.calcOpticalFlowPyrLK``) on the mask
   pixels, run on a "magenta-ness" image ``min(R, B) - G`` (the grey levels of the fingers and the table
   are too close for LK). Points failing the forward-backward check are dropped. LK predicts, and the
   colour mask inside a small window around the prediction corrects (the paper's segmenter + point
   tracker; pure LK drifted by ~4 px median when a finger hid behind the palm or the jaws moved). When
   too few points survive, the marker is re-detected by colour near the last position, then anywhere.
3. **Clean** with RANSAC: fit an uncalibrated 3x4 projection matrix (normalised DLT) from the robot's
   3D TCP positions to the tracked pixels, keep the inliers, refit, and reproject the 3D TCP track. The
   cleaned track is that reprojection.

The tracked visual point (finger centroid) is not the TCP. With a fixed gripper orientation the offset
``o`` is a constant world vector and the DLT fits ``P [X + o]`` exactly, so the cleaned track is the
projection of ``X + o``: it differs from the exact TCP projection by the parallax of ``o``. Measured on
600 panda demos (``tcot labels``): 0.71 px median / 1.14 px p90 after RANSAC (raw tracker 0.89 / 1.52);
``VisionLabelConfig.marker_offset_m`` = 0.01 m (the finger ends, robot geometry) brings it to ~0.3 px.
``RansacConfig.fit`` chooses one matrix per file (default: the camera is fixed per file, and the pooled
fit survives demos whose 3D track is nearly planar) or one per demo (file fit as fallback).
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np

from tcot_hybrid.config import require_choice, require_int, require_positive
from tcot_hybrid.errors import ConfigError, DatasetError

# --- 1. detection --------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class MarkerConfig:
    """Colour segmentation of the magenta fingers (OpenCV HSV, hue in degrees here).

    hue_deg:        marker hue [deg]; magenta = 300.
    hue_tol_deg:    accepted hue distance [deg]. Up: tolerates lighting tints, risks other objects.
    min_saturation: [0..1]. Down: accepts washed-out (specular) marker pixels, risks the table.
    min_value:      [0..1]. Down: accepts shadowed marker pixels.
    merge_radius_px: blobs within this distance [px] of the largest one are merged (the two fingers are
                    up to ~17 px apart when open at 128 px). Down: fewer stray blobs merged.
    min_area_px:    smallest accepted marker area [px]. Up: fewer false detections, more "not found".
    """

    hue_deg: float = 300.0
    hue_tol_deg: float = 25.0
    min_saturation: float = 0.45
    min_value: float = 0.2
    merge_radius_px: float = 24.0
    min_area_px: int = 1

    def __post_init__(self) -> None:
        for f in ("hue_tol_deg", "min_saturation", "min_value", "merge_radius_px"):
            require_positive(f"marker.{f}", getattr(self, f))
        require_int("marker.min_area_px", self.min_area_px, minimum=1)
        if not 0 <= self.hue_deg < 360:
            raise ConfigError(f"marker.hue_deg must be in [0, 360), got {self.hue_deg}")


class Detection(NamedTuple):
    """found: marker seen; uv_px (2,) mask centroid [px] (NaN if not found); area_px: pixels in the mask."""

    found: bool
    uv_px: np.ndarray
    area_px: int
    mask: np.ndarray


def _check_image(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8 or img.shape[0] < 2 or img.shape[1] < 2:
        raise DatasetError(f"expected an RGB uint8 image (H, W, 3), got shape {img.shape} dtype {img.dtype}")
    return img


def marker_mask(image: np.ndarray, cfg: MarkerConfig = MarkerConfig()) -> np.ndarray:
    """(H, W) bool mask of marker-coloured pixels of an RGB uint8 image."""
    hsv = cv2.cvtColor(_check_image(image), cv2.COLOR_RGB2HSV)  # H in [0, 180), S, V in [0, 255]
    hue = hsv[..., 0].astype(np.float32) * 2.0
    dh = np.abs((hue - cfg.hue_deg + 180.0) % 360.0 - 180.0)
    return (dh <= cfg.hue_tol_deg) & (hsv[..., 1] >= 255 * cfg.min_saturation) & (hsv[..., 2] >= 255 * cfg.min_value)


def detect_marker(image: np.ndarray, cfg: MarkerConfig = MarkerConfig(), *, near_px: np.ndarray | None = None,
                  radius_px: float | None = None) -> Detection:
    """Find the gripper marker: largest colour blob merged with the blobs within ``merge_radius_px`` of it;
    ``uv_px`` is the centroid of the merged mask. With ``near_px``/``radius_px`` only pixels within that
    disc are considered (the returned mask is still full-size)."""
    img = _check_image(image)
    h, w = img.shape[:2]
    u0 = v0 = 0
    if near_px is not None and radius_px is not None:  # segment only a window around the estimate
        u0, v0 = max(int(np.floor(near_px[0] - radius_px)), 0), max(int(np.floor(near_px[1] - radius_px)), 0)
        u1, v1 = min(int(np.ceil(near_px[0] + radius_px)) + 1, w), min(int(np.ceil(near_px[1] + radius_px)) + 1, h)
        if u1 <= u0 or v1 <= v0:
            return Detection(False, np.full(2, np.nan), 0, np.zeros((h, w), bool))
        sub = marker_mask(img[v0:v1, u0:u1], cfg)
        vv, uu = np.mgrid[v0:v1, u0:u1]
        sub &= (uu - near_px[0]) ** 2 + (vv - near_px[1]) ** 2 <= radius_px ** 2
    else:
        sub = marker_mask(img, cfg)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(sub.astype(np.uint8), connectivity=8)
    mask = np.zeros((h, w), bool)
    if n <= 1:
        return Detection(False, np.full(2, np.nan), 0, mask)
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    keep = [i for i in range(1, n) if np.linalg.norm(cents[i] - cents[best]) <= cfg.merge_radius_px]
    sel = np.isin(labels, keep)
    mask[v0:v0 + sel.shape[0], u0:u0 + sel.shape[1]] = sel
    area = int(sel.sum())
    if area < cfg.min_area_px:
        return Detection(False, np.full(2, np.nan), area, mask)
    vs, us = np.nonzero(sel)
    return Detection(True, np.array([us.mean() + u0, vs.mean() + v0]), area, mask)


# --- 2. tracking ---------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class TrackerConfig:
    """Pyramidal Lucas-Kanade on the marker mask pixels.

    win_px:          LK window side [px], odd. Up: follows faster motion, blurs small blobs together.
    levels:          pyramid levels above the base. Up: larger motions per frame.
    max_fb_error_px: forward-backward error above which a point is dropped [px]. Down: stricter.
    min_points:      fewer surviving points than this = lost → re-detect near the last position.
    redetect_radius_px: search radius of the re-detection [px]; if nothing is there, search the image.
    max_points:      mask pixels used as LK features (subsampled evenly) [-].
    refine:          after LK, re-segment the marker by colour within ``refine_radius_px`` of the LK
                     estimate and use that centroid (LK predicts, segmentation corrects; without it the
                     median LK shift drifts by several px when a finger is hidden or the jaws move).
    refine_radius_px: window radius of the correction [px]; must cover both fingers.
    """

    win_px: int = 9
    levels: int = 2
    max_fb_error_px: float = 1.0
    min_points: int = 2
    redetect_radius_px: float = 15.0
    max_points: int = 40
    refine: bool = True
    refine_radius_px: float = 14.0

    def __post_init__(self) -> None:
        require_int("tracker.win_px", self.win_px, minimum=3)
        if self.win_px % 2 == 0:
            raise ConfigError(f"tracker.win_px must be odd, got {self.win_px}")
        require_int("tracker.levels", self.levels, minimum=0)
        require_positive("tracker.max_fb_error_px", self.max_fb_error_px)
        require_int("tracker.min_points", self.min_points, minimum=1)
        require_positive("tracker.redetect_radius_px", self.redetect_radius_px)
        require_int("tracker.max_points", self.max_points, minimum=1)
        require_positive("tracker.refine_radius_px", self.refine_radius_px)


# per-frame tracker status codes
DETECTED, TRACKED, REDETECTED, LOST = 0, 1, 2, 3
STATUS_NAMES = ("detected", "tracked", "redetected", "lost")


class TrackResult(NamedTuple):
    """uv_px (T, 2) tracked marker point [px], NaN where lost; status (T,) int8 (DETECTED … LOST)."""

    uv_px: np.ndarray
    status: np.ndarray


def _magentaness(image: np.ndarray) -> np.ndarray:
    img = image.astype(np.int16)
    return np.clip(np.minimum(img[..., 0], img[..., 2]) - img[..., 1], 0, 255).astype(np.uint8)


def _features(det: Detection, max_points: int) -> np.ndarray:
    vs, us = np.nonzero(det.mask)
    pts = np.stack([us, vs], axis=1).astype(np.float32)
    if len(pts) > max_points:
        pts = pts[np.linspace(0, len(pts) - 1, max_points).round().astype(int)]
    return pts.reshape(-1, 1, 2)


def track_marker(frames: np.ndarray, marker: MarkerConfig = MarkerConfig(),
                 tracker: TrackerConfig = TrackerConfig()) -> TrackResult:
    """Track the gripper marker through ``frames`` (T, H, W, 3) uint8: detect in frame 0 only, then LK.

    The tracked point moves by the median displacement of the surviving feature points; a frame where
    too few survive re-detects by colour near the last position (then anywhere), else it is LOST (NaN).
    """
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[0] < 1:
        raise DatasetError(f"frames must have shape (T>=1, H, W, 3), got {frames.shape}")
    T = frames.shape[0]
    uv = np.full((T, 2), np.nan)
    status = np.full(T, LOST, dtype=np.int8)
    lk = dict(winSize=(tracker.win_px, tracker.win_px), maxLevel=tracker.levels,
              criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.03))
    det = detect_marker(_check_image(frames[0]), marker)
    pts = None
    if det.found:
        uv[0], status[0] = det.uv_px, DETECTED
        pts = _features(det, tracker.max_points)
    prev_img = _magentaness(frames[0])
    last = uv[0].copy() if det.found else None
    for t in range(1, T):
        img = _magentaness(_check_image(frames[t]))
        point = None
        if pts is not None and len(pts):
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(prev_img, img, pts, None, **lk)
            back, st2, _ = cv2.calcOpticalFlowPyrLK(img, prev_img, nxt, None, **lk)
            fb = np.linalg.norm((back - pts).reshape(-1, 2), axis=1)
            good = (st.ravel() == 1) & (st2.ravel() == 1) & (fb <= tracker.max_fb_error_px)
            if good.sum() >= tracker.min_points:
                shift = np.median((nxt - pts).reshape(-1, 2)[good], axis=0)
                point = last + shift
                pts = nxt[good].reshape(-1, 1, 2)
                status[t] = TRACKED
                if tracker.refine:
                    det = detect_marker(frames[t], marker, near_px=point, radius_px=tracker.refine_radius_px)
                    if det.found:
                        point = det.uv_px
                        pts = _features(det, tracker.max_points)
        if point is None:  # lost: re-detect near the last position, then anywhere
            det = (detect_marker(frames[t], marker, near_px=last, radius_px=tracker.redetect_radius_px)
                   if last is not None else Detection(False, np.full(2, np.nan), 0, None))
            if not det.found:
                det = detect_marker(frames[t], marker)
            if det.found:
                point, status[t] = det.uv_px, REDETECTED
                pts = _features(det, tracker.max_points)
            else:
                pts = None
        if point is not None:
            uv[t] = point
            last = point
        prev_img = img
    return TrackResult(uv, status)


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
        if not 0 < self.min_inlier_fraction <= 1:
            raise ConfigError(f"ransac.min_inlier_fraction must be in (0, 1], got {self.min_inlier_fraction}")
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


def _errors(P: np.ndarray, X: np.ndarray, uv: np.ndarray) -> np.ndarray:
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
        e = _errors(P, Xv, uvv)
        mask = e <= cfg.threshold_px
    if mask.sum() < max(cfg.min_inliers, cfg.min_inlier_fraction * len(idx)):
        return RansacResult(nan_P, np.zeros(n, bool), False, "too_few_inliers", float("nan"))
    P = fit_projection_dlt(Xv[mask], uvv[mask])
    Xf = X[np.isfinite(X).all(axis=1)]
    if not (np.c_[Xf, np.ones(len(Xf))] @ P[2] > 0).all():
        # every 3D point (tracked or not) must lie in front of the fitted camera, else its reprojection
        # is meaningless: the fit only explains a degenerate subset
        return RansacResult(nan_P, np.zeros(n, bool), False, "points_behind_camera", float("nan"))
    e = _errors(P, Xv, uvv)
    inliers = np.zeros(n, bool)
    inliers[idx] = e <= cfg.threshold_px
    rms = float(np.sqrt(np.mean(e[e <= cfg.threshold_px] ** 2))) if inliers.any() else float("nan")
    return RansacResult(P, inliers, True, "ok", rms)


# --- the whole path on a file --------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class VisionLabelConfig:
    """Everything the vision label path needs.

    marker_offset_m: where the tracked visual point sits relative to the TCP, along the TCP approach
        axis [m] (+ = past the TCP toward the fingertips). The 3D points of the fit are moved by it, and
        the TCP track is reprojected, so the parallax of the offset is removed. It is robot geometry, not
        camera calibration; 0 = unknown. Measured on the panda file: 0 → 0.71 px median, 0.01 → 0.32 px.
    """

    marker: MarkerConfig = MarkerConfig()
    tracker: TrackerConfig = TrackerConfig()
    ransac: RansacConfig = RansacConfig()
    marker_offset_m: float = 0.0

    def __post_init__(self) -> None:
        if not np.isfinite(self.marker_offset_m) or abs(self.marker_offset_m) > 0.2:
            raise ConfigError(f"marker_offset_m must be finite and within ±0.2 m, got {self.marker_offset_m}")


class VisionTrack(NamedTuple):
    """One demo through the vision path. uv_tracked (T, 2) raw tracker output (NaN = lost);
    uv_clean (T, 2) reprojection of the 3D TCP track through the fitted P; inliers (T,) bool;
    status (T,) tracker codes; fit_status: "ok", "pooled" (per-demo fit degenerate → file fit) or a
    RansacResult status."""

    uv_tracked: np.ndarray
    uv_clean: np.ndarray
    inliers: np.ndarray
    status: np.ndarray
    fit_status: str


def _stats(err: np.ndarray) -> dict:
    """Error statistics over the finite entries; ``missing`` counts samples without a pixel (NaN)."""
    missing = int((~np.isfinite(err)).sum())
    err = err[np.isfinite(err)]
    if err.size == 0:
        return {"n": 0, "missing": missing, "median_px": None, "p90_px": None, "mean_px": None, "max_px": None}
    return {"n": int(err.size), "missing": missing, "median_px": round(float(np.median(err)), 3),
            "p90_px": round(float(np.percentile(err, 90)), 3), "mean_px": round(float(err.mean()), 3),
            "max_px": round(float(err.max()), 3)}


class RawTrack(NamedTuple):
    """Tracker output of one demo with its 3D tracks: uv_px (T, 2) [px] (NaN = lost), status (T,),
    X (T, 3) TCP positions, world [m]; X_marker (T, 3) the tracked point's assumed 3D position (fit input)."""

    uv_px: np.ndarray
    status: np.ndarray
    X: np.ndarray
    X_marker: np.ndarray


def approach_axis(quat_wxyz: np.ndarray) -> np.ndarray:
    """(T, 4) TCP orientations (w, x, y, z) → (T, 3) TCP z axes (approach direction) in the world."""
    w, x, y, z = np.asarray(quat_wxyz, dtype=float).T
    return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=1)


def track_demos(demo_file, names: list[str], cfg: VisionLabelConfig = VisionLabelConfig()) -> dict[str, RawTrack]:
    """Steps 1-2 (detect in frame 0, track) for demos ``names`` of an open :class:`DemoFile`."""
    out = {}
    for name in names:
        arr = demo_file.read(name, [demo_file.image_key, "obs/robot0_eef_pos", "obs/robot0_eef_quat"])
        tr = track_marker(arr[demo_file.image_key], cfg.marker, cfg.tracker)
        X = arr["obs/robot0_eef_pos"].astype(float)
        Xm = X + cfg.marker_offset_m * approach_axis(arr["obs/robot0_eef_quat"]) if cfg.marker_offset_m else X
        out[name] = RawTrack(tr.uv_px, tr.status, X, Xm)
    return out


def clean_tracks(raw: dict[str, RawTrack], cfg: RansacConfig = RansacConfig()) -> dict[str, VisionTrack]:
    """Step 3: RANSAC-fit the projection (per file, or per demo with the file fit as fallback) and
    reproject each demo's 3D TCP track."""
    pooled = ransac_projection(np.concatenate([r.X_marker for r in raw.values()]),
                               np.concatenate([r.uv_px for r in raw.values()]), cfg)
    out = {}
    for name, r in raw.items():
        res, fit_status = pooled, "ok"
        if cfg.fit == "demo":
            res = ransac_projection(r.X_marker, r.uv_px, cfg)
            if not res.ok:
                res, fit_status = pooled, "pooled"
        if not res.ok:
            out[name] = VisionTrack(r.uv_px, np.full_like(r.uv_px, np.nan), np.zeros(len(r.X), bool), r.status,
                                    res.status)
            continue
        inliers = _errors(res.P, r.X_marker, r.uv_px) <= cfg.threshold_px
        out[name] = VisionTrack(r.uv_px, project(res.P, r.X), inliers, r.status, fit_status)
    return out


def vision_tracks(demo_file, names: list[str], cfg: VisionLabelConfig = VisionLabelConfig()) -> dict[str, VisionTrack]:
    """The whole vision path (detect, track, RANSAC-clean) on demos ``names`` of an open DemoFile."""
    return clean_tracks(track_demos(demo_file, names, cfg), cfg.ransac)


def error_report(tracks: dict[str, VisionTrack], exact: dict[str, np.ndarray]) -> dict:
    """Pixel errors of vision tracks against exact projections, before RANSAC (raw tracker, lost frames
    excluded) and after (cleaned track)."""
    names = list(tracks)
    before = np.concatenate([np.linalg.norm(tracks[n].uv_tracked - exact[n], axis=1) for n in names])
    after = np.concatenate([np.linalg.norm(tracks[n].uv_clean - exact[n], axis=1) for n in names])
    status = np.concatenate([tracks[n].status for n in names])
    inl = np.concatenate([tracks[n].inliers for n in names])
    per_demo = [np.linalg.norm(tracks[n].uv_clean - exact[n], axis=1) for n in names]
    medians = [float(np.median(e)) if np.isfinite(e).all() else float("inf") for e in per_demo]
    fit_status: dict[str, int] = {}
    for n in names:
        fit_status[tracks[n].fit_status] = fit_status.get(tracks[n].fit_status, 0) + 1
    return {
        "demos": len(names), "samples": int(len(before)),
        "before_ransac": _stats(before), "after_ransac": _stats(after),
        "tracker_status": {STATUS_NAMES[k]: int((status == k).sum()) for k in range(4)},
        "inlier_fraction": round(float(inl.mean()), 4), "fit_status": fit_status,
        "worst_demo_median_px": round(max(medians), 3) if np.isfinite(max(medians)) else None,
        "demos_without_clean_track": int(sum(not np.isfinite(m) for m in medians)),
    }


def label_report(path: str | Path, *, fits: tuple[str, ...] = ("file", "demo"), threshold_px: float = 2.0,
                 max_demos: int | None = None, corrupt_fraction: float = 0.0, corrupt_seed: int = 0,
                 cfg: VisionLabelConfig = VisionLabelConfig()) -> dict:
    """Pixel error of the vision track against the exact projection ``obs/eef_uv_px`` over the demos of a
    file (the first ``max_demos`` if given), for each RANSAC fit scope in ``fits``. With
    ``corrupt_fraction`` > 0 each fit is repeated after moving that fraction of the tracked points to
    random pixels (outlier-rejection check). Tracking runs once."""
    from tcot_hybrid.data.dataset import open_demos

    if not 0 <= corrupt_fraction < 1:
        raise ConfigError(f"corrupt_fraction must be in [0, 1), got {corrupt_fraction}")
    t0 = time.perf_counter()
    with open_demos(path) as f:
        names = f.demos if max_demos is None else f.demos[:max_demos]
        if not names:
            raise DatasetError(f"demo file {path} holds no demos")
        raw = track_demos(f, names, cfg)
        exact = {n: f.read(n, ["obs/eef_uv_px"])["obs/eef_uv_px"].astype(float) for n in names}
        w, h = int(f.env_args["width"]), int(f.env_args["height"])
    t_track = time.perf_counter() - t0
    results = {}
    for fit in fits:
        rc = replace(cfg.ransac, fit=fit, threshold_px=threshold_px)
        t1 = time.perf_counter()
        results[f"fit per {fit}"] = {**error_report(clean_tracks(raw, rc), exact),
                                     "fit_time_s": round(time.perf_counter() - t1, 2)}
        if corrupt_fraction > 0:
            rng = np.random.default_rng(corrupt_seed)
            bad = {n: r._replace(uv_px=corrupt_points(r.uv_px, corrupt_fraction, rng, width=w, height=h))
                   for n, r in raw.items()}
            results[f"fit per {fit}, {corrupt_fraction:.0%} of tracked points corrupted"] = error_report(
                clean_tracks(bad, rc), exact)
    return {"file": str(path), "config": asdict(cfg), "threshold_px": threshold_px,
            "corrupt_fraction": corrupt_fraction, "track_time_s": round(t_track, 2),
            "track_ms_per_frame": round(1000 * t_track / max(1, sum(len(r.X) for r in raw.values())), 2),
            "results": results}


def corrupt_points(uv: np.ndarray, fraction: float, rng: np.random.Generator, *, width: int, height: int,
                   min_offset_px: float = 8.0) -> np.ndarray:
    """Copy of ``uv`` with ``fraction`` of its rows moved to random pixels at least ``min_offset_px`` away."""
    out = np.array(uv, dtype=float)
    k = int(round(fraction * len(out)))
    rows = rng.choice(len(out), k, replace=False)
    for r in rows:
        while True:
            p = rng.uniform([0, 0], [width - 1, height - 1])
            if not np.isfinite(out[r]).all() or np.linalg.norm(p - out[r]) >= min_offset_px:
                out[r] = p
                break
    return out


def cmd_labels(argv: list[str]) -> int:
    """``tcot labels --data FILE [--out report.json]``: vision-path pixel error report."""
    p = argparse.ArgumentParser(prog="tcot labels", description=(
        "Track the gripper in the demo videos (colour detection in the first frame, Lucas-Kanade tracking), "
        "clean the track with a RANSAC-fitted uncalibrated projection of the 3D TCP positions, and report "
        "the pixel error against the exact projection (median and p90, before and after RANSAC)."))
    p.add_argument("--data", type=Path, required=True, help="demo file written by tcot collect")
    p.add_argument("--out", type=Path, help="write the report as JSON here")
    p.add_argument("--fit", choices=("file", "demo", "both"), default="both",
                   help="one projection per file, per demo, or report both (default)")
    p.add_argument("--max-demos", type=int, help="only the first N demos (faster)")
    p.add_argument("--threshold-px", type=float, default=RansacConfig.threshold_px, help="RANSAC inlier threshold [px]")
    p.add_argument("--marker-offset-m", type=float, default=0.0,
                   help="tracked point's offset from the TCP along the approach axis [m] (robot geometry; "
                        "0 = unknown, 0.01 = finger ends on the panda/ur5e gripper)")
    p.add_argument("--corrupt", type=float, default=0.0,
                   help="also replace this fraction of tracked points with random pixels (outlier check)")
    args = p.parse_args(argv)
    if args.max_demos is not None and args.max_demos < 1:
        raise ConfigError(f"--max-demos must be >= 1, got {args.max_demos}")
    fits = ("file", "demo") if args.fit == "both" else (args.fit,)
    report = label_report(args.data, fits=fits, threshold_px=args.threshold_px, max_demos=args.max_demos,
                          corrupt_fraction=args.corrupt, cfg=VisionLabelConfig(marker_offset_m=args.marker_offset_m))
    for key, r in report["results"].items():
        print(_summary(key, r))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=2))
        print(f"-> {args.out}")
    return 0


def _summary(title: str, r: dict) -> str:
    b, a = r["before_ransac"], r["after_ransac"]
    return (f"{title}: {r['demos']} demos, {r['samples']} samples: before RANSAC median {b['median_px']} px, "
            f"p90 {b['p90_px']} px (n={b['n']}); after RANSAC median {a['median_px']} px, p90 {a['p90_px']} px; "
            f"inliers {r['inlier_fraction']:.1%}; tracker {r['tracker_status']}; fits {r['fit_status']}")


__all__ = ["Detection", "MarkerConfig", "RansacConfig", "RansacResult", "RawTrack", "TrackResult", "TrackerConfig",
           "VisionLabelConfig", "VisionTrack", "clean_tracks", "cmd_labels", "corrupt_points", "detect_marker",
           "error_report", "fit_projection_dlt", "marker_mask", "project", "ransac_projection", "track_demos",
           "track_marker", "label_report", "vision_tracks"]
