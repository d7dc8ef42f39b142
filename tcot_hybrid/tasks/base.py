"""Task interface, the privileged world view, layout sampling and the oracle's skills.

A task adds its objects to the scene spec, samples a seeded layout, judges success from simulator
state, and (for the oracle planner only) scripts itself as a list of skills. Skills read true object
poses; nothing the learned planner sees comes from here.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import mujoco
import numpy as np

from tcot_hybrid.tasks.objects import (
    HOOK_HALF_WIDTH,
    STICK_GRIP_FROM_END,
    STICK_LENGTH,
    ObjectInfo,
)

TRAVEL_Z = 0.20  # [m] TCP height for transport moves (clears bowls, baskets and the drawer cabinet)
APPROACH_DZ = 0.08  # [m] pre-grasp/pre-place height above the target point
RETREAT_DZ = 0.10  # [m] lift after releasing
# [m] gap between the lowered hook and the target's far face. A learned planner imitates the demo's TCP track
# sampled every n_g = 4 steps; that chord cuts the corner where the hook comes down. Replaying the sampled
# track itself as a frozen plan (`tcot replay` on 10 demos of seeds 1000-1009, collected at each value)
# succeeded in 0/10 demos at 1.5 cm, 7/10 at 3.5 cm, 10/10 at 5 and at 6.5 cm.
HOOK_CLEARANCE_M = 0.065


@dataclass(frozen=True)
class Keyframe:
    """A TCP position [m, world], the gripper command to hold from here on, and optionally the TCP orientation
    (3x3, world; None = top-down, fingers closing along world y: ``robot.R_DOWN``)."""

    pos: np.ndarray
    closed: bool
    rot: np.ndarray | None = None


def subtree_geoms(model: mujoco.MjModel, body_id: int) -> frozenset[int]:
    """Geom ids of ``body_id`` and every body below it (an object's parts, a finger's pads)."""
    in_tree = np.zeros(model.nbody, bool)
    for b in range(model.nbody):
        p = b
        while p > 0 and p != body_id:
            p = model.body_parentid[p]
        in_tree[b] = p == body_id
    return frozenset(int(g) for g in np.flatnonzero(in_tree[model.geom_bodyid]))


class World:
    """Read/write access to the simulated scene by object name (privileged: oracle, predicates, resets)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, objects: dict[str, ObjectInfo], *,
                 ee_site: str, finger_geoms: tuple[tuple[int, ...], ...],
                 gripper: tuple[tuple[int, float, float], ...]):
        """``gripper``: (actuator id, ctrl when open, ctrl when closed) per gripper actuator."""
        self.model, self.data, self.objects = model, data, objects
        if not gripper:
            raise ValueError("World needs at least one gripper actuator (id, open ctrl, closed ctrl)")
        self.gripper = tuple((int(a), float(o), float(c)) for a, o, c in gripper)
        self._body = {o.name: model.body(o.body).id for o in objects.values()}
        self._jnt = {o.name: model.joint(o.joint).id for o in objects.values()}
        self._site = model.site(ee_site).id
        self.fingers = tuple(frozenset(f) for f in finger_geoms)  # geom ids per finger
        self.finger_geoms = frozenset().union(*self.fingers)
        self._geoms_of = {name: subtree_geoms(model, self._body[name]) for name in objects}

    def pos(self, name: str) -> np.ndarray:
        return self.data.xpos[self._body[name]].copy()

    def rot(self, name: str) -> np.ndarray:
        return self.data.xmat[self._body[name]].reshape(3, 3).copy()

    def joint_q(self, joint: str) -> float:
        """Position of a 1-dof joint by joint name [m or rad]."""
        return float(self.data.qpos[self.model.jnt_qposadr[self.model.joint(joint).id]])

    def tcp_pos(self) -> np.ndarray:
        return self.data.site_xpos[self._site].copy()

    def tcp_rot(self) -> np.ndarray:
        """TCP orientation (3x3, world): columns x, y = finger closing axis, z = approach axis."""
        return self.data.site_xmat[self._site].reshape(3, 3).copy()

    def set_pose(self, name: str, pos, yaw: float = 0.0) -> None:
        """Place a free object at pos [m] with yaw [rad] about world z, at rest."""
        j = self._jnt[name]
        a, v = self.model.jnt_qposadr[j], self.model.jnt_dofadr[j]
        self.data.qpos[a:a + 3] = pos
        self.data.qpos[a + 3:a + 7] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
        self.data.qvel[v:v + 6] = 0.0

    def shift(self, name: str, delta) -> None:
        """Translate a free object by ``delta`` [m, world], orientation kept, at rest."""
        j = self._jnt[name]
        a, v = self.model.jnt_qposadr[j], self.model.jnt_dofadr[j]
        self.data.qpos[a:a + 3] += np.asarray(delta, float)
        self.data.qvel[v:v + 6] = 0.0

    def penetrating(self, name: str, depth_m: float = 0.001) -> list[str]:
        """Bodies the object's geoms overlap by more than ``depth_m`` [m] as the scene stands now (positions
        and contacts recomputed first: call it after :meth:`shift` or :meth:`set_pose`); [] when it is free."""
        mujoco.mj_fwdPosition(self.model, self.data)
        obj, d = self._geoms_of[name], self.data
        hit = set()
        for i in range(d.ncon):
            g1, g2 = int(d.contact.geom1[i]), int(d.contact.geom2[i])
            if (g1 in obj) != (g2 in obj) and d.contact.dist[i] < -depth_m:
                hit.add(self.model.body(int(self.model.geom_bodyid[g2 if g1 in obj else g1])).name)
        return sorted(hit)

    def touching(self, name: str, geoms: frozenset[int]) -> bool:
        obj = self._geoms_of[name]
        d = self.data
        for i in range(d.ncon):
            g1, g2 = int(d.contact.geom1[i]), int(d.contact.geom2[i])
            if (g1 in obj and g2 in geoms) or (g2 in obj and g1 in geoms):
                return True
        return False

    def is_held(self, name: str) -> bool:
        """True when both fingers touch the object (it is between the closed fingers, lifted or not)."""
        return all(self.touching(name, f) for f in self.fingers)

    def fingers_open(self) -> bool:
        """Every gripper actuator is commanded open (its ctrl nearer the open value than the closed one)."""
        ctrl = self.data.ctrl
        return all(abs(ctrl[a] - o) < abs(ctrl[a] - c) for a, o, c in self.gripper)

    def is_grasped(self, name: str) -> bool:
        """True when the object touches the gripper's fingers and is off the table."""
        o = self.objects[name]
        return self.touching(name, self.finger_geoms) and self.pos(name)[2] > o.rest_z + 0.01

    def speed(self, name: str) -> float:
        """Linear speed of a free object [m/s] (a drawer: its slide speed)."""
        j = self._jnt[name]
        v = self.model.jnt_dofadr[j]
        return float(np.linalg.norm(self.data.qvel[v:v + (3 if self.model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE else 1)]))

    def spin(self, name: str) -> float:
        """Angular speed of a free object [rad/s]; 0 for objects on other joints."""
        j = self._jnt[name]
        if self.model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            return 0.0
        v = self.model.jnt_dofadr[j]
        return float(np.linalg.norm(self.data.qvel[v + 3:v + 6]))


