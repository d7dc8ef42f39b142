"""06 — Full pick-and-place: oracle planner → lift → IK → Ruckig → controller → MuJoCo, with a video.

Run: python examples/06_pick_and_place.py [--headless] [--video out.mp4]
"""
# --- tunables -------------------------------------------------------------------------------------
TASK = "object_red_cube_in_basket"
SEED = 2
ROBOT = "panda"
CONTROLLER = "computed_torque"
IK = "mink"
# --------------------------------------------------------------------------------------------------
import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from tcot_hybrid.episode import EpisodeRunner
from tcot_hybrid.run_config import RunConfig
from tcot_hybrid.video import EpisodeVideo


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--headless", action="store_true")
    p.add_argument("--video", default=None, help="write an MP4 with the plan drawn on the front camera")
    args = p.parse_args()
    runner = EpisodeRunner(RunConfig(task=TASK, seed=SEED, robot=ROBOT, controller=CONTROLLER, ik=IK))
    video = EpisodeVideo(runner, args.video) if args.video else None
    if video:
        runner.frame_hook = video.capture
    rec = runner.run()
    if video:
        video.close()
    print(f"{TASK} ({runner.stack.task.instruction!r}): success={rec['success']} "
          f"sim {rec['sim_time_s']:.1f}s wall {rec['wall_time_s']:.2f}s, {rec['plans']} plan(s)")


if __name__ == "__main__":
    main()
