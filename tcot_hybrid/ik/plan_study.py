"""``tcot ik-plans``: per-waypoint IK (mink, pinocchio) against the whole-plan casadi solve on the same plans.

Two plan sources, both seeded:

- ``workcell``: the oracle's first global plan of every workcell task (lifted and squared exactly as the
  executor sees it), top-down at every waypoint; the plan starts from the settled home pose.
- ``yawed``: top-down pick-and-place plans with a grasp yaw per waypoint, uniform in (-pi, pi] and not folded
  into a half-turn (hover, grasp, hover at the pick; hover, release, hover at the place): the per-waypoint
  orientation LIBERO plans will carry, where a wrist joint's limit decides what is reachable.

Per plan: the per-waypoint backends solve the waypoints in order, each seeded from the last solution (what the
executor does); casadi solves them jointly. A plan "hits a limit" when a waypoint's solve had a joint at the
limit box (``IKResult.limit_active``; for casadi, a joint at the box in a returned configuration) and "fails"
when a waypoint did not converge (casadi: the plan is not converged).
"""
from __future__ import annotations

import dataclasses
import json
import math
import statistics
import time
from pathlib import Path

import numpy as np

from tcot_hybrid.ik import IKConfig, make_ik
from tcot_hybrid.robot import R_DOWN, load_robot_spec

PER_WAYPOINT = ("mink", "pinocchio")
SOURCES = ("workcell", "yawed")


