"""Every controller drives the LIBERO Panda's torque motors (no robosuite controller), with its base away from
the world origin: OSC compares Pinocchio's base-frame reference with the measured TCP, so a missing
world->base transform would make it diverge at once."""
import numpy as np
import pytest

from tcot_hybrid.controllers import list_controllers


@pytest.mark.parametrize("controller", list_controllers())
def test_controller_tracks_a_joint_segment_on_libero(controller, spatial_task):
    pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig

    runner = EpisodeRunner(RunConfig(task=spatial_task, seed=1, controller=controller))
    try:
        runner.settle()
        ex, spec, sim = runner.stack.executor, runner.stack.robot, runner.stack.sim
        assert np.abs(sim.q - spec.home_q).max() < 0.05  # held LIBERO's init posture while objects settled
        target = spec.home_q + np.array([0.5, 0.4, -0.3, 0.5, 0.4, -0.4, 0.6])
        ex.smoother.set_target(target)
        worst = 0.0
        for _ in range(300):  # 3 s: the segment takes ~1.5 s
            ex.control_tick()
            worst = max(worst, float(np.abs(ex.smoother.reference.q - sim.q).max()))
        print(f"{controller} on LIBERO: max tracking error {worst:.4f} rad, final {np.abs(target - sim.q).max():.5f} rad")
        assert sim.fault is None and ex.tracking_reflexes == 0
        assert worst < 0.03
        assert np.abs(target - sim.q).max() < 2e-3
    finally:
        runner.stack.sim.close()
