"""The ``tcot`` command: list, run (more subcommands join as the planner and GLSR land).

Every config field can be set from a file (``--config run.yaml``) and overridden on the command line
(``--timing.ctrl-dt 0.004``, ``--ik-params.damping 1e-3``, ``--controller-params kp_scale 2``).
Bad input exits non-zero with a message naming the bad value and the valid choices.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

os.environ.setdefault("MUJOCO_GL", "egl")

import tyro  # noqa: E402

from tcot_hybrid.errors import TcotError  # noqa: E402
from tcot_hybrid.run_config import RunConfig, load_config_file  # noqa: E402


# --- tcot list ----------------------------------------------------------------------------------------

def listing() -> dict:
    from tcot_hybrid.controllers import list_controllers
    from tcot_hybrid.ik import list_ik
    from tcot_hybrid.perturbations import list_perturbations
    from tcot_hybrid.planners import list_planners
    from tcot_hybrid.robot import list_robots
    from tcot_hybrid.tasks import list_all_tasks

    return {
        "tasks": list_all_tasks(),  # the workcell's, then every suite the installed LIBERO registers
        "robots": list_robots(),
        "controllers": list_controllers(),
        "ik": list_ik(),
        "planners": list_planners(),
        "perturbations": [{"name": p["name"], "description": p["description"]} for p in list_perturbations()],
    }


def cmd_list(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="tcot list", description="tasks by suite, robots, controllers, IK backends, planners")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    args = p.parse_args(argv)
    data = listing()
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    suites: dict[str, list] = {}
    for t in data["tasks"]:
        suites.setdefault(t["suite"], []).append(t)
    print("tasks:")
    for suite, tasks in suites.items():
        print(f"  {suite}:")
        for t in tasks:
            print(f"    {t['name']:<34} {t['instruction']}")
    from tcot_hybrid.libero import libero_available

    if not libero_available():
        print("  (LIBERO's suites appear here once LIBERO is installed: `make libero`)")
    for key in ("robots", "controllers", "ik", "planners"):
        print(f"{key}: {', '.join(data[key])}")
    print("perturbations:")
    for p in data["perturbations"]:
        print(f"    {p['name']:<16} {p['description']}")
    return 0


# --- tcot run -----------------------------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class RunCommand:
    """Run one episode and write DIR/episode.json (and a video if asked)."""

    cfg: Annotated[RunConfig, tyro.conf.arg(name="")] = field(default_factory=RunConfig)
    config: Path | None = None
    """YAML/TOML/JSON file with any RunConfig fields; command-line flags override it."""
    video: Path | None = None
    """Write an MP4 of the front camera with the planned waypoints drawn on it."""
    timeline: Path | None = None
    """Write a PNG timeline (GLSR state, p(success), replans, joints vs Ruckig reference)."""
    out: Path = Path("runs/latest")
    """Directory for episode.json."""
    viewer: bool = False
    """Open MuJoCo's interactive viewer (needs a display)."""


def perturb_shorthand(argv: list[str]) -> list[str]:
    """``tcot run --perturb NAME`` is short for ``--perturb.name NAME`` (the spelling ``tcot eval`` and
    ``tcot collect`` use for their perturbation lists)."""
    return ["--perturb.name" if a == "--perturb" else
            "--perturb.name=" + a.split("=", 1)[1] if a.startswith("--perturb=") else a for a in argv]


def parse_with_config(command_cls, argv: list[str], prog: str):
    """Parse a command dataclass whose ``cfg`` defaults come from ``--config FILE`` (if given) and whose
    flags override that file."""
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--config", type=Path)
    known, _ = pre.parse_known_args(argv)
    base = load_config_file(known.config) if known.config is not None else RunConfig()
    cmd = tyro.cli(command_cls, args=argv, default=command_cls(cfg=base, config=known.config), prog=prog)
    if not robot_given(argv, base):  # robot "auto": the robot of the task actually chosen (--task may change it)
        cmd = dataclasses.replace(cmd, cfg=dataclasses.replace(cmd.cfg, robot="auto"))
    return cmd


