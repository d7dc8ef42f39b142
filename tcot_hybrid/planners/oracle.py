"""Privileged oracle planner: reads true object poses, emits the same plan type as the learned planner.

It scripts the task as skills (see tasks/base.py), turns their keyframes into a dense 3D path, and
projects that path into the planner camera: pixel + depth lift cue + gripper bit per waypoint. It is the
demonstrator for data collection and the upper bound in evaluations.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.config import require_int, require_positive
from tcot_hybrid.errors import PlanningError
from tcot_hybrid.plan import WaypointPlan
from tcot_hybrid.planners.base import MODES, Observation, Planner
from tcot_hybrid.tasks import Task, World
from tcot_hybrid.robot import R_DOWN
from tcot_hybrid.tasks.base import TRAVEL_Z, Keyframe


RESUME_LATERAL_M = 0.02  # [m] a TCP this close (in xy) to the scripted approach resumes along it


@dataclass(frozen=True, kw_only=True)
class OracleConfig:
    """spacing_m: max distance between consecutive waypoints [m]; smaller = straighter paths, more IK calls.
    rot_spacing_rad: max TCP turn between consecutive waypoints [rad] (skills that tilt or turn the hand);
        smaller = the hand turns more gradually along the path, more waypoints.
    local_waypoints: waypoints in a local plan; more = longer horizon between replans.
    """

    spacing_m: float = 0.04
    rot_spacing_rad: float = 0.3
    local_waypoints: int = 6

    def __post_init__(self) -> None:
        require_positive("spacing_m", self.spacing_m)
        require_positive("rot_spacing_rad", self.rot_spacing_rad)
        require_int("local_waypoints", self.local_waypoints, minimum=1)


def densify_posed(keyframes: list[Keyframe], start: np.ndarray, spacing: float, *, start_closed: bool,
                  start_rot: np.ndarray | None = None,
                  rot_spacing: float = np.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Insert points so no two consecutive ones are farther apart than ``spacing`` [m] or turned more than
    ``rot_spacing`` [rad]; orientations are slerped between keyframes (None = ``R_DOWN``).

    A keyframe's gripper bit applies from the keyframe on, so the points leading up to it keep the
    previous command (``start_closed`` before the first keyframe). Returns points (N, 3), bits (N,) and
    orientations (N, 3, 3).
    """
    from scipy.spatial.transform import Rotation, Slerp

    pts, grip, rots = [], [], []
    prev, prev_closed = np.asarray(start, dtype=float), bool(start_closed)
    prev_rot = Rotation.from_matrix(R_DOWN if start_rot is None else start_rot)
    for kf in keyframes:
        rot = Rotation.from_matrix(R_DOWN if kf.rot is None else kf.rot)
        angle = float((prev_rot.inv() * rot).magnitude())
        n = max(int(np.ceil(np.linalg.norm(kf.pos - prev) / spacing)), int(np.ceil(angle / rot_spacing)), 1)
        slerp = Slerp([0.0, 1.0], Rotation.concatenate([prev_rot, rot]))
        turned = slerp(np.arange(1, n + 1) / n).as_matrix()
        for i in range(1, n + 1):
            pts.append(prev + (kf.pos - prev) * i / n)
            grip.append(kf.closed if i == n else prev_closed)
            rots.append(turned[i - 1])
        prev, prev_closed, prev_rot = kf.pos, kf.closed, rot
    return np.array(pts), np.array(grip, dtype=bool), np.array(rots).reshape(-1, 3, 3)


