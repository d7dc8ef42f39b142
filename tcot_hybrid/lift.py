"""Lift 2D image waypoints to 3D world points.

Two lift cues are supported:

* depth (:func:`lift_waypoints`): each waypoint comes with its depth along the camera's optical axis
  (OpenCV z) — predicted by the planner, or read from a rendered/sensed depth image;
* a second view (:func:`lift_two_view`): the same waypoint seen in a second calibrated camera,
  triangulated.

Nothing is clipped: a waypoint outside the image, behind the camera, at a non-finite or
out-of-range depth is refused with :class:`LiftError` naming the waypoint index, the bad value and
the valid range, so the supervisor can count the plan as failed and replan.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tcot_hybrid.camera import CameraModel, triangulate
from tcot_hybrid.config import require_nonnegative, require_positive
from tcot_hybrid.errors import LiftError


@dataclass(frozen=True, kw_only=True)
class LiftConfig:
    """How strict lifting is.

    margin_px:           waypoints closer than this to the image border are refused [px]. 0 accepts
                         the whole image; turn up to refuse edge pixels where planner predictions
                         (and lens models of real cameras) are least reliable.
    max_reprojection_px: two-view lift only: a triangulated point whose reprojection into either
                         view is farther than this from the given pixel is refused [px]. Turn down
                         to reject inconsistent correspondences sooner, up to tolerate noisier ones.
    """

    margin_px: float = 0.0
    max_reprojection_px: float = 1.0

    def __post_init__(self) -> None:
        require_nonnegative("margin_px", self.margin_px)
        require_positive("max_reprojection_px", self.max_reprojection_px)


def _pixels(name: str, uv_px: object) -> np.ndarray:
    try:
        uv = np.asarray(uv_px, dtype=float)
    except (TypeError, ValueError) as exc:
        raise LiftError(f"{name} must be a numeric array of shape (N, 2) [px], got {uv_px!r}") from exc
    if uv.ndim != 2 or uv.shape[1] != 2 or uv.shape[0] == 0:
        raise LiftError(f"{name} must have shape (N>=1, 2) [px], got {uv.shape}")
    return uv


def _check_in_image(name: str, uv: np.ndarray, camera: CameraModel, margin_px: float) -> None:
    finite = np.isfinite(uv).all(axis=1)
    bad = np.flatnonzero(~finite)
    if bad.size:
        i = int(bad[0])
        raise LiftError(f"waypoint {i}: {name} = {uv[i].tolist()} is not finite ({bad.size} of {len(uv)} waypoints bad)")
    inside = camera.in_image(uv, margin_px=margin_px)
    bad = np.flatnonzero(~inside)
    if bad.size:
        i = int(bad[0])
        raise LiftError(
            f"waypoint {i}: {name} = {uv[i].tolist()} is outside camera {camera.name!r}'s image; valid "
            f"u in [{-0.5 + margin_px}, {camera.width - 0.5 - margin_px}], "
            f"v in [{-0.5 + margin_px}, {camera.height - 0.5 - margin_px}] px (margin_px = {margin_px}); "
            f"{bad.size} of {len(uv)} waypoints outside"
        )


def _check_depth(name: str, depth: np.ndarray, camera: CameraModel) -> None:
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(depth) & (depth > camera.near_m) & (depth <= camera.far_m)
    bad = np.flatnonzero(~ok)
    if bad.size:
        i = int(bad[0])
        raise LiftError(
            f"waypoint {i}: {name} = {depth[i]} is outside camera {camera.name!r}'s valid depth range "
            f"(near_m, far_m] = ({camera.near_m:.6g}, {camera.far_m:.6g}] m; {bad.size} of {len(depth)} waypoints bad"
        )


def lift_waypoints(uv_px: np.ndarray, depth_m: np.ndarray, camera: CameraModel, *, config: LiftConfig = LiftConfig()) -> np.ndarray:
    """Lift pixels with known depth to world points.

    uv_px:   (N, 2) pixels in ``camera``'s image (integer = pixel centre) [px]
    depth_m: (N,) depth along the optical axis (OpenCV z, not ray length) [m], in (near_m, far_m]
    returns: (N, 3) world points [m]

    Raises LiftError for wrong shapes, non-finite pixels, pixels outside the image (minus
    ``config.margin_px``) and depths that are non-finite, <= near_m or > far_m.
    """
    uv = _pixels("uv_px", uv_px)
    n = len(uv)
    try:
        depth = np.asarray(depth_m, dtype=float)
    except (TypeError, ValueError) as exc:
        raise LiftError(f"depth_m must be a numeric array of shape ({n},) [m], got {depth_m!r}") from exc
    if depth.shape != (n,):
        raise LiftError(f"depth_m must have shape ({n},) to match uv_px {uv.shape}, got {depth.shape}")
    _check_in_image("uv_px", uv, camera, config.margin_px)
    _check_depth("depth_m", depth, camera)
    return camera.unproject(uv, depth)


def lift_two_view(
    uv_a: np.ndarray,
    cam_a: CameraModel,
    uv_b: np.ndarray,
    cam_b: CameraModel,
    *,
    config: LiftConfig = LiftConfig(),
) -> np.ndarray:
    """Lift matching pixels seen by two calibrated cameras (triangulation) to world points.

    uv_a, uv_b: (N, 2) pixels of the same N waypoints in ``cam_a`` and ``cam_b`` [px]
    returns:    (N, 3) world points [m]

    Refuses (LiftError naming the waypoint) pixels outside either image, triangulated points outside
    either camera's depth range (behind a camera included), and points whose reprojection error in
    either view exceeds ``config.max_reprojection_px`` (the two pixels do not show the same point).
    """
    a = _pixels("uv_a", uv_a)
    b = _pixels("uv_b", uv_b)
    if a.shape != b.shape:
        raise LiftError(f"uv_a and uv_b must describe the same waypoints, got shapes {a.shape} and {b.shape}")
    _check_in_image("uv_a", a, cam_a, config.margin_px)
    _check_in_image("uv_b", b, cam_b, config.margin_px)
    points = triangulate(cam_a, a, cam_b, b)
    for name, cam, uv in (("a", cam_a, a), ("b", cam_b, b)):
        reproj, depth = cam.project(points)
        _check_depth(f"triangulated depth in camera {name}", depth, cam)
        err = np.linalg.norm(reproj - uv, axis=1)
        bad = np.flatnonzero(~(err <= config.max_reprojection_px))
        if bad.size:
            i = int(bad[0])
            raise LiftError(
                f"waypoint {i}: triangulated point reprojects {err[i]:.3g} px from uv_{name} = {uv[i].tolist()} "
                f"in camera {cam.name!r}; allowed <= max_reprojection_px = {config.max_reprojection_px} px"
            )
    return points
