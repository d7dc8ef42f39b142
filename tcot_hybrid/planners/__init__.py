"""Planner registry: one place that knows how to build each planner by name.

The boundary between privileged and deployable planners is structural: a factory registered with
``privileged=True`` (the scripted oracle) gets the task and the simulator world; every other factory gets an
:class:`ObservationContext` (camera model, robot name, settings) and, per step, an :class:`Observation` (image,
proprioception, instruction) — no reference to simulator state (``tests/test_planner_boundary.py``)."""
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
class ObservationContext:
    """What an observation-only planner's factory gets: how to read observations, nothing about the world.

    camera:     the planner camera's model (intrinsics, pose, image size): the calibration a real robot has.
    robot_name: the robot (checkpoint compatibility, its own kinematic model).
    options:    planner settings (``RunConfig.oracle`` / ``learned``, the checkpoint path, and the task and its
                suite, which choose a shipped checkpoint when no path is given).
    robot:      the run's RobotSpec (its model, as a real robot knows its own): checkpoints are matched to it
                by model digest, not by name. None when unknown (then the name is compared).
    world_kind: "workcell" or "libero": which world the task is in (checkpoints are refused in another world).
    T_world_base: the robot's mounting pose in the world (4x4; the base calibration a real robot has, like its
                camera's): where its own kinematics sit in the frame plans are lifted in. Identity in the
                workcell; LIBERO mounts the arm at e.g. (-0.66, 0, 0.912). None: the identity.
    At every step the planner then gets an :class:`Observation` (image, proprioception, instruction).
    """

    camera: CameraModel
    robot_name: str
    options: dict[str, Any]
    robot: Any = None
    world_kind: str = "workcell"
    T_world_base: Any = None


@dataclass(frozen=True, kw_only=True)
class PlannerContext:
    """The privileged context: the observation context's fields plus the task (its scripted skills) and the
    live simulator ``world``. Only factories registered with ``privileged=True`` (the oracle) receive it;
    :func:`make_planner` hands every other factory :meth:`observation_only`, so a learned planner cannot reach
    simulator state by construction."""

    task: Task
    world: World
    camera: CameraModel
    robot_name: str
    options: dict[str, Any]
    robot: Any = None  # the run's RobotSpec: checkpoints are matched to it by model digest, not by name
    world_kind: str = "workcell"  # "workcell" or "libero"
    T_world_base: Any = None  # the robot's mounting pose (4x4, a calibration; None: identity)

    def observation_only(self) -> ObservationContext:
        import numpy as np

        base = None if self.T_world_base is None else np.array(self.T_world_base, dtype=float)  # a copy
        return ObservationContext(camera=self.camera, robot_name=self.robot_name, options=dict(self.options),
                                  robot=self.robot, world_kind=self.world_kind, T_world_base=base)


_FACTORIES: dict[str, Callable[[Any], Planner]] = {}
_PRIVILEGED: set[str] = set()


def register_planner(name: str, *, privileged: bool = False):
    """Register a planner factory under ``name``. The factory gets an :class:`ObservationContext`; with
    ``privileged=True`` a :class:`PlannerContext` (task and simulator world: scripted oracles only)."""
    def deco(factory: Callable[[Any], Planner]):
        _FACTORIES[name] = factory
        _PRIVILEGED.discard(name)
        if privileged:
            _PRIVILEGED.add(name)
        return factory
    return deco


def is_privileged(name: str) -> bool:
    """Whether planner ``name`` reads the simulator world (its figures are not those of a deployable planner)."""
    check_planner_name(name)
    return name in _PRIVILEGED


def list_planners() -> list[str]:
    return sorted(_FACTORIES)


def check_planner_name(name: str) -> None:
    if name not in _FACTORIES:
        raise ConfigError(unknown_name("planner", name, _FACTORIES))


# Planners that run a network checkpoint, and the checkpoint kind each loads.
CHECKPOINT_KINDS = {"learned": "trajectory", "direct": "direct"}


