"""02 — IK reach: solve a top-down TCP target with both backends, seeded from home.

Run: python examples/02_ik_reach.py [--headless]
"""
# --- tunables -------------------------------------------------------------------------------------
ROBOT = "panda"
TARGET_POS = (0.55, -0.15, 0.05)  # TCP target [m, world]
# --------------------------------------------------------------------------------------------------
import argparse

import numpy as np

from tcot_hybrid.robot import R_DOWN
from tcot_hybrid.ik import IKTarget, list_ik, make_ik
from tcot_hybrid.robot import load_robot_spec


def main() -> None:
    argparse.ArgumentParser(description=__doc__).add_argument("--headless", action="store_true")
    robot = load_robot_spec(ROBOT)
    for name in list_ik():
        res = make_ik(name, robot).solve(IKTarget(pos=np.array(TARGET_POS), rot=R_DOWN), robot.home_q)
        print(f"{name:>9}: {res.status:<10} iters={res.iters:<3} pos_err={res.pos_err * 1e3:.3f} mm "
              f"rot_err={res.rot_err:.2e} rad q={np.round(res.q, 3)}")


if __name__ == "__main__":
    main()
