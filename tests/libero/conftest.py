"""LIBERO tests build one scene per module (2.5-4 s each); without LIBERO they are skipped, except the ones that
check the LIBERO-less install's error."""
import numpy as np
import pytest

SPATIAL_TASK = "libero_spatial:pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate"


@pytest.fixture(scope="module")
def libero_runner():
    pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig

    runner = EpisodeRunner(RunConfig(task=SPATIAL_TASK, seed=0, init="shipped"))
    yield runner
    runner.stack.sim.close()


@pytest.fixture
def spatial_task():
    return SPATIAL_TASK


@pytest.fixture
def rng():
    return np.random.default_rng(7)