def robot_given(argv: list[str], base: RunConfig) -> bool:
    """Did the user name a robot (``--robot`` or a config file's robot other than its task's own)?"""
    from tcot_hybrid.tasks import default_robot

    return any(a == "--robot" or a.startswith("--robot=") for a in argv) or base.robot != default_robot(base.task)


def _unstarted_record(cfg: RunConfig, exc: BaseException) -> dict:
    """Record of a run that failed before its stack existed: what was asked, why it stopped, the hashes."""
    from tcot_hybrid.episode import file_digest, run_environment
    from tcot_hybrid.planners import run_checkpoint

    def digest(path_of):
        try:
            path = path_of()
            return None if path is None else file_digest(path)
        except Exception:  # noqa: BLE001 - e.g. the robot or checkpoint is what was refused
            return None

    from tcot_hybrid.robot import load_robot_spec

    return {"task": cfg.task, "robot": cfg.robot, "controller": cfg.controller, "ik": cfg.ik, "planner": cfg.planner,
            "mode": cfg.supervisor.mode, "seed": cfg.seed, "success": False,
            "fault": f"not started: {type(exc).__name__}: {exc}", "sim_time_s": 0.0, "wall_time_s": 0.0,
            "steps": 0, "plans": 0, "perturb": cfg.perturb.name, "events": [], "config": cfg.to_dict(),
            "config_hash": cfg.digest(), "robot_model_hash": digest(lambda: load_robot_spec(cfg.robot).mjcf_path),
            "checkpoint_hash": digest(lambda: run_checkpoint(cfg)),
            "versions": run_environment()}


def outcome(record: dict) -> str:
    """SUCCESS, failure, or the fault that ended the episode (``FAULT sim_fault:mjWARN_BADQACC``)."""
    if record.get("success"):
        return "SUCCESS"
    return f"FAULT {record['fault']}" if record.get("fault") else "failure"


def cmd_run(argv: list[str]) -> int:
    from tqdm import tqdm

    from tcot_hybrid.episode import EpisodeRunner, write_record
    from tcot_hybrid.video import EpisodeVideo, Timeline
    from tcot_hybrid.workers import one_torch_thread

    cmd = parse_with_config(RunCommand, perturb_shorthand(argv), "tcot run")
    if cmd.viewer and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise TcotError("--viewer needs a display (DISPLAY/WAYLAND_DISPLAY is not set); "
                        "use --video out.mp4 to record the episode instead")
    from tcot_hybrid.jsonio import check_output_dir, check_output_file
    from tcot_hybrid.video import check_timeline_path

    check_output_dir(cmd.out)  # an unusable --out, --video or --timeline is found now, not after the episode
    if (cmd.out / "episode.json").is_dir():
        from tcot_hybrid.errors import OutputError

        raise OutputError(f"--out {str(cmd.out)!r} holds a directory named episode.json; the record cannot go there")
    for flag, path in (("--video", cmd.video), ("--timeline", cmd.timeline)):
        if path is not None:
            check_output_file(path, what=flag)
    if cmd.timeline is not None:
        check_timeline_path(cmd.timeline)
    from tcot_hybrid.planners import check_checkpoint_used

    check_checkpoint_used(cmd.cfg.checkpoint, [cmd.cfg.planner])
    try:
        runner = EpisodeRunner(cmd.cfg)
    except BaseException as exc:  # refused or crashed before anything moved: the record says so
        write_record(_unstarted_record(cmd.cfg, exc), cmd.out)
        raise
    for line in runner.warning_lines():  # before the first step
        print(f"warning: {line}", file=sys.stderr)
    video = EpisodeVideo(runner, cmd.video) if cmd.video else None
    timeline = Timeline() if cmd.timeline else None
    hooks = [h.capture for h in (video, timeline) if h is not None]
    if hooks:
        runner.frame_hook = lambda r, step: [h(r, step) for h in hooks]
    viewer = None
    if cmd.viewer:
        import mujoco.viewer

        viewer = mujoco.viewer.launch_passive(runner.stack.sim.model, runner.stack.sim.data)
        previous = runner.frame_hook
        def sync(r, step):  # noqa: E306
            if previous:
                previous(r, step)
            viewer.sync()
        runner.frame_hook = sync
    total = int(round(runner.stack.task.time_limit_s / cmd.cfg.timing.plan_dt))
    record: dict | None = None
    abort: BaseException | None = None
    try:
        # torch on one thread, as in `tcot eval`: the network's outputs differ in their last bits between thread
        # counts, and a LIBERO episode can go another way from there, so `tcot run` replays an evaluated episode
        with one_torch_thread(), tqdm(total=total, desc=cmd.cfg.task, unit="step", leave=False, disable=None) as bar:
            record = runner.run(progress=bar)
    except BaseException as exc:  # noqa: BLE001 - re-raised below, after the record is written
        abort = exc
        raise
    finally:
        if record is None:  # aborted: still leave a record
            why = f"aborted: {type(abort).__name__}: {abort}" if abort is not None else "aborted"
            try:
                record = runner.record(0.0)
                record["fault"] = record.get("fault") or why
                record["success"] = False
            except Exception as exc:  # noqa: BLE001 - the record itself failed: keep the essentials
                record = _unstarted_record(cmd.cfg, abort or exc)
                record["fault"] = why
        path = write_record(record, cmd.out)
        if video:
            video.close()
        if timeline:
            timeline.save(cmd.timeline, title=f"{cmd.cfg.task} seed {cmd.cfg.seed} ({cmd.cfg.supervisor.mode})")
        if viewer:
            viewer.close()
    print(f"{record['task']} seed={record['seed']} robot={record['robot']} controller={record['controller']} "
          f"ik={record['ik']} planner={record['planner']}: {outcome(record)} "
          f"in {record['sim_time_s']:.1f}s sim / {record['wall_time_s']:.1f}s wall, "
          f"{len(record['events'])} events -> {path}" + (f", video {cmd.video}" if cmd.video else ""))
    for line in run_notes(record):
        print(line)
    return 0


