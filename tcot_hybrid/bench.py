"""``tcot bench``: speed and memory figures, each a median over repeats with its spread, and every
comparison a ratio measured in the same run. Writes DIR/bench.json and DIR/bench.md.

bench.json: {"figures": {name: {median, min, max, unit}}, "ratios": {name: value}, "command": ...}.
The tick ratio per controller is ``ratios["tick_over_mj_step/<controller>"]``: wall time of one full
control tick (Ruckig sample + controller + safety + ctrl_dt/sim_dt physics steps) over the wall time
of the same number of bare ``mj_step`` calls on the same task scene.
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np

from tcot_hybrid.errors import TcotError
from tcot_hybrid.markdown import bench_markdown
from tcot_hybrid.run_config import RunConfig

BENCH_TASK = "goal_cube_on_plate"
# A LIBERO tabletop scene (kitchen: cabinet, stove, five objects), measured when LIBERO is installed.
LIBERO_BENCH_TASK = "libero_spatial:pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate"


def _stat(samples, unit: str) -> dict:
    s = [float(x) for x in samples]
    return {"median": statistics.median(s), "min": min(s), "max": max(s), "unit": unit, "n": len(s)}


def _runner(cfg: RunConfig, *, plan: bool = True):
    from tcot_hybrid.episode import EpisodeRunner

    r = EpisodeRunner(cfg)
    r.settle()
    if plan:
        r.stack.executor.set_plan(r.stack.planner.plan(r.observe(0), mode="global"))
    return r


def bare_step_us(cfg: RunConfig, n: int) -> float:
    """Per-step wall time of bare mj_step on the task scene, robot torques held at gravity compensation."""
    r = _runner(cfg, plan=False)
    sim = r.stack.sim
    m, d = sim.model, sim.data
    mujoco.mj_forward(m, d)
    d.ctrl[sim.arm_act] = d.qfrc_bias[sim.arm_dof]
    t = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(m, d)
    return (time.perf_counter() - t) / n * 1e6


def tick_us(cfg: RunConfig, n: int, *, plan: bool = True) -> float:
    """Per-tick wall time of the control tick (Ruckig sample + controller + safety + physics) while the
    arm follows a long joint-space segment (after the first IK targets of an oracle plan, when ``plan``)."""
    r = _runner(cfg, plan=plan)
    ex = r.stack.executor
    for _ in range(20):  # warm up (first IK solves, caches) with the full tick
        ex.tick()
    spec = r.stack.robot
    far = np.clip(spec.home_q + 0.6 * np.sign(spec.q_max + spec.q_min - 2 * spec.home_q), spec.q_min + 0.05,
                  spec.q_max - 0.05)
    ex.smoother.set_target(far)  # a multi-second segment: every measured tick moves the arm
    t = time.perf_counter()
    for _ in range(n):
        ex.control_tick()
    return (time.perf_counter() - t) / n * 1e6


def episode_rtf(cfg: RunConfig, *, render: bool) -> tuple[float, float]:
    """Real-time factor (sim time / wall time) of a whole oracle episode, optionally rendering the planner
    image at every planner step (as a learned planner would need)."""
    from tcot_hybrid.episode import EpisodeRunner

    r = EpisodeRunner(cfg)
    if render:
        px = cfg.scene.planner_image_px
        r.frame_hook = lambda rr, step: rr.stack.sim.render(cfg.scene.planner_camera, px, px)
    rec = r.run()
    return rec["sim_time_s"] / rec["wall_time_s"], rec["sim_time_s"]


def ik_figures(robot_name: str, n: int, seed: int = 0) -> dict[str, dict]:
    from tcot_hybrid.ik import IKConfig, IKTarget, make_ik
    from tcot_hybrid.robot import build_pinocchio_model, load_robot_spec

    import pinocchio as pin

    spec = load_robot_spec(robot_name)
    pr = build_pinocchio_model(spec, lock_gripper=True)
    data = pr.model.createData()
    rng = np.random.default_rng(seed)
    out = {}
    # Reachable targets: TCP poses of configurations near home, seeded from home.
    targets, seeds = [], []
    for _ in range(n):
        q = np.clip(spec.home_q + rng.normal(0, 0.25, spec.dof), spec.q_min + 0.05, spec.q_max - 0.05)
        pin.framesForwardKinematics(pr.model, data, q)
        T = data.oMf[pr.tcp_frame_id]
        targets.append(IKTarget(pos=T.translation.copy(), rot=T.rotation.copy()))
        seeds.append(spec.home_q.copy())
    for label, name, solver in (("mink_daqp", "mink", "daqp"), ("mink_osqp", "mink", "osqp"),
                                ("pinocchio", "pinocchio", None)):
        cfg = IKConfig() if solver is None else dataclasses.replace(IKConfig(), solver=solver)
        ik = make_ik(name, spec, cfg)
        times, conv = [], 0
        for tgt, s in zip(targets, seeds):
            t = time.perf_counter()
            res = ik.solve(tgt, s)
            times.append((time.perf_counter() - t) * 1e3)
            conv += bool(res.converged)
        out[f"ik_solve_ms/{label}"] = _stat(times, "ms")
        out[f"ik_converged/{label}"] = _stat([conv / n], "fraction")
    return out


def ik_plan_figures(robot_name: str, seeds: int) -> tuple[dict[str, dict], dict[str, float]]:
    """Solve time per plan: the whole-plan casadi solve against mink's per-waypoint total (each waypoint seeded
    from the last) on the same plans, the oracle's first global plan of every task for seeds 0..seeds-1. The
    executor runs either when a plan is adopted, at planner rate; the control tick never waits on it.
    casadi keeps one IPOPT solver per plan length: ``ik_plan_build_ms`` is the first plan of a length (NLP built),
    ``ik_plan_ms/casadi`` every later one."""
    from tcot_hybrid.ik import IKConfig, IKTarget, make_ik
    from tcot_hybrid.ik.plan_study import workcell_plans
    from tcot_hybrid.robot import load_robot_spec

    spec = load_robot_spec(robot_name)
    plans = workcell_plans(robot_name, range(seeds))
    mink, cas = make_ik("mink", spec, IKConfig()), make_ik("casadi", spec, IKConfig())
    t_mink, t_cas, t_build, conv = [], [], [], 0
    for plan in plans:
        P, R, q0 = plan["positions"], plan["rotations"], plan["q_start"]
        t = time.perf_counter()
        q = q0
        for i in range(len(P)):
            q = mink.solve(IKTarget(P[i], R[i]), q).q
        t_mink.append((time.perf_counter() - t) * 1e3)
        built = (len(P), "plan") in cas._solvers
        t = time.perf_counter()
        res = cas.solve_plan(P, R, q0)
        (t_cas if built else t_build).append((time.perf_counter() - t) * 1e3)
        if not built:  # solve again with the solver built, as every later plan of this length is
            t = time.perf_counter()
            res = cas.solve_plan(P, R, q0)
            t_cas.append((time.perf_counter() - t) * 1e3)
        conv += res.converged
    figures = {"ik_plan_ms/casadi": _stat(t_cas, "ms"), "ik_plan_build_ms/casadi": _stat(t_build, "ms"),
               "ik_plan_ms/mink_per_waypoint": _stat(t_mink, "ms"),
               "ik_plan_converged/casadi": _stat([conv / len(plans)], "fraction")}
    ratios = {"ik_plan_ms_p95/casadi": round(float(np.percentile(t_cas, 95)), 3),
              "ik_plan_ms_p95/mink_per_waypoint": round(float(np.percentile(t_mink, 95)), 3),
              "ik_plan_casadi_over_mink_median": round(statistics.median(t_cas) / statistics.median(t_mink), 3),
              "ik_plan_waypoints_median": float(statistics.median(len(p["positions"]) for p in plans))}
    return figures, ratios


def ruckig_figures(robot_name: str, n: int, seed: int = 0) -> dict[str, dict]:
    from tcot_hybrid.robot import load_robot_spec
    from tcot_hybrid.smoothing import JointSmoother

    spec = load_robot_spec(robot_name)
    sm = JointSmoother.from_spec(spec, ctrl_dt=0.01)
    sm.reset(spec.home_q)
    rng = np.random.default_rng(seed)
    seg, tick = [], []
    for _ in range(n):
        target = np.clip(spec.home_q + rng.normal(0, 0.3, spec.dof), spec.q_min + 0.05, spec.q_max - 0.05)
        t = time.perf_counter()
        sm.set_target(target)
        seg.append((time.perf_counter() - t) * 1e6)
        for _ in range(5):
            t = time.perf_counter()
            sm.step()
            tick.append((time.perf_counter() - t) * 1e6)
    return {"ruckig_segment_us": _stat(seg, "us"), "ruckig_step_us": _stat(tick, "us")}


def render_ms(cfg: RunConfig, n: int) -> float:
    r = _runner(cfg, plan=False)
    px = cfg.scene.planner_image_px
    r.stack.sim.render(cfg.scene.planner_camera, px, px)
    t = time.perf_counter()
    for _ in range(n):
        r.stack.sim.render(cfg.scene.planner_camera, px, px)
    return (time.perf_counter() - t) / n * 1e3


@contextlib.contextmanager
def torch_threads(n: int):
    """Run the block with ``n`` torch compute threads, then restore the previous count."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def planner_inference_ms(cfg: RunConfig, n: int) -> dict[str, dict]:
    """Batch-1 latency of the learned planner per mode (shipped checkpoint, image to plan) with 2 torch
    threads (``planner_inference_ms``) and with 1 (``..._1thread``, what each eval worker uses)."""
    r = _runner(dataclasses.replace(cfg, planner="learned"))
    planner, obs = r.stack.planner, r.observe(0)
    out = {}
    for threads, suffix in ((2, ""), (1, "_1thread")):
        for label, call in (("global", lambda: planner.plan(obs, mode="global")),
                            ("local", lambda: planner.plan(obs, mode="local")),
                            ("detect", lambda: planner.success_probability(obs))):
            with torch_threads(threads):
                call()
                times = []
                for _ in range(n):
                    t = time.perf_counter()
                    call()
                    times.append((time.perf_counter() - t) * 1e3)
            out[f"planner_inference_ms{suffix}/{label}"] = _stat(times, "ms")
    return out


