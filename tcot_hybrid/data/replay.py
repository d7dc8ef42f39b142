"""Label replay: execute each demonstration's own global trajectory label as a frozen plan.

The learned planner is trained to reproduce the global window at t = 0 (``L_g // 2 + 1`` points of the demo's
TCP track: every ``n_g`` steps (eq. 4) or event-spaced, ``--global-spacing``), and its frozen-global success is
bounded by how well that label itself solves the task when run through the real motion stack (lift → IK →
Ruckig → controller). A time-sampled track cuts corners: the hook of the tool task came down on the cube in
every replay while its clearance was 1.5 cm. ``tcot replay`` measures this ceiling per task, optionally with Gaussian noise on every point:

    tcot replay --data data/heldout_panda.hdf5 --out docs/planner-eval/replay.json --readme docs/planner.md

Each demo is re-run with its own seed, robot, controller, IK backend, timing and camera (recorded in the file),
so the scene is the one that was recorded; every other motion-stack setting is the default.
"""
from __future__ import annotations

import argparse
import itertools
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tcot_hybrid.config import require_nonnegative
from tcot_hybrid.data.dataset import open_demos
from tcot_hybrid.data.labels import (GLOBAL_PATHS, GLOBAL_SPACINGS, SEGMENT_POINTS, TRACK_KEYS, Track,
                                     TrajectoryWindowConfig, commanded_track, global_labels, track_from_arrays)
from tcot_hybrid.errors import ConfigError, PlanningError
from tcot_hybrid.planners.base import Observation, Planner
from tcot_hybrid.planners.learned import LearnedPlannerConfig, height_plan
from tcot_hybrid.workers import one_torch_thread, worker_pool


@dataclass(frozen=True, kw_only=True)
class ReplayConfig:
    """windows: the label windows (only the global ones matter: L_g, n_g or global_spacing/points_per_segment,
    segment_points, global_path).
    orientation: also replay the demo's TCP orientation at each point (what a planner with a rotation head
    plans: LIBERO's); else every point keeps the executor's default hand orientation.
    noise_px / noise_z_m: standard deviation of the Gaussian noise added to every replayed pixel [px] / TCP height [m] (0 = the exact label); seeded per demo
    by ``noise_seed`` and the demo's seed."""

    windows: TrajectoryWindowConfig = TrajectoryWindowConfig()
    noise_px: float = 0.0
    noise_z_m: float = 0.0
    noise_seed: int = 0
    orientation: bool = False
    learned: LearnedPlannerConfig = LearnedPlannerConfig()

    def __post_init__(self) -> None:
        require_nonnegative("noise_px", self.noise_px)
        require_nonnegative("noise_z_m", self.noise_z_m)


class LabelReplayPlanner(Planner):
    """Returns the demo's t = 0 global label (points from now on) as its only plan; no image, no detector.
    ``track`` is the demo's (observed) track; ``target_xyz`` its commanded waypoints (global_path 'commanded');
    ``tcp_rot`` (T, 3, 3) its world TCP orientations (``config.orientation``)."""

    name = "label_replay"
    needs_image = False

    def __init__(self, track: Track, camera, *, config: ReplayConfig, demo_seed: int,
                 target_xyz: np.ndarray | None = None, tcp_rot: np.ndarray | None = None):
        w = config.windows
        if w.global_path == "commanded":
            track = commanded_track(track, target_xyz, camera)
        label = global_labels(track, w)
        idx = label.indices[0, w.global_center:]
        rng = np.random.default_rng([config.noise_seed, demo_seed])
        self.uv = track.uv_px[idx].astype(float) + rng.normal(0.0, config.noise_px, (len(idx), 2))
        self.z = track.z_m[idx].astype(float) + rng.normal(0.0, config.noise_z_m, len(idx))
        self.closed = np.asarray(track.gripper_closed)[idx].astype(bool)
        self.rot = None if tcp_rot is None else np.asarray(tcp_rot, float)[idx]
        self.camera, self.config = camera, config

    def plan(self, obs: Observation, *, mode: str):
        if mode != "global" or obs.step != 0:
            raise PlanningError(f"label replay has only the t = 0 global label; asked for a {mode!r} plan at "
                                f"step {obs.step} (run it with supervisor.mode = 'global')")
        return height_plan(self.camera, self.uv, self.z, self.closed, kind="global", step=0,
                           config=self.config.learned, global_spacing=self.config.windows.global_spacing,
                           tcp_rot=self.rot)


