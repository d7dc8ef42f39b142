"""Seeded, named perturbations that make a frozen global plan fail the way real manipulation fails.

Each perturbation fires once per episode at a planner step (or when its condition holds), is recorded
as a ``perturbation`` event, and draws its randomness from the episode seed, so a run is reproducible
from (seed, config). Strength units are per perturbation (see ``describe()``).
"""
from __future__ import annotations

from abc import ABC
from dataclasses import dataclass
from typing import ClassVar

import mujoco
import numpy as np

from tcot_hybrid.config import require_int, require_nonnegative
from tcot_hybrid.errors import ConfigError, PlanningError, unknown_name

WORKSPACE = (0.33, 0.62, -0.27, 0.27)  # xmin, xmax, ymin, ymax [m] where moved objects may land
FAR_ZONE = (0.74, 0.86, -0.15, 0.15)  # ... and, for objects out of reach (tool task), where they stay
FREE_RADIUS = {"cube": 0.035, "cylinder": 0.035, "plate": 0.085, "bowl": 0.09, "basket": 0.1, "stick": 0.0}


@dataclass(frozen=True, kw_only=True)
class PerturbConfig:
    """Which perturbation to inject.

    name:     "none" or a registered perturbation (``tcot list`` shows them).
    strength: size of the perturbation in the perturbation's unit; None = its default. Up = harder.
    at_step:  planner step at which it fires (or from which its condition is watched); None = default.
    """

    name: str = "none"
    strength: float | None = None
    at_step: int | None = None

    def __post_init__(self) -> None:
        valid = ["none", *_REGISTRY]
        if self.name not in valid:
            raise ConfigError(unknown_name("perturbation", self.name, valid))
        if self.strength is not None:
            require_nonnegative("perturb.strength", self.strength)
        if self.at_step is not None:
            require_int("perturb.at_step", self.at_step, minimum=1)


class Perturbation(ABC):
    """Base: subclasses implement ``fire`` (state change at a step) and/or ``on_image``."""

    name: ClassVar[str]
    description: ClassVar[str]
    unit: ClassVar[str]
    default_strength: ClassVar[float]
    default_at_step: ClassVar[int] = 8

    def __init__(self, config: PerturbConfig, seed: int):
        self.strength = self.default_strength if config.strength is None else float(config.strength)
        self.at_step = self.default_at_step if config.at_step is None else config.at_step
        self.rng = np.random.default_rng([seed, 7919])  # independent of the layout's stream
        self.fired = False
        self.pending: list[tuple[int, callable]] = []

    def on_step(self, runner, step: int) -> dict | None:
        """Called at the start of every planner step; returns an event dict when something happened."""
        for due, action in list(self.pending):
            if step >= due:
                self.pending.remove((due, action))
                action()
        if self.fired or step < self.at_step:
            return None
        info = self.fire(runner, step)
        if info is not None:
            self.fired = True
            mujoco.mj_forward(runner.stack.sim.model, runner.stack.sim.data)
            return {"kind": "perturbation", "name": self.name, "step": step, **info}
        return None

    def fire(self, runner, step: int) -> dict | None:  # noqa: ARG002 - image-only perturbations
        return None

    def cannot_apply(self, task, planner, last_step: int) -> str | None:
        """Why this perturbation can never fire in an episode of ``task`` with ``planner`` whose last planner
        step is ``last_step``; None when it can (whether it does depends on the episode). Subclasses add
        their own reasons to this one."""
        if self.at_step > last_step:
            return (f"at_step {self.at_step} is after the episode's last planner step {last_step} "
                    f"({task.name}: time limit {task.time_limit_s} s)")
        return None

    def on_image(self, image: np.ndarray) -> np.ndarray:
        return image

    def undo(self, runner) -> None:  # noqa: ARG002 - most perturbations change only the episode's state
        """Put back what the perturbation changed in the model (not the state): called when the episode ends,
        because a model outlives its episode (LIBERO scenes are reused by the next episode of the task)."""


def _first_open_skill(runner):
    """The task's first skill not yet done, which the object and target perturbations act on; None when all are
    done, or when the task's skills cannot be derived from the scene as it stands (a LIBERO book lying where no
    grasp fits the open hand: the oracle refuses it): the perturbation waits, the episode goes on."""
    world = runner.stack.sim.world
    try:
        skills = runner.stack.task.skills()
    except PlanningError:
        return None
    for skill in skills:
        if not skill.done(world):
            return skill
    return None