def _check_one_layout_mode(first: RunConfig, last: RunConfig) -> None:
    """Without --init, a LIBERO cell whose seeds run past the shipped init states would mix them with sampled layouts
    (the default changes there): refused, naming both, so one table never holds two kinds of layout."""
    if first.init is not None:
        return
    from tcot_hybrid.errors import ConfigError
    from tcot_hybrid.tasks import make_task

    modes = []
    for cfg in (first, last):
        task = make_task(cfg.task)
        task.set_episode(seed=cfg.seed, init=None)
        modes.append(task.init)
    if modes[0] != modes[1]:
        raise ConfigError(f"seeds {first.seed}-{last.seed} of {first.task!r} would run {modes[0]} layouts and then "
                          f"{modes[1]} ones ({task.init_note}); give --init {modes[0]} or --init {modes[1]}")


def run_notes(record: dict) -> list[str]:
    """What a reader of one episode's summary must not miss: a perturbation that did not fire (and why), how a
    detector-stopped episode ended."""
    notes = []
    if record.get("perturbation_fired") is False:
        notes.append(f"perturbation {record['perturb']} did NOT fire: {record.get('perturbation_note')}; "
                     f"this episode is not a perturbed one")
    elif record.get("perturbation_fired"):
        step = next((e.get("step") for e in record.get("events", []) if e.get("kind") == "perturbation"), None)
        notes.append(f"perturbation {record['perturb']} fired at planner step {step}")
    if record.get("stop_on") in ("detector", "either") and record.get("stopped_by") != "simulator":
        notes.append(f"stopped by {record.get('stopped_by')}; the success predicate on the final state says "
                     f"{'success' if record['success'] else 'failure'}"
                     + (" (premature stop)" if record.get("premature_stop") else ""))
    return notes


