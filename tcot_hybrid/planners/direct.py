"""The paper's direct-action baseline: the same backbone maps the observation straight to the next action.

Every planner step it predicts the TCP displacement over the next ``direct_horizon`` planner steps
[m, world] and the gripper command, adds the displacement to the current TCP position (forward
kinematics of the measured joints) and emits a one-waypoint plan of kind ``"direct"``, which goes
through the same lift → IK → Ruckig → controller chain as every other plan. ``replan_every_step``
tells the supervisor to ask it at every step, whatever the supervision mode.
"""
from __future__ import annotations

import mujoco
import numpy as np

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.errors import PlanningError
from tcot_hybrid.plan import WaypointPlan
from tcot_hybrid.planners.base import Observation
from tcot_hybrid.planners.learned import NetworkPlanner, check_outputs
from tcot_hybrid.robot import load_robot_spec, robot_mjspec


class TcpKinematics:
    """TCP position [m, world] of the robot for given arm joints [rad] (MuJoCo forward kinematics of the
    robot model alone; the robot base is the world origin, as in the workcell)."""

    def __init__(self, robot_name: str):
        spec = load_robot_spec(robot_name)
        self.model = robot_mjspec(spec).compile()
        self.data = mujoco.MjData(self.model)
        self.qadr = np.array([self.model.jnt_qposadr[self.model.joint(j).id] for j in spec.arm_joints])
        self.site = self.model.site(spec.ee_site).id

    def tcp(self, q: np.ndarray) -> np.ndarray:
        self.data.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.site_xpos[self.site].copy()


class DirectPlanner(NetworkPlanner):
    """Next-action baseline (no trajectory): one waypoint ``direct_horizon`` steps ahead, every step."""

    name = "direct"
    needs_image = True
    kind = "direct"
    replan_every_step = True

    def __init__(self, checkpoint, camera: CameraModel, *, robot_name: str):
        super().__init__(checkpoint, camera)
        self.kinematics = TcpKinematics(robot_name)

    @classmethod
    def from_context(cls, ctx) -> DirectPlanner:
        from tcot_hybrid.learning.checkpoint import load_checkpoint
        from tcot_hybrid.planners import planner_checkpoint

        from tcot_hybrid.robot import robot_ref

        path = planner_checkpoint(cls.name, ctx.robot_name, ctx.options.get("checkpoint"),
                                  robot_ref=robot_ref(ctx.robot) if ctx.robot is not None else None)
        ck = load_checkpoint(path, robot=ctx.robot_name, camera=ctx.camera, kind=cls.kind, robot_spec=ctx.robot,
                             world=ctx.world_kind)
        return cls(ck, ctx.camera, robot_name=ctx.robot_name)

    def plan(self, obs: Observation, *, mode: str = "direct") -> WaypointPlan:
        out = self.infer(obs, "global")  # the direct model has no mode prompt; the id is ignored
        delta = out["delta_m"].astype(float)
        logit = float(out["grip_logit"][0])
        p = 1.0 / (1.0 + np.exp(-logit)) if np.isfinite(logit) and logit > -700 else (0.0 if logit == -np.inf else np.nan)
        target = self.kinematics.tcp(np.asarray(obs.q, dtype=float)) + delta
        if not np.isfinite(target).all():
            raise PlanningError(f"direct planner output is not finite: delta_m={delta.tolist()}")
        check_outputs(np.zeros((1, 2)), np.zeros(1), np.array([p]))
        uv, depth = self.camera.project(target[None])
        if not depth[0] > self.camera.near_m or not self.camera.in_image(uv)[0]:
            raise PlanningError(f"direct planner target {target.round(4).tolist()} m projects outside camera "
                                f"{self.camera.name!r}'s image (uv {uv[0].round(1).tolist()}, depth {depth[0]:.3f} m)")
        return WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([p > 0.5]), camera=self.camera.name,
                            kind="direct", step=obs.step, meta={"delta_m": delta, "gripper_prob": p})