def _rz(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def yawed_plan(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A top-down pick-and-place plan with a grasp yaw per waypoint (positions (6, 3) [m], rotations (6, 3, 3))."""
    rng = np.random.default_rng(seed)
    while True:
        pick = rng.uniform([0.35, -0.25], [0.65, 0.25])
        place = rng.uniform([0.35, -0.25], [0.65, 0.25])
        if np.linalg.norm(pick - place) >= 0.15:
            break
    yaw_pick, yaw_place = rng.uniform(-math.pi, math.pi, 2)
    hover, grasp, release = 0.20, 0.02, 0.06
    P = np.array([[*pick, hover], [*pick, grasp], [*pick, hover], [*place, hover], [*place, release], [*place, hover]])
    R = np.array([_rz(y) @ R_DOWN for y in (yaw_pick,) * 3 + (yaw_place,) * 3])
    return P, R


def workcell_plans(robot: str, seeds: range, tasks: list[str] | None = None) -> list[dict]:
    """The oracle's first global plan per (task, seed), as the executor adopts it (after lift and square transits)."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig
    from tcot_hybrid.tasks import list_tasks

    names = tasks or [t.name for t in list_tasks()]
    out = []
    for task in names:
        for seed in seeds:
            runner = EpisodeRunner(RunConfig(task=task, seed=seed, robot=robot))
            runner.settle()
            ex = runner.stack.executor
            q0 = ex.sim.q.copy()
            runner._step_once(0, may_plan=True)
            if ex.plan is None:
                continue
            out.append({"source": "workcell", "task": task, "seed": seed, "positions": ex.points.copy(),
                        "rotations": np.broadcast_to(R_DOWN, (len(ex.points), 3, 3)).copy(), "q_start": q0})
    return out


def compare_plan(solvers: dict, plan: dict) -> dict:
    """Per-waypoint backends and the whole-plan solve on one plan: status, limit contact and wall time."""
    from tcot_hybrid.ik import IKTarget

    P, R, q0 = plan["positions"], plan["rotations"], plan["q_start"]
    row = {k: plan[k] for k in ("source", "task", "seed")}
    row["waypoints"] = len(P)
    for name in PER_WAYPOINT:
        ik, q = solvers[name], q0.copy()
        failed, limit = [], []
        t0 = time.perf_counter()
        for i in range(len(P)):
            r = ik.solve(IKTarget(P[i], R[i]), q)
            q = r.q
            if not r.converged:
                failed.append(i)
            if r.limit_active:
                limit.append(i)
        row[name] = {"time_ms": (time.perf_counter() - t0) * 1e3, "not_converged": failed, "limit": limit}
    t0 = time.perf_counter()
    res = solvers["casadi"].solve_plan(P, R, q0)
    row["casadi"] = {"time_ms": (time.perf_counter() - t0) * 1e3, "status": res.status,
                     "solver_status": res.solver_status, "iters": res.iters, "offending": list(res.offending),
                     "limit": [int(i) for i in np.flatnonzero(res.limit_active)],
                     "max_pos_err_m": float(np.max(res.pos_err)), "fallback": bool(res.fallback)}
    return row


def _solvers(robot: str, config: IKConfig) -> dict:
    spec = load_robot_spec(robot)
    return {name: make_ik(name, spec, config) for name in PER_WAYPOINT + ("casadi",)}


def study(robots: list[str], *, seed_start: int, seeds: int, yawed_seeds: int | None = None, sources=SOURCES,
          config: IKConfig | None = None, progress: bool = True) -> dict:
    from tqdm import tqdm

    config = config or IKConfig()
    rows = []
    for robot in robots:
        solvers = _solvers(robot, config)
        plans: list[dict] = []
        if "workcell" in sources:
            plans += workcell_plans(robot, range(seed_start, seed_start + seeds))
        if "yawed" in sources:
            for seed in range(seed_start, seed_start + (seeds if yawed_seeds is None else yawed_seeds)):
                P, R = yawed_plan(seed)
                plans.append({"source": "yawed", "task": "-", "seed": seed, "positions": P, "rotations": R,
                              "q_start": load_robot_spec(robot).home_q.copy()})
        for plan in tqdm(plans, desc=f"ik-plans {robot}", unit="plan", disable=not progress or None):
            rows.append({"robot": robot, **compare_plan(solvers, plan)})
    return {"rows": rows, "summary": summarize(rows), "config": dataclasses.asdict(config),
            "seed_start": seed_start, "seeds": seeds, "yawed_seeds": seeds if yawed_seeds is None else yawed_seeds,
            "robots": list(robots), "sources": list(sources)}


def _pct(xs: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(xs, float), q)) if xs else float("nan")


def summarize(rows: list[dict]) -> list[dict]:
    groups: dict[tuple, list] = {}
    for r in rows:
        groups.setdefault((r["robot"], r["source"]), []).append(r)
    out = []
    for (robot, source), rs in sorted(groups.items()):
        cas_ok = [r["casadi"]["status"] == "converged" for r in rs]
        cas_free = [ok and not r["casadi"]["limit"] for ok, r in zip(cas_ok, rs)]
        s = {"robot": robot, "source": source, "plans": len(rs), "waypoints": sum(r["waypoints"] for r in rs),
             "casadi_converged": sum(cas_ok), "casadi_at_limit": sum(bool(r["casadi"]["limit"]) for r in rs),
             "casadi_ms_median": round(statistics.median(r["casadi"]["time_ms"] for r in rs), 3),
             "casadi_ms_p95": round(_pct([r["casadi"]["time_ms"] for r in rs], 95), 3)}
        for name in PER_WAYPOINT:
            failed = [bool(r[name]["not_converged"]) for r in rs]
            limit = [bool(r[name]["limit"]) for r in rs]
            s[f"{name}_failed"] = sum(failed)
            s[f"{name}_at_limit"] = sum(limit)
            # where it helps: the per-waypoint chain failed (or touched a limit) and the whole-plan solve did not
            s[f"helps_vs_{name}_failed"] = sum(f and ok for f, ok in zip(failed, cas_ok))
            s[f"helps_vs_{name}_limit"] = sum(lim and free for lim, free in zip(limit, cas_free))
            s[f"hurts_vs_{name}"] = sum((not f) and (not ok) for f, ok in zip(failed, cas_ok))
            s[f"{name}_ms_median"] = round(statistics.median(r[name]["time_ms"] for r in rs), 3)
            s[f"{name}_ms_p95"] = round(_pct([r[name]["time_ms"] for r in rs], 95), 3)
        out.append(s)
    return out


def markdown(result: dict, command: str) -> str:
    first = result["seed_start"]
    lines = [f"Measured by `{command}` (development seeds: workcell {first}-{first + result['seeds'] - 1} per task, "
             f"yawed plans {first}-{first + result['yawed_seeds'] - 1}). Per-waypoint backends solve the waypoints in order, each seeded "
             "from the last; casadi solves the plan jointly (warm start: "
             f"{result['config']['casadi']['warm_start']}).", "",
             "| robot | plans | waypoints | mink failed | mink at limit | pinocchio failed | pinocchio at limit | "
             "casadi converged | casadi at limit | helps: mink failed, casadi solved | helps: mink at limit, casadi "
             "solved clear of limits | hurts: mink solved, casadi not | helps: pinocchio failed, casadi solved | "
             "hurts: pinocchio solved, casadi not |",
             "|" + "---|" * 14]
    for s in result["summary"]:
        lines.append(f"| {s['robot']} / {s['source']} | {s['plans']} | {s['waypoints']} | {s['mink_failed']} | "
                     f"{s['mink_at_limit']} | {s['pinocchio_failed']} | {s['pinocchio_at_limit']} | "
                     f"{s['casadi_converged']} | {s['casadi_at_limit']} | {s['helps_vs_mink_failed']} | "
                     f"{s['helps_vs_mink_limit']} | {s['hurts_vs_mink']} | {s['helps_vs_pinocchio_failed']} | "
                     f"{s['hurts_vs_pinocchio']} |")
    lines += ["", "Solve time per plan [ms] (wall, one process; casadi includes its per-waypoint warm start):", "",
              "| robot | casadi median | casadi p95 | mink per-waypoint total median | mink p95 | "
              "pinocchio per-waypoint total median | pinocchio p95 |", "|---|---|---|---|---|---|---|"]
    for s in result["summary"]:
        lines.append(f"| {s['robot']} / {s['source']} | {s['casadi_ms_median']} | {s['casadi_ms_p95']} | "
                     f"{s['mink_ms_median']} | {s['mink_ms_p95']} | {s['pinocchio_ms_median']} | "
                     f"{s['pinocchio_ms_p95']} |")
    return "\n".join(lines) + "\n"


def cmd_ik_plans(argv: list[str]) -> int:
    import argparse

    from tcot_hybrid.errors import ConfigError

    p = argparse.ArgumentParser(prog="tcot ik-plans", description="per-waypoint IK vs the whole-plan casadi solve on "
                                "the same plans (workcell oracle plans and yawed pick-and-place plans); writes "
                                "DIR/ik_plans.json and DIR/ik_plans.md")
    p.add_argument("--robots", default="panda,ur5e", help="comma-separated robots")
    p.add_argument("--sources", default=",".join(SOURCES), help=f"comma-separated plan sources: {', '.join(SOURCES)}")
    p.add_argument("--seed-start", type=int, default=2000, help="first seed (use development seeds)")
    p.add_argument("--seeds", type=int, default=20, help="seeds per task (workcell plans)")
    p.add_argument("--yawed-seeds", type=int, default=None, help="yawed plans per robot (default: --seeds)")
    p.add_argument("--out", type=Path, default=Path("runs/ik-plans"))
    p.add_argument("--readme", type=Path, default=None, help="also write the tables into this Markdown file's "
                   "<!-- ik-plans:start/end --> section")
    args = p.parse_args(argv)
    robots = [r for r in args.robots.split(",") if r]
    sources = [s for s in args.sources.split(",") if s]
    bad = [s for s in sources if s not in SOURCES]
    if bad or not sources:
        raise ConfigError(f"--sources {args.sources!r}: unknown source(s) {bad}; valid sources: {', '.join(SOURCES)}")
    if args.seeds < 1 or args.seed_start < 0 or (args.yawed_seeds is not None and args.yawed_seeds < 1):
        raise ConfigError(f"--seeds and --yawed-seeds must be >= 1 and --seed-start >= 0, got {args.seeds}, "
                          f"{args.yawed_seeds} and {args.seed_start}")
    for r in robots:
        load_robot_spec(r)
    command = "tcot ik-plans " + " ".join(argv)
    result = study(robots, seed_start=args.seed_start, seeds=args.seeds, yawed_seeds=args.yawed_seeds, sources=sources)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "ik_plans.json").write_text(json.dumps(result, indent=1))
    md = markdown(result, command)
    (args.out / "ik_plans.md").write_text(md)
    if args.readme:
        from tcot_hybrid.markdown import update_readme_section

        update_readme_section(args.readme, "ik-plans", md)
    print(md)
    return 0
