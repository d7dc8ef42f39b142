"""One LIBERO episode's waypoints as the executor solves them: for each, how far the plan asks the hand to turn from
the hand of the IK seed (the previous waypoint's answer) and how far its half-turned twin lies, and what IK answers
for each from the same seed (position miss, joint travel, a joint limit shaping it). A diagnostic for docs/libero-planner.md ("The hand the arm
stands nearer"); nothing is saved. ``--before`` runs the executor as it was before a turn alone asked for the twin.

    MUJOCO_GL=egl .venv/bin/python docs/libero-planner/hand_turn_trace.py --seed 20026 [--before]
"""
from __future__ import annotations

import argparse

import numpy as np

import dev_runs  # this folder's: run as a script, the folder is on sys.path

KETCHUP = "libero_object:pick_up_the_ketchup_and_place_it_in_the_basket"


def main() -> None:
    from tcot_hybrid import executor
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.ik import rotation_angle

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default=KETCHUP)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--mode", default="global", choices=("global", "glsr"))
    ap.add_argument("--before", action="store_true", help="the twin only on a miss or a limit")
    a = ap.parse_args()
    if a.before:
        executor.TWIN_TURN_RAD = np.inf
    activate = executor.MotionExecutor._activate
    print("| waypoint | turn asked [deg] | twin's turn [deg] | as asked: miss [m], travel [rad], limit | "
          "twin: miss [m], travel [rad], limit | taken: the twin? | events |")
    print("|---|---|---|---|---|---|---|")

    def traced(ex, i: int) -> None:
        seed, turned, n = ex._ik_seed.copy(), ex._hand_turned, len(ex.events)
        activate(ex, i)
        if ex._plan_q is not None or ex.phase == "done":
            return
        asked, twin = ex.ik_target(i, turned), ex.ik_target(i, not turned)
        held = ex.ik.tcp_pose(seed)[1]
        cells = []
        for target in (asked, twin):
            res = ex.ik.solve(target, seed)
            cells.append(f"{res.pos_err:.3f}, {np.abs(res.q - seed).sum():.2f}, {'yes' if res.limit_active else 'no'}")
        print(f"| {i} | {np.degrees(rotation_angle(held, asked.rot)):.0f} | "
              f"{np.degrees(rotation_angle(held, twin.rot)):.0f} | {cells[0]} | {cells[1]} | "
              f"{'yes' if ex._hand_turned != turned else 'no'} | {', '.join(e['kind'] for e in ex.events[n:])} |")

    executor.MotionExecutor._activate = traced
    rec = EpisodeRunner(dev_runs.episode_config(a.task, a.seed, "learned", a.mode)).run()
    print(f"\nsuccess: {rec['success']}; tracking reflexes: {rec['tracking_reflexes']}")


if __name__ == "__main__":
    main()