def replay_demo(path: str | Path, name: str, config: ReplayConfig) -> dict:
    """Run one demo's label as a frozen global plan; {demo, task, seed, steps, success, fault}."""
    from tcot_hybrid.config import TimingConfig
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig
    from tcot_hybrid.scene import SceneConfig

    with open_demos(path) as f:
        info, env = f.info(name), dict(f.env_args)
        track = track_from_arrays(f.read(name, TRACK_KEYS))
        target = rot = None
        if config.windows.global_path == "commanded":
            target = f.commanded_targets(name)
        if config.orientation:
            from tcot_hybrid.learning.data import quat_wxyz_to_matrix

            rot = quat_wxyz_to_matrix(f.read(name, ["obs/robot0_eef_quat"])["obs/robot0_eef_quat"])
    base = RunConfig()
    # the demo's own layout mode (`tcot collect` records sampled or spread layouts, never the shipped init states:
    # on LIBERO the default, "shipped", would put the demo's label on another layout, and the test set)
    cfg = RunConfig(task=info.task, seed=info.seed, init=info.init, robot=info.robot,
                    controller=env["controller"], ik=env["ik"],
                    timing=TimingConfig(sim_dt=env["sim_dt"], ctrl_dt=env["ctrl_dt"], plan_dt=env["plan_dt"]),
                    scene=replace(SceneConfig(), planner_camera=env["camera"], planner_image_px=int(env["width"])),
                    supervisor=replace(base.supervisor, mode="global"))
    runner = EpisodeRunner(cfg, planner_factory=lambda ctx: LabelReplayPlanner(
        track, ctx.camera, config=config, demo_seed=info.seed, target_xyz=target, tcp_rot=rot))
    rec = runner.run()
    return {"demo": name, "task": info.task, "seed": info.seed, "steps": len(track.uv_px), "success": rec["success"],
            "fault": rec["fault"]}


def _job(args):
    return replay_demo(*args)


def replay_file(path: str | Path, *, config: ReplayConfig = ReplayConfig(), tasks: list[str] | None = None,
                workers: int = 2, progress: bool = True, max_per_task: int | None = None) -> dict:
    """Replay every successful demo of ``path`` (optionally only ``tasks``, and only each task's
    ``max_per_task`` lowest-seed ones); per-task success and the demos."""
    from tqdm import tqdm

    with open_demos(path) as f:
        infos = [f.info(n) for n in f.demos]
    known = sorted({i.task for i in infos})
    for t in tasks or []:
        if t not in known:
            raise ConfigError(f"task {t!r} has no demo in {path}; its tasks: {', '.join(known)}")
    chosen = sorted((i for i in infos if i.success and (not tasks or i.task in tasks)), key=lambda i: (i.task, i.seed))
    if max_per_task is not None:  # sorted by task: each task's first max_per_task seeds
        chosen = [i for _, group in itertools.groupby(chosen, key=lambda i: i.task)
                  for i in itertools.islice(group, max_per_task)]
    names = [i.name for i in chosen]
    if not names:
        raise ConfigError(f"no successful demo to replay in {path}")
    t0 = time.perf_counter()
    jobs = [(str(path), n, config) for n in names]
    rows: list[dict] = []
    with tqdm(total=len(jobs), desc="replay", unit="demo", disable=not progress) as bar:
        if workers > 1:
            with worker_pool(min(workers, len(jobs))) as pool:
                for r in pool.imap_unordered(_job, jobs):
                    rows.append(r)
                    bar.update()
        else:
            with one_torch_thread():
                for j in jobs:
                    rows.append(_job(j))
                    bar.update()
    rows.sort(key=lambda r: (r["task"], r["seed"]))
    per_task: dict[str, dict] = {}
    for r in rows:
        c = per_task.setdefault(r["task"], {"demos": 0, "successes": 0})
        c["demos"] += 1
        c["successes"] += int(r["success"])
    for c in per_task.values():
        c["success_rate"] = round(c["successes"] / c["demos"], 4)
    w = config.windows
    return {"data": str(path), "L_g": w.L_g, "n_g": w.n_g, "global_spacing": w.global_spacing,
            "points_per_segment": w.points_per_segment, "segment_points": w.segment_points,
            "global_path": w.global_path, "orientation": config.orientation, "noise_px": config.noise_px, "noise_z_m": config.noise_z_m,
            "noise_seed": config.noise_seed, "per_task": per_task,
            "success_rate": round(sum(r["success"] for r in rows) / len(rows), 4), "demos": rows,
            "wall_s": round(time.perf_counter() - t0, 1)}


