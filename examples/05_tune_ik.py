"""05 — Tune IK: how damping and posture cost trade convergence, error and iterations.

Run: python examples/05_tune_ik.py [--headless]
"""
# --- tunables -------------------------------------------------------------------------------------
ROBOT = "panda"
BACKEND = "mink"
DAMPINGS = (1e-4, 1e-2, 1.0)  # Levenberg-Marquardt damping values to compare
POSTURE_COSTS = (1e-3, 1e-1)  # posture pull values to compare
N_TARGETS = 40
SEED = 0
# --------------------------------------------------------------------------------------------------
import argparse
import dataclasses

import numpy as np

from tcot_hybrid.robot import R_DOWN
from tcot_hybrid.ik import IKConfig, IKTarget, make_ik
from tcot_hybrid.robot import load_robot_spec


def main() -> None:
    argparse.ArgumentParser(description=__doc__).add_argument("--headless", action="store_true")
    robot = load_robot_spec(ROBOT)
    rng = np.random.default_rng(SEED)
    targets = np.column_stack([rng.uniform(0.35, 0.65, N_TARGETS), rng.uniform(-0.25, 0.25, N_TARGETS),
                               rng.uniform(0.02, 0.3, N_TARGETS)])
    print(f"{'damping':>8} {'posture':>8} {'converged':>9} {'mean iters':>10} {'median err [mm]':>15}")
    for damping in DAMPINGS:
        for posture in POSTURE_COSTS:
            cfg = dataclasses.replace(IKConfig(), damping=damping, posture_cost=posture)
            ik = make_ik(BACKEND, robot, cfg)
            res = [ik.solve(IKTarget(pos=t, rot=R_DOWN), robot.home_q) for t in targets]
            print(f"{damping:>8.0e} {posture:>8.0e} {np.mean([r.converged for r in res]):>9.0%} "
                  f"{np.mean([r.iters for r in res]):>10.1f} {np.median([r.pos_err for r in res]) * 1e3:>15.3f}")


if __name__ == "__main__":
    main()
