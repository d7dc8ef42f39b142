"""The simulated world: compiled MuJoCo model of robot + scene + task objects, stepping and rendering.

The task builds the scene (``Task.build_scene``): this project's workcell, or a LIBERO scene. Either way the
simulation exposes the same robot measurements, gripper commands, rendering and fault polling, plus the
world<->base transform (``T_world_base``): IK works in the robot's own base frame, plans in the world.

Stepping is split (``mj_step1`` → control → ``mj_step2``) so controllers see dynamics quantities of the
current state at no extra cost. Every step polls MuJoCo's warning counters: MuJoCo silently resets the
state on divergence, and a reset episode must never be reported as a success.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tcot_hybrid.config import TimingConfig
from tcot_hybrid.errors import SimulationError
from tcot_hybrid.robot import RobotSpec
from tcot_hybrid.scene import SceneConfig
from tcot_hybrid.tasks import Task, World
from tcot_hybrid.tasks.base import subtree_geoms

# Warnings that mean the physics state can no longer be trusted.
FATAL_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADCTRL,
)
_FATAL_IDX = np.array([int(k) for k in FATAL_WARNINGS])


OBJECT_FLOOR_DZ = 0.05  # [m] an object this far below the support surface has fallen through it
# [m] a closed hand whose finger opening (gripper_opening_m) is below this holds nothing: the LIBERO Panda's fingers stop
# at 1.2 mm closing on nothing and at 3.5 mm or more on the thinnest object grasped (docs/libero-planner.md)
EMPTY_HAND_OPENING_M = 0.0025


@dataclass(frozen=True)
class SimFault:
    """A physics fault: which MuJoCo warning fired, at what simulated time [s]."""

    time_s: float
    warning: str
    count: int


class Simulation:
    """Robot + workcell + task objects, compiled once; ``reset(seed)`` starts a new episode."""

    def __init__(self, robot: RobotSpec, task: Task, *, timing: TimingConfig, scene: SceneConfig):
        self.robot, self.task, self.timing, self.scene_config = robot, task, timing, scene
        built = task.build_scene(robot, timing=timing, scene=scene)
        self.model, self.data, self.objects = built.model, built.data, built.objects
        self.support_z = built.support_z  # [m] world height of the surface objects rest on
        self.render_option = built.render_option
        self._scene_flags_off = built.scene_flags_off
        m = self.model
        self.arm_qpos = np.array([m.jnt_qposadr[m.joint(j).id] for j in robot.arm_joints])
        self.arm_dof = np.array([m.jnt_dofadr[m.joint(j).id] for j in robot.arm_joints])
        self.arm_act = np.array([m.actuator(a).id for a in robot.arm_actuators])
        self.gripper_act = m.actuator(robot.gripper_actuator).id
        # Every finger actuator and the sign of the command it gets (a mirrored second finger gets -ctrl).
        self._grip_acts = np.array([self.gripper_act] + ([m.actuator(robot.gripper_mirror_actuator).id]
                                                         if robot.gripper_mirror_actuator else []), dtype=int)
        self._grip_sign = np.array([1.0, -1.0][: self._grip_acts.size])
        self.gripper_qpos = np.array([m.jnt_qposadr[m.joint(j).id] for j in robot.gripper_joints])
        finger_bodies = [int(m.jnt_bodyid[m.joint(j).id]) for j in robot.gripper_joints]
        # a finger's pads may sit in child bodies (robosuite)
        finger_geoms = tuple(tuple(sorted(subtree_geoms(m, b))) for b in finger_bodies)
        self.world = World(m, self.data, self.objects, ee_site=robot.ee_site, finger_geoms=finger_geoms,
                           gripper=tuple((int(a), sign * robot.gripper_open, sign * robot.gripper_closed)
                                         for a, sign in zip(self._grip_acts, self._grip_sign)))
        self.ee_site = m.site(robot.ee_site).id
        self._wrist_force_adr = _wrist_force_sensor(m, robot.arm_joints[-1])
        self.T_world_base = base_transform(robot, m, self.data)
        self.T_base_world = np.linalg.inv(self.T_world_base)
        self._object_bodies = np.array([m.body(o.body).id for o in self.objects.values()], dtype=int)
        # (width, height) -> renderer; the scene's own cache when it keeps one across episodes
        self._owns_renderers = built.renderers is None
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {} if built.renderers is None else built.renderers
        self._fault: SimFault | None = None
        self._time_offset = 0.0  # [s] simulated time lost to MuJoCo's own resets of a diverged state

    # --- episode lifecycle ------------------------------------------------------------------------
    def reset(self, rng: np.random.Generator) -> None:
        """Robot at home with the gripper open, objects placed by the task (seeded; a LIBERO task may also set
        the robot, from its shipped init state)."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self.arm_qpos] = self.robot.home_q
        d.qpos[self.gripper_qpos] = self._finger_open()
        self.task.reset(self.world, rng)
        self.set_gripper(False)  # after the task: LIBERO's reset clears every ctrl
        mujoco.mj_forward(m, d)
        self._fault = None
        self._time_offset = 0.0
        d.warning.number[:] = 0

    def _finger_open(self) -> np.ndarray:
        """Each finger joint at its open end (the end of its range farther from zero)."""
        out = []
        for name in self.robot.gripper_joints:
            lo, hi = self.model.jnt_range[self.model.joint(name).id]
            out.append(hi if abs(hi) >= abs(lo) else lo)
        return np.array(out)

    # --- stepping ---------------------------------------------------------------------------------
    def step1(self) -> None:
        mujoco.mj_step1(self.model, self.data)

    def step2(self, n_more: int) -> None:
        """Finish the current step, then ``n_more`` full steps with the control held."""
        m, d = self.model, self.data
        t0 = d.time
        mujoco.mj_step2(m, d)
        for _ in range(n_more):
            mujoco.mj_step(m, d)
        expected = t0 + (1 + n_more) * m.opt.timestep
        if d.time < expected - 0.5 * m.opt.timestep:  # MuJoCo reset a diverged state (time back to 0)
            self._time_offset += expected - d.time
        self._poll_warnings()

    def _poll_warnings(self) -> None:
        if self._fault is not None:
            return
        counts = self.data.warning.number  # one array read; per-warning struct access costs 4x more
        if counts[_FATAL_IDX].any():
            kind = next(k for k in FATAL_WARNINGS if counts[int(k)])
            self._fault = SimFault(self.time_s, kind.name, int(counts[int(kind)]))
            return
        # An object pushed through the table falls forever without any MuJoCo warning: a fault too.
        if self._object_bodies.size and \
                self.data.xpos[self._object_bodies, 2].min() < self.support_z - OBJECT_FLOOR_DZ:
            self._fault = SimFault(self.time_s, "OBJECT_BELOW_TABLE", 1)

    @property
    def time_s(self) -> float:
        """Simulated time since ``reset`` [s]. ``data.time`` restarts at 0 when MuJoCo resets a diverged
        state by itself; this keeps counting."""
        return float(self.data.time + self._time_offset)

    @property
    def fault(self) -> SimFault | None:
        return self._fault

    def raise_if_faulted(self) -> None:
        if self._fault is not None:
            raise SimulationError(f"simulation diverged at t={self._fault.time_s:.3f}s: {self._fault.warning}")

    def set_gripper(self, closed: bool) -> None:
        value = self.robot.gripper_closed if closed else self.robot.gripper_open
        self.data.ctrl[self._grip_acts] = self._grip_sign * value

    # --- measurements -----------------------------------------------------------------------------
    @property
    def q(self) -> np.ndarray:
        return self.data.qpos[self.arm_qpos].copy()

    @property
    def qd(self) -> np.ndarray:
        return self.data.qvel[self.arm_dof].copy()

    def tcp_pos(self) -> np.ndarray:
        return self.data.site_xpos[self.ee_site].copy()

    def gripper_closed_cmd(self) -> bool:
        return bool(self.data.ctrl[self.gripper_act] == self.robot.gripper_closed)

    def wrist_force(self) -> np.ndarray | None:
        """The wrist force sensor's reading [N, in its site's frame] (a force sensor between the arm and the hand, as
        robosuite's ``gripper0_force_ee``), or None when the robot has none."""
        if self._wrist_force_adr is None:
            return None
        return self.data.sensordata[self._wrist_force_adr:self._wrist_force_adr + 3].copy()

    def gripper_opening_m(self) -> float:
        """Measured finger opening [m]: the finger joints' travel from closed (joint position 0 on the bundled
        grippers), summed (proprioception)."""
        return float(np.abs(self.data.qpos[self.gripper_qpos]).sum())

    # --- rendering --------------------------------------------------------------------------------
    def renderer(self, width: int, height: int) -> mujoco.Renderer:
        key = (width, height)
        if key not in self._renderers:
            r = mujoco.Renderer(self.model, height=height, width=width)
            for flag in self._scene_flags_off:
                r.scene.flags[flag] = 0
            self._renderers[key] = r
        return self._renderers[key]

    def render(self, camera: str, width: int, height: int, *, depth: bool = False,
               markers: list[tuple[np.ndarray, tuple]] | None = None) -> np.ndarray:
        """RGB (or depth [m]) image; ``markers`` = [(points (N,3) [m], rgba)] drawn as small spheres in
        the scene (e.g. a lifted 3D path) — for videos only, never for planner images."""
        r = self.renderer(width, height)
        self.task.show_state()
        if self.render_option is None:
            r.update_scene(self.data, camera=camera)
        else:
            r.update_scene(self.data, camera=camera, scene_option=self.render_option)
        for points, rgba in markers or ():
            scn = r.scene
            for p in points:
                if scn.ngeom >= scn.maxgeom:
                    break
                mujoco.mjv_initGeom(scn.geoms[scn.ngeom], mujoco.mjtGeom.mjGEOM_SPHERE, np.array([0.006, 0, 0]),
                                    np.asarray(p, dtype=float), np.eye(3).ravel(), np.asarray(rgba, dtype=np.float32))
                scn.ngeom += 1
        if depth:
            r.enable_depth_rendering()
            img = r.render().copy()
            r.disable_depth_rendering()
            return img
        return r.render().copy()

    def close(self) -> None:
        if self._owns_renderers:
            for r in self._renderers.values():
                r.close()
            self._renderers.clear()
        self.task.release_scene()