def sample_apart(rng: np.random.Generator, regions: dict[str, tuple[float, float, float, float]],
                 radii: dict[str, float], *, gap: float = 0.02, tries: int = 2000) -> dict[str, np.ndarray]:
    """Sample xy for each named object in its region (xmin, xmax, ymin, ymax) without overlaps."""
    for _ in range(tries):
        out: dict[str, np.ndarray] = {}
        ok = True
        for name, (x0, x1, y0, y1) in regions.items():
            p = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
            if any(np.linalg.norm(p - q) < radii[name] + radii[n] + gap for n, q in out.items()):
                ok = False
                break
            out[name] = p
        if ok:
            return out
    raise RuntimeError(f"could not place {list(regions)} apart in {tries} tries; regions too small")


# --- skills: the oracle's script pieces --------------------------------------------------------------

class Skill(ABC):
    """One step of an oracle script: done(world) tells whether it is achieved; keyframes() from now.

    ``obj`` is what the robot grasps or acts on, ``target`` where it goes (None when there is no
    receptacle); perturbations use them to know what to move.
    """

    obj: str
    target: str | None = None

    @abstractmethod
    def done(self, world: World) -> bool: ...

    @abstractmethod
    def keyframes(self, world: World) -> list[Keyframe]: ...


def _kf(x, y, z, closed: bool) -> Keyframe:
    return Keyframe(np.array([x, y, z], dtype=float), closed)


