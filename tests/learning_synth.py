"""Synthetic demonstration files for the learning tests (no simulation: seconds, not minutes).

Each demo: a grey table with a green "object" square at a random pixel; a magenta "gripper" disc moves
from a fixed start to the object in T steps, then the gripper closes and success holds for the last
frames. Written with the data package's writer so the real reader validates it.
"""
from __future__ import annotations

import json
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import h5py
import numpy as np

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.data.collect import DemoRecord, write_demo, write_masks
from tcot_hybrid.data.dataset import FORMAT

PX = 128
DOF = 7


def agentview_camera(px: int = PX) -> CameraModel:
    """The workcell's planner camera (built from the real scene so checkpoints match real runs)."""
    from tcot_hybrid.config import TimingConfig
    from tcot_hybrid.robot import load_robot_spec
    from tcot_hybrid.scene import SceneConfig
    from tcot_hybrid.sim import Simulation
    from tcot_hybrid.tasks import make_task

    sim = Simulation(load_robot_spec("panda"), make_task("goal_cube_on_plate"), timing=TimingConfig(),
                     scene=SceneConfig(planner_image_px=px))
    sim.reset(np.random.default_rng(0))
    cam = CameraModel.from_mujoco(sim.model, sim.data, "agentview", width=px, height=px)
    sim.close()
    return cam


def _frame(uv_obj, uv_grip, closed, rng, px=PX) -> np.ndarray:
    img = np.full((px, px, 3), 170, np.uint8)
    img += rng.integers(0, 6, size=(px, px, 1), dtype=np.uint8)
    u, v = np.round(uv_obj).astype(int)
    img[max(v - 3, 0):v + 4, max(u - 3, 0):u + 4] = (40, 200, 60)
    yy, xx = np.mgrid[0:px, 0:px]
    r = 3 if closed else 5
    img[(xx - uv_grip[0]) ** 2 + (yy - uv_grip[1]) ** 2 <= r * r] = (230, 40, 220)
    return img


def make_demo_file(path, camera: CameraModel, *, seeds=range(12), T: int = 24, robot: str = "panda",
                   instructions=("put the cube on the plate", "open the drawer"), episode=None,
                   camera_for=None, quat_for=None) -> None:
    """Write a synthetic tcot-demos-v1 file with one demo per seed (seed % 10 == 0 → valid split).

    ``episode(seed) -> dict`` overrides demo attributes (e.g. an online rollout: source, planner, success,
    perturb, perturb_step, recover_step); an unsuccessful episode never has its success predicate hold.
    ``camera_for(seed) -> (CameraModel, support_z)`` gives every demo its own camera (a LIBERO-style file,
    env_args camera_per_demo) and table height (the track is lifted by it); ``quat_for(seed) -> (4,)`` its TCP
    orientation (w, x, y, z; default top-down)."""
    with h5py.File(path, "w") as h5:
        h5.attrs["format"] = FORMAT
        h5.attrs["tcot_version"] = "test"
        data = h5.create_group("data")
        data.attrs["total"] = 0
        for seed in seeds:
            rng = np.random.default_rng(seed)
            cam, support_z = camera_for(seed) if camera_for else (camera, 0.0)
            start = np.array([0.45, 0.0, 0.35 + support_z])
            goal = np.array([rng.uniform(0.35, 0.6), rng.uniform(-0.2, 0.2), 0.02 + support_z])
            s = np.clip(np.arange(T) / (T - 8), 0, 1)[:, None]
            pos = (start + (goal - start) * s).astype(np.float32)
            uv, depth = cam.project(pos.astype(float))
            uv_obj, _ = cam.project(goal[None])
            closed = (np.arange(T) >= T - 6).astype(np.uint8)
            succ = (np.arange(T) >= T - 3).astype(np.uint8)
            imgs = np.stack([_frame(uv_obj[0], uv[t], closed[t], rng) for t in range(T)])
            q = np.tile(np.linspace(-0.5, 0.5, DOF, dtype=np.float32), (T, 1)) + s.astype(np.float32) * 0.3
            actions = np.zeros((T, 4), np.float32)
            actions[:-1, :3] = pos[1:] - pos[:-1]
            actions[:-1, 3] = closed[1:]
            actions[-1, 3] = closed[-1]
            arrays = {
                "obs/agentview_image": imgs, "obs/robot0_joint_pos": q,
                "obs/robot0_joint_vel": np.zeros((T, DOF), np.float32), "obs/robot0_eef_pos": pos,
                "obs/robot0_eef_quat": np.tile(np.float32(quat_for(seed) if quat_for else [0, 1, 0, 0]), (T, 1)),
                "obs/robot0_gripper_qpos": np.zeros((T, 2), np.float32), "obs/robot0_gripper_closed": closed,
                "obs/eef_uv_px": uv.astype(np.float32), "obs/eef_depth_m": depth.astype(np.float32),
                "task_success": succ, "actions": actions,
            }
            instr = instructions[seed % len(instructions)]
            attrs = {"task": f"synthetic_{seed % len(instructions)}", "suite": "goal", "instruction": instr,
                     "seed": int(seed), "robot": robot, "planner": "oracle", "mode": "global", "perturb": "none",
                     "perturb_step": -1, "recover_step": -1, "source": "demo", "success": True, "t_success": T - 3,
                     "num_samples": T}
            attrs.update(episode(seed) if episode else {})
            if camera_for:
                attrs.update(K=np.asarray(cam.K, float), T_world_cam=np.asarray(cam.T_world_cam, float),
                             support_z=float(support_z))
            if not attrs["success"]:
                arrays["task_success"] = np.zeros(T, np.uint8)
                attrs["t_success"] = -1
            write_demo(h5, DemoRecord(attrs=attrs, arrays=arrays, env_args={}, wall_s=0.0), compression="lzf")
        env = {"robot": robot, "camera": camera.name, "K": camera.K.tolist(),
               "T_world_cam": camera.T_world_cam.tolist(), "width": camera.width, "height": camera.height,
               "near_m": camera.near_m, "far_m": camera.far_m, "sim_dt": 0.002, "ctrl_dt": 0.01, "plan_dt": 0.1,
               "config_hash": "synthetic", "camera_per_demo": camera_for is not None,
               "world": "libero" if camera_for else "workcell"}
        data.attrs["env_args"] = json.dumps(env)
        write_masks(h5)
