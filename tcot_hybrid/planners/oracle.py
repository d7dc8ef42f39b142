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
from tcot_hybrid.tasks.base import Keyframe


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


def densify(keyframes: list[Keyframe], start: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Insert points so no two consecutive ones are farther apart than ``spacing`` [m]."""
    pts, grip = [], []
    prev = np.asarray(start, dtype=float)
    for kf in keyframes:
        n = max(int(np.ceil(np.linalg.norm(kf.pos - prev) / spacing)), 1)
        for i in range(1, n + 1):
            pts.append(prev + (kf.pos - prev) * i / n)
            grip.append(kf.closed if i == n else (grip[-1] if grip else False))
        prev = kf.pos
    return np.array(pts), np.array(grip, dtype=bool)


class OraclePlanner(Planner):
    name = "oracle"
    needs_image = False

    def __init__(self, task: Task, world: World, camera: CameraModel, *, config: OracleConfig = OracleConfig()):
        self.task, self.world, self.camera, self.config = task, world, camera, config

    def path(self) -> tuple[np.ndarray, np.ndarray]:
        """Dense 3D path [m] and gripper bits for the not-yet-achieved skills, from the current TCP."""
        keyframes: list[Keyframe] = []
        for skill in self.task.skills():
            if not skill.done(self.world):
                keyframes += skill.keyframes(self.world)
        tcp = self.world.tcp_pos()
        if not keyframes:  # nothing left to do: hold here
            return tcp[None, :], np.array([False])
        return densify(keyframes, tcp, self.config.spacing_m)

    def plan(self, obs: Observation, *, mode: str) -> WaypointPlan:
        if mode not in MODES:
            raise PlanningError(f"oracle plan mode {mode!r} is not one of {', '.join(MODES)}")
        points, grip = self.path()
        if mode == "local":
            points, grip = points[: self.config.local_waypoints], grip[: self.config.local_waypoints]
        uv, depth = self.camera.project(points)
        return WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=grip, camera=self.camera.name, kind=mode,
                            step=obs.step, meta={"points_world": points})
