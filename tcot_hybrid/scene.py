"""Workcell scene: table, lights, cameras and task objects around a robot, built with MjSpec.

The robot's own MJCF is the base spec; the scene adds to it, so robot names stay unprefixed. Rendering
settings are chosen for software rendering (EGL/llvmpipe): no shadows, no reflections, no
multisampling, few simple geoms.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from tcot_hybrid.config import require_int, require_positive

if TYPE_CHECKING:
    from tcot_hybrid.robot import RobotSpec
    from tcot_hybrid.tasks.objects import ObjectInfo

GEOM = mujoco.mjtGeom
TABLE_TOP_Z = 0.0  # [m] the table surface is the world's z = 0 plane (robot base sits on it)

# Object collision tuning: soft enough to be stable at sim_dt = 2 ms, grippy enough for friction grasps.
OBJECT_FRICTION = (1.0, 0.01, 0.001)
OBJECT_SOLREF = (0.01, 1.0)


MAX_VIDEO_PX = 4096  # [px] largest video side
MAX_PLANNER_IMAGE_PX = 1024  # [px] largest planner image side (the shipped planner uses 128)


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """Scene and camera settings.

    planner_camera: camera whose image the planner sees and whose pixels waypoints live in.
    planner_image_px: square planner image size [px]; larger = finer waypoints, slower render/training.
    video_width/height: size of recorded videos [px]; bigger costs render time only when recording.
    """

    planner_camera: str = "agentview"
    planner_image_px: int = 128
    video_width: int = 320
    video_height: int = 240

    def __post_init__(self) -> None:
        for name, top in (("planner_image_px", MAX_PLANNER_IMAGE_PX), ("video_width", MAX_VIDEO_PX),
                          ("video_height", MAX_VIDEO_PX)):
            require_int(name, getattr(self, name), minimum=16)
            if getattr(self, name) > top:
                from tcot_hybrid.errors import ConfigError

                raise ConfigError(f"{name} = {getattr(self, name)} px is above the {top} px maximum (an offscreen "
                                  f"buffer that size takes gigabytes and minutes per frame)")
        if not isinstance(self.planner_camera, str) or not self.planner_camera:
            from tcot_hybrid.errors import ConfigError

            raise ConfigError(f"planner_camera must be a camera name, got {self.planner_camera!r}")


@dataclass(frozen=True, kw_only=True, eq=False)
class BuiltScene:
    """A compiled world, whoever built it (the workcell here, or a LIBERO scene).

    objects:       the task's objects by name (what the predicates, the oracle and perturbations know)
    support_z:     world height of the surface objects rest on [m] (the table top; 0 in the workcell)
    render_option: scene option for every render (e.g. collision geoms hidden), None for MuJoCo's default
    renderers:     a renderer cache the scene owns and keeps across the episodes that reuse it (a LIBERO scene's
                   renderer takes ~1 s to make: its textures go to the GL context); None = each simulation makes
                   and closes its own
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    objects: dict[str, "ObjectInfo"]
    support_z: float = TABLE_TOP_Z
    render_option: mujoco.MjvOption | None = None
    scene_flags_off: tuple[int, ...] = ()  # mjtRndFlag values switched off in every renderer (e.g. skybox)
    renderers: dict | None = None


def check_camera(model: mujoco.MjModel, name: str) -> None:
    """The planner camera must exist in the compiled scene (error lists the scene's cameras)."""
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name) < 0:
        from tcot_hybrid.errors import ConfigError

        cams = [model.camera(i).name for i in range(model.ncam)]
        raise ConfigError(f"planner_camera = {name!r} is not a camera of this scene; choose one of {', '.join(cams)}")


