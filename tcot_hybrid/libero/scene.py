"""A LIBERO scene as a :class:`tcot_hybrid.scene.BuiltScene`: LIBERO builds it, this stack drives it.

LIBERO (through robosuite 1.4) parses the task file, assembles the scene XML and compiles it; from then on
only its model, data, init states, layout sampler and goal check are used. No robosuite controller ever
runs: the stack's controllers write the Panda's torque motors at ``ctrl_dt`` and MuJoCo steps the same
``MjData`` robosuite reads its goal predicates from.

Two changes to LIBERO's scene, both before it compiles: the stack's TCP site (``tcot_tcp``, the same
site as in ``robots/libero_panda/libero_panda.xml``) is added to ``robot0_link7``, and rendering is set up
for software GL (no shadows, reflections, skybox or multisampling; collision geoms hidden).
"""
from __future__ import annotations

import contextlib
import io
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from tcot_hybrid.libero import require_libero
from tcot_hybrid.libero.robot_model import LINK7, TCP_SITE

# robosuite's visual geoms are group 1, collision geoms group 0: hide group 0 in every image.
COLLISION_GROUP = 0


@contextlib.contextmanager
def quiet_stdout():
    """LIBERO and robosuite print progress lines to stdout; keep them off it (e.g. `tcot list --json`)."""
    with contextlib.redirect_stdout(io.StringIO()):
        yield


def _tcp_site_xml() -> tuple[str, str]:
    """The TCP site's pos and quat strings, read from the bundled robot MJCF (one source of truth)."""
    import xml.etree.ElementTree as ET

    from tcot_hybrid.robot import load_robot_spec

    root = ET.parse(load_robot_spec("libero_panda").mjcf_path).getroot()
    site = root.find(f".//site[@name='{TCP_SITE}']")
    return site.get("pos"), site.get("quat")


def _env_class(problem_name: str):
    """LIBERO's env class for the task file's problem, with the TCP site added to the robot before compiling."""
    from libero.libero.envs import TASK_MAPPING

    base = TASK_MAPPING[problem_name]
    pos, quat = _tcp_site_xml()

    def _load_model(self):
        base._load_model(self)
        link7 = self.model.worldbody.find(f".//body[@name='{LINK7}']")
        if link7 is None:
            raise RuntimeError(f"LIBERO's robot has no body {LINK7!r}; this stack knows only the Panda")
        import xml.etree.ElementTree as ET

        ET.SubElement(link7, "site", name=TCP_SITE, pos=pos, quat=quat, size="0.005", rgba="0 0 0 0", group="5")

    def _reset_internal(self):
        # LIBERO places an object that sits on a fixture (a bowl on the stove, on the cabinet) at the
        # fixture's new position *plus* the fixture site's current world position, which is right only on a
        # freshly compiled model (fixtures at their XML pose: robosuite's hard reset). With hard_reset off
        # the fixtures keep the previous layout's pose and such objects land in mid-air or off the table,
        # so every body is put back to its compiled pose before LIBERO samples.
        m = self.sim.model._model
        if getattr(self, "_tcot_body_pose0", None) is None:
            self._tcot_body_pose0 = (m.body_pos.copy(), m.body_quat.copy())
        m.body_pos[:], m.body_quat[:] = self._tcot_body_pose0
        base._reset_internal(self)

    # LIBERO asserts the class name equals the task file's problem name: keep it.
    return type(base.__name__, (base,), {"_load_model": _load_model, "_reset_internal": _reset_internal,
                                         "__module__": __name__})


# Built scenes not in use, by (task file, sim_dt): an evaluation worker runs many episodes of one task, and
# building a scene costs 2.5-4 s against 1-2 s for a whole oracle episode. A Simulation takes a scene out
# (no two simulations ever share one) and puts it back when it closes.
_IDLE: dict[tuple[str, float], "LiberoScene"] = {}
BUILD_SEED = 0  # numpy seed for LIBERO's fixture placement when a scene is built
# A shipped init state holds no fixture's place (fixtures have no joints): LIBERO's evaluation resets the env, whose
# sampler draws every fixture's place afresh (+-1 cm, its regions), before it sets the state. This stack draws them
# the same way, seeded by the state's number: numpy seed SHIPPED_FIXTURE_SEED + that number (docs/libero.md).
SHIPPED_FIXTURE_SEED = 2_000_000
# [rad] std of the gaussian offset from home on each arm joint of a sampled layout: robosuite's default
# initialization noise (gaussian, 0.02). LIBERO's shipped init states start so (largest joint 0.01-0.05 rad
# off home on the 20 read), while its own evaluation wrapper, and this stack before stop 49, reset the arm
# exactly to home: development layouts and demonstrations never showed the test set's starts.
ARM_START_NOISE_RAD = 0.02
ARM_NOISE_STREAM = 1  # the arm's noise is drawn from numpy Generator([seed, ARM_NOISE_STREAM])


