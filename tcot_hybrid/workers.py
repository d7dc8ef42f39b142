"""Worker processes for episodes (``tcot eval``, ``tcot collect``, demo replays): one compute thread each; episodes
run in the calling process (one worker) on one torch thread too."""
from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
from collections.abc import Iterator
from multiprocessing.pool import Pool

# W workers on W cores: torch's default of one thread per core in every worker oversubscribes them (measured here:
# ~15 % more CPU per LIBERO episode on an idle machine; batch-1 inference up to ~40x slower under load)
ONE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def user_chose_threads() -> bool:
    """The environment sets a thread count (``OMP_NUM_THREADS`` or ``MKL_NUM_THREADS``): it is left as it is."""
    return any(os.environ.get(k) is not None for k in ONE_THREAD_ENV)


@contextlib.contextmanager
def worker_pool(workers: int, **pool_kwargs) -> Iterator[Pool]:
    """A spawn pool of ``workers`` processes that start with one compute thread each (``ONE_THREAD_ENV``; if the
    environment already sets either variable, the user chose the threads, and it is left as it is). The variables go into the environment the workers start from, for the
    pool's whole life (``maxtasksperchild`` starts new workers): a worker setting them itself is too late, since
    its first imports (the IK's QP solvers) have started OpenMP by then. The parent's environment is restored and
    the pool terminated on exit."""
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    saved = {k: os.environ.get(k) for k in ONE_THREAD_ENV}
    if not user_chose_threads():
        os.environ.update(ONE_THREAD_ENV)
    try:
        pool = mp.get_context("spawn").Pool(workers, **pool_kwargs)
        try:
            yield pool
        finally:
            pool.terminate()
            pool.join()
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextlib.contextmanager
def one_torch_thread() -> Iterator[None]:
    """Episodes run in this process (one worker: eval, collect, replay) with torch on one thread, as in a worker: with
    torch's default of one thread per core, a LIBERO episode took 200-230 s instead of 45 s while two other processes
    shared the two cores, and the network's outputs are the same whatever the worker count. Left alone when
    :func:`user_chose_threads`; restored on exit."""
    if user_chose_threads():
        yield
        return
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)
