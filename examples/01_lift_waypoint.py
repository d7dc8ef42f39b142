"""01 — Lift a waypoint: pixel + depth in the planner camera → 3D world point, and back.

Run: python examples/01_lift_waypoint.py [--headless]
"""
# --- tunables -------------------------------------------------------------------------------------
TASK = "goal_cube_on_plate"  # scene to take the camera from
SEED = 0
IMAGE_PX = 128  # planner image size [px]
POINT_WORLD = (0.45, 0.10, 0.02)  # a point on the table [m]
# --------------------------------------------------------------------------------------------------
import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.config import TimingConfig
from tcot_hybrid.errors import LiftError
from tcot_hybrid.lift import lift_waypoints
from tcot_hybrid.robot import load_robot_spec
from tcot_hybrid.scene import SceneConfig
from tcot_hybrid.sim import Simulation
from tcot_hybrid.tasks import make_task


def main() -> None:
    argparse.ArgumentParser(description=__doc__).add_argument("--headless", action="store_true")
    sim = Simulation(load_robot_spec("panda"), make_task(TASK), timing=TimingConfig(), scene=SceneConfig())
    sim.reset(np.random.default_rng(SEED))
    cam = CameraModel.from_mujoco(sim.model, sim.data, "agentview", width=IMAGE_PX, height=IMAGE_PX)
    uv, depth = cam.project(np.array([POINT_WORLD]))
    print(f"world {POINT_WORLD} m -> pixel {uv[0].round(2)} px at depth {depth[0]:.4f} m")
    back = lift_waypoints(uv, depth, cam)
    print(f"lifted back -> {back[0].round(6)} m (error {np.linalg.norm(back[0] - POINT_WORLD):.2e} m)")
    try:
        lift_waypoints(np.array([[IMAGE_PX + 5.0, 10.0]]), np.array([1.0]), cam)
    except LiftError as exc:
        print(f"out-of-image waypoint refused: {exc}")


if __name__ == "__main__":
    main()
