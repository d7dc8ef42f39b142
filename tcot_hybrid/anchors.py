"""Grasp tracking: has the object a frozen global plan reaches for moved since the plan's image?

A global plan is made from one image and then followed frozen (``supervisor.t_f``); when the object it reaches for is
moved meanwhile (knocked, slid, or by the ``object_moved`` perturbation), the plan closes the hand where the object
was. The supervisor watches the plan's next grasp in the planner camera instead, until the hand closes: the image
patch around the grasp point's pixel in the plan's image is the object as the planner saw it. When the patch no
longer matches there, and it matches again nearby where the image changed (something appeared), the object has moved
by that much; the way to the grasp, the grasp and its lift are shifted with it (:func:`shifted_plan`) and followed on.
Non-privileged: the planner camera's images and its calibration, nothing from the simulator. (The release after it
was watched the same way too, and dropped: docs/libero-planner.md, "Tracking what the plan grasps".)

Template matching is OpenCV's normalised cross-correlation (``cv2.matchTemplate``, TM_CCOEFF_NORMED) on lightly
blurred images; the new spot must also be where the image changed, so a look-alike that stayed put (another black
bowl, a second can) is not taken for the moved object.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from tcot_hybrid.config import require_choice, require_int, require_positive

TRACK_MODES = ("auto", "on", "off")
LIFT_XY_M = 0.02  # waypoints this close sideways to a grasp are its descent and lift: they move with it [m]


@dataclass(frozen=True, kw_only=True)
class GraspTrackConfig:
    """How the supervisor tracks a frozen global plan's next grasp (module doc). Pixel sizes are in the planner
    image (LIBERO's 128 px: about 0.7 cm a pixel on the table). Needs a planner that looks at the image.

    mode:            "on", "off", or "auto": on for LIBERO's GLSR (chosen on development layouts under
                     ``object_moved``: docs/libero-planner.md, "Tracking what the plan grasps"), off on the workcell (its
                     reporting tables were measured without it). Global-only and local-only never track.
    every_steps:     planner steps between two looks (each renders the planner image). Down: sooner, costlier.
    patch_px:        half size of the patch around the grasp point's pixel [px] (13 x 13 at 6). Up: more context
                     (background that moves with nothing), down: less texture to match.
    search_px:       how far from that pixel the patch is searched for [px].
    gone_ncc:        the patch counts as gone when its correlation at that pixel falls below this.
    found_ncc:       a match elsewhere must correlate at least this well. Up: fewer wrong moves, more missed ones.
    changed_level:   a pixel whose colour changed by more than this (0-255, any channel, after a 3 x 3 blur) changed.
    changed_frac:    at least this share of a match's patch must have changed (the object appeared there).
    max_image_changed: no move is taken when more than this share of the whole image changed (the camera itself
                     moved, or noise): a tracked shift would then be the view's, not the object's.
    min_shift_px:    a match this close to that pixel is no move [px].
    confirm_looks:   consecutive looks that must find the same move (within 2 px) before the plan is shifted: a
                     passing occlusion (``camera_noise``'s patch) moves at random between images, a moved object not.
    hand_clear_m:    the grasp is not looked at while the hand is this close to it [m] (it hides the object).
    max_moves:       shifts an episode at most.
    """

    mode: str = "auto"
    every_steps: int = 2
    patch_px: int = 6
    search_px: int = 24
    gone_ncc: float = 0.5
    found_ncc: float = 0.55
    changed_level: float = 25.0
    changed_frac: float = 0.25
    max_image_changed: float = 0.2
    min_shift_px: float = 3.0
    confirm_looks: int = 2
    hand_clear_m: float = 0.12
    max_moves: int = 2

    def __post_init__(self) -> None:
        require_choice("supervisor.track.mode", self.mode, TRACK_MODES)
        for name in ("every_steps", "patch_px", "search_px", "confirm_looks"):
            require_int(f"supervisor.track.{name}", getattr(self, name), minimum=1)
        require_int("supervisor.track.max_moves", self.max_moves, minimum=0)
        for name in ("changed_level", "min_shift_px", "hand_clear_m"):
            require_positive(f"supervisor.track.{name}", getattr(self, name))
        for name in ("gone_ncc", "found_ncc", "changed_frac", "max_image_changed"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and -1.0 <= v <= 1.0 and (name in ("gone_ncc", "found_ncc") or v > 0)):
                from tcot_hybrid.errors import ConfigError

                valid = "[-1, 1]" if name.endswith("ncc") else "(0, 1]"
                raise ConfigError(f"supervisor.track.{name} must be in {valid}, got {v!r}")

    def enabled(self, world_kind: str) -> bool:
        return self.mode == "on" or (self.mode == "auto" and world_kind == "libero")


class Look(NamedTuple):
    """One comparison of the grasp patch between the plan's image and a later one."""

    here: float           # correlation at the grasp pixel
    best: float           # best correlation among changed spots (-1: none)
    uv_px: np.ndarray     # where that best match is [px]
    image_changed: float  # share of the image's pixels that changed
    moved: bool           # what was at the pixel is gone from it and found at ``uv_px``


def look(before: np.ndarray, after: np.ndarray, uv_px: np.ndarray, cfg: GraspTrackConfig) -> Look | None:
    """Compare the patch around ``uv_px`` in ``before`` with ``after`` (both (H, W, 3) uint8 images of the same
    camera); None when the patch is off the image or featureless (nothing to track)."""
    import cv2

    if before.shape != after.shape or before.ndim != 3:
        raise ValueError(f"images must be two (H, W, 3) arrays of one shape, got {before.shape} and {after.shape}")
    h, r = cfg.patch_px, cfg.search_px
    H, W = before.shape[:2]
    u, v = int(round(float(uv_px[0]))), int(round(float(uv_px[1])))
    if not (h <= u < W - h and h <= v < H - h):
        return None
    i0 = cv2.GaussianBlur(before.astype(np.float32), (3, 3), 0)
    i1 = cv2.GaussianBlur(after.astype(np.float32), (3, 3), 0)
    tpl = i0[v - h:v + h + 1, u - h:u + h + 1]
    if float(tpl.std()) < 2.0:
        return None
    changed = (np.abs(i1 - i0).max(axis=2) > cfg.changed_level).astype(np.float32)
    y0, y1, x0, x1 = max(0, v - h - r), min(H, v + h + r + 1), max(0, u - h - r), min(W, u + h + r + 1)
    ncc = cv2.matchTemplate(i1[y0:y1, x0:x1], tpl, cv2.TM_CCOEFF_NORMED)
    here = float(ncc[v - h - y0, u - h - x0])
    frac = cv2.boxFilter(changed[y0:y1, x0:x1], -1, (2 * h + 1, 2 * h + 1), normalize=True,
                         borderType=cv2.BORDER_CONSTANT)[h:h + ncc.shape[0], h:h + ncc.shape[1]]
    scored = np.where(frac >= cfg.changed_frac, ncc, -1.0).astype(np.float32)
    _, best, _, loc = cv2.minMaxLoc(scored)
    at = np.array([loc[0] + x0 + h, loc[1] + y0 + h], float) + (np.asarray(uv_px, float) - (u, v))
    image_changed = float(changed.mean())
    moved = (here < cfg.gone_ncc and best >= cfg.found_ncc and image_changed <= cfg.max_image_changed
             and float(np.hypot(*(at - uv_px))) >= cfg.min_shift_px)
    return Look(here=here, best=float(best), uv_px=at, image_changed=image_changed, moved=bool(moved))


def shift_on_plane(camera, point_m: np.ndarray, uv_to: np.ndarray) -> np.ndarray:
    """World displacement [m] (z = 0) that moves ``point_m`` to where the pixel ray of ``uv_to`` meets the horizontal
    plane through it: an object slid on its support, seen at the height of the point."""
    ray = camera.unproject(np.asarray(uv_to, float)[None], np.ones(1))[0] - camera.T_world_cam[:3, 3]
    origin = camera.T_world_cam[:3, 3]
    if abs(ray[2]) < 1e-9:
        raise ValueError(f"pixel {np.round(uv_to, 2).tolist()} looks along the horizontal plane: no shift on it")
    s = (point_m[2] - origin[2]) / ray[2]
    d = origin + s * ray - point_m
    d[2] = 0.0
    return d


def grasp_neighbourhood(points: np.ndarray, grasp: int) -> list[int]:
    """Waypoint ``grasp`` and the contiguous waypoints before and after it within LIFT_XY_M sideways of it: the
    descent to it and the lift from it, which move with it."""
    near = np.linalg.norm(points[:, :2] - points[grasp, :2], axis=1) <= LIFT_XY_M
    lo, hi = grasp, grasp
    while lo > 0 and near[lo - 1]:
        lo -= 1
    while hi + 1 < len(points) and near[hi + 1]:
        hi += 1
    return list(range(lo, hi + 1))


def shifted_plan(plan, camera, start: int, grasp: int, shift_m: np.ndarray, step: int):
    """``plan`` from its waypoint ``start`` on, with every waypoint from ``start`` to the grasp ``grasp`` (the way
    there and the descent) and the lift after it (:func:`grasp_neighbourhood`) moved by ``shift_m`` [m, world]; the
    rest (the carry, the release) stays. Pixels and depths re-projected through the camera the plan is lifted with."""
    from tcot_hybrid.plan import WaypointPlan

    if not 0 <= start <= grasp < len(plan):
        raise ValueError(f"need 0 <= start <= grasp < {len(plan)} waypoints, got start {start}, grasp {grasp}")
    cam = plan.lift_camera(camera)
    pts = cam.unproject(plan.uv_px, plan.depth_m)
    grip = np.asarray(plan.gripper_closed, bool)
    moving = set(range(start, grasp + 1)) | {i for i in grasp_neighbourhood(pts, grasp) if i >= start}
    pts[sorted(moving)] += np.asarray(shift_m, float)
    uv, depth = cam.project(pts[start:])
    return WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=grip[start:], camera=plan.camera, kind=plan.kind,
                        step=step, tcp_rot=None if plan.tcp_rot is None else plan.tcp_rot[start:],
                        calibration=plan.calibration,
                        meta={**plan.meta, "tracked_from_step": plan.step,
                              "tracked_shift_m": np.round(shift_m, 4).tolist()})


