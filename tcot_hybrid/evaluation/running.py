"""Running evaluation jobs: one episode per job in worker processes (or on a Ray cluster), resumable
from ``DIR/episodes.jsonl``."""
from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import time
from pathlib import Path

from tcot_hybrid.errors import ConfigError
from tcot_hybrid.jsonio import atomic_write_text, check_output_dir
from tcot_hybrid.evaluation.aggregation import aggregate, detector_metrics
from tcot_hybrid.evaluation.jobs import Job
from tcot_hybrid.evaluation.reports import markdown
from tcot_hybrid.workers import one_torch_thread, worker_pool

DETECTOR_STEPS_AFTER_SUCCESS = 5  # planner steps past success on which the detector is probed


def run_job(job: Job) -> dict:
    """Run one episode in this process; never raises (a crash is a failed, faulted episode)."""
    os.environ.setdefault("MUJOCO_GL", "egl")  # compute threads: set before the worker started (worker_pool)
    from tcot_hybrid.episode import EpisodeRunner

    c = job.cfg
    runner = None
    try:
        runner = EpisodeRunner(c)
        # post-success probes of the detector (false alarms) only where the simulator ended the episode
        probe = c.supervisor.mode.startswith("glsr") and runner.stop_on in ("simulator", "either")
        rec = runner.run(steps_after_success=DETECTOR_STEPS_AFTER_SUCCESS if probe else 0, probe_detector=probe)
        rec.pop("config", None)  # every event `tcot run` records is kept: a failure is diagnosed without a re-run
    except Exception as exc:  # noqa: BLE001 - recorded, counted as failure
        rec = {"task": c.task, "planner": c.planner, "mode": c.supervisor.mode, "robot": c.robot,
               "controller": c.controller, "ik": c.ik, "seed": c.seed, "success": False,
               "fault": f"crash:{type(exc).__name__}: {exc}"}
    finally:
        if runner is not None:  # frees renderers; a LIBERO scene stays built for this worker's next episode
            runner.stack.sim.close()
    rec["perturb"] = job.perturb
    rec["sweep"] = job.sweep
    rec["key"] = job.key
    return rec


def longest_first(jobs: list[Job]) -> list[Job]:
    """Jobs with the longest task time limit first (stable otherwise): workers that pick up the long
    episodes early finish together, instead of one worker running a last long episode alone."""
    from tcot_hybrid.tasks import make_task

    limits = {name: make_task(name).time_limit_s for name in {j.cfg.task for j in jobs}}
    return sorted(jobs, key=lambda j: -limits[j.cfg.task])


def _done_keys(path: Path) -> dict[str, dict]:
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                rec = json.loads(line)
                done[rec["key"]] = rec
            except (json.JSONDecodeError, KeyError):
                continue  # a line cut off by an interruption: that episode is simply re-run
    return done


def _ray_results(todo: list[Job], address: str):
    try:
        import ray
    except ImportError as exc:
        raise ConfigError("--ray-address needs Ray: pip install 'ray[default]' (not a default dependency)") from exc
    ray.init(address=address, ignore_reinit_error=True, log_to_driver=False)
    remote = ray.remote(run_job)
    pending = [remote.remote(j) for j in todo]
    while pending:
        ready, pending = ray.wait(pending, num_returns=1)
        yield ray.get(ready[0])


def evaluate(jobs: list[Job], out_dir: str | Path, *, workers: int = 2, progress: bool = True,
             ray_address: str | None = None) -> dict:
    from tqdm import tqdm

    from tcot_hybrid.tasks import make_task

    out = check_output_dir(out_dir)
    log = out / "episodes.jsonl"
    done = _done_keys(log)
    jobs = [dataclasses.replace(j, fixed_key=j.key) for j in jobs]  # hashed once, here: workers reuse it
    todo = longest_first([j for j in jobs if j.key not in done])
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        f = stack.enter_context(open(log, "a"))
        bar = stack.enter_context(tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc="eval", unit="ep",
                                       disable=not progress))
        if ray_address:
            results = _ray_results(todo, ray_address)
        elif workers <= 1:
            stack.enter_context(one_torch_thread())
            results = map(run_job, todo)
        else:
            pool = stack.enter_context(worker_pool(workers, maxtasksperchild=50))
            results = pool.imap_unordered(run_job, todo, chunksize=1)
        for rec in results:
            f.write(json.dumps(rec) + "\n")
            f.flush()
            done[rec["key"]] = rec
            bar.update(1)
    wall = time.perf_counter() - t0
    records = [done[j.key] for j in jobs]
    for r in records:
        r.setdefault("suite", make_task(r["task"]).suite)
    cells = aggregate(records)
    result = {"cells": cells, "episodes": len(records), "ran_now": len(todo), "wall_time_s": round(wall, 2),
              "workers": workers, "detector": detector_metrics(records)}
    atomic_write_text(out / "eval.json", json.dumps(result, indent=2))
    atomic_write_text(out / "eval.md", markdown(result))
    return result


