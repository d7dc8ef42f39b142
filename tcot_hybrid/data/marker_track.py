"""Detecting and tracking the gripper marker in demonstration video (steps 1 and 2 of the vision label path,
:mod:`tcot_hybrid.data.vision_labels`): a colour threshold finds the magenta fingers, pyramidal Lucas-Kanade
tracks them, the colour mask near the prediction corrects the track."""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from tcot_hybrid.config import require_int, require_positive
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