def check_checkpoint_used(checkpoint: str | Path | None, planners: list[str]) -> None:
    """Refuse a ``--checkpoint`` no planner of the run loads (e.g. the oracle alone): it would be ignored."""
    if checkpoint is not None and not any(p in CHECKPOINT_KINDS for p in planners):
        raise ConfigError(f"checkpoint {str(checkpoint)!r} is loaded by no planner of this run "
                          f"({', '.join(planners)}); the planners that load one: {', '.join(sorted(CHECKPOINT_KINDS))}")


def planner_checkpoint(name: str, robot: str, checkpoint: str | Path | None, *, suite: str | None = None,
                       task: str | None = None, robot_ref: str | None = None) -> Path | None:
    """The checkpoint file planner ``name`` loads: ``checkpoint`` if given, else the robot's shipped default for
    ``task`` of ``suite`` (a model routed to that task, else that suite's own model if one is shipped;
    ``CheckpointError`` naming the shipped ones if there is none); None for planners without a network.
    ``robot_ref`` is how the user names the robot (a path for one of their own), for the error's advice."""
    kind = CHECKPOINT_KINDS.get(name)
    if kind is None:
        return None
    from tcot_hybrid.learning.checkpoint import default_checkpoint

    return Path(checkpoint) if checkpoint else default_checkpoint(robot, kind, suite=suite, task=task,
                                                                  robot_ref=robot_ref)


def run_checkpoint(cfg: Any) -> Path | None:
    """:func:`planner_checkpoint` of a run configuration (a ``RunConfig``): its planner, robot and ``--checkpoint``,
    else the shipped model for its task and that task's suite."""
    from tcot_hybrid.tasks import make_task

    task = make_task(cfg.task)
    return planner_checkpoint(cfg.planner, cfg.robot, cfg.checkpoint, suite=task.suite, task=task.name)


def context_checkpoint(name: str, ctx: ObservationContext) -> Path | None:
    """:func:`planner_checkpoint` for a planner built from ``ctx`` (its options' checkpoint, task and suite)."""
    from tcot_hybrid.robot import robot_ref

    return planner_checkpoint(name, ctx.robot_name, ctx.options.get("checkpoint"), suite=ctx.options.get("suite"),
                              task=ctx.options.get("task"),
                              robot_ref=robot_ref(ctx.robot) if ctx.robot is not None else None)


def make_planner(name: str, ctx: PlannerContext | ObservationContext) -> Planner:
    """Build planner ``name``: a privileged one from the full :class:`PlannerContext`, any other from the
    observation-only view of ``ctx``."""
    check_planner_name(name)
    if name in _PRIVILEGED:
        if not isinstance(ctx, PlannerContext):
            raise ConfigError(f"planner {name!r} reads the simulator world and needs a PlannerContext, "
                              f"got {type(ctx).__name__}")
        return _FACTORIES[name](ctx)
    return _FACTORIES[name](ctx.observation_only() if isinstance(ctx, PlannerContext) else ctx)


@register_planner("oracle", privileged=True)
def _oracle(ctx: PlannerContext) -> Planner:
    from tcot_hybrid.planners.oracle import OracleConfig, OraclePlanner

    return OraclePlanner(ctx.task, ctx.world, ctx.camera, config=ctx.options.get("oracle", OracleConfig()))


@register_planner("learned")
def _learned(ctx: ObservationContext) -> Planner:
    from tcot_hybrid.planners.learned import LearnedPlanner  # lazy: torch loads only when needed

    return LearnedPlanner.from_context(ctx)


@register_planner("direct")
def _direct(ctx: ObservationContext) -> Planner:
    from tcot_hybrid.planners.direct import DirectPlanner

    return DirectPlanner.from_context(ctx)


__all__ = ["MODES", "Observation", "ObservationContext", "Planner", "PlannerContext", "check_planner_name",
           "is_privileged", "list_planners", "make_planner", "register_planner"]