def build_workcell_scene(robot: "RobotSpec", add_objects, *, config: SceneConfig, sim_dt: float) -> BuiltScene:
    """This project's workcell around ``robot`` with the objects ``add_objects(spec)`` adds, compiled."""
    from tcot_hybrid.robot import robot_mjspec

    spec = build_workcell(robot_mjspec(robot), config=config, sim_dt=sim_dt)
    objects = add_objects(spec)
    model = spec.compile()
    check_camera(model, config.planner_camera)
    return BuiltScene(model=model, data=mujoco.MjData(model), objects=objects)


# name -> (position [m], look-at point [m], vertical field of view [deg])
CAMERAS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float], float]] = {
    # Front camera facing the robot from across the table, steep enough that the workspace fills the image.
    "agentview": ((1.0, 0.0, 1.0), (0.55, 0.0, 0.05), 52.0),
    # Side camera (second view for triangulation and for watching depth errors).
    "sideview": ((0.5, -1.05, 0.55), (0.5, 0.0, 0.05), 50.0),
}


def look_at_xyaxes(pos, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """MuJoCo camera ``xyaxes`` (camera looks along its -z, y up) for a camera at pos looking at target."""
    pos, target, up = (np.asarray(v, dtype=float) for v in (pos, target, up))
    forward = target - pos
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, forward)
    return np.concatenate([right, cam_up])


def add_geom(body, *, type, size, pos=(0, 0, 0), rgba=(0.7, 0.7, 0.7, 1), name="", mass=None, quat=None,
             friction=OBJECT_FRICTION, condim=4):
    g = body.add_geom()
    g.name = name
    g.type = type
    g.size = np.resize(np.asarray(size, dtype=float), 3)
    g.pos = pos
    g.rgba = rgba
    g.friction = friction
    g.condim = condim
    g.solref = OBJECT_SOLREF
    if quat is not None:
        g.quat = quat
    if mass is not None:
        g.mass = mass
    return g


def add_free_body(spec: mujoco.MjSpec, name: str, pos=(0.5, 0.0, 0.05)):
    body = spec.worldbody.add_body()
    body.name = name
    body.pos = pos
    joint = body.add_freejoint()
    joint.name = f"{name}_free"
    return body


def build_workcell(robot_spec_mj: mujoco.MjSpec, *, config: SceneConfig, sim_dt: float) -> mujoco.MjSpec:
    """Add table, lights, cameras and render settings to the robot's spec (in place) and return it."""
    require_positive("sim_dt", sim_dt)
    spec = robot_spec_mj
    spec.option.timestep = sim_dt
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0  # stiffer friction: grasped objects slip less
    spec.visual.quality.shadowsize = 0
    spec.visual.quality.offsamples = 0
    spec.visual.global_.offwidth = max(config.video_width, config.planner_image_px, 640)
    spec.visual.global_.offheight = max(config.video_height, config.planner_image_px, 480)
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]

    world = spec.worldbody
    light = world.add_light()
    light.name = "key"
    light.pos = [0.6, -0.3, 2.0]
    light.dir = [-0.1, 0.15, -1.0]
    light.castshadow = False
    light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL

    table = world.add_body()
    table.name = "table"
    add_geom(table, type=GEOM.mjGEOM_BOX, size=(0.65, 0.7, 0.02), pos=(0.4, 0.0, TABLE_TOP_Z - 0.02),
             rgba=(0.62, 0.55, 0.45, 1), name="table_top", friction=(1.0, 0.005, 0.0001), condim=3)
    floor = world.add_geom()
    floor.name = "floor"
    floor.type = GEOM.mjGEOM_PLANE
    floor.size = [3, 3, 0.1]
    floor.pos = [0, 0, -0.75]
    floor.rgba = [0.3, 0.3, 0.32, 1]
    floor.contype = 0
    floor.conaffinity = 0

    for name, (pos, target, fovy) in CAMERAS.items():
        cam = world.add_camera()
        cam.name = name
        cam.pos = pos
        cam.fovy = fovy
        cam.alt.type = mujoco.mjtOrientation.mjORIENTATION_XYAXES
        cam.alt.xyaxes = look_at_xyaxes(pos, target)
    return spec