def _relocate(runner, name: str, distance: float, rng) -> dict | None:
    """Move a free object ``distance`` [m] in a random direction to a free spot in the workspace: clear of the
    other objects' footprints and overlapping nothing (a LIBERO plate dropped into a box or a fixture is pushed
    through the table: a simulator fault, not a perturbation)."""
    world = runner.stack.sim.world
    if name not in world.objects:  # e.g. a LIBERO fixture or region (a cabinet, a plate's site): not movable
        return None
    info = world.objects[name]
    if info.kind == "drawer":  # the cabinet is fixed to the table: shift it sideways instead
        cab = world.model.body(f"{name}_cabinet").id
        dy = float(rng.choice([-1.0, 1.0])) * min(distance, 0.06)
        world.model.body_pos[cab][1] += dy
        return {"object": name, "moved_m": [0.0, round(dy, 4), 0.0]}
    if info.kind == "stick":
        return None
    old = world.pos(name)
    others = [(world.pos(n)[:2], FREE_RADIUS.get(o.kind, 0.04)) for n, o in world.objects.items()
              if n != name and o.kind in FREE_RADIUS]
    r = FREE_RADIUS.get(info.kind, 0.04)
    zone = runner.stack.task.relocation_zone(world, name)
    if zone is None:
        return None
    x0, x1, y0, y1 = zone
    data = world.data
    qpos, qvel = data.qpos.copy(), data.qvel.copy()
    overlapped = 0
    for _ in range(200):
        a = rng.uniform(0, 2 * np.pi)
        p = old[:2] + distance * np.array([np.cos(a), np.sin(a)])
        if not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
            continue
        if all(np.linalg.norm(p - q) >= r + rq + 0.01 for q, rq in others):
            if runner.stack.task.world_kind == "workcell":
                world.set_pose(name, (p[0], p[1], info.rest_z + 0.001), float(rng.uniform(-0.3, 0.3)) * (
                    info.kind in ("cube", "cylinder")))
            else:  # LIBERO: translated on the same support, its resting orientation kept (set_pose's pure yaw
                world.shift(name, (p[0] - old[0], p[1] - old[1], 0.001))  # laid bottles and boxes on their side)
            if world.penetrating(name):
                data.qpos[:], data.qvel[:] = qpos, qvel
                overlapped += 1
                continue
            moved = {"object": name, "moved_m": np.round(np.append(p - old[:2], 0.0), 4).tolist()}
            return moved | ({"spots_overlapping": overlapped} if overlapped else {})
    if overlapped:
        mujoco.mj_fwdPosition(world.model, data)  # the scene as it was, its contacts too
    return None


class ObjectMoved(Perturbation):
    name = "object_moved"
    description = "the object to manipulate is moved after the global plan is made"
    unit = "m"
    default_strength = 0.10
    default_at_step = 5

    def fire(self, runner, step):
        skill = _first_open_skill(runner)
        world = runner.stack.sim.world
        # a LIBERO joint skill's object is a fixture or a region (a drawer, the stove): nothing to move
        if skill is None or skill.obj not in world.objects or world.is_grasped(skill.obj):
            return None
        return _relocate(runner, skill.obj, self.strength, self.rng)


class TargetMoved(Perturbation):
    name = "target_moved"
    description = "the target receptacle (plate, bowl, basket, bottom block, drawer) moves after the plan is made"
    unit = "m"
    default_strength = 0.10
    default_at_step = 5

    def cannot_apply(self, task, planner, last_step):
        if all(skill.target is None for skill in task.skills()):
            return f"task {task.name} has no target receptacle (none of its skills places onto or into something)"
        return super().cannot_apply(task, planner, last_step)

    def fire(self, runner, step):
        skill = _first_open_skill(runner)
        if skill is None or skill.target is None:
            return None
        return _relocate(runner, skill.target, self.strength, self.rng)


class ObjectDrop(Perturbation):
    name = "object_drop"
    description = "the grasp slips and the held object drops mid-transport (gripper forced open briefly)"
    unit = "s open"
    default_strength = 0.2
    default_at_step = 1

    def fire(self, runner, step):
        sim = runner.stack.sim
        world = sim.world
        held = [n for n in world.objects if world.is_grasped(n)]
        if not held or sim.tcp_pos()[2] - sim.support_z < 0.08:  # low over the support: a drop is a place
            return None
        closed_cmd = sim.gripper_closed_cmd()
        sim.set_gripper(False)
        steps_open = max(1, int(round(self.strength / runner.cfg.timing.plan_dt)))

        def restore():
            sim.set_gripper(closed_cmd)
        self.pending.append((step + steps_open, restore))
        return {"object": held[0], "tcp_z_m": round(float(sim.tcp_pos()[2]), 3)}


