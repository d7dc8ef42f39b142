"""Worker pools: each worker computes on one thread, however its imports start OpenMP; the parent is untouched."""
import os

import pytest

from tcot_hybrid.workers import ONE_THREAD_ENV, one_torch_thread, worker_pool


def _threads_after_job_imports(_):
    import tcot_hybrid.evaluation.jobs  # noqa: F401  (what a worker imports to unpickle a job: starts OpenMP)
    import torch

    return torch.get_num_threads(), os.environ.get("OMP_NUM_THREADS")


def test_workers_start_with_one_compute_thread(monkeypatch):
    for k in ONE_THREAD_ENV:
        monkeypatch.delenv(k, raising=False)
    with worker_pool(2, maxtasksperchild=1) as pool:  # a worker started mid-run (maxtasksperchild) too
        got = pool.map(_threads_after_job_imports, range(3), chunksize=1)
    assert got == [(1, "1")] * 3
    assert all(k not in os.environ for k in ONE_THREAD_ENV)  # the parent's environment is restored


def test_a_thread_count_the_user_set_is_kept(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    with worker_pool(1) as pool:
        assert pool.map(_threads_after_job_imports, [0]) == [(2, "2")]
    assert os.environ["OMP_NUM_THREADS"] == "2"


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_bad_worker_count_names_the_value(bad):
    with pytest.raises(ValueError, match="workers must be an integer >= 1, got"):
        with worker_pool(bad):
            pass


def test_episodes_in_this_process_run_on_one_torch_thread(monkeypatch):
    import torch

    for k in ONE_THREAD_ENV:
        monkeypatch.delenv(k, raising=False)
    torch.set_num_threads(2)
    with one_torch_thread():
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2  # restored
    monkeypatch.setenv("MKL_NUM_THREADS", "2")  # the user chose: left alone
    with one_torch_thread():
        assert torch.get_num_threads() == 2
