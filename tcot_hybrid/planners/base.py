"""Planner interface: observation in, ``WaypointPlan`` out (and, for learned planners, p(success))."""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from tcot_hybrid.plan import WaypointPlan

MODES = ("global", "local")


@dataclass(frozen=True, kw_only=True)
class Observation:
    """What a planner may see at planner step ``step``.

    image:   planner-camera RGB (H, W, 3) uint8, or None when the planner does not need one
    depth_m: planner-camera depth (H, W) [m] along the optical axis, or None
    q:       arm joint positions [rad]
    gripper_closed: current gripper command
    instruction: the task's natural-language instruction
    tcp_pos_m: the TCP's world position from the measured joints (forward kinematics) [m], or None; the
             learned planner checks its camera's calibration against where it sees the hand
             (:mod:`tcot_hybrid.calibration`)
    """

    step: int
    image: np.ndarray | None
    depth_m: np.ndarray | None
    q: np.ndarray
    gripper_closed: bool
    instruction: str
    tcp_pos_m: np.ndarray | None = None


class Planner(ABC):
    """Produces waypoint plans. ``needs_image`` tells the episode loop whether to render for it."""

    name: ClassVar[str]
    needs_image: ClassVar[bool] = True
    has_detector: ClassVar[bool] = False  # success_probability works (GLSR, --stop-on detector)
    replan_every_step: ClassVar[bool] = False  # direct-action policies act every step

    @abstractmethod
    def plan(self, obs: Observation, *, mode: str) -> WaypointPlan:
        """A global (whole task) or local (short horizon from now) plan."""

    def prepare(self) -> None:
        """Work done once the scene has settled and before the first planner call, outside the plan latency
        budget (``max_plan_latency_s`` times planner calls, not episode set-up). Default: nothing."""

    def success_probability(self, obs: Observation) -> float:
        """p(task successful) for failure detection; planners without a detector cannot run GLSR."""
        from tcot_hybrid.errors import PlanningError

        raise PlanningError(f"planner {self.name!r} has no failure detector; GLSR modes need one")