def densify(keyframes: list[Keyframe], start: np.ndarray, spacing: float, *,
            start_closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Positions and gripper bits of :func:`densify_posed` (top-down skills)."""
    points, grip, _ = densify_posed(keyframes, start, spacing, start_closed=start_closed)
    return points, grip


class OraclePlanner(Planner):
    name = "oracle"
    needs_image = False

    def __init__(self, task: Task, world: World, camera: CameraModel, *, config: OracleConfig = OracleConfig()):
        self.task, self.world, self.camera, self.config = task, world, camera, config

    def path(self, *, gripper_closed: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Dense 3D path [m] and gripper bits (see :meth:`path_posed`)."""
        points, grip, _ = self.path_posed(gripper_closed=gripper_closed)
        return points, grip

    def path_posed(self, *, gripper_closed: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Dense 3D path [m], gripper bits and TCP orientations (None when every skill is top-down) for the
        not-yet-achieved skills, from the current TCP.

        When the TCP is already on the scripted approach (e.g. halfway down to a grasp after a local
        replan), the path resumes from the nearest point of that approach instead of starting over.
        """
        keyframes: list[Keyframe] = []
        for skill in self.task.skills():
            if not skill.done(self.world):
                keyframes += skill.keyframes(self.world)
        tcp = self.world.tcp_pos()
        posed = any(kf.rot is not None for kf in keyframes)
        if not keyframes:  # nothing left to do: hold here
            return tcp[None, :], np.array([gripper_closed]), None
        cfg = self.config
        points, grip, rots = densify_posed(keyframes, keyframes[0].pos, cfg.spacing_m, start_closed=keyframes[0].closed,
                                           start_rot=keyframes[0].rot, rot_spacing=cfg.rot_spacing_rad)
        points, grip = np.vstack([keyframes[0].pos, points]), np.append(keyframes[0].closed, grip)
        rots = np.concatenate([(R_DOWN if keyframes[0].rot is None else keyframes[0].rot)[None], rots])
        toggles = np.flatnonzero(grip != grip[0])
        last = int(toggles[0]) if toggles.size else len(points) - 1
        lateral = np.linalg.norm(points[: last + 1, :2] - tcp[:2], axis=1)
        on_path = np.flatnonzero(lateral <= RESUME_LATERAL_M)
        start = 0
        if on_path.size:
            start = int(on_path[np.argmin(np.linalg.norm(points[on_path] - tcp, axis=1))])
        rest = [Keyframe(p, bool(g), r if posed else None) for p, g, r in zip(points[start:], grip[start:], rots[start:])]
        travel_z = getattr(self.task, "travel_z", TRAVEL_Z)
        if start == 0 and not gripper_closed and tcp[2] < travel_z - 0.02 and \
                np.linalg.norm(rest[0].pos[:2] - tcp[:2]) > RESUME_LATERAL_M:
            # Low with an open gripper (e.g. just released) and heading elsewhere: go straight up first so
            # the open fingers do not drag what was just placed.
            rest.insert(0, Keyframe(np.array([tcp[0], tcp[1], travel_z]), False,
                                    self.world.tcp_rot() if posed else None))
        points, grip, rots = densify_posed(rest, tcp, cfg.spacing_m, start_closed=gripper_closed,
                                           start_rot=self.world.tcp_rot() if posed else None,
                                           rot_spacing=cfg.rot_spacing_rad)
        return points, grip, (rots if posed else None)

    def prepare(self) -> None:
        """Compose the script and its grasps for the settled scene (LIBERO's take ~0.6 s, and the first call
        is timed: under load it went stale): the first plan at this instant reuses them. A script that cannot be
        composed is left to the first plan call, which raises the same PlanningError and the episode logs it
        as a rejected plan (it is no crash)."""
        try:
            self.path_posed()
        except PlanningError:
            pass

    def success_probability(self, obs: Observation) -> float:
        """Privileged: the simulator's own success predicate (the detector's upper bound)."""
        return 1.0 if self.task.success(self.world) else 0.0

    def plan(self, obs: Observation, *, mode: str) -> WaypointPlan:
        if mode not in MODES:
            raise PlanningError(f"oracle plan mode {mode!r} is not one of {', '.join(MODES)}")
        points, grip, rots = self.path_posed(gripper_closed=obs.gripper_closed)
        if mode == "local":
            k = self.config.local_waypoints
            points, grip, rots = points[:k], grip[:k], (None if rots is None else rots[:k])
        uv, depth = self.camera.project(points)
        return WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=grip, camera=self.camera.name, kind=mode,
                            step=obs.step, tcp_rot=rots, meta={"points_world": points})
