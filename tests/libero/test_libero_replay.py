"""Label replay on LIBERO: a demonstration's own t = 0 label is replayed on the layout it was recorded on."""
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.data.replay import replay_file  # noqa: E402


def test_a_demo_label_replays_on_its_own_sampled_layout(libero_demos):
    """Replayed on LIBERO's default init (the shipped state of the same number) the label missed the bowl."""
    report = replay_file(libero_demos, workers=1, progress=False)
    assert [r["seed"] for r in report["demos"]] == [0, 1, 2]
    assert all(r["fault"] is None for r in report["demos"])
    assert all(r["success"] for r in report["demos"]), report["demos"]