def eval_wall_s(workers: int, *, seeds: int, robot: str) -> float:
    """Wall time of ``tcot eval`` with ``workers`` processes [s]: the learned planner in GLSR mode under
    ``object_moved`` (the ablation's workload), every task, ``seeds`` seeds. One worker runs in this process
    with one torch thread, as ``tcot eval --workers 1`` does."""
    from tcot_hybrid.evaluation import evaluate, make_jobs
    from tcot_hybrid.tasks import list_tasks

    jobs = make_jobs(RunConfig(planner="learned", robot=robot), tasks=[t.name for t in list_tasks()],
                     planners=["learned"], modes=["glsr"], robots=[robot], controllers=["computed_torque"],
                     iks=["mink"], episodes=seeds, seed_start=1000, perturbs=("object_moved",))
    with torch_threads(1), tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        evaluate(jobs, tmp, workers=workers, progress=False)
        return time.perf_counter() - t


def peak_rss_mb_of(argv: list[str]) -> float:
    """Peak resident memory of a separate ``tcot ...`` process [MB]."""
    code = ("import resource, sys; from tcot_hybrid.cli import main; rc = main(sys.argv[1:]); "
            "print('PEAK_KB', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)")
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True,
                         env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})
    for line in out.stdout.splitlines():
        if line.startswith("PEAK_KB"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"`tcot {' '.join(argv)}` failed in the bench: {out.stderr[-500:]}")


