"""Planner registry: one place that knows how to build each planner by name."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.errors import ConfigError, unknown_name
from tcot_hybrid.planners.base import MODES, Observation, Planner
from tcot_hybrid.tasks import Task, World


@dataclass(frozen=True, kw_only=True)
class PlannerContext:
    """Everything a planner factory may use. Only the oracle may read ``world`` (privileged)."""

    task: Task
    world: World
    camera: CameraModel
    robot_name: str
    options: dict[str, Any]
    robot: Any = None  # the run's RobotSpec: checkpoints are matched to it by model digest, not by name


_FACTORIES: dict[str, Callable[[PlannerContext], Planner]] = {}


def register_planner(name: str):
    def deco(factory: Callable[[PlannerContext], Planner]):
        _FACTORIES[name] = factory
        return factory
    return deco


def list_planners() -> list[str]:
    return sorted(_FACTORIES)


def check_planner_name(name: str) -> None:
    if name not in _FACTORIES:
        raise ConfigError(unknown_name("planner", name, _FACTORIES))


# Planners that run a network checkpoint, and the checkpoint kind each loads.
CHECKPOINT_KINDS = {"learned": "trajectory", "direct": "direct"}


def planner_checkpoint(name: str, robot: str, checkpoint: str | Path | None, *,
                       robot_ref: str | None = None) -> Path | None:
    """The checkpoint file planner ``name`` loads: ``checkpoint`` if given, else the robot's shipped default
    (``CheckpointError`` naming the shipped ones if there is none); None for planners without a network.
    ``robot_ref`` is how the user names the robot (a path for one of their own), for the error's advice."""
    kind = CHECKPOINT_KINDS.get(name)
    if kind is None:
        return None
    from tcot_hybrid.learning.checkpoint import default_checkpoint

    return Path(checkpoint) if checkpoint else default_checkpoint(robot, kind, robot_ref=robot_ref)


def make_planner(name: str, ctx: PlannerContext) -> Planner:
    check_planner_name(name)
    return _FACTORIES[name](ctx)


@register_planner("oracle")
def _oracle(ctx: PlannerContext) -> Planner:
    from tcot_hybrid.planners.oracle import OracleConfig, OraclePlanner

    return OraclePlanner(ctx.task, ctx.world, ctx.camera, config=ctx.options.get("oracle", OracleConfig()))


@register_planner("learned")
def _learned(ctx: PlannerContext) -> Planner:
    from tcot_hybrid.planners.learned import LearnedPlanner  # lazy: torch loads only when needed

    return LearnedPlanner.from_context(ctx)


@register_planner("direct")
def _direct(ctx: PlannerContext) -> Planner:
    from tcot_hybrid.planners.direct import DirectPlanner

    return DirectPlanner.from_context(ctx)


__all__ = ["MODES", "Observation", "Planner", "PlannerContext", "list_planners", "make_planner",
           "register_planner", "check_planner_name"]
