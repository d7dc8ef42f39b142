"""The first global plan of an episode, point by point, as the executor will follow it (after lifting, squared
transits and the retreat from a release): world position [m], gripper, and the hand's approach axis. A diagnostic
for docs/libero-planner.md ("The bottom drawer: a bowl carried out again"); nothing is saved.

    MUJOCO_GL=egl .venv/bin/python docs/libero-planner/first_plan.py --task TASK --seed 20026 --planner learned
"""
from __future__ import annotations

import argparse

import numpy as np

import dev_runs  # this folder's: run as a script, the folder is on sys.path


class _Planned(Exception):
    """Raised once the step-0 plan is adopted: the probe needs nothing after it."""


def first_plan(task: str, seed: int, planner: str, checkpoint: str | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.workers import one_torch_thread

    cfg = dev_runs.episode_config(task, seed, planner, checkpoint=checkpoint)

    def stop(runner, step):
        if step == 1:
            raise _Planned

    runner = EpisodeRunner(cfg, pre_step_hook=stop)
    try:
        with one_torch_thread():  # as `tcot run` and the evaluation's workers
            runner.run()
    except _Planned:
        pass
    ex = runner.stack.executor
    return ex.points, ex.grip, ex.rots[:, :, 2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--planner", default="learned", choices=("learned", "oracle"))
    ap.add_argument("--checkpoint", help="the learned planner's checkpoint (default: the task's shipped model)")
    a = ap.parse_args()
    points, grip, approach = first_plan(a.task, a.seed, a.planner, a.checkpoint)
    print("| point | x [m] | y [m] | z [m] | gripper | approach axis |")
    print("|---|---|---|---|---|---|")
    for i, (p, g, z) in enumerate(zip(points, grip, approach)):
        print(f"| {i} | {p[0]:.3f} | {p[1]:.3f} | {p[2]:.3f} | {'closed' if g else 'open'} | "
              f"({z[0]:+.2f}, {z[1]:+.2f}, {z[2]:+.2f}) |")


if __name__ == "__main__":
    main()