def markdown(report: dict) -> str:
    """Per-task table of a replay report, with the command that wrote it."""
    spacing = (f"n_g = {report['n_g']}" if report.get("global_spacing", "time") == "time" else
               f"event-spaced, {report['points_per_segment']} points per piece")
    lines = [f"Measured by `{report['command']}` ({len(report['demos'])} demos of `{report['data']}`, global window "
             f"L_g = {report['L_g']}, {spacing}, noise {report['noise_px']} px / {report['noise_z_m']} m):",
             "", "| task | demos | label replay succeeded |", "|---|---|---|"]
    lines += [f"| {t} | {c['demos']} | {c['successes']} ({c['success_rate']:.0%}) |" for t, c in report["per_task"].items()]
    lines += ["", f"All: {report['success_rate']:.3f}."]
    return "\n".join(lines) + "\n"


def cmd_replay(argv: list[str]) -> int:
    """``tcot replay --data FILE``: success of each demo's own t = 0 global label run as a frozen plan."""
    p = argparse.ArgumentParser(prog="tcot replay", description=(
        "Run every demonstration's own global trajectory label (eq. 4 at t = 0) as a frozen plan through the "
        "motion stack, with the demo's seed: the ceiling of frozen-global imitation for these windows."))
    p.add_argument("--data", type=Path, required=True, help="demo file written by tcot collect")
    p.add_argument("--tasks", help="comma-separated task names (default: every task in the file)")
    p.add_argument("--L-g", dest="L_g", type=int, default=TrajectoryWindowConfig.L_g, help="global window length")
    p.add_argument("--n-g", dest="n_g", type=int, default=TrajectoryWindowConfig.n_g, help="global stride [steps]")
    p.add_argument("--global-spacing", choices=GLOBAL_SPACINGS, default=TrajectoryWindowConfig.global_spacing,
                   help="time: eq. 4, every n_g steps; events: points per piece between gripper switches")
    p.add_argument("--points-per-segment", type=int, default=TrajectoryWindowConfig.points_per_segment,
                   help="events spacing: points per piece between gripper switches")
    p.add_argument("--segment-points", choices=SEGMENT_POINTS, default=TrajectoryWindowConfig.segment_points,
                   help="events spacing: a piece's points at equal path-length fractions or where the path turns")
    p.add_argument("--global-path", choices=GLOBAL_PATHS, default=TrajectoryWindowConfig.global_path,
                   help="label the observed TCP path or the commanded waypoints (obs/tcp_target_pos)")
    p.add_argument("--orientation", action="store_true",
                   help="also replay the demo's TCP orientation (what a planner with a rotation head plans)")
    p.add_argument("--max-per-task", type=int, help="replay only each task's first N successful demos (by seed)")
    p.add_argument("--noise-px", type=float, default=0.0, help="Gaussian noise on every pixel [px]")
    p.add_argument("--noise-z-m", type=float, default=0.0, help="Gaussian noise on every TCP height [m]")
    p.add_argument("--noise-seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, help="write the report as JSON here")
    p.add_argument("--readme", type=Path, help="also write the table into this Markdown file's "
                   "<!-- replay:start/end --> section")
    args = p.parse_args(argv)
    from tcot_hybrid.markdown import has_readme_section, update_readme_section

    if args.readme is not None and not has_readme_section(args.readme, "replay"):
        raise ConfigError(f"--readme {args.readme} has no <!-- replay:start --> ... <!-- replay:end --> section")
    if args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    if args.max_per_task is not None and args.max_per_task < 1:
        raise ConfigError(f"--max-per-task must be >= 1, got {args.max_per_task}")
    if args.n_g < 2:  # TrajectoryWindowConfig needs some local stride n_l < n_g; the replay uses no local window
        raise ConfigError(f"--n-g must be >= 2, got {args.n_g}")
    windows = TrajectoryWindowConfig(L_g=args.L_g, n_g=args.n_g, L_l=1, n_l=1, global_spacing=args.global_spacing,
                                     points_per_segment=args.points_per_segment, segment_points=args.segment_points,
                                     global_path=args.global_path)
    cfg = ReplayConfig(windows=windows, noise_px=args.noise_px, noise_z_m=args.noise_z_m, noise_seed=args.noise_seed,
                       orientation=args.orientation)
    tasks = [t for t in args.tasks.split(",") if t] if args.tasks else None
    report = replay_file(args.data, config=cfg, tasks=tasks, workers=args.workers, max_per_task=args.max_per_task)
    report["command"] = "tcot replay " + " ".join(argv)
    for task, c in report["per_task"].items():
        print(f"{task}: {c['successes']}/{c['demos']}")
    print(f"all: {report['success_rate']:.3f} over {len(report['demos'])} demos in {report['wall_s']} s")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1) + "\n")
        print(f"-> {args.out}")
    if args.readme is not None:
        update_readme_section(args.readme, "replay", markdown(report))
    return 0
