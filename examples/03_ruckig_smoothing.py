"""03 — Ruckig smoothing: a jerk-limited joint segment sampled at ctrl_dt, retargeted mid-motion.

Run: python examples/03_ruckig_smoothing.py [--headless]
"""
# --- tunables -------------------------------------------------------------------------------------
ROBOT = "panda"
CTRL_DT = 0.01  # [s]
VELOCITY_SCALE = 0.5  # fraction of the robot's v_max
DELTA_Q = 0.6  # joint offset of the first target [rad]
# --------------------------------------------------------------------------------------------------
import argparse

import numpy as np

from tcot_hybrid.robot import load_robot_spec
from tcot_hybrid.smoothing import JointSmoother, SmoothingConfig


def main() -> None:
    argparse.ArgumentParser(description=__doc__).add_argument("--headless", action="store_true")
    robot = load_robot_spec(ROBOT)
    sm = JointSmoother.from_spec(robot, ctrl_dt=CTRL_DT, config=SmoothingConfig(velocity_scale=VELOCITY_SCALE))
    sm.reset(robot.home_q)
    seg = sm.set_target(robot.home_q + DELTA_Q * np.sign(robot.q_max - robot.home_q - DELTA_Q))
    print(f"segment: {seg.duration_s:.3f} s, computed in {seg.compute_s * 1e6:.0f} us")
    peak_v = 0.0
    for i in range(int(seg.duration_s / CTRL_DT / 2)):
        peak_v = max(peak_v, float(np.max(np.abs(sm.step().qd) / robot.v_max)))
    seg2 = sm.set_target(robot.home_q)  # retarget from the moving state: no jump
    print(f"retargeted halfway: new segment {seg2.duration_s:.3f} s from a moving start")
    while not sm.done:
        peak_v = max(peak_v, float(np.max(np.abs(sm.step().qd) / robot.v_max)))
    print(f"peak |qd|/v_max = {peak_v:.3f} (<= {VELOCITY_SCALE}); final error "
          f"{np.max(np.abs(sm.reference.q - robot.home_q)):.1e} rad")


if __name__ == "__main__":
    main()
