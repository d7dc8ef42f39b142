"""The observation-only planner boundary: learned and direct planners (and any planner not registered as
privileged) are built from an ObservationContext and fed Observations; nothing they hold reaches simulator
state (the World, the Simulation, the Task, the scene's MjModel/MjData). Only the oracle gets the world."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import dataclasses
import types

import mujoco
import numpy as np
import pytest

from tcot_hybrid.episode import EpisodeRunner, build_stack
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.planners import (ObservationContext, PlannerContext, _FACTORIES, _PRIVILEGED, is_privileged,
                                  make_planner, register_planner)
from tcot_hybrid.planners.oracle import OraclePlanner
from tcot_hybrid.run_config import RunConfig
from tcot_hybrid.sim import Simulation
from tcot_hybrid.tasks import Task, World

_OPAQUE = (str, bytes, int, float, bool, type(None), np.ndarray, np.generic, types.ModuleType, type,
           types.FunctionType, types.BuiltinFunctionType, types.CodeType)


def reachable(root, *, limit: int = 200_000):
    """Every object reachable from ``root`` through instance attributes, containers, bound methods and
    closures (not through modules, classes or functions' globals, which reach everything by design)."""
    import torch

    seen, stack, out = set(), [root], []
    while stack and len(seen) < limit:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        out.append(obj)
        if isinstance(obj, _OPAQUE) or isinstance(obj, torch.Tensor):
            continue
        if isinstance(obj, dict):
            stack.extend(obj.keys())
            stack.extend(obj.values())
        elif isinstance(obj, (list, tuple, set, frozenset)):
            stack.extend(obj)
        elif isinstance(obj, types.MethodType):
            stack.append(obj.__self__)
        elif isinstance(obj, functools_partial_types()):
            stack.extend((obj.func, *obj.args, *obj.keywords.values()))
        else:
            if hasattr(obj, "__dict__"):
                stack.append(vars(obj))
            for slot in getattr(type(obj), "__slots__", ()):
                if hasattr(obj, slot):
                    stack.append(getattr(obj, slot))
            if dataclasses.is_dataclass(obj) and not hasattr(obj, "__dict__"):
                stack.extend(getattr(obj, f.name) for f in dataclasses.fields(obj))
    return out


def functools_partial_types():
    import functools

    return (functools.partial,)


def privileged_objects(runner):
    sim = runner.stack.sim
    return {id(sim): "Simulation", id(sim.world): "World", id(sim.data): "scene MjData", id(sim.model): "scene MjModel",
            id(runner.stack.task): "Task"}


@pytest.mark.parametrize("planner", ["learned", "direct"])
def test_learned_planners_cannot_reach_simulator_state(planner):
    runner = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=3, planner=planner))
    bad = privileged_objects(runner)
    found = [o for o in reachable(runner.stack.planner)
             if id(o) in bad or isinstance(o, (World, Simulation, Task))]
    assert not found, f"{planner} planner reaches {[bad.get(id(o), type(o).__name__) for o in found]}"
    # its own kinematic model (direct planner) is the robot alone, not the scene
    scene_bodies = runner.stack.sim.model.nbody
    for o in reachable(runner.stack.planner):
        if isinstance(o, mujoco.MjModel):
            assert o.nbody < scene_bodies


def test_the_walk_finds_the_world_when_it_is_there():
    """The check above is not vacuous: the oracle (privileged) does reach the world through the same walk."""
    runner = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=3, planner="oracle"))
    bad = privileged_objects(runner)
    found = {bad[id(o)] for o in reachable(runner.stack.planner) if id(o) in bad}
    assert {"World", "scene MjData"} <= found


def test_observations_carry_only_copies():
    runner = EpisodeRunner(RunConfig(task="goal_cube_in_bowl", seed=3, planner="learned"))
    obs = runner.observe(0)
    # proprioception (joints, the TCP from them) and the image; never an object's pose
    assert {f.name for f in dataclasses.fields(obs)} == {"step", "image", "depth_m", "q", "gripper_closed",
                                                          "instruction", "tcp_pos_m"}
    data = runner.stack.sim.data
    for arr in (obs.image, obs.q, obs.tcp_pos_m):
        assert isinstance(arr, np.ndarray) and not np.shares_memory(arr, data.qpos)
        assert not np.shares_memory(arr, data.site_xpos)


def test_factories_get_the_context_they_are_entitled_to():
    seen = {}

    @register_planner("spy_observer")
    def _spy(ctx):
        seen["observer"] = ctx
        return OraclePlanner.__new__(OraclePlanner)

    @register_planner("spy_privileged", privileged=True)
    def _spy_priv(ctx):
        seen["privileged"] = ctx
        return OraclePlanner.__new__(OraclePlanner)

    try:
        stack = build_stack(RunConfig(task="goal_cube_on_plate", seed=1, planner="spy_observer"))
        ctx = seen["observer"]
        assert type(ctx) is ObservationContext
        assert {f.name for f in dataclasses.fields(ctx)} == {"camera", "robot_name", "options", "robot", "world_kind",
                                                             "T_world_base"}
        # the robot's mounting pose: a calibration (a copy of a 4x4 transform), not the simulator's arrays
        assert ctx.T_world_base.shape == (4, 4) and not np.shares_memory(ctx.T_world_base, stack.sim.T_world_base)
        assert type(ctx.robot).__name__ == "RobotSpec"  # the arm's own model (checkpoint matching), not the world
        assert ctx.world_kind == "workcell"  # which world (a string: checkpoints are matched to it), not its state
        assert not hasattr(ctx, "world") and not hasattr(ctx, "task")
        build_stack(RunConfig(task="goal_cube_on_plate", seed=1, planner="spy_privileged"))
        assert type(seen["privileged"]) is PlannerContext and isinstance(seen["privileged"].world, World)
        assert is_privileged("oracle") and is_privileged("spy_privileged")
        assert not is_privileged("learned") and not is_privileged("direct")
        with pytest.raises(ConfigError, match="needs a PlannerContext"):
            make_planner("spy_privileged", ObservationContext(camera=stack.camera, robot_name="panda", options={}))
    finally:
        for name in ("spy_observer", "spy_privileged"):
            _FACTORIES.pop(name, None)
            _PRIVILEGED.discard(name)
