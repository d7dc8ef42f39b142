"""The paper's direct-action baseline: the same backbone maps the observation straight to the next action.

Every planner step it predicts the TCP displacement over the next ``direct_horizon`` planner steps
[m, world] and the gripper command, adds the displacement to the current TCP position (forward
kinematics of the measured joints, placed in the world by the robot's mounting pose ``T_world_base``: the
identity in the workcell, e.g. (-0.66, 0, 0.912) on LIBERO's tabletop scenes) and emits a one-waypoint plan of
kind ``"direct"``, which goes through the same lift → IK → Ruckig → controller chain as every other plan.
``replan_every_step`` tells the supervisor to ask it at every step, whatever the supervision mode.

Orientation: the network predicts no rotation (the paper's baseline outputs a displacement and a gripper
bit). In the workcell the plan carries none (the executor's top-down hand, what every workcell demonstration
holds); with a LIBERO checkpoint (``world: libero``) every plan holds the TCP orientation the episode started
with (forward kinematics of the first observation's joints), so the baseline never turns the hand: LIBERO's
tilted and turned grasps are out of its reach by construction (docs/libero-planner.md, "Direct baseline on
LIBERO").
"""
from __future__ import annotations

import mujoco
import numpy as np

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.errors import ConfigError, PlanningError
from tcot_hybrid.plan import WaypointPlan
from tcot_hybrid.planners.base import Observation
from tcot_hybrid.planners.learned import NetworkPlanner, check_outputs
from tcot_hybrid.robot import load_robot_spec, robot_mjspec


class TcpKinematics:
    """TCP pose [m, world] of the robot for given arm joints [rad]: MuJoCo forward kinematics of the robot model
    alone, in its own frame, then placed in the world by ``T_world_base`` (4x4, the robot's mounting pose; None:
    the identity, as in the workcell)."""

    def __init__(self, robot_name: str, T_world_base: np.ndarray | None = None):
        spec = load_robot_spec(robot_name)
        self.model = robot_mjspec(spec).compile()
        self.data = mujoco.MjData(self.model)
        self.qadr = np.array([self.model.jnt_qposadr[self.model.joint(j).id] for j in spec.arm_joints])
        self.site = self.model.site(spec.ee_site).id
        T = np.eye(4) if T_world_base is None else np.asarray(T_world_base, dtype=float)
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise ConfigError(f"T_world_base must be a finite 4x4 transform, got {np.asarray(T_world_base).tolist()}")
        R = T[:3, :3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or not np.allclose(T[3], [0, 0, 0, 1]):
            raise ConfigError(f"T_world_base is not a rigid transform: {T.round(6).tolist()}")
        self.T_world_base = T

    def pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,) [m], orientation (3, 3)) of the TCP in the world for arm joints ``q``."""
        self.data.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        R, p = self.T_world_base[:3, :3], self.T_world_base[:3, 3]
        return R @ self.data.site_xpos[self.site] + p, R @ self.data.site_xmat[self.site].reshape(3, 3)

    def tcp(self, q: np.ndarray) -> np.ndarray:
        return self.pose(q)[0]


class DirectPlanner(NetworkPlanner):
    """Next-action baseline (no trajectory): one waypoint ``direct_horizon`` steps ahead, every step."""

    name = "direct"
    needs_image = True
    kind = "direct"
    replan_every_step = True

    def __init__(self, checkpoint, camera: CameraModel, *, robot_name: str, T_world_base: np.ndarray | None = None):
        super().__init__(checkpoint, camera)
        from tcot_hybrid.learning.checkpoint import checkpoint_world

        self.kinematics = TcpKinematics(robot_name, T_world_base)
        self.hold_orientation = checkpoint_world(self.meta) == "libero"  # see the module doc
        self._start_rot: np.ndarray | None = None

    def prepare(self) -> None:
        self._start_rot = None  # a new episode: its first observation sets the orientation held

    @classmethod
    def from_context(cls, ctx) -> DirectPlanner:
        from tcot_hybrid.learning.checkpoint import load_checkpoint
        from tcot_hybrid.planners import context_checkpoint

        path = context_checkpoint(cls.name, ctx)
        ck = load_checkpoint(path, robot=ctx.robot_name, camera=ctx.camera, kind=cls.kind, robot_spec=ctx.robot,
                             world=ctx.world_kind)
        return cls(ck, ctx.camera, robot_name=ctx.robot_name, T_world_base=ctx.T_world_base)

    def plan(self, obs: Observation, *, mode: str = "direct") -> WaypointPlan:
        out = self.infer(obs, "global")  # the direct model has no mode prompt; the id is ignored
        delta = out["delta_m"].astype(float)
        logit = float(out["grip_logit"][0])
        p = 1.0 / (1.0 + np.exp(-logit)) if np.isfinite(logit) and logit > -700 else (0.0 if logit == -np.inf else np.nan)
        tcp, rot = self.kinematics.pose(np.asarray(obs.q, dtype=float))
        if self._start_rot is None:
            self._start_rot = rot
        target = tcp + delta
        if not np.isfinite(target).all():
            raise PlanningError(f"direct planner output is not finite: delta_m={delta.tolist()}")
        check_outputs(np.zeros((1, 2)), np.zeros(1), np.array([p]))
        uv, depth = self.camera.project(target[None])
        if not depth[0] > self.camera.near_m or not self.camera.in_image(uv)[0]:
            raise PlanningError(f"direct planner target {target.round(4).tolist()} m projects outside camera "
                                f"{self.camera.name!r}'s image (uv {uv[0].round(1).tolist()}, depth {depth[0]:.3f} m)")
        return WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([p > 0.5]), camera=self.camera.name,
                            kind="direct", step=obs.step, meta={"delta_m": delta, "gripper_prob": p},
                            tcp_rot=self._start_rot[None].copy() if self.hold_orientation else None)