@dataclass
class GraspAnchor:
    """The next grasp of a global plan, as seen in the image the plan (or its last shift) was made from."""

    plan: object             # the WaypointPlan it belongs to (identity: a new plan needs a new anchor)
    image: np.ndarray        # the plan's image
    point_m: np.ndarray      # the grasp point [m, world]
    uv_px: np.ndarray        # its pixel in that image
    plan_index: int          # its index among the plan's waypoints
    closes: int              # executor.closes when it was made: once the hand has closed, it is done
    candidate: np.ndarray | None = None  # where the last look found the object moved to [px]
    seen: int = 0            # consecutive looks that found it there

    def done(self, executor) -> bool:
        return executor.closes != self.closes


def grasp_anchor(plan, executor, image: np.ndarray) -> GraspAnchor | None:
    """The anchor of ``plan``'s next grasp among the points the executor has not reached yet, or None (the hand is
    closed, or the plan grasps nothing more)."""
    if executor.index < 0 or not len(executor.points) or executor.sim.gripper_closed_cmd():
        return None
    ahead = np.flatnonzero(np.asarray(executor.grip[executor.index:], bool))
    if not ahead.size:
        return None
    i = executor.index + int(ahead[0])
    point = executor.points[i].copy()
    uv, depth = plan.lift_camera(executor.camera).project(point[None])
    if not depth[0] > 0:
        return None
    return GraspAnchor(plan=plan, image=image, point_m=point, uv_px=uv[0], plan_index=int(executor.point_source[i]),
                       closes=executor.closes)