class PickPlace(Skill):
    """Pick ``obj`` top-down and release it at ``place(world)`` (xy + the object's centre height)."""

    def __init__(self, obj: str, place, achieved, *, grasp_dz: float = 0.0):
        self.obj, self.place, self.achieved, self.grasp_dz = obj, place, achieved, grasp_dz
        self.target = getattr(place, "target", None)

    def done(self, world: World) -> bool:
        return self.achieved(world)

    def keyframes(self, world: World) -> list[Keyframe]:
        p = world.pos(self.obj)
        goal = np.asarray(self.place(world), dtype=float)
        kfs: list[Keyframe] = []
        if not world.is_held(self.obj):
            gz = p[2] + self.grasp_dz
            kfs += [_kf(p[0], p[1], max(TRAVEL_Z, gz + APPROACH_DZ), False),
                    _kf(p[0], p[1], gz + APPROACH_DZ / 2, False),
                    _kf(p[0], p[1], gz, True),
                    _kf(p[0], p[1], TRAVEL_Z, True)]
        else:
            t = world.tcp_pos()
            kfs.append(_kf(t[0], t[1], TRAVEL_Z, True))
        release_z = goal[2] + 0.012  # drop from just above so the object never jams into the surface
        kfs += [_kf(goal[0], goal[1], TRAVEL_Z, True),
                _kf(goal[0], goal[1], release_z + APPROACH_DZ / 2, True),
                _kf(goal[0], goal[1], release_z, False),
                _kf(goal[0], goal[1], release_z + RETREAT_DZ, False)]
        return kfs


class PullDrawer(Skill):
    """Grasp the drawer handle top-down and pull it open by ``distance`` [m] along -x."""

    def __init__(self, drawer: str, *, distance: float, achieved):
        self.drawer, self.distance, self.achieved = drawer, distance, achieved
        self.obj = drawer

    def done(self, world: World) -> bool:
        return self.achieved(world)

    def keyframes(self, world: World) -> list[Keyframe]:
        h = world.model.geom(f"{self.drawer}_handle").id
        hp = world.data.geom_xpos[h].copy()
        remaining = max(self.distance - world.joint_q(f"{self.drawer}_slide"), 0.02)
        x1 = hp[0] - remaining
        kfs = [_kf(hp[0], hp[1], hp[2] + APPROACH_DZ + 0.04, False),
               _kf(hp[0], hp[1], hp[2] + APPROACH_DZ / 2, False),
               _kf(hp[0], hp[1], hp[2], True)]
        for f in (0.33, 0.66, 1.0):
            kfs.append(_kf(hp[0] + (x1 - hp[0]) * f, hp[1], hp[2], True))
        kfs += [_kf(x1, hp[1], hp[2], False), _kf(x1, hp[1], hp[2] + RETREAT_DZ, False)]
        return kfs


class HookPull(Skill):
    """Grasp the stick, put its hook behind ``target`` and drag the target toward the robot."""

    def __init__(self, stick: str, target: str, *, pull_to_x: float, achieved):
        self.stick, self.pull_to_x, self.achieved = stick, pull_to_x, achieved
        self.obj = target  # what has to move is the target cube; the stick is the tool
        self.target = None

    def done(self, world: World) -> bool:
        return self.achieved(world)

    def keyframes(self, world: World) -> list[Keyframe]:
        s = world.pos(self.stick)
        axis = world.rot(self.stick)[:, 0]
        grip = s + axis * STICK_GRIP_FROM_END
        hook = s + axis * (STICK_LENGTH - 0.0125)
        c = world.pos(self.obj)
        half = world.objects[self.obj].half_height
        gz_low = world.objects[self.stick].rest_z + 0.004  # TCP height that drags the stick on the table
        lift_z = 0.09
        held = world.is_held(self.stick)
        tcp = world.tcp_pos()
        if held and hook[0] > c[0] + half and abs(hook[1] - c[1]) < HOOK_HALF_WIDTH and tcp[2] < lift_z - 0.02:
            # Already hooked behind the target and low: keep pulling from here (stable under replanning).
            return [_kf(self.pull_to_x, tcp[1], gz_low, True), _kf(self.pull_to_x, tcp[1], gz_low, False),
                    _kf(self.pull_to_x, tcp[1], gz_low + RETREAT_DZ, False)]
        # Hook's near face HOOK_CLEARANCE_M behind the target's far face; the shaft runs beside the target (on
        # the stick's side) so that lowering the stick does not land it on top of the target.
        hook_x = c[0] + half + HOOK_CLEARANCE_M + 0.0125
        gx = hook_x - (STICK_LENGTH - 0.0125 - STICK_GRIP_FROM_END)
        side = 1.0 if grip[1] >= c[1] else -1.0
        gy = c[1] + side * (half + 0.0125 + 0.012)
        kfs: list[Keyframe] = []
        if not held:
            kfs += [_kf(grip[0], grip[1], TRAVEL_Z, False),
                    _kf(grip[0], grip[1], grip[2] + APPROACH_DZ / 2, False),
                    _kf(grip[0], grip[1], grip[2], True)]
        kfs += [_kf(grip[0], grip[1], lift_z, True),
                _kf(gx, gy, lift_z, True),
                _kf(gx, gy, gz_low, True)]
        for f in (0.25, 0.5, 0.75, 1.0):
            kfs.append(_kf(gx + (self.pull_to_x - gx) * f, gy, gz_low, True))
        kfs += [_kf(self.pull_to_x, gy, gz_low, False), _kf(self.pull_to_x, gy, gz_low + RETREAT_DZ, False)]
        return kfs


