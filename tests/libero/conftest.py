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


@pytest.fixture(scope="session")
def libero_demos(tmp_path_factory):
    """Three oracle demonstrations of SPATIAL_TASK on sampled layouts (training seeds 0-2, every 3rd frame imaged):
    the tiny data the learned and direct planners' end-to-end tests train on (collected once per session)."""
    pytest.importorskip("libero.libero")
    from tcot_hybrid.data.collect import collect
    from tcot_hybrid.run_config import RunConfig

    data = tmp_path_factory.mktemp("libero_demos") / "demos.hdf5"
    base = RunConfig(task=SPATIAL_TASK, robot="libero_panda", init="sampled")
    s = collect(base, tasks=[SPATIAL_TASK], seeds=[0, 1, 2], out=data, workers=1, progress=False, image_every=3)
    assert s.written == 3 and not s.crashes
    return data


@pytest.fixture
def spatial_task():
    return SPATIAL_TASK


@pytest.fixture
def rng():
    return np.random.default_rng(7)
