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
from tcot_hybrid.tasks.base import TRAVEL_Z, Keyframe


RESUME_LATERAL_M = 0.02  # [m] a TCP this close (in xy) to the scripted approach resumes along it


@dataclass(frozen=True, kw_only=True)
class OracleConfig:
    """spacing_m: max distance between consecutive waypoints [m]; smaller = straighter paths, more IK calls.
    local_waypoints: waypoints in a local plan; more = longer horizon between replans.
    """

    spacing_m: float = 0.04
    local_waypoints: int = 6

    def __post_init__(self) -> None:
        require_positive("spacing_m", self.spacing_m)
        require_int("local_waypoints", self.local_waypoints, minimum=1)


def densify(keyframes: list[Keyframe], start: np.ndarray, spacing: float, *,
            start_closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Insert points so no two consecutive ones are farther apart than ``spacing`` [m].

    A keyframe's gripper bit applies from the keyframe on, so the points leading up to it keep the
    previous command (``start_closed`` before the first keyframe).
    """
    pts, grip = [], []
    prev, prev_closed = np.asarray(start, dtype=float), bool(start_closed)
    for kf in keyframes:
        n = max(int(np.ceil(np.linalg.norm(kf.pos - prev) / spacing)), 1)
        for i in range(1, n + 1):
            pts.append(prev + (kf.pos - prev) * i / n)
            grip.append(kf.closed if i == n else prev_closed)
        prev, prev_closed = kf.pos, kf.closed
    return np.array(pts), np.array(grip, dtype=bool)


class OraclePlanner(Planner):
    name = "oracle"
    needs_image = False

    def __init__(self, task: Task, world: World, camera: CameraModel, *, config: OracleConfig = OracleConfig()):
        self.task, self.world, self.camera, self.config = task, world, camera, config

    def path(self, *, gripper_closed: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Dense 3D path [m] and gripper bits for the not-yet-achieved skills, from the current TCP.

        When the TCP is already on the scripted approach (e.g. halfway down to a grasp after a local
        replan), the path resumes from the nearest point of that approach instead of starting over.
        """
        keyframes: list[Keyframe] = []
        for skill in self.task.skills():
            if not skill.done(self.world):
                keyframes += skill.keyframes(self.world)
        tcp = self.world.tcp_pos()
        if not keyframes:  # nothing left to do: hold here
            return tcp[None, :], np.array([gripper_closed])
        points, grip = densify(keyframes, keyframes[0].pos, self.config.spacing_m, start_closed=keyframes[0].closed)
        points, grip = np.vstack([keyframes[0].pos, points]), np.append(keyframes[0].closed, grip)
        toggles = np.flatnonzero(grip != grip[0])
        last = int(toggles[0]) if toggles.size else len(points) - 1
        lateral = np.linalg.norm(points[: last + 1, :2] - tcp[:2], axis=1)
        on_path = np.flatnonzero(lateral <= RESUME_LATERAL_M)
        start = 0
        if on_path.size:
            start = int(on_path[np.argmin(np.linalg.norm(points[on_path] - tcp, axis=1))])
        rest = [Keyframe(p, bool(g)) for p, g in zip(points[start:], grip[start:])]
        if start == 0 and not gripper_closed and tcp[2] < TRAVEL_Z - 0.02 and \
                np.linalg.norm(rest[0].pos[:2] - tcp[:2]) > RESUME_LATERAL_M:
            # Low with an open gripper (e.g. just released) and heading elsewhere: go straight up first so
            # the open fingers do not drag what was just placed.
            rest.insert(0, Keyframe(np.array([tcp[0], tcp[1], TRAVEL_Z]), False))
        return densify(rest, tcp, self.config.spacing_m, start_closed=gripper_closed)

    def success_probability(self, obs: Observation) -> float:
        """Privileged: the simulator's own success predicate (the detector's upper bound)."""
        return 1.0 if self.task.success(self.world) else 0.0

    def plan(self, obs: Observation, *, mode: str) -> WaypointPlan:
        if mode not in MODES:
            raise PlanningError(f"oracle plan mode {mode!r} is not one of {', '.join(MODES)}")
        points, grip = self.path(gripper_closed=obs.gripper_closed)
        if mode == "local":
            points, grip = points[: self.config.local_waypoints], grip[: self.config.local_waypoints]
        uv, depth = self.camera.project(points)
        return WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=grip, camera=self.camera.name, kind=mode,
                            step=obs.step, meta={"points_world": points})