# --- tcot eval ----------------------------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class EvalCommand:
    """Evaluate planners × modes over tasks and seeds (parallel, resumable); writes DIR/eval.json + eval.md."""

    cfg: Annotated[RunConfig, tyro.conf.arg(name="")] = field(default_factory=RunConfig)
    config: Path | None = None
    """YAML/TOML/JSON file with RunConfig fields shared by every episode."""
    suite: str | None = None
    """Evaluate every task of these comma-separated suites (default: the workcell's suites); LIBERO suites
    too, e.g. libero_spatial,libero_object,libero_goal,libero_10."""
    tasks: str | None = None
    """Comma-separated task names (instead of --suite)."""
    planners: str | None = None
    """Comma-separated planners (default: --planner)."""
    modes: str = "global"
    """Comma-separated supervisor modes."""
    perturb: str | None = None
    """Comma-separated perturbations to inject (default: --perturb.name, i.e. none); `tcot list` shows them."""
    robots: str | None = None
    """Comma-separated robots (default: --robot, else each task's own robot)."""
    controllers: str | None = None
    """Comma-separated controllers (default: --controller)."""
    iks: str | None = None
    """Comma-separated IK backends (default: --ik)."""
    episodes: int = 20
    """Seeds per cell."""
    seed_start: int = 1000
    """First seed; seeds are seed_start .. seed_start + episodes - 1 (LIBERO's shipped init states: 0-49)."""
    workers: int = 2
    """Worker processes."""
    out: Path = Path("runs/eval")
    """Output directory (re-running with the same DIR resumes)."""
    sweep: str | None = None
    """FIELD=V1,V2,...: one cell per value of any config field, e.g. ik_params.damping=1e-3,1e-2."""
    ray_address: str | None = None
    """Run the episodes on a Ray cluster at this address (needs `pip install ray`) instead of local workers."""
    readme: Path | None = None
    """Also write the tables into this README's <!-- eval:start/end --> section."""


def _split(value: str | None, default: str) -> list[str]:
    return [v.strip() for v in (value or default).split(",") if v.strip()]


def cmd_eval(argv: list[str]) -> int:
    from tcot_hybrid.episode import validate_names
    from tcot_hybrid.errors import ConfigError
    from tcot_hybrid.evaluation import evaluate, make_jobs
    from tcot_hybrid.tasks import list_tasks, suite_task_names

    cmd = parse_with_config(EvalCommand, argv, "tcot eval")
    if cmd.suite and cmd.tasks:
        raise ConfigError("give --suite or --tasks, not both")
    all_tasks = list_tasks()
    tasks = ([name for suite in _split(cmd.suite, "") for name in suite_task_names(suite)] if cmd.suite else
             _split(cmd.tasks, ",".join(t.name for t in all_tasks)))
    if cmd.episodes < 1 or cmd.workers < 1 or cmd.seed_start < 0:
        raise ConfigError(f"--episodes and --workers must be >= 1 and --seed-start >= 0; got "
                          f"{cmd.episodes}, {cmd.workers}, {cmd.seed_start}")
    jobs = make_jobs(cmd.cfg, tasks=tasks, planners=_split(cmd.planners, cmd.cfg.planner),
                     modes=_split(cmd.modes, "global"), robots=_split(cmd.robots, cmd.cfg.robot if robot_given(
                         argv, load_config_file(cmd.config) if cmd.config else RunConfig()) else "auto"),
                     controllers=_split(cmd.controllers, cmd.cfg.controller), iks=_split(cmd.iks, cmd.cfg.ik),
                     episodes=cmd.episodes, seed_start=cmd.seed_start,
                     perturbs=_split(cmd.perturb, cmd.cfg.perturb.name), sweep=cmd.sweep)
    from tcot_hybrid.planners import check_checkpoint_used

    check_checkpoint_used(cmd.cfg.checkpoint, sorted({j.cfg.planner for j in jobs}))
    first_seed, last_seed = {}, {}  # every name checked before any episode runs, with each cell's last seed
    for j in jobs:
        key = (j.cfg.task, j.cfg.robot, j.cfg.controller, j.cfg.ik, j.cfg.planner, j.cfg.supervisor.mode)
        if key not in last_seed or j.cfg.seed > last_seed[key].seed:
            last_seed[key] = j.cfg
        if key not in first_seed or j.cfg.seed < first_seed[key].seed:
            first_seed[key] = j.cfg
    for key, cfg in last_seed.items():
        validate_names(cfg)  # a shipped init state past the task's is refused here
        _check_one_layout_mode(first_seed[key], cfg)
    result = evaluate(jobs, cmd.out, workers=cmd.workers, ray_address=cmd.ray_address)
    if cmd.readme:
        from tcot_hybrid.markdown import update_readme_section
        from tcot_hybrid.evaluation import markdown

        summary = (f"Measured by `tcot eval {' '.join(argv)}` ({result['episodes']} episodes; all cells in "
                   f"`{cmd.out}/eval.md`):\n" + markdown(result, with_cells=False))
        update_readme_section(cmd.readme, f"eval:{cmd.out}", summary, inside="eval")
    tot = sum(c["successes"] for c in result["cells"])
    print(f"{tot}/{result['episodes']} episodes succeeded across {len(result['cells'])} cells in "
          f"{result['wall_time_s']:.1f}s with {cmd.workers} workers -> {cmd.out / 'eval.json'}")
    if any(c.get("stop_on") in ("detector", "either") for c in result["cells"]):
        print(f"stopped by the detector: premature stops {sum(c['premature_stops'] for c in result['cells'])} "
              f"of {result['episodes']} episodes")
    for planner, d in (result.get("detector") or {}).items():
        print(f"detector ({planner}): AUROC in-episode {d['in_episode_auroc']} over {d['in_episode_frames']} frames; "
              f"with post-success probes {d['auroc']} over {d['calls']}")
    from tcot_hybrid.evaluation.reports import perturbation_notes

    for line in perturbation_notes(result["cells"]):
        print("perturbation " + line[2:])
    return 0