@dataclass(frozen=True)
class LayoutSpread:
    """Layouts wider than LIBERO's own: its table regions are 2-5 cm boxes, one per object, so a planner
    trained on them can learn where each object stands instead of looking (under ``object_moved`` it grasped
    where the object had been). Every movable object's region is shifted by one common offset (uniform in
    +-``shift_m`` in x and y: the objects keep their relations, which the spatial suite's instructions name,
    "the bowl between the plate and the ramekin") and grown by ``widen_m`` on each side. Fixtures stay."""

    shift_m: float = 0.08  # [m] the whole arrangement moves by up to this, in x and in y
    widen_m: float = 0.02  # [m] each object's region grows by this on every side

    def __post_init__(self):
        for name in ("shift_m", "widen_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0.0 <= value <= 0.3):
                raise ValueError(f"LayoutSpread.{name} = {value!r} must be in [0, 0.3] m")

    def apply(self, regions: dict, rng) -> tuple[float, float]:
        """Move ``regions`` (sampler -> its compiled ranges, from :meth:`LiberoScene.table_regions`) in place;
        returns the common shift (dx, dy) [m] drawn from ``rng`` (numpy's global generator, as LIBERO's)."""
        dx, dy = (float(v) for v in rng.uniform(-self.shift_m, self.shift_m, size=2))
        w = self.widen_m
        for sampler, (x_ranges, y_ranges) in regions.items():
            sampler.x_ranges = [(lo + dx - w, hi + dx + w) for lo, hi in x_ranges]
            sampler.y_ranges = [(lo + dy - w, hi + dy + w) for lo, hi in y_ranges]
        return dx, dy
MAX_IDLE = 2


@dataclass
class LiberoScene:
    """One task file's compiled scene: the robosuite env (goal check, sampler) and the raw MuJoCo model/data."""

    env: object
    model: mujoco.MjModel
    data: mujoco.MjData
    bddl_path: Path
    renderers: dict = field(default_factory=dict)  # (width, height) -> mujoco.Renderer, kept with the scene

    @classmethod
    def acquire(cls, bddl_path: str | Path, *, sim_dt: float, max_image_px: int) -> "LiberoScene":
        """An idle scene of this task file if one was released in this process, else a new one."""
        scene = _IDLE.pop((str(bddl_path), sim_dt), None)
        if scene is not None:
            _fast_render_settings(scene.model, max_image_px)
            return scene
        return cls.build(bddl_path, sim_dt=sim_dt, max_image_px=max_image_px)

    def release(self) -> None:
        """Done with this scene: keep it for the next episode of the same task in this process."""
        key = (str(self.bddl_path), float(self.model.opt.timestep))
        old = _IDLE.pop(key, None)
        if old is not None and old is not self:
            old.close()
        while len(_IDLE) >= MAX_IDLE:
            _IDLE.pop(next(iter(_IDLE))).close()
        _IDLE[key] = self

    @classmethod
    def build(cls, bddl_path: str | Path, *, sim_dt: float, max_image_px: int) -> "LiberoScene":
        require_libero()
        bddl_path = Path(bddl_path)
        state = np.random.get_state()
        # robosuite's constructor resets the env, and LIBERO's sampler places the fixtures (cabinets, racks)
        # from numpy's global generator: seeded, so every build of a task file puts them in the same place
        # (unseeded they moved by up to 1.2 cm from one process to the next, and so did the oracle's grasps)
        np.random.seed(BUILD_SEED)
        try:
            with quiet_stdout():
                import robosuite
                import libero.libero.envs.bddl_utils as bddl_utils

                info = bddl_utils.get_problem_info(str(bddl_path))
                env = _env_class(info["problem_name"])(
                    str(bddl_path), robots=["Panda"],
                    controller_configs=robosuite.load_controller_config(default_controller="OSC_POSE"),
                    gripper_types="default", initialization_noise=None, use_camera_obs=False,
                    has_renderer=False, has_offscreen_renderer=False, hard_reset=False, ignore_done=True,
                    camera_names=["agentview"], control_freq=20, horizon=100000,
                )
        finally:
            np.random.set_state(state)
        model, data = env.sim.model._model, env.sim.data._data
        model.opt.timestep = sim_dt
        _fast_render_settings(model, max_image_px)
        # robosuite's reset hides its debugging sites (the gripper's aiming line and frames); its constructor leaves
        # them shown (a scene set to a shipped state with its build's fixtures is never reset): hide them once here
        env.visualize(vis_settings={name: False for name in env._visualizations})
        scene = cls(env=env, model=model, data=data, bddl_path=bddl_path)
        scene.built_body_pose = (model.body_pos.copy(), model.body_quat.copy())
        return scene

    # --- layouts ----------------------------------------------------------------------------------------
    def sample_layout(self, seed: int, spread: "LayoutSpread | None" = None, *,
                      arm_noise_rad: float | None = None) -> None:
        """A fresh layout from the task file's placement regions (LIBERO's own sampler), seeded. The sampler
        draws from numpy's global generator, so it is seeded here and restored afterwards. ``spread`` moves
        the table regions of the movable objects (see :class:`LayoutSpread`) for this layout only. The arm
        starts off home by a gaussian of std ``arm_noise_rad`` on each joint (None: ``ARM_START_NOISE_RAD``),
        drawn from its own generator so that the objects stand where they did without it."""
        if arm_noise_rad is None:
            arm_noise_rad = ARM_START_NOISE_RAD
        if not (np.isfinite(arm_noise_rad) and 0.0 <= arm_noise_rad <= 0.2):
            raise ValueError(f"arm_noise_rad = {arm_noise_rad!r} must be in [0, 0.2] rad")
        from robosuite.utils.errors import RandomizationError

        state = np.random.get_state()
        np.random.seed(seed % 2**32)
        regions = self.table_regions() if spread is not None else {}  # put back below: the scene is reused
        try:
            if spread is not None:
                spread.apply(regions, np.random)
            for _ in range(100):
                try:
                    with quiet_stdout():
                        self.env.reset()
                    break
                except RandomizationError:
                    continue
            else:
                raise RuntimeError(f"LIBERO could not sample a layout for {self.bddl_path.name} in 100 tries")
        finally:
            np.random.set_state(state)
            for sampler, (x_ranges, y_ranges) in regions.items():
                sampler.x_ranges, sampler.y_ranges = x_ranges, y_ranges
        if self.env.sim.model._model is not self.model or self.env.sim.data._data is not self.data:
            raise RuntimeError("LIBERO rebuilt its simulation on reset (hard_reset must stay off)")
        arm = np.asarray(self.env.robots[0]._ref_joint_pos_indexes)
        noise = np.random.default_rng([seed % 2**32, ARM_NOISE_STREAM]).normal(0.0, arm_noise_rad, arm.size)
        self.data.qpos[arm] += noise
        mujoco.mj_forward(self.model, self.data)

    def table_regions(self) -> dict:
        """The placement samplers that put the task's movable objects on the table (not inside or on top of
        another object or fixture), each with its (x_ranges, y_ranges) as LIBERO compiled them."""
        from libero.libero.envs.regions.base_region_sampler import MultiRegionRandomSampler

        movable = set(self.env.objects_dict)
        return {s: (list(s.x_ranges), list(s.y_ranges))
                for s in self.env.placement_initializer.samplers.values()
                if isinstance(s, MultiRegionRandomSampler) and s.mujoco_objects
                and all(o.name in movable for o in s.mujoco_objects)}

    def set_state(self, state: np.ndarray, *, fixture_seed: int | None) -> None:
        """A shipped init state: [time, qpos, qvel] as LIBERO saved it. Fixtures are not in the state: with
        ``fixture_seed`` LIBERO's sampler draws their places first, seeded, as the reset before LIBERO's evaluation
        sets a state draws them (:data:`SHIPPED_FIXTURE_SEED`); None keeps them where this scene's build placed
        them (every state of a task at one draw: this stack's protocol before stop 64)."""
        m = self.model
        expected = 1 + m.nq + m.nv
        if state.shape != (expected,):
            raise ValueError(f"init state has {state.shape} values, the scene needs ({expected},)")
        if fixture_seed is None:  # a sampled layout of an earlier episode may have moved them
            m.body_pos[:], m.body_quat[:] = self.built_body_pose
        else:  # a LIBERO reset: the fixtures drawn; the objects and the arm it placed are replaced below
            self.sample_layout(fixture_seed, arm_noise_rad=0.0)
        self.data.qpos[:] = state[1:1 + m.nq]
        self.data.qvel[:] = state[1 + m.nq:]
        mujoco.mj_forward(m, self.data)

    def show_state(self) -> None:
        """The sites LIBERO updates from the state after every step (a stove's burner red while it is on), for the
        frame about to be rendered (robosuite's debugging sites are hidden once, at build)."""
        self.env._post_process()

    def goal_reached(self) -> bool:
        """LIBERO's own goal check (the conjunction of the task file's goal predicates), on the current state."""
        return bool(self.env._check_success())

    def support_z(self) -> float:
        """World height objects rest on: the table top where the scene has one, else the floor."""
        m = self.model
        sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "table_top")
        if sid >= 0:
            mujoco.mj_kinematics(m, self.data)
            return float(self.data.site_xpos[sid][2])
        return 0.0

    def close(self) -> None:
        for r in self.renderers.values():
            with contextlib.suppress(Exception):
                r.close()
        self.renderers.clear()
        with contextlib.suppress(Exception):
            self.env.close()


def _fast_render_settings(model: mujoco.MjModel, max_image_px: int) -> None:
    """Software-GL settings (DESIGN.md, LIBERO): no shadows, no reflections, no multisampling."""
    model.vis.quality.shadowsize = 0
    model.vis.quality.offsamples = 0
    model.mat_reflectance[:] = 0.0
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), max_image_px)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), max_image_px)
    model.light_castshadow[:] = 0


def render_option() -> mujoco.MjvOption:
    opt = mujoco.MjvOption()
    opt.geomgroup[COLLISION_GROUP] = 0
    return opt