def _pose(xpos, xmat) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = np.asarray(xmat).reshape(3, 3), xpos
    return T


def _wrist_force_sensor(model: mujoco.MjModel, last_arm_joint: str) -> int | None:
    """Address in ``sensordata`` of the first force sensor on a site carried by the arm's last joint (the hand's
    force/torque sensor, between the arm and the fingers), or None."""
    wrist = int(model.jnt_bodyid[model.joint(last_arm_joint).id])
    for i in range(model.nsensor):
        if model.sensor_type[i] != mujoco.mjtSensor.mjSENS_FORCE or model.sensor_objtype[i] != mujoco.mjtObj.mjOBJ_SITE:
            continue
        b = int(model.site_bodyid[model.sensor_objid[i]])
        while b not in (0, wrist):
            b = int(model.body_parentid[b])
        if b == wrist:
            return int(model.sensor_adr[i])
    return None


def robot_root_body(model: mujoco.MjModel, first_arm_joint: str) -> int:
    """The robot's root body: the ancestor of the first arm joint's body that hangs off the world body."""
    b = int(model.jnt_bodyid[model.joint(first_arm_joint).id])
    while model.body_parentid[b] != 0:
        b = int(model.body_parentid[b])
    return b


def base_transform(robot: RobotSpec, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """T_world_base (4x4): maps a point of the robot's own MJCF frame (where Pinocchio and mink solve IK) into
    the scene's world frame. Identity in the workcell (the robot is the scene's base); a LIBERO robot sits at
    e.g. (-0.66, 0, 0.912). Measured from the robot's root body, which is fixed in both models."""
    mujoco.mj_kinematics(model, data)
    root = robot_root_body(model, robot.arm_joints[0])
    name = model.body(root).name
    own = mujoco.MjModel.from_xml_path(str(robot.mjcf_path))
    own_d = mujoco.MjData(own)
    mujoco.mj_kinematics(own, own_d)
    try:
        own_root = own.body(name).id
    except KeyError:
        from tcot_hybrid.errors import RobotModelError

        raise RobotModelError(f"robot {robot.name!r}: the scene's robot root body {name!r} is not in its MJCF "
                              f"{str(robot.mjcf_path)!r}") from None
    return _pose(data.xpos[root], data.xmat[root]) @ np.linalg.inv(_pose(own_d.xpos[own_root], own_d.xmat[own_root]))
