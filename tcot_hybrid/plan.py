"""The plan type every planner emits: 2D pixel waypoints in the planner camera + lift cue + gripper bit.

The oracle, the learned planner and any future planner produce exactly this, so the classical half
of the stack (lift → IK → smoothing → controller) is exercised identically whichever planner runs.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.errors import PlanningError

PLAN_KINDS = ("global", "local", "direct")
ROT_TOL = 1e-6  # max |R^T R - I| entry of a waypoint orientation


@dataclass(frozen=True, kw_only=True)
class WaypointPlan:
    """Waypoints in the planner camera image.

    uv_px:          (N, 2) pixel coordinates (u right, v down) [px]
    depth_m:        (N,) lift cue: depth along the planner camera's optical axis (OpenCV z) [m]
    gripper_closed: (N,) gripper command to hold from this waypoint on (True = closed)
    camera:         name of the planner camera the pixels live in
    kind:           "global" (whole task), "local" (short horizon) or "direct" (one-step action)
    step:           planner step at which the plan was made
    calibration:    the planner camera model the pixels and depths are lifted with when it is not the
                    stack's nominal one (a pose re-estimated during the episode: :mod:`tcot_hybrid.calibration`);
                    None = the nominal calibration
    tcp_rot:        optional (N, 3, 3) TCP orientation per waypoint in the world frame (columns: the TCP's
                    x, y = finger closing axis, z = approach axis). None = top-down with the fingers closing
                    along world y (``robot.R_DOWN``), all the workcell's skills need. LIBERO's skills grasp
                    tilted and turned (rims, handles, knobs), so its oracle gives one per waypoint.
    """

    uv_px: np.ndarray
    depth_m: np.ndarray
    gripper_closed: np.ndarray
    camera: str
    kind: str
    step: int = 0
    tcp_rot: np.ndarray | None = None
    calibration: CameraModel | None = field(default=None, compare=False)
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        try:  # non-numeric output is a refused plan like NaN, not a crash
            uv = np.asarray(self.uv_px, dtype=float)
            depth = np.asarray(self.depth_m, dtype=float)
        except (TypeError, ValueError) as exc:
            raise PlanningError(f"uv_px and depth_m must be numeric arrays: {exc}") from exc
        grip = np.asarray(self.gripper_closed)
        if uv.ndim != 2 or uv.shape[1] != 2 or uv.shape[0] == 0:
            raise PlanningError(f"uv_px must have shape (N>=1, 2), got {uv.shape}")
        n = uv.shape[0]
        if depth.shape != (n,):
            raise PlanningError(f"depth_m must have shape ({n},) to match uv_px, got {depth.shape}")
        if grip.shape != (n,):
            raise PlanningError(f"gripper_closed must have shape ({n},) to match uv_px, got {grip.shape}")
        if grip.dtype != bool:  # 0/1 numbers are bits too; NaN, 0.5 or a string would be a silent guess
            is_bit = np.zeros(n, bool)
            if grip.dtype.kind in "iuf":
                is_bit = (grip == 0) | (grip == 1)
            if not is_bit.all():
                i = int(np.flatnonzero(~is_bit)[0])
                raise PlanningError(f"gripper_closed[{i}] = {grip[i]!r} is not a bit (bool or 0/1)")
        bad = np.flatnonzero(~np.isfinite(uv).all(axis=1) | ~np.isfinite(depth))
        if bad.size:
            i = int(bad[0])
            raise PlanningError(
                f"waypoint {i} is not finite: uv_px={uv[i].tolist()}, depth_m={depth[i]} "
                f"({bad.size} of {n} waypoints bad)"
            )
        if self.tcp_rot is not None:
            try:
                rot = np.asarray(self.tcp_rot, dtype=float)
            except (TypeError, ValueError) as exc:
                raise PlanningError(f"tcp_rot must be a numeric array: {exc}") from exc
            if rot.shape != (n, 3, 3):
                raise PlanningError(f"tcp_rot must have shape ({n}, 3, 3) to match uv_px, got {rot.shape}")
            ortho = np.abs(np.einsum("nji,njk->nik", rot, rot) - np.eye(3)).max(axis=(1, 2)) if n else np.zeros(0)
            bad_rot = np.flatnonzero(~np.isfinite(ortho) | (ortho > ROT_TOL) | (np.linalg.det(rot) < 0))
            if bad_rot.size:
                i = int(bad_rot[0])
                raise PlanningError(f"tcp_rot[{i}] is not a rotation matrix (|R^T R - I| = {ortho[i]:.3g}, "
                                    f"det = {np.linalg.det(rot[i]):.3g})")
            rot = rot.copy()
            rot.setflags(write=False)
            object.__setattr__(self, "tcp_rot", rot)
        if self.kind not in PLAN_KINDS:
            raise PlanningError(f"plan kind {self.kind!r} is not one of {', '.join(PLAN_KINDS)}")
        if self.calibration is not None and self.calibration.name != self.camera:
            raise PlanningError(f"plan calibration is of camera {self.calibration.name!r}, but its pixels live in "
                                f"camera {self.camera!r}")
        for name, arr in (("uv_px", uv), ("depth_m", depth), ("gripper_closed", grip.astype(bool))):
            arr = np.array(arr)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def lift_camera(self, nominal: CameraModel) -> CameraModel:
        """The camera model this plan's pixels and depths are lifted with: its own calibration, else ``nominal``."""
        return nominal if self.calibration is None else self.calibration

    def __len__(self) -> int:
        return int(self.uv_px.shape[0])
