"""Probe, not the shipped behaviour (docs/libero-planner.md, "What is left", since stop 60): a stroke made with an
empty closed hand (a knob or a plate pushed with closed fingers) ends PUSH_M [m] further along its last segment. Runs
`tcot eval` in this process with the executor patched (so --workers 1), e.g.

    PUSH_M=0.03 MUJOCO_GL=egl .venv/bin/python docs/libero-planner/probe_push_through.py --planners learned \
        --tasks libero_10:KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it --init sampled --modes global \
        --episodes 16 --seed-start 20109 --workers 1 --checkpoint runs/libero/planner_libero10_100_more.safetensors \
        --out runs/dev/probe_push_3cm
"""
import os
import sys

import numpy as np

from tcot_hybrid.executor import MotionExecutor
from tcot_hybrid.supervision import SupervisorConfig

PUSH_M = float(os.environ.get("PUSH_M", "0.03"))
EMPTY_M = SupervisorConfig().empty_grasp_m


def main() -> int:
    orig_next = MotionExecutor._next

    def push_through(self):  # the settle after a close ends here: lengthen the stroke to the next open
        i = self.index
        if (self.phase == "settle" and self._plan_q is None and i >= 0 and self.grip[i]
                and self.sim.gripper_closed_cmd() and self.sim.gripper_opening_m() < EMPTY_M):
            opens = [j for j in range(i + 1, len(self.points)) if not self.grip[j]]
            if opens:
                j = opens[0]
                seg = self.points[j] - self.points[j - 1] if j - 1 > i else self.points[j] - self.points[i]
                h = np.array([seg[0], seg[1], 0.0])
                if np.linalg.norm(h) < 0.005:
                    h = self.points[j] - self.points[i]
                    h[2] = 0.0
                if np.linalg.norm(h) > 0.005:
                    self.points = self.points.copy()
                    self.points[j] = self.points[j] + PUSH_M * h / np.linalg.norm(h)
                    self.event("probe_push_through", waypoint=j, push_m=PUSH_M)
        return orig_next(self)

    MotionExecutor._next = push_through
    from tcot_hybrid.cli import main as cli_main

    return cli_main(["eval", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