# --- tcot bench ---------------------------------------------------------------------------------------

def cmd_bench(argv: list[str]) -> int:
    from tcot_hybrid.bench import run_bench
    from tcot_hybrid.markdown import bench_markdown, update_readme_section

    p = argparse.ArgumentParser(prog="tcot bench", description="speed and memory figures (medians with spread, "
                                "ratios measured in the same run); writes DIR/bench.json and DIR/bench.md")
    p.add_argument("--quick", action="store_true", help="fewer repeats (under a minute)")
    p.add_argument("--out", type=Path, default=Path("runs/bench"), help="output directory")
    p.add_argument("--robot", default="panda", help="robot to measure")
    p.add_argument("--readme", type=Path, default=None,
                   help="also write the tables into this README's <!-- bench:start/end --> section")
    args = p.parse_args(argv)
    from tcot_hybrid.robot import load_robot_spec

    load_robot_spec(args.robot)
    command = "tcot bench " + " ".join(argv)
    result = run_bench(args.out, quick=args.quick, robot=args.robot, command=command.strip())
    if args.readme:
        update_readme_section(args.readme, "bench", bench_markdown(result))
    for k, v in result["ratios"].items():
        print(f"{k}: {v}")
    print(f"-> {args.out / 'bench.json'}")
    return 0


# --- tcot robot check --------------------------------------------------------------------------------

