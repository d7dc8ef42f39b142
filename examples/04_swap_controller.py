"""04 — Swap controllers: run a task, switching the low-level controller mid-episode (bumplessly).

Run: python examples/04_swap_controller.py [--headless]
"""
# --- tunables -------------------------------------------------------------------------------------
TASK = "goal_cube_in_bowl"
SEED = 1
FIRST, SECOND = "computed_torque", "joint_pd"
SWITCH_AT_STEP = 15  # planner step at which to switch
# --------------------------------------------------------------------------------------------------
import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from tcot_hybrid.controllers import make_controller
from tcot_hybrid.episode import EpisodeRunner
from tcot_hybrid.run_config import RunConfig


def main() -> None:
    argparse.ArgumentParser(description=__doc__).add_argument("--headless", action="store_true")
    runner = EpisodeRunner(RunConfig(task=TASK, seed=SEED, controller=FIRST))

    def switch(r, step):
        if step == SWITCH_AT_STEP:
            ex = r.stack.executor
            ex.switch_controller(make_controller(SECOND, r.stack.robot, ctrl_dt=r.cfg.timing.ctrl_dt))

    runner.frame_hook = switch
    rec = runner.run()
    switches = [e for e in rec["events"] if e["kind"] == "controller_switched"]
    print(f"{TASK}: success={rec['success']} after switching {switches}")


if __name__ == "__main__":
    main()
