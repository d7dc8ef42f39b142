"""Label replay on LIBERO: a demonstration's own t = 0 label is replayed on the layout it was recorded on."""
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.data.collect import collect  # noqa: E402
from tcot_hybrid.data.dataset import DemoFile  # noqa: E402
from tcot_hybrid.data.replay import replay_file  # noqa: E402
from tcot_hybrid.run_config import RunConfig  # noqa: E402


def test_a_demo_label_replays_on_its_own_sampled_layout(libero_demos):
    """Replayed on LIBERO's default init (the shipped state of the same number) the label missed the bowl."""
    report = replay_file(libero_demos, workers=1, progress=False)
    assert [r["seed"] for r in report["demos"]] == [0, 1, 2]
    assert all(r["fault"] is None for r in report["demos"])
    assert all(r["success"] for r in report["demos"]), report["demos"]


def test_a_spread_demo_records_its_layout_mode_and_replays_on_it(tmp_path, spatial_task):
    """A demo on a spread layout (``--init spread``) says so, and its label replays on that layout, not on the
    sampled layout of the same seed (the bowl stands up to 8 cm elsewhere there)."""
    out = tmp_path / "spread.hdf5"
    base = RunConfig(task=spatial_task, robot="libero_panda", init="spread")
    s = collect(base, tasks=[spatial_task], seeds=[5000], out=out, workers=1, progress=False, image_every=50)
    assert s.written == 1 and not s.crashes
    with DemoFile(out) as f:
        assert [i.init for i in f.infos()] == ["spread"]
    report = replay_file(out, workers=1, progress=False)
    assert report["demos"][0]["success"], report["demos"]
