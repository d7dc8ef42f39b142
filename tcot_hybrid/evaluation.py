"""``tcot eval``: suites × planners × modes × (robots × controllers × IK) × seeds, in parallel, resumable.

Every finished episode is appended to ``DIR/episodes.jsonl`` at once, so an interrupted evaluation
resumes where it stopped. ``DIR/eval.json`` holds one cell per task × planner × mode × perturbation ×
robot × controller × IK with success rate and standard error; ``DIR/eval.md`` the tables.
"""
from __future__ import annotations

import dataclasses
import itertools
import json
import math
import multiprocessing as mp
import os
import time
from collections import defaultdict
from pathlib import Path

from tcot_hybrid.run_config import RunConfig

CELL_KEYS = ("task", "suite", "planner", "mode", "perturb", "robot", "controller", "ik")


@dataclasses.dataclass(frozen=True)
class Job:
    cfg: RunConfig

    @property
    def perturb(self) -> str:
        return self.cfg.perturb.name

    @property
    def key(self) -> str:
        c = self.cfg
        return "|".join(map(str, (c.task, c.planner, c.supervisor.mode, self.perturb, c.robot, c.controller,
                                  c.ik, c.seed, c.digest())))


def make_jobs(base: RunConfig, *, tasks, planners, modes, robots, controllers, iks, episodes: int,
              seed_start: int, perturbs=("none",)) -> list[Job]:
    """The cross product, every field validated by the config dataclasses before anything runs."""
    jobs = []
    for task, planner, mode, perturb, robot, ctrl, ik in itertools.product(
            tasks, planners, modes, perturbs, robots, controllers, iks):
        for seed in range(seed_start, seed_start + episodes):
            cfg = dataclasses.replace(
                base, task=task, planner=planner, robot=robot, controller=ctrl, ik=ik, seed=seed,
                supervisor=dataclasses.replace(base.supervisor, mode=mode),
                perturb=dataclasses.replace(base.perturb, name=perturb))
            jobs.append(Job(cfg))
    return jobs


def run_job(job: Job) -> dict:
    """Run one episode in this process; never raises (a crash is a failed, faulted episode)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from tcot_hybrid.episode import EpisodeRunner

    try:
        rec = EpisodeRunner(job.cfg).run()
        rec.pop("config", None)
        rec["events"] = [e for e in rec["events"] if e["kind"] not in ("plan_adopted", "gripper")]
    except Exception as exc:  # noqa: BLE001 - recorded, counted as failure
        c = job.cfg
        rec = {"task": c.task, "planner": c.planner, "mode": c.supervisor.mode, "robot": c.robot,
               "controller": c.controller, "ik": c.ik, "seed": c.seed, "success": False,
               "fault": f"crash:{type(exc).__name__}: {exc}"}
    rec["perturb"] = job.perturb
    rec["key"] = job.key
    return rec


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


def evaluate(jobs: list[Job], out_dir: str | Path, *, workers: int = 2, progress: bool = True) -> dict:
    from tqdm import tqdm

    from tcot_hybrid.tasks import make_task

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "episodes.jsonl"
    done = _done_keys(log)
    todo = [j for j in jobs if j.key not in done]
    t0 = time.perf_counter()
    with open(log, "a") as f, tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc="eval", unit="ep",
                                    disable=not progress) as bar:
        if workers <= 1:
            results = map(run_job, todo)
        else:
            pool = mp.get_context("spawn").Pool(workers, maxtasksperchild=50)
            results = pool.imap_unordered(run_job, todo, chunksize=1)
        for rec in results:
            f.write(json.dumps(rec) + "\n")
            f.flush()
            done[rec["key"]] = rec
            bar.update(1)
        if workers > 1:
            pool.close()
            pool.join()
    wall = time.perf_counter() - t0
    records = [done[j.key] for j in jobs]
    for r in records:
        r.setdefault("suite", make_task(r["task"]).suite)
    cells = aggregate(records)
    result = {"cells": cells, "episodes": len(records), "wall_time_s": round(wall, 2), "workers": workers}
    (out / "eval.json").write_text(json.dumps(result, indent=2))
    (out / "eval.md").write_text(markdown(cells))
    return result


def aggregate(records: list[dict]) -> list[dict]:
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        groups[tuple(r.get(k, "none") for k in CELL_KEYS)].append(r)
    cells = []
    for key, recs in groups.items():
        n = len(recs)
        k = sum(bool(r["success"]) for r in recs)
        p = k / n
        cell = dict(zip(CELL_KEYS, key))
        cell.update(episodes=n, successes=k, success_rate=round(p, 4),
                    stderr=round(math.sqrt(p * (1 - p) / n), 4),
                    faults=sum(bool(r.get("fault")) for r in recs),
                    mean_sim_time_s=round(sum(r.get("sim_time_s", 0.0) for r in recs) / n, 3),
                    mean_wall_time_s=round(sum(r.get("wall_time_s", 0.0) for r in recs) / n, 3),
                    max_joint_limit_violation_rad=max(r.get("max_joint_limit_violation_rad", 0.0) for r in recs),
                    max_velocity_ratio=round(max(r.get("max_velocity_ratio", 0.0) for r in recs), 4),
                    max_tracking_error_rad=round(max(r.get("max_tracking_error_rad", 0.0) for r in recs), 4),
                    failed_seeds=sorted(r["seed"] for r in recs if not r["success"]))
        cells.append(cell)
    return cells


def markdown(cells: list[dict]) -> str:
    lines = ["| task | suite | planner | mode | perturb | robot | controller | ik | success | ± s.e. | n | "
             "max limit viol. [rad] | max \\|q̇\\|/v_max |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cells:
        lines.append(f"| {c['task']} | {c['suite']} | {c['planner']} | {c['mode']} | {c['perturb']} | {c['robot']} | "
                     f"{c['controller']} | {c['ik']} | {c['success_rate']:.2f} | {c['stderr']:.2f} | {c['episodes']} | "
                     f"{c['max_joint_limit_violation_rad']:.1e} | {c['max_velocity_ratio']:.2f} |")
    # per-suite summary (paper Table 1 form)
    suites: dict[tuple, list[int]] = defaultdict(lambda: [0, 0])
    for c in cells:
        key = (c["planner"], c["mode"], c["robot"], c["controller"], c["ik"])
        suites[key + (c["suite"],)][0] += c["successes"]
        suites[key + (c["suite"],)][1] += c["episodes"]
    lines += ["", "| planner | mode | robot | controller | ik | suite | success ± s.e. | n |", "|---|---|---|---|---|---|---|---|"]
    for key, (k, n) in sorted(suites.items()):
        p = k / n
        lines.append(f"| {' | '.join(key)} | {p:.3f} ± {math.sqrt(p * (1 - p) / n):.3f} | {n} |")
    return "\n".join(lines) + "\n"