class Task(ABC):
    """A manipulation task: objects, a seeded layout, a success predicate and an oracle script.

    The scene comes from ``build_scene``: this project's workcell by default; a LIBERO task builds its own.
    ``default_robot`` is the robot the task is meant for when the run names none (None: the run's default);
    ``init_modes`` are the ``--init`` choices the task knows, the first being its default.
    """

    name: ClassVar[str]
    suite: ClassVar[str]
    instruction: ClassVar[str]
    time_limit_s: ClassVar[float] = 30.0
    settle_s: ClassVar[float] = 0.2  # [s] objects settle (robot holding home) before the first planner step
    default_robot: ClassVar[str | None] = None
    init_modes: ClassVar[tuple[str, ...]] = ("sampled",)
    init_note: str | None = None  # why the episode's layout is not the default's (a task whose default depends on the seed)
    fixture_seed: int | None = None  # the seed the episode's fixtures were drawn with, when the layout's own seed is not it
    world_kind: ClassVar[str] = "workcell"  # "workcell" or "libero"

    def build_scene(self, robot, *, timing, scene):
        """Compile robot + scene + this task's objects into a :class:`tcot_hybrid.scene.BuiltScene`."""
        from tcot_hybrid.scene import build_workcell_scene

        return build_workcell_scene(robot, self.add_objects, config=scene, sim_dt=timing.sim_dt)

    def relocation_zone(self, world: "World", name: str) -> tuple[float, float, float, float] | None:
        """(xmin, xmax, ymin, ymax) [m, world] where a perturbation may move object ``name``; None = nowhere."""
        from tcot_hybrid.perturbations import FAR_ZONE, WORKSPACE

        return WORKSPACE if world.pos(name)[0] <= WORKSPACE[1] else FAR_ZONE

    def cameras(self) -> tuple[str, ...]:
        """Camera names the task's scene has (checked before anything is built)."""
        from tcot_hybrid.scene import CAMERAS

        return tuple(CAMERAS)

    def release_scene(self) -> None:
        """The simulation built from ``build_scene`` is closed (a LIBERO task keeps its scene for reuse)."""

    def show_state(self) -> None:
        """Bring the scene's state-dependent visuals up to date before a frame is rendered (a LIBERO stove's
        burner glows while its knob is on). Default: the workcell's scenes have none."""

    def set_episode(self, *, seed: int, init: str | None) -> None:
        """Choose how ``reset`` lays the scene out for the episode ``seed``: ``init`` is one of ``init_modes``
        (None: the first). Workcell tasks always sample a fresh layout from the seed."""
        from tcot_hybrid.errors import ConfigError

        if init is not None and init not in self.init_modes:
            raise ConfigError(f"init = {init!r} is not available for task {self.name!r}; choose one of "
                              f"{', '.join(self.init_modes)}")
        self.episode_seed, self.init = seed, init or self.init_modes[0]

    @abstractmethod
    def add_objects(self, spec: mujoco.MjSpec) -> dict[str, ObjectInfo]:
        """Add this task's bodies to the scene spec; return their descriptions by name."""

    @abstractmethod
    def reset(self, world: World, rng: np.random.Generator) -> None:
        """Place the objects for a new episode (seeded)."""

    def arm_moved_before_start(self) -> None:
        """The stack moved the arm before the first plan (``EpisodeRunner.go_to_home``): an oracle script composed
        while the arm stood elsewhere is stale. Default: nothing is kept between calls to :meth:`skills`."""

    @abstractmethod
    def success(self, world: World) -> bool:
        """Task success from simulator state only."""

    @abstractmethod
    def skills(self) -> list[Skill]:
        """The privileged oracle script, in order."""
