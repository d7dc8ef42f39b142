"""Switch tracking: has what a frozen global plan grasps, or where it puts it down, moved since the plan's image?

A global plan is made from one image and then followed frozen (``supervisor.t_f``); when the object it reaches for is
moved meanwhile (knocked, slid, or by the ``object_moved`` perturbation), the plan closes the hand where the object
was, and when the plate or bowl it places onto moves (``target_moved``), it lets go where the plate was. The
supervisor watches both in the planner camera until the hand closes (afterwards what it carries changes the view by
itself), each against the plan's image:

* the grasp (:func:`look`): the small patch around the grasp point's pixel is the object as the planner saw it. When
  it no longer matches there and matches again nearby where the image changed (something appeared), the object moved
  by that much. OpenCV's normalised cross-correlation (``cv2.matchTemplate``, TM_CCOEFF_NORMED) on lightly blurred
  images; the new spot must be where the image changed, so a look-alike that stayed put (another black bowl, a second
  can) is not taken for the moved object.
* the release of a placement (:func:`look_receptacle`): a plate is featureless inside and the plan lets go near its
  rim, so a small patch finds nothing. The larger window around the release pixel is compared instead, only at the
  pixels that changed since the plan's image (the receptacle's old place and its new one), by masked squared
  differences (``cv2.matchTemplate``, TM_SQDIFF with a mask): the shift that carries those pixels onto changed pixels
  of the new image that look like them is the receptacle's move. Only a release after a lift counts as a placement
  (``placement_lift_m``): a drawer's handle let go at the end of a pull lies where the arm passes on its way. And it
  is looked at only while the object to grasp is still as the plan saw it: one that moved away from beside its plate
  changes the plate's window as a moved plate does.

The way to a grasp, the grasp and its lift, or a release's descent, release and retreat, are shifted with what moved
(:func:`shifted_plan`) and followed on. Non-privileged: the planner camera's images and its calibration, nothing from
the simulator. Measured in docs/libero-planner.md, "Tracking what the plan grasps".
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from tcot_hybrid.config import require_bool, require_choice, require_in_range, require_int, require_positive

TRACK_MODES = ("auto", "on", "off")
LIFT_XY_M = 0.02  # waypoints this close sideways to a switch are its descent and lift or retreat: they move with it [m]


@dataclass(frozen=True, kw_only=True)
class TrackConfig:
    """How the supervisor tracks a frozen global plan's next grasp and the placement after it (module doc). Pixel
    sizes are in the planner image (LIBERO's 128 px: about 0.7 cm a pixel on the table). Needs a planner that looks at
    the image.

    mode:            "on", "off", or "auto": on for LIBERO's GLSR (chosen on development layouts under
                     ``object_moved`` and ``target_moved``: docs/libero-planner.md, "Tracking what the plan grasps"),
                     off on the workcell (its reporting tables were measured without it). Global-only and local-only
                     never track.
    every_steps:     planner steps between two looks (each renders the planner image). Down: sooner, costlier.
    patch_px:        half size of the patch around the grasp point's pixel [px] (13 x 13 at 6). Up: more context
                     (background that moves with nothing), down: less texture to match. Also the radius around the
                     grasp pixel that must be unchanged for a placement to be judged (``look_receptacle``).
    search_px:       how far from that pixel the patch (or, for a placement, the release window) is searched for [px].
    gone_ncc:        the patch counts as gone when its correlation at that pixel falls below this.
    found_ncc:       a match elsewhere must correlate at least this well. Up: fewer wrong moves, more missed ones.
    changed_level:   a pixel whose colour changed by more than this (0-255, any channel, after a 3 x 3 blur) changed.
    changed_frac:    at least this share of a match's patch must have changed (the object appeared there); a
                     placement is not judged while more than this share around the grasp pixel changed.
    max_image_changed: no move is taken when more than this share of the whole image changed (the camera itself
                     moved, or noise): a tracked shift would then be the view's, not the object's.
    min_shift_px:    a match this close to that pixel is no move [px].
    confirm_looks:   consecutive looks that must find the same move (within 2 px) before the plan is shifted: a
                     passing occlusion (``camera_noise``'s patch) moves at random between images, a moved object not.
    hand_clear_m:    a grasp or a release is not looked at while the hand is this close to it [m] (it hides it).
    max_moves:       shifts an episode at most (grasps and releases together).
    releases:        also watch the release of a placement (``look_receptacle``); False: grasps only.
    placement_lift_m: a release counts as a placement when the plan lifts at least this much between its grasp and
                     it, above both [m]; else (a pull, a push) it is not watched.
    release_window_px: half size of the window around the release pixel whose changed pixels are matched [px].
    release_changed_frac: the window is looked at only when at least this share of it changed.
    release_max_residual: a match's RMS colour difference (0-255) must be at most this ...
    release_residual_ratio: ... and at most this share of the difference with no shift (the receptacle left).
    release_landed_frac: at least this share of the changed pixels, shifted, must land on changed pixels (the
                     receptacle appeared there): a move onto unchanged table is no move.
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
    releases: bool = True
    placement_lift_m: float = 0.04
    release_window_px: int = 14
    release_changed_frac: float = 0.1
    release_max_residual: float = 22.0
    release_residual_ratio: float = 0.5
    release_landed_frac: float = 0.25

    def __post_init__(self) -> None:
        require_choice("supervisor.track.mode", self.mode, TRACK_MODES)
        for name in ("every_steps", "patch_px", "search_px", "confirm_looks", "release_window_px"):
            require_int(f"supervisor.track.{name}", getattr(self, name), minimum=1)
        require_int("supervisor.track.max_moves", self.max_moves, minimum=0)
        require_bool("supervisor.track.releases", self.releases)
        for name in ("changed_level", "min_shift_px", "hand_clear_m", "placement_lift_m", "release_max_residual"):
            require_positive(f"supervisor.track.{name}", getattr(self, name))
        # found_ncc = -1 would take the score look() gives "no changed spot" as a match
        for name, lowest, closed in (("gone_ncc", -1.0, True), ("found_ncc", -1.0, False),
                                     *((n, 0.0, False) for n in ("changed_frac", "max_image_changed",
                                                                 "release_changed_frac", "release_residual_ratio",
                                                                 "release_landed_frac"))):
            require_in_range(f"supervisor.track.{name}", getattr(self, name), lowest, 1.0, low_closed=closed)

    def enabled(self, world_kind: str) -> bool:
        return self.mode == "on" or (self.mode == "auto" and world_kind == "libero")


class Look(NamedTuple):
    """One comparison between the plan's image and a later one at a grasp (:func:`look`: correlations) or a release
    (:func:`look_receptacle`: RMS colour differences)."""

    here: float           # the score with no shift (at the switch's own pixel)
    best: float           # the best score (grasp: among changed spots, -1 when none; release: at the best shift)
    uv_px: np.ndarray     # where that best match is [px]
    image_changed: float  # share of the image's pixels that changed
    moved: bool           # what was at the pixel is gone from it and found at ``uv_px``


def _blurred_and_changed(before: np.ndarray, after: np.ndarray, cfg: TrackConfig):
    """Both images 3 x 3-blurred (float32) and the mask of pixels whose colour changed by more than
    ``cfg.changed_level`` in any channel."""
    import cv2

    if before.shape != after.shape or before.ndim != 3:
        raise ValueError(f"images must be two (H, W, 3) arrays of one shape, got {before.shape} and {after.shape}")
    i0 = cv2.GaussianBlur(before.astype(np.float32), (3, 3), 0)
    i1 = cv2.GaussianBlur(after.astype(np.float32), (3, 3), 0)
    return i0, i1, np.abs(i1 - i0).max(axis=2) > cfg.changed_level


def look(before: np.ndarray, after: np.ndarray, uv_px: np.ndarray, cfg: TrackConfig) -> Look | None:
    """Compare the patch around ``uv_px`` in ``before`` with ``after`` (both (H, W, 3) uint8 images of the same
    camera); None when the patch is off the image or featureless (nothing to track)."""
    import cv2

    i0, i1, changed = _blurred_and_changed(before, after, cfg)
    changed = changed.astype(np.float32)
    h, r = cfg.patch_px, cfg.search_px
    H, W = before.shape[:2]
    u, v = int(round(float(uv_px[0]))), int(round(float(uv_px[1])))
    if not (h <= u < W - h and h <= v < H - h):
        return None
    tpl = i0[v - h:v + h + 1, u - h:u + h + 1]
    if float(tpl.std()) < 2.0:
        return None
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


def look_receptacle(before: np.ndarray, after: np.ndarray, uv_px: np.ndarray, cfg: TrackConfig,
                    grasp_uv_px: np.ndarray | None = None) -> Look | None:
    """Has the receptacle under the release pixel ``uv_px`` moved between ``before`` and ``after`` (module doc)?
    ``here`` and ``best`` are RMS colour differences (0-255) of the window's changed pixels with no shift and at the
    best shift. A receptacle near the image's edge whose changed pixels would shift off it is not found (the
    cautious way: no move). None when the pixel is off the image, too little of its window changed to say, or the
    object the plan grasps first (at ``grasp_uv_px`` in ``before``) is off the image or no longer as it was: more than
    ``changed_frac`` of the pixels within ``patch_px`` of it changed. One change at a time: an object moved away from
    beside its plate changes the plate's window as a moved plate does (and a hand at the object hides it)."""
    import cv2

    i0, i1, changed = _blurred_and_changed(before, after, cfg)
    H, W = before.shape[:2]
    u, v = int(round(float(uv_px[0]))), int(round(float(uv_px[1])))
    if not (0 <= u < W and 0 <= v < H):
        return None
    if grasp_uv_px is not None:
        yy, xx = np.mgrid[:H, :W]
        near = (xx - float(grasp_uv_px[0])) ** 2 + (yy - float(grasp_uv_px[1])) ** 2 <= cfg.patch_px ** 2
        if not near.any() or changed[near].mean() > cfg.changed_frac:  # an object out of view cannot be judged
            return None
    w, r = cfg.release_window_px, cfg.search_px
    pad = w + r  # near the border the window and its search run off the image: padding that never matches
    u, v = u + pad, v + pad
    changed_p = np.pad(changed, pad)
    window = changed_p[v - w:v + w + 1, u - w:u + w + 1]
    if window.mean() < cfg.release_changed_frac:
        return None
    i0 = np.pad(i0, ((pad, pad), (pad, pad), (0, 0)))
    i1 = np.pad(i1, ((pad, pad), (pad, pad), (0, 0)), constant_values=-1000.0)
    mask = np.repeat(window[:, :, None], 3, axis=2).astype(np.float32)
    sq = cv2.matchTemplate(i1[v - w - r:v + w + r + 1, u - w - r:u + w + r + 1], i0[v - w:v + w + 1, u - w:u + w + 1],
                           cv2.TM_SQDIFF, mask=mask) / float(mask.sum())
    _, _, (bx, by), _ = cv2.minMaxLoc(sq)
    du, dv = bx - r, by - r
    best, here = float(np.sqrt(max(sq[by, bx], 0.0))), float(np.sqrt(max(sq[r, r], 0.0)))
    landed = float((window & changed_p[v - w + dv:v + w + 1 + dv, u - w + du:u + w + 1 + du]).sum() / window.sum())
    image_changed = float(changed.mean())
    at = np.asarray(uv_px, float) + (du, dv)
    moved = (best <= cfg.release_max_residual and best <= cfg.release_residual_ratio * here
             and landed >= cfg.release_landed_frac and image_changed <= cfg.max_image_changed
             and float(np.hypot(du, dv)) >= cfg.min_shift_px)
    return Look(here=here, best=best, uv_px=at, image_changed=image_changed, moved=bool(moved))


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


def switch_neighbourhood(points: np.ndarray, gripper_closed: np.ndarray, switch: int) -> list[int]:
    """Waypoint ``switch`` (the first with the gripper's new state) and the contiguous waypoints before and after it
    within LIFT_XY_M sideways of it, up to the gripper's previous and next switch: the descent to it and the lift or
    retreat from it, which move with it (a grasp just beside its release stays where it is)."""
    near = np.linalg.norm(points[:, :2] - points[switch, :2], axis=1) <= LIFT_XY_M
    grip = np.asarray(gripper_closed, bool)

    def a_switch(j: int) -> bool:
        return j > 0 and grip[j] != grip[j - 1]

    lo, hi = switch, switch
    while lo > 0 and near[lo - 1] and not a_switch(lo - 1):
        lo -= 1
    while hi + 1 < len(points) and near[hi + 1] and not a_switch(hi + 1):
        hi += 1
    return list(range(lo, hi + 1))


def shifted_plan(plan, camera, start: int, switch: int, shift_m: np.ndarray, step: int, *, approach: bool):
    """``plan`` from its waypoint ``start`` on, with waypoint ``switch`` (a grasp or a release) and the descent and the
    lift or retreat around it (:func:`switch_neighbourhood`) moved by ``shift_m`` [m, world], and with ``approach``
    every waypoint from ``start`` to it too (the way to a grasp; a release keeps the carry). Pixels and depths
    re-projected through the camera the plan is lifted with."""
    from tcot_hybrid.plan import WaypointPlan

    if not 0 <= start <= switch < len(plan):
        raise ValueError(f"need 0 <= start <= switch < {len(plan)} waypoints, got start {start}, switch {switch}")
    cam = plan.lift_camera(camera)
    pts = cam.unproject(plan.uv_px, plan.depth_m)
    grip = np.asarray(plan.gripper_closed, bool)
    moving = set(switch_neighbourhood(pts, grip, switch)) | (set(range(start, switch + 1)) if approach else set())
    pts[sorted(i for i in moving if i >= start)] += np.asarray(shift_m, float)
    uv, depth = cam.project(pts[start:])
    return WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=grip[start:], camera=plan.camera, kind=plan.kind,
                        step=step, tcp_rot=None if plan.tcp_rot is None else plan.tcp_rot[start:],
                        calibration=plan.calibration,
                        meta={**plan.meta, "tracked_from_step": plan.step,
                              "tracked_shift_m": np.round(shift_m, 4).tolist()})