def peak_rss_mb_of_run(task: str) -> float:
    """Peak resident memory of a ``tcot run`` of ``task`` [MB]."""
    with tempfile.TemporaryDirectory() as tmp:
        return peak_rss_mb_of(["run", "--task", task, "--seed", "0", "--out", tmp])


def libero_figures(*, quick: bool, repeats: int, n_steps: int, n_ticks: int) -> dict[str, dict]:
    """The same figures on a LIBERO scene (``libero/`` prefix): scene build, bare mj_step, control tick per
    controller, planner-image render, and whole oracle episodes' real-time factor with and without rendering."""
    from tcot_hybrid.controllers import list_controllers
    from tcot_hybrid.libero.scene import LiberoScene
    from tcot_hybrid.libero.tasks import libero_catalog

    base = RunConfig(task=LIBERO_BENCH_TASK, seed=0)
    out: dict[str, dict] = {}
    builds = []
    for _ in range(2 if quick else 3):
        t = time.perf_counter()
        LiberoScene.build(libero_catalog()[LIBERO_BENCH_TASK].bddl_path, sim_dt=base.timing.sim_dt,
                          max_image_px=base.scene.planner_image_px).close()
        builds.append(time.perf_counter() - t)
    out["libero/scene_build_s"] = _stat(builds, "s")
    out["libero/mj_step_us"] = _stat([bare_step_us(base, n_steps) for _ in range(repeats)], "us")
    for ctrl in list_controllers():
        cfg = dataclasses.replace(base, controller=ctrl)
        out[f"libero/tick_us/{ctrl}"] = _stat([tick_us(cfg, n_ticks, plan=False) for _ in range(repeats)], "us")
    out["libero/render_planner_image_ms"] = _stat([render_ms(base, 10 if quick else 40) for _ in range(repeats)],
                                                  "ms")
    rtf_plain, rtf_render = [], []
    for seed in range(2 if quick else 4):
        try:
            cfg = dataclasses.replace(base, seed=seed)
            rtf_plain.append(episode_rtf(cfg, render=False)[0])
            rtf_render.append(episode_rtf(cfg, render=True)[0])
        except TcotError:  # e.g. a goal the oracle has no skill for: no episode figure
            break
    if rtf_plain:
        out["libero/episode_real_time_factor"] = _stat(rtf_plain, "x")
        out["libero/episode_real_time_factor_rendering"] = _stat(rtf_render, "x")
    return out


