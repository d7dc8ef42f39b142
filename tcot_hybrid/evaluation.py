"""``tcot eval``: tasks × planners × modes × perturbations × (robots × controllers × IK) × sweep values
× seeds, in parallel worker processes (or on a Ray cluster), resumable.

Every finished episode is appended to ``DIR/episodes.jsonl`` at once, so an interrupted evaluation
resumes where it stopped (jobs are keyed by their full config hash, the hash of the task code and the hash of
the checkpoint their planner loads, so a retrained or replaced checkpoint, or a changed oracle script, is never
credited with the old episodes). ``DIR/eval.json`` holds one cell
per task × planner × mode × perturbation × robot × controller × IK × sweep value with success rate and
standard error, plus failure-detector metrics; ``DIR/eval.md`` has the paper's tables (Table 1: per
suite success ± s.e.; Table 4: ablation of the planning modes).
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import itertools
import json
import math
import multiprocessing as mp
import os
import time
import typing
from collections import defaultdict
from pathlib import Path

from tcot_hybrid.errors import ConfigError, TcotError
from tcot_hybrid.jsonio import atomic_write_text, check_output_dir
from tcot_hybrid.run_config import RunConfig, _coerce

CELL_KEYS = ("task", "suite", "planner", "mode", "perturb", "robot", "controller", "ik", "sweep")
DETECTOR_STEPS_AFTER_SUCCESS = 5  # planner steps past success on which the detector is probed


@dataclasses.dataclass(frozen=True)
class Job:
    cfg: RunConfig
    sweep: str = "-"  # "field=value" when this job belongs to a sweep
    fixed_key: str | None = None  # the key as the parent process computed it (workers never recompute it)

    @property
    def perturb(self) -> str:
        return self.cfg.perturb.name

    @property
    def key(self) -> str:
        if self.fixed_key is not None:
            return self.fixed_key
        c = self.cfg
        ck = checkpoint_digest(c)
        return "|".join(map(str, (c.task, c.planner, c.supervisor.mode, self.perturb, c.robot, c.controller,
                                  c.ik, self.sweep, c.seed, c.digest(), task_code_digest(), *([ck] if ck else []))))


@functools.lru_cache(maxsize=1)
def task_code_digest() -> str:
    """Hash of the task package's source (layouts, success predicates, oracle scripts): an episode run with
    other task code is not credited on resume (e.g. the oracle's hook clearance changed)."""
    import hashlib

    from tcot_hybrid import tasks

    h = hashlib.sha256()
    for f in sorted(Path(tasks.__file__).parent.glob("*.py")):
        h.update(f.name.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]


def checkpoint_digest(cfg: RunConfig) -> str | None:
    """Hash of the checkpoint the job's planner will load (the shipped default or ``--checkpoint``): its weights
    and its JSON metadata, which holds inference settings too (e.g. ``model.readout_radius_cells``). None for
    planners without one, or when it cannot be resolved (the episode then records why)."""
    from tcot_hybrid.learning.checkpoint import meta_path
    from tcot_hybrid.planners import planner_checkpoint

    try:
        path = planner_checkpoint(cfg.planner, cfg.robot, cfg.checkpoint)
    except TcotError:
        return None
    if path is None or not path.is_file():
        return None
    parts = []
    for f in (path, meta_path(path)):
        if f.is_file():
            st = f.stat()
            parts.append(_digest_of(str(f.resolve()), st.st_mtime_ns, st.st_size))
    return hashlib.sha256("".join(parts).encode()).hexdigest()[:16]


@functools.lru_cache(maxsize=64)
def _digest_of(path: str, mtime_ns: int, size: int) -> str:  # keyed by mtime/size: a rewritten file is re-hashed
    from tcot_hybrid.episode import file_digest

    return file_digest(path)


# --- sweeps --------------------------------------------------------------------------------------------

def parse_sweep(spec: str) -> tuple[str, list[str]]:
    """"ik_params.damping=1e-3,1e-2" -> ("ik_params.damping", ["1e-3", "1e-2"])."""
    if "=" not in spec:
        raise ConfigError(f"--sweep {spec!r} must look like FIELD=V1,V2 (e.g. ik_params.damping=1e-3,1e-2)")
    field, values = spec.split("=", 1)
    vals = [v.strip() for v in values.split(",") if v.strip()]
    if not vals:
        raise ConfigError(f"--sweep {spec!r} lists no values")
    return field.strip().replace("-", "_"), vals


def with_field(cfg, path: str, raw: str):
    """A copy of the config tree with the dotted field ``path`` set from the string ``raw`` (typed and
    validated like a config file value)."""
    head, _, rest = path.partition(".")
    names = {f.name: f for f in dataclasses.fields(cfg)}
    if head not in names:
        raise ConfigError(f"--sweep: unknown field {head!r} in {type(cfg).__name__}; valid: {', '.join(sorted(names))}")
    hint = typing.get_type_hints(type(cfg))[head]
    if rest:
        sub = getattr(cfg, head)
        if not dataclasses.is_dataclass(sub):
            raise ConfigError(f"--sweep: {head!r} has no sub-fields")
        return dataclasses.replace(cfg, **{head: with_field(sub, rest, raw)})
    import yaml

    value = yaml.safe_load(raw)  # numbers, booleans and strings as in a config file
    return dataclasses.replace(cfg, **{head: _coerce(path, hint, value)})


def make_jobs(base: RunConfig, *, tasks, planners, modes, robots, controllers, iks, episodes: int,
              seed_start: int, perturbs=("none",), sweep: str | None = None) -> list[Job]:
    """The cross product, every field validated by the config dataclasses before anything runs."""
    variants = [(base, "-")]
    if sweep:
        field, values = parse_sweep(sweep)
        variants = [(with_field(base, field, v), f"{field}={v}") for v in values]
    jobs = []
    for (cfg0, label), task, planner, mode, perturb, robot, ctrl, ik in itertools.product(
            variants, tasks, planners, modes, perturbs, robots, controllers, iks):
        for seed in range(seed_start, seed_start + episodes):
            cfg = dataclasses.replace(
                cfg0, task=task, planner=planner, robot=robot, controller=ctrl, ik=ik, seed=seed,
                supervisor=dataclasses.replace(cfg0.supervisor, mode=mode),
                perturb=dataclasses.replace(cfg0.perturb, name=perturb))
            jobs.append(Job(cfg, label))
    return jobs


# --- running -------------------------------------------------------------------------------------------

def run_job(job: Job) -> dict:
    """Run one episode in this process; never raises (a crash is a failed, faulted episode)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    # One compute thread per worker: W workers on W cores; torch's default (all cores per process)
    # oversubscribes and made batch-1 inference ~40x slower in measurements here.
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("MKL_NUM_THREADS", "1")
    from tcot_hybrid.episode import EpisodeRunner

    c = job.cfg
    try:
        runner = EpisodeRunner(c)
        probe = c.supervisor.mode.startswith("glsr")
        rec = runner.run(steps_after_success=DETECTOR_STEPS_AFTER_SUCCESS if probe else 0, probe_detector=probe)
        rec.pop("config", None)  # every event `tcot run` records is kept: a failure is diagnosed without a re-run
    except Exception as exc:  # noqa: BLE001 - recorded, counted as failure
        rec = {"task": c.task, "planner": c.planner, "mode": c.supervisor.mode, "robot": c.robot,
               "controller": c.controller, "ik": c.ik, "seed": c.seed, "success": False,
               "fault": f"crash:{type(exc).__name__}: {exc}"}
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
    pool = None
    with open(log, "a") as f, tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc="eval", unit="ep",
                                    disable=not progress) as bar:
        if ray_address:
            results = _ray_results(todo, ray_address)
        elif workers <= 1:
            results = map(run_job, todo)
        else:
            pool = mp.get_context("spawn").Pool(workers, maxtasksperchild=50)
            results = pool.imap_unordered(run_job, todo, chunksize=1)
        for rec in results:
            f.write(json.dumps(rec) + "\n")
            f.flush()
            done[rec["key"]] = rec
            bar.update(1)
        if pool is not None:
            pool.close()
            pool.join()
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


# --- aggregation ---------------------------------------------------------------------------------------

def _mean(xs):
    xs = [x for x in xs if x is not None]
    return round(sum(xs) / len(xs), 4) if xs else None


def aggregate(records: list[dict]) -> list[dict]:
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        groups[tuple(r.get(k, "-" if k == "sweep" else "none") for k in CELL_KEYS)].append(r)
    cells = []
    for key, recs in groups.items():
        n = len(recs)
        k = sum(bool(r["success"]) for r in recs)
        p = k / n
        cell = dict(zip(CELL_KEYS, key))
        cell.update(episodes=n, successes=k, success_rate=round(p, 4),
                    stderr=round(math.sqrt(p * (1 - p) / n), 4),
                    faults=sum(bool(r.get("fault")) for r in recs),
                    mean_episode_time_s=_mean([r.get("success_time_s") or r.get("sim_time_s") for r in recs]),
                    mean_wall_time_s=_mean([r.get("wall_time_s") for r in recs]),
                    mean_replans=_mean([r.get("replans") for r in recs]),
                    mean_tracking_error_rad=_mean([r.get("max_tracking_error_rad") for r in recs]),
                    max_joint_limit_violation_rad=max(r.get("max_joint_limit_violation_rad", 0.0) for r in recs),
                    max_velocity_ratio=round(max(r.get("max_velocity_ratio", 0.0) for r in recs), 4),
                    failed_seeds=sorted(r["seed"] for r in recs if not r["success"]))
        cells.append(cell)
    return cells


def auroc(scores: list[float], labels: list[bool]) -> float | None:
    """Area under the ROC curve (Mann-Whitney U with tie correction); None without both classes."""
    pos = [s for s, y in zip(scores, labels) if y]
    neg = [s for s, y in zip(scores, labels) if not y]
    if not pos or not neg:
        return None
    ranked = sorted((s, i) for i, s in enumerate(scores))
    ranks = [0.0] * len(scores)
    i = 0
    while i < len(ranked):
        j = i
        while j + 1 < len(ranked) and ranked[j + 1][0] == ranked[i][0]:
            j += 1
        for t in range(i, j + 1):
            ranks[ranked[t][1]] = (i + j) / 2 + 1
        i = j + 1
    r_pos = sum(r for r, y in zip(ranks, labels) if y)
    return (r_pos - len(pos) * (len(pos) + 1) / 2) / (len(pos) * len(neg))


def detector_metrics(records: list[dict], threshold: float = 0.5) -> dict:
    """Failure-detector figures per planner from the logged (p_success, ground truth) pairs.

    auroc: over every detector call (after t_f during the episode, and on the steps after success).
    false_alarm_rate: fraction of successful episodes in which the detector judged the finished task
        not successful (p < threshold) on any post-success step, i.e. would have replanned needlessly.
    detection_latency_steps: planner steps from true success to the detector's first p >= threshold.
    """
    by_planner: dict[str, dict] = defaultdict(lambda: {"scores": [], "labels": [], "alarms": 0,
                                                       "successes": 0, "latency": []})
    for r in records:
        calls = [e for e in r.get("events", []) if e.get("kind") in ("supervisor", "detector") and "p_success" in e]
        if not calls:
            continue
        d = by_planner[r["planner"]]
        for e in calls:
            d["scores"].append(e["p_success"])
            d["labels"].append(bool(e.get("true_success")))
        post = [e for e in calls if e["kind"] == "detector"]
        if r.get("success") and post:
            d["successes"] += 1
            d["alarms"] += any(e["p_success"] < threshold for e in post)
            hits = [i for i, e in enumerate(post) if e["p_success"] >= threshold]
            if hits:
                d["latency"].append(hits[0])
    out = {}
    for planner, d in by_planner.items():
        a = auroc(d["scores"], d["labels"])
        out[planner] = {"calls": len(d["scores"]), "positives": sum(d["labels"]),
                        "auroc": None if a is None else round(a, 4),
                        "false_alarm_rate": round(d["alarms"] / d["successes"], 4) if d["successes"] else None,
                        "successful_episodes_probed": d["successes"],
                        "detection_latency_steps": _mean(d["latency"])}
    return out


def _rate(group: list[dict]) -> tuple[float, float, int]:
    k = sum(c["successes"] for c in group)
    n = sum(c["episodes"] for c in group)
    p = k / n if n else 0.0
    return p, math.sqrt(p * (1 - p) / n) if n else 0.0, n


def markdown(result: dict, *, with_cells: bool = True) -> str:
    """The evaluation as Markdown: every cell (optional), Table 1 and Table 4 forms, detector metrics."""
    cells = result["cells"]
    lines = [] if not with_cells else ["## Cells", "",
             "| task | planner | mode | perturb | robot | controller | ik | sweep | success ± s.e. | n | "
             "mean time [s] | replans | max limit viol. [rad] | max \\|q̇\\|/v_max |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cells if with_cells else ():
        lines.append(f"| {c['task']} | {c['planner']} | {c['mode']} | {c['perturb']} | {c['robot']} | "
                     f"{c['controller']} | {c['ik']} | {c['sweep']} | {c['success_rate']:.2f} ± {c['stderr']:.2f} | "
                     f"{c['episodes']} | {c['mean_episode_time_s']} | {c['mean_replans']} | "
                     f"{c['max_joint_limit_violation_rad']:.1e} | {c['max_velocity_ratio']:.2f} |")
    n_ep = sum(c["episodes"] for c in cells)
    lines += ["", f"Over all {n_ep} episodes: max joint-limit violation "
              f"{max(c['max_joint_limit_violation_rad'] for c in cells):.2e} rad, max |q̇|/v_max "
              f"{max(c['max_velocity_ratio'] for c in cells):.3f}, sim faults {sum(c['faults'] for c in cells)}."]
    # Table 1: per suite success ± s.e. for each configuration row.
    suites = sorted({c["suite"] for c in cells})
    rows: dict[tuple, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for c in cells:
        rows[(c["planner"], c["mode"], c["perturb"], c["robot"], c["controller"], c["ik"], c["sweep"])][c["suite"]].append(c)
    lines += ["", "#### Table 1 form: success per suite (± standard error)", "",
              "| planner | mode | perturb | robot | controller | ik | sweep | " + " | ".join(suites) + " | avg |",
              "|" + "---|" * (8 + len(suites))]
    for key, by_suite in sorted(rows.items()):
        vals = [_rate(by_suite[s]) if by_suite.get(s) else None for s in suites]
        avg = _rate([c for s in suites for c in by_suite.get(s, [])])
        lines.append("| " + " | ".join(key) + " | " + " | ".join(
            f"{v[0]:.3f} ± {v[1]:.3f}" if v else "–" for v in vals) + f" | {avg[0]:.3f} ± {avg[1]:.3f} |")
    # Table 4: ablation of planning modes (averaged over suites), per perturbation.
    abl: dict[tuple, list] = defaultdict(list)
    for c in cells:
        label = "direct (no trajectory)" if c["planner"] == "direct" else (
            f"oracle ({c['mode']})" if c["planner"] == "oracle" else c["mode"])
        abl[(c["perturb"], label)].append(c)
    lines += ["", "#### Table 4 form: ablation (average over suites)", "",
              "| perturbation | method | success ± s.e. | n |", "|---|---|---|---|"]
    for (pert, label), group in sorted(abl.items()):
        p, se, n = _rate(group)
        lines.append(f"| {pert} | {label} | {p:.3f} ± {se:.3f} | {n} |")
    det = result.get("detector") or {}
    if det:
        lines += ["", "#### Failure detector", "", "| planner | calls | AUROC | false-alarm rate | latency [steps] |",
                  "|---|---|---|---|---|"]
        for planner, d in det.items():
            lines.append(f"| {planner} | {d['calls']} | {d['auroc']} | {d['false_alarm_rate']} | "
                         f"{d['detection_latency_steps']} |")
    return "\n".join(lines) + "\n"