class OffCentreGrasp(Perturbation):
    name = "offcenter_grasp"
    description = "the object is nudged just before the fingers close, so the grasp lands off-centre"
    unit = "m"
    default_strength = 0.025
    default_at_step = 1

    def cannot_apply(self, task, planner, last_step):
        if task.world_kind == "libero":
            from tcot_hybrid.libero.skills import PickPlace as LiberoPickPlace

            if not any(isinstance(s, LiberoPickPlace) for s in task.skills()):
                return f"task {task.name} has no pick-and-place (the grasp it nudges)"
            return super().cannot_apply(task, planner, last_step)
        from tcot_hybrid.tasks.base import PickPlace

        if not any(isinstance(s, PickPlace) for s in task.skills()):  # fire() also checks the object's kind
            return f"task {task.name} has no top-down pick-and-place (the grasp it nudges)"
        return super().cannot_apply(task, planner, last_step)

    def fire(self, runner, step):
        sim = runner.stack.sim
        world = sim.world
        skill = _first_open_skill(runner)
        if runner.stack.task.world_kind == "libero":
            return self._fire_libero(world, skill)
        if skill is None or world.objects[skill.obj].kind not in ("cube", "cylinder"):
            return None
        p, tcp = world.pos(skill.obj), sim.tcp_pos()
        if np.linalg.norm(tcp[:2] - p[:2]) > 0.02 or not (p[2] < tcp[2] < p[2] + 0.07):
            return None
        d = self.strength * float(self.rng.choice([-1.0, 1.0]))
        world.set_pose(skill.obj, (p[0] + d, p[1], p[2]), 0.0)
        return {"object": skill.obj, "moved_m": [round(d, 4), 0.0, 0.0]}


    def _fire_libero(self, world, skill) -> dict | None:
        """LIBERO's grasps are rims, handles and sides, not centres: the object is shifted along the open fingers'
        closing axis (made horizontal) once the fingertips are at it, i.e. inside its bounding box grown by
        GRASP_REACH_M, the moment before they close."""
        from tcot_hybrid.libero.skills import PickPlace as LiberoPickPlace

        if not isinstance(skill, LiberoPickPlace) or skill.obj not in world.objects or not world.fingers_open() \
                or world.touching(skill.obj, world.finger_geoms):
            return None
        lo, hi = skill.ctx.object_boxes(skill.obj, []).aabb()
        if not np.all((world.tcp_pos() >= lo - GRASP_REACH_M) & (world.tcp_pos() <= hi + GRASP_REACH_M)):
            return None
        closing = world.tcp_rot()[:, 0] * np.array([1.0, 1.0, 0.0])
        if np.linalg.norm(closing) < 0.3:  # fingers closing almost vertically (a drawer-style pinch): no sideways slip
            return None
        d = self.strength * float(self.rng.choice([-1.0, 1.0])) * closing / np.linalg.norm(closing)
        world.shift(skill.obj, d)
        return {"object": skill.obj, "moved_m": np.round(d, 4).tolist()}


GRASP_REACH_M = 0.01  # [m] LIBERO off-centre grasp: the fingertips count as at the object this far outside its box


class ArmPush(Perturbation):
    name = "arm_push"
    description = "an external horizontal push on the arm's last link for 0.2 s"
    unit = "N"
    default_strength = 40.0
    default_at_step = 12

    def fire(self, runner, step):
        sim = runner.stack.sim
        body = sim.model.site_bodyid[sim.ee_site]
        a = self.rng.uniform(0, 2 * np.pi)
        force = self.strength * np.array([np.cos(a), np.sin(a), 0.0])
        sim.data.xfrc_applied[body, :3] = force

        def release():
            sim.data.xfrc_applied[body, :3] = 0.0
        self.pending.append((step + 2, release))
        return {"force_n": np.round(force, 2).tolist()}