def run_bench(out_dir: str | Path, *, quick: bool, robot: str = "panda", command: str = "") -> dict:
    from tqdm import tqdm

    from tcot_hybrid.controllers import list_controllers

    repeats = 3 if quick else 7
    n_steps = 1000 if quick else 4000
    n_ticks = 200 if quick else 800
    base = RunConfig(task=BENCH_TASK, robot=robot, seed=0)
    substeps = base.timing.substeps
    figures: dict[str, dict] = {}
    ratios: dict[str, float] = {}
    result_notes: list[str] = []
    controllers = list_controllers()
    steps = tqdm(total=repeats * (1 + len(controllers)) + 7, desc="bench", unit="job", disable=None)
    bare = []
    for _ in range(repeats):
        bare.append(bare_step_us(base, n_steps))
        steps.update(1)
    figures["mj_step_us"] = _stat(bare, "us")
    figures["mj_step_rate_hz"] = _stat([1e6 / b for b in bare], "Hz")
    for ctrl in controllers:
        cfg = dataclasses.replace(base, controller=ctrl)
        ticks = []
        for _ in range(repeats):
            ticks.append(tick_us(cfg, n_ticks))
            steps.update(1)
        figures[f"tick_us/{ctrl}"] = _stat(ticks, "us")
        ratios[f"tick_over_mj_step/{ctrl}"] = round(statistics.median(ticks) / (substeps * statistics.median(bare)), 3)
        ratios[f"tick_over_ctrl_dt/{ctrl}"] = round(statistics.median(ticks) * 1e-6 / base.timing.ctrl_dt, 4)
    figures.update(ik_figures(robot, 30 if quick else 150)); steps.update(1)
    plan_figures, plan_ratios = ik_plan_figures(robot, 1 if quick else 5)
    figures.update(plan_figures)
    ratios.update(plan_ratios)
    steps.update(1)
    figures.update(ruckig_figures(robot, 50 if quick else 300)); steps.update(1)
    figures["render_planner_image_ms"] = _stat([render_ms(base, 20 if quick else 100) for _ in range(repeats)], "ms")
    steps.update(1)
    rtf_plain, rtf_render = [], []
    for seed in range(2 if quick else 5):
        cfg = dataclasses.replace(base, seed=seed)
        rtf_plain.append(episode_rtf(cfg, render=False)[0])
        rtf_render.append(episode_rtf(cfg, render=True)[0])
    steps.update(2)
    figures["episode_real_time_factor"] = _stat(rtf_plain, "x")
    figures["episode_real_time_factor_rendering"] = _stat(rtf_render, "x")
    ratios["bare_physics_real_time_factor"] = round(base.timing.sim_dt / (statistics.median(bare) * 1e-6), 1)
    ratios["episode_rtf_over_bare_physics_rtf"] = round(statistics.median(rtf_plain) / ratios["bare_physics_real_time_factor"], 3)
    figures["peak_rss_mb/tcot_run"] = _stat([peak_rss_mb_of_run(BENCH_TASK)], "MB")
    steps.update(1)
    try:
        figures.update(planner_inference_ms(base, 20 if quick else 200))
    except TcotError as exc:  # no shipped checkpoint for this robot: say so instead of a number
        result_notes.append(f"planner inference not measured: {exc}")
    if not quick and "planner_inference_ms/global" in figures:
        walls = {w: eval_wall_s(w, seeds=3, robot=robot) for w in (1, 2)}
        for w, wall in walls.items():
            figures[f"eval_wall_s/workers_{w}"] = _stat([wall], "s")
        ratios["eval_speedup_2_over_1_workers"] = round(walls[1] / walls[2], 2)
    default_data = Path("data") / f"demos_{robot}.hdf5"
    if not quick and default_data.exists():
        with tempfile.TemporaryDirectory() as tmp:  # the data load dominates; half a minute of training
            figures["peak_rss_mb/tcot_train"] = _stat([peak_rss_mb_of(
                ["train", "--data", str(default_data), "--out", f"{tmp}/bench.safetensors", "--max-minutes", "0.5"])],
                "MB")
    elif not quick:
        result_notes.append(f"peak memory of tcot train not measured: {default_data} missing (run tcot collect)")
    steps.close()
    from tcot_hybrid.libero import libero_available

    if libero_available():
        figures.update(libero_figures(quick=quick, repeats=repeats, n_steps=n_steps, n_ticks=n_ticks))
    else:
        result_notes.append("LIBERO figures not measured: LIBERO is not installed (make libero)")
    result = {"figures": figures, "ratios": ratios, "notes": result_notes, "command": command, "quick": quick,
              "robot": robot,
              "task": BENCH_TASK, "timing": dataclasses.asdict(base.timing),
              "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "mujoco": mujoco.__version__}}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(result, indent=2))
    (out / "bench.md").write_text(bench_markdown(result))
    return result
