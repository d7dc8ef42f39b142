"""Probe, not the shipped behaviour (docs/libero-planner.md, "The book: a grasp 2 cm off"): on a tracking reflex with
the gripper closed, open it at once. Does a wedged book drop into the caddy's back compartment? Runs `tcot eval` in
this process with the executor patched (so --workers 1), e.g.

    MUJOCO_GL=egl .venv/bin/python docs/libero-planner/probe_release_on_reflex.py --planners learned --init sampled \
        --tasks libero_10:STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_back_compartment_of_the_caddy \
        --modes global,glsr --episodes 16 --seed-start 20109 --workers 1 \
        --checkpoint runs/libero/planner_libero10_100_more.safetensors --out runs/dev/probe_book_release
"""
import sys

from tcot_hybrid.executor import MotionExecutor


def main() -> int:
    reflex = MotionExecutor._tracking_reflex

    def release_on_reflex(self, joint, err, limit):
        reflex(self, joint, err, limit)
        if self.sim.gripper_closed_cmd():
            self.sim.set_gripper(False)
            self.event("gripper", closed=False, reason="probe_release_on_reflex")

    MotionExecutor._tracking_reflex = release_on_reflex
    from tcot_hybrid.cli import main as cli_main

    return cli_main(["eval", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