class CameraNoise(Perturbation):
    name = "camera_noise"
    description = "Gaussian pixel noise and a random occluding patch on the planner image"
    unit = "intensity sigma (0-255)"
    default_strength = 12.0
    default_at_step = 0

    def cannot_apply(self, task, planner, last_step):
        if not planner.needs_image:
            return f"planner {planner.name!r} does not look at the image"
        return super().cannot_apply(task, planner, last_step)

    def fire(self, runner, step):
        return {"sigma": self.strength}

    def on_image(self, image: np.ndarray) -> np.ndarray:
        if not self.fired:
            return image
        h, w = image.shape[:2]
        noisy = image.astype(np.float32) + self.rng.normal(0.0, self.strength, image.shape)
        ph, pw = h // 6, w // 6
        y, x = self.rng.integers(0, h - ph), self.rng.integers(0, w - pw)
        noisy[y:y + ph, x:x + pw] = 90.0
        return np.clip(noisy, 0, 255).astype(np.uint8)


def _random_unit(rng) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


class CameraShift(Perturbation):
    """The planner camera is bumped before the episode: it moves ``strength`` metres in a random direction and
    turns ``CAMERA_SHIFT_DEG_PER_M * strength`` degrees about a random axis, while the calibration the lift
    uses stays the nominal one (LIBERO-Plus's camera shift; a fixed camera knocked after calibration)."""

    name = "camera_shift"
    description = "the planner camera moves a few cm and degrees; the lift keeps the nominal calibration"
    unit = "m (and 100 deg per m of turn)"
    default_strength = 0.03
    default_at_step = 0
    CAMERA_SHIFT_DEG_PER_M = 100.0

    def __init__(self, config, seed):
        super().__init__(config, seed)
        self._saved = None

    def cannot_apply(self, task, planner, last_step):
        if not planner.needs_image:
            return f"planner {planner.name!r} does not look at the image"
        return super().cannot_apply(task, planner, last_step)

    def fire(self, runner, step):
        sim, name = runner.stack.sim, runner.cfg.scene.planner_camera
        m = sim.model
        cid = m.camera(name).id
        self._saved = (cid, m.cam_pos[cid].copy(), m.cam_quat[cid].copy())
        shift = _random_unit(self.rng) * self.strength
        angle = np.deg2rad(self.CAMERA_SHIFT_DEG_PER_M * self.strength)
        turn = np.zeros(4)
        mujoco.mju_axisAngle2Quat(turn, _random_unit(self.rng), angle)
        quat = np.zeros(4)
        mujoco.mju_mulQuat(quat, turn, m.cam_quat[cid])  # turned in the camera's parent frame
        m.cam_pos[cid] += shift
        m.cam_quat[cid] = quat
        runner.invalidate_observation()
        return {"camera": name, "moved_m": np.round(shift, 4).tolist(), "turned_deg": round(float(np.rad2deg(angle)), 2)}

    def undo(self, runner):
        if self._saved is not None:
            cid, pos, quat = self._saved
            runner.stack.sim.model.cam_pos[cid] = pos
            runner.stack.sim.model.cam_quat[cid] = quat
            self._saved = None


class InitPosture(Perturbation):
    """The arm starts away from its nominal initial posture: every joint offset by up to ``strength`` rad (random
    signs, inside the joint limits), before the first plan (LIBERO-Plus's robot initial-state shift)."""

    name = "init_posture"
    description = "the robot starts from a perturbed joint posture (each joint off by up to strength rad)"
    unit = "rad"
    default_strength = 0.2
    default_at_step = 0

    def fire(self, runner, step):
        sim, ex = runner.stack.sim, runner.stack.executor
        spec = sim.robot
        margin = 0.05
        q0 = sim.q
        for _ in range(100):
            q = q0 + self.rng.uniform(-self.strength, self.strength, size=spec.dof)
            if np.all(q > spec.q_min + margin) and np.all(q < spec.q_max - margin):
                break
        else:
            return None  # no offset of this size fits inside the limits here: did not fire
        sim.data.qpos[sim.arm_qpos] = q
        sim.data.qvel[sim.arm_dof] = 0.0
        ex.resync_to_measured("init_posture")
        runner.invalidate_observation()
        return {"offset_rad": np.round(q - q0, 4).tolist()}


# Order matters: the first three are the failure modes a frozen global plan cannot survive.
_REGISTRY: dict[str, type[Perturbation]] = {
    c.name: c for c in (ObjectMoved, TargetMoved, ObjectDrop, OffCentreGrasp, ArmPush, CameraNoise, CameraShift,
                        InitPosture)
}


def list_perturbations() -> list[dict]:
    return [{"name": c.name, "description": c.description, "unit": c.unit, "default_strength": c.default_strength}
            for c in _REGISTRY.values()]


def make_perturbation(config: PerturbConfig, seed: int) -> Perturbation | None:
    if config.name == "none":
        return None
    return _REGISTRY[config.name](config, seed)