def cmd_robot(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="tcot robot", description="check a robot before using it (`tcot robot check "
                                "NAME|PATH`): spec + MJCF, Pinocchio vs MuJoCo, gripper, and a reach map of the "
                                "task workspace and of every task's grasp and release points")
    sub = p.add_subparsers(dest="action", required=True)
    c = sub.add_parser("check", help="validate a robot and map where it can grasp top-down")
    c.add_argument("robot", help="a bundled robot name (`tcot list`) or the path of a robot.toml (or its folder)")
    c.add_argument("--json", action="store_true", help="print the report as one JSON object on stdout")
    c.add_argument("--png", type=Path, default=None,
                   help="reach map PNG (default runs/robot_check/<robot>_reach.png; 'none' for no map)")
    c.add_argument("--tasks", default=None, help="comma-separated tasks to check (default: all)")
    c.add_argument("--seeds", type=int, default=10, help="seeded layouts per task (default 10)")
    c.add_argument("--step", type=float, default=0.02, help="workspace grid step [m] (default 0.02)")
    args = p.parse_args(argv)
    from tcot_hybrid.errors import ConfigError
    from tcot_hybrid.robot_check import check_robot
    from tcot_hybrid.tasks import list_tasks

    if args.seeds < 1 or not 0.005 <= args.step <= 0.2:
        raise ConfigError(f"--seeds must be >= 1 and --step in [0.005, 0.2] m; got {args.seeds}, {args.step}")
    tasks = [t.strip() for t in args.tasks.split(",") if t.strip()] if args.tasks else None
    known = [t.name for t in list_tasks()]
    for t in tasks or []:
        if t not in known:
            from tcot_hybrid.errors import unknown_name

            raise ConfigError(unknown_name("task", t, known))
    png = None if args.png is not None and str(args.png).lower() == "none" else (
        args.png or Path("runs/robot_check") / f"{Path(str(args.robot)).stem if '/' in str(args.robot) else args.robot}_reach.png")
    if png is not None:
        from tcot_hybrid.jsonio import check_output_file

        check_output_file(png, what="--png")
    report = check_robot(args.robot, tasks=tasks, seeds=args.seeds, step_m=args.step, png=png)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(f"robot {report['robot']}" + (f" ({report.get('mjcf')})" if report.get("mjcf") else ""))
        for ch in report["checks"]:
            mark = "ok  " if ch["ok"] else ("WARN" if ch["severity"] == "warning" else "FAIL")
            print(f"  [{mark}] {ch['name']}: {ch['detail']}")
        if "reachable_fraction" in report:
            print(f"  reachable_fraction {report['reachable_fraction']:.3f} of the workspace "
                  f"x {report['workspace']['x_m']} m, y {report['workspace']['y_m']} m at z {report['workspace']['z_m']} m")
            for t in report["tasks"]:
                def pct(v):
                    return "-" if v is None else f"{v:.0%}"
                print(f"    {t['task']:<34} grasps {pct(t['grasp_reachable_fraction']):>5} of {t['grasp_points']:<3} "
                      f"releases {pct(t['release_reachable_fraction']):>5} of {t['release_points']}")
        if report.get("png"):
            print(f"  map -> {report['png']}")
    return 0 if report["ok"] else 1


COMMANDS = {"list": cmd_list, "run": cmd_run, "eval": cmd_eval, "bench": cmd_bench, "robot": cmd_robot}
COMMANDS["collect"] = lambda argv: __import__("tcot_hybrid.data.collect", fromlist=["_"]).cmd_collect(argv)
COMMANDS["labels"] = lambda argv: __import__("tcot_hybrid.data.vision_labels", fromlist=["_"]).cmd_labels(argv)
COMMANDS["replay"] = lambda argv: __import__("tcot_hybrid.data.replay", fromlist=["_"]).cmd_replay(argv)
COMMANDS["train"] = lambda argv: __import__("tcot_hybrid.learning.train_cli", fromlist=["_"]).cmd_train(argv)
COMMANDS["ik-plans"] = lambda argv: __import__("tcot_hybrid.ik.plan_study", fromlist=["_"]).cmd_ik_plans(argv)


MAX_ERROR_CHARS = 2000
"""Longest error text printed (a message that somehow echoes a huge value is cut, never streamed out)."""


def bounded_message(exc: BaseException) -> str:
    msg = str(exc)
    return msg if len(msg) <= MAX_ERROR_CHARS else msg[:MAX_ERROR_CHARS - 40] + f" ... [{len(msg)} chars, cut]"


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: tcot {" + ",".join(COMMANDS) + "} ...\n\n" + __doc__.strip())
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"error: unknown command {name!r}; valid commands: {', '.join(COMMANDS)}", file=sys.stderr)
        return 2
    try:
        return COMMANDS[name](rest)
    except TcotError as exc:
        print(f"error: {bounded_message(exc)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