@dataclass
class SwitchAnchor:
    """A gripper switch ahead of a global plan (its next grasp, or the placement after it), as seen in the image the
    plan (or its last shift) was made from. Watched until the hand closes."""

    kind: str                # "grasp" | "release"
    plan: object             # the WaypointPlan it belongs to (identity: a new plan needs new anchors)
    image: np.ndarray        # the plan's image
    point_m: np.ndarray      # the switch's TCP point [m, world]
    uv_px: np.ndarray        # its pixel in that image
    plan_index: int          # its index among the plan's waypoints
    closes: int              # executor.closes when it was made: once the hand has closed, it is done
    grasp_uv_px: np.ndarray | None = None  # a release's: the pixel of the grasp before it (look_receptacle)
    candidate: np.ndarray | None = None  # where the last look found it moved to [px]
    seen: int = 0            # consecutive looks that found it there
    refused: bool = False    # the executor refused the plan shifted with it: not offered again

    def done(self, executor) -> bool:
        return executor.closes != self.closes

    def look(self, image: np.ndarray, cfg: TrackConfig) -> Look | None:
        if self.kind == "grasp":
            return look(self.image, image, self.uv_px, cfg)
        return look_receptacle(self.image, image, self.uv_px, cfg, self.grasp_uv_px)


def switch_anchors(plan, executor, image: np.ndarray, cfg: TrackConfig) -> list[SwitchAnchor]:
    """Anchors of ``plan``'s next grasp among the points the executor has not reached yet and, with
    ``cfg.releases``, of the release after it when that is a placement (``cfg.placement_lift_m``); none while the hand
    is closed."""
    if executor.index < 0 or not len(executor.points) or executor.sim.gripper_closed_cmd():
        return []
    grip = np.asarray(executor.grip, bool)
    ahead = np.flatnonzero(grip[executor.index:])
    if not ahead.size:
        return []
    grasp = executor.index + int(ahead[0])
    wanted = [("grasp", grasp)]
    opens = np.flatnonzero(~grip[grasp:])
    if cfg.releases and opens.size:
        release = grasp + int(opens[0])
        z = executor.points[grasp:release + 1, 2]
        if z.max() - max(z[0], z[-1]) >= cfg.placement_lift_m:
            wanted.append(("release", release))
    cam = plan.lift_camera(executor.camera)
    uv, depth = cam.project(executor.points[[i for _, i in wanted]])
    out = []
    for (kind, i), uv_i, depth_i in zip(wanted, uv, depth):
        if depth_i > 0 and depth[0] > 0:  # a placement is judged only beside its grasp's pixel (look_receptacle)
            out.append(SwitchAnchor(kind=kind, plan=plan, image=image, point_m=executor.points[i].copy(), uv_px=uv_i,
                                    plan_index=int(executor.point_source[i]), closes=executor.closes,
                                    grasp_uv_px=uv[0] if kind == "release" else None))
    return out
