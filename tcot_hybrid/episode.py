"""One episode end to end: build the stack from a RunConfig, run planner steps, write the record.

The record (``episode.json``) is written even when the episode aborts, and a faulted episode is never
reported as a success.
"""
from __future__ import annotations

import functools
import hashlib
import json
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from tcot_hybrid import __version__
from tcot_hybrid.camera import CameraModel
from tcot_hybrid.controllers import make_controller
from tcot_hybrid.dynamics import MujocoArmDynamics
from tcot_hybrid.errors import PlanningError, SimulationError
from tcot_hybrid.executor import MotionExecutor
from tcot_hybrid.ik import make_ik
from tcot_hybrid.perturbations import make_perturbation
from tcot_hybrid.planners import Observation, Planner, PlannerContext, check_planner_name, make_planner
from tcot_hybrid.robot import RobotSpec, load_robot_spec
from tcot_hybrid.run_config import RunConfig
from tcot_hybrid.safety import SafetyLayer
from tcot_hybrid.sim import Simulation
from tcot_hybrid.smoothing import JointSmoother
from tcot_hybrid.supervision import Supervisor
from tcot_hybrid.tasks import Task, make_task
from tcot_hybrid.jsonio import json_default as _json_default

START_HOME_MAX_S = 3.0  # [s] longest the arm is given to reach home before the first plan (a LIBERO start: 0.3 s)


def file_digest(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


@dataclass
class Stack:
    """Every stage of the motion stack for one episode, wired together."""

    cfg: RunConfig
    robot: RobotSpec
    task: Task
    sim: Simulation
    camera: CameraModel
    executor: MotionExecutor
    planner: Planner


def validate_names(cfg: RunConfig) -> None:
    """Fail on any unknown name or bad controller parameter before anything is built (each error lists
    the valid choices)."""
    from tcot_hybrid.controllers import list_controllers
    from tcot_hybrid.errors import ControllerError, unknown_name
    from tcot_hybrid.ik.base import check_ik_options, ik_backend, joint_bounds

    task = make_task(cfg.task)
    task.set_episode(seed=cfg.seed, init=cfg.init)  # e.g. --init shipped on a workcell task
    if cfg.scene.planner_camera not in task.cameras():
        from tcot_hybrid.errors import ConfigError

        raise ConfigError(f"scene.planner_camera = {cfg.scene.planner_camera!r} is not a camera of task "
                          f"{cfg.task!r}'s scene; choose one of {', '.join(task.cameras())}")
    robot = load_robot_spec(cfg.robot)
    if cfg.controller not in list_controllers():
        raise ControllerError(unknown_name("controller", cfg.controller, list_controllers()))
    make_controller(cfg.controller, robot, ctrl_dt=cfg.timing.ctrl_dt, params=cfg.controller_params)
    backend = ik_backend(cfg.ik)  # an unknown name is refused listing the backends
    joint_bounds(robot, cfg.ik_params)  # a joint-limit margin this robot cannot take
    check_ik_options(backend, cfg.ik_params)  # e.g. collision avoidance asked of a backend without it
    check_planner_name(cfg.planner)
    if cfg.checkpoint is not None and not Path(cfg.checkpoint).is_file():  # else the record's hash fails at the end
        from tcot_hybrid.errors import ConfigError

        raise ConfigError(f"checkpoint {cfg.checkpoint!r} is not a file")


def build_stack(cfg: RunConfig, *, planner_factory=None) -> Stack:
    """Wire every stage for ``cfg``. ``planner_factory(ctx)`` replaces the registry's ``cfg.planner`` (a planner
    that is not a registry entry, e.g. :class:`tcot_hybrid.data.replay.LabelReplayPlanner`)."""
    validate_names(cfg)
    robot = load_robot_spec(cfg.robot)
    task = make_task(cfg.task)
    task.set_episode(seed=cfg.seed, init=cfg.init)
    sim = Simulation(robot, task, timing=cfg.timing, scene=cfg.scene)
    sim.reset(np.random.default_rng(cfg.seed))
    px = cfg.scene.planner_image_px
    camera = CameraModel.from_mujoco(sim.model, sim.data, cfg.scene.planner_camera, width=px, height=px)
    dyn = MujocoArmDynamics(sim.model, sim.data, robot, T_base_world=sim.T_base_world)
    smoother = JointSmoother.from_spec(robot, ctrl_dt=cfg.timing.ctrl_dt, config=cfg.smoothing,
                                       torques=dyn.inverse_torques)
    smoother.reset(sim.q)
    controller = make_controller(cfg.controller, robot, ctrl_dt=cfg.timing.ctrl_dt,
                                 params=cfg.controller_params)
    safety = SafetyLayer(robot)
    ik = make_ik(cfg.ik, robot, cfg.ik_params)
    executor = MotionExecutor(sim, ik=ik, smoother=smoother, controller=controller, safety=safety,
                              dynamics=dyn, camera=camera, config=cfg.executor, lift_config=cfg.lift,
                              world_kind=task.world_kind)
    ctx = PlannerContext(task=task, world=sim.world, camera=camera, robot_name=robot.name, robot=robot,
                         world_kind=task.world_kind, T_world_base=sim.T_world_base,
                         options={"oracle": cfg.oracle, "learned": cfg.learned, "checkpoint": cfg.checkpoint,
                                  "suite": task.suite, "task": task.name})
    # planner_factory (e.g. label replay) is not privileged: it sees what a learned planner sees
    planner = make_planner(cfg.planner, ctx) if planner_factory is None else planner_factory(ctx.observation_only())
    return Stack(cfg=cfg, robot=robot, task=task, sim=sim, camera=camera, executor=executor, planner=planner)


def reach_warnings(stack: Stack) -> list[dict]:
    """Grasp/release points of the episode's layout its robot cannot reach (``robot_check``); a check that
    cannot run (a task without a script) warns about nothing rather than stopping the run."""
    from tcot_hybrid.robot_check import unreachable_targets

    try:
        return unreachable_targets(stack.robot, stack.task, stack.sim.world, stack.sim.T_base_world)
    except Exception:  # noqa: BLE001 - advisory only
        return []


def resolve_stop_on(cfg: RunConfig, task: Task, planner: Planner) -> str:
    """The episode's ``stop_on`` with "auto" resolved (see :class:`RunConfig`); ConfigError when "detector" or
    "either" is asked of a planner without a failure detector."""
    if cfg.stop_on == "auto":
        glsr = cfg.supervisor.mode.startswith("glsr")
        return "either" if glsr and planner.has_detector and task.world_kind == "libero" else "simulator"
    if cfg.stop_on in ("detector", "either") and not planner.has_detector:
        from tcot_hybrid.errors import ConfigError

        raise ConfigError(f"stop_on = {cfg.stop_on!r} needs a planner with a failure detector; planner "
                          f"{cfg.planner!r} has none (use stop_on = 'simulator', or a learned planner)")
    return cfg.stop_on


class EpisodeRunner:
    """Runs one episode step by step (the CLI, the evaluator, the bench and the examples share it).

    Per planner step: hooks → perturbation → supervisor decision (maybe a new plan) → ctrl ticks →
    fault and success checks.
    """

    def __init__(self, cfg: RunConfig, *, frame_hook=None, pre_step_hook=None, planner_factory=None):
        self.cfg = cfg
        self.stack = build_stack(cfg, planner_factory=planner_factory)
        self.frame_hook = frame_hook  # called after every planner step: frame_hook(runner, step)
        self.pre_step_hook = pre_step_hook  # called at the start of every planner step, before planning
        self.supervisor = Supervisor(cfg.supervisor, self.stack.planner, world_kind=self.stack.task.world_kind)
        self.stop_on = resolve_stop_on(cfg, self.stack.task, self.stack.planner)  # "auto" made concrete
        self.perturbation = make_perturbation(cfg.perturb, cfg.seed)
        self.perturbation_note = self._perturbation_note()
        self.steps = 0
        self.homing_steps = 0  # planner steps spent going home before a plan (start_home_tol_rad); count to the limit
        self.success = False
        self.stopped_by: str | None = None  # simulator | detector | time_limit | fault
        self._stop_hold = 0
        self.fault: str | None = None
        self.plans: list = []
        self._obs: tuple[int, Observation] | None = None
        self.success_time_s: float | None = None
        self.reach_warnings = reach_warnings(self.stack)  # before any step: printed by `tcot run`, recorded

    def warning_lines(self) -> list[str]:
        """The task's note on its layout (a LIBERO seed past the shipped init states), then one line per grasp/release
        point of this layout the robot cannot reach top-down."""
        from tcot_hybrid.robot import robot_ref

        r = self.stack.robot
        where = robot_ref(r)
        note = [self.stack.task.init_note] if self.stack.task.init_note else []
        return note + [f"robot {r.name!r} cannot reach the {w['target']} point {w['pos']} m of {self.cfg.task!r} "
                       f"top-down (IK misses it by {w['pos_err_m'] * 100:.1f} cm): the episode will likely fail; "
                       f"`tcot robot check {where}` maps its reach" for w in self.reach_warnings]

    def observe(self, step: int) -> Observation:
        """The planner's observation at this step (rendered at most once per step)."""
        if self._obs is not None and self._obs[0] == step:
            return self._obs[1]
        s = self.stack
        image = None
        if s.planner.needs_image:
            px = self.cfg.scene.planner_image_px
            image = s.sim.render(self.cfg.scene.planner_camera, px, px)
            if self.perturbation is not None:
                image = self.perturbation.on_image(image)
        obs = Observation(step=step, image=image, depth_m=None, q=s.sim.q,
                          gripper_closed=s.sim.gripper_closed_cmd(), instruction=s.task.instruction,
                          tcp_pos_m=s.sim.tcp_pos())
        self._obs = (step, obs)
        return obs

    def invalidate_observation(self) -> None:
        """The scene changed within this step (e.g. a perturbation moved the camera): render afresh."""
        self._obs = None

    def settle(self) -> None:
        ex = self.stack.executor
        for _ in range(round(self.stack.task.settle_s / self.cfg.timing.ctrl_dt)):
            ex.tick()

    def go_to_home(self) -> None:
        """An arm that starts off the robot's home posture by more than ``executor.start_home_tol_rad`` on some joint
        goes there before the first plan, whole planner steps at a time, until it is within that tolerance (at
        most START_HOME_MAX_S); the steps count against the time limit (``homing_steps``)."""
        s, ex = self.stack, self.stack.executor
        tol, home = ex.config.start_home_tol_rad, s.sim.robot.home_q

        def off_home() -> float:  # [rad] the largest joint's distance from home
            return float(np.max(np.abs(s.sim.q - home)))

        start_off = off_home()
        if tol is None or start_off <= tol:
            return
        ex.start_from_home(home)
        steps = 0
        while steps < round(START_HOME_MAX_S / self.cfg.timing.plan_dt) and s.sim.fault is None:
            for _ in range(self.cfg.timing.ticks_per_plan):
                ex.tick()
            steps += 1
            if ex.plan_finished and off_home() <= tol:
                break
        self.homing_steps += steps
        self._obs = None
        s.task.arm_moved_before_start()
        ex.event("started_at_home", steps=steps, start_offset_rad=round(start_off, 4), residual_rad=round(off_home(), 5))

    def _reset_scene(self) -> None:
        """glsr_reset: restore the episode's initial layout and send the arm home (same seed)."""
        s = self.stack
        s.sim.reset(np.random.default_rng(self.cfg.seed))
        s.executor.reset_after_scene_reset()
        self._obs = None
        self.settle()
        self.go_to_home()
        s.planner.prepare()

    def _step_once(self, step: int, *, may_plan: bool) -> None:
        s, ex = self.stack, self.stack.executor
        if self.pre_step_hook is not None:
            self.pre_step_hook(self, step)
        if self.perturbation is not None and self.perturbation_note is None:  # one that cannot apply never fires
            ev = self.perturbation.on_step(self, step)
            if ev is not None:
                ex.event(**ev)
        if may_plan:
            d = self.supervisor.decide(step, observe=lambda: self.observe(step), executor=ex)
            if d.event is not None:
                if "p_success" in d.event:  # ground truth beside the detector's call, for its metrics
                    d.event["true_success"] = bool(s.task.success(s.sim.world))
                ex.event(**d.event)
                if d.event.get("reason") == "grasp_empty":  # the gripper was opened: observe the open hand
                    self.invalidate_observation()
                if d.event.get("reason") == "detector_overruled":  # the planner says there is work left: a
                    self._stop_hold = 0  # detector stop (stop_on detector/either) counts its verdicts afresh
            if d.reset:
                self._reset_scene()
            if d.plan is not None:  # the supervisor made the plan already (confirm_success, a tracked grasp)
                taken = ex.set_plan(d.plan)
                if taken:
                    self.plans.append(d.plan)
                self.supervisor.plan_outcome(d.plan, taken)
            elif d.plan_mode is not None:
                self._plan(step, d.plan_mode)
        for _ in range(self.cfg.timing.ticks_per_plan):
            ex.tick()
            if s.sim.fault is not None:
                break
        self.steps = step + 1

    def _plan(self, step: int, mode: str) -> None:
        """Ask the planner; a refused plan (bad output) or a stale one (over the latency budget) is
        logged and dropped, and the executor keeps following the last valid plan."""
        s, ex = self.stack, self.stack.executor
        obs = self.observe(step)
        t0 = time.perf_counter()
        try:
            plan = s.planner.plan(obs, mode=mode)
        except PlanningError as exc:
            ex.event("plan_rejected", step=step, plan_kind=mode, reason=str(exc))
            return
        latency = time.perf_counter() - t0
        budget = self.cfg.supervisor.max_plan_latency_s
        if budget is not None and latency > budget:
            ex.event("plan_stale", step=step, plan_kind=mode, latency_s=round(latency, 4), budget_s=budget)
            return
        if ex.set_plan(plan):
            self.plans.append(plan)

    @property
    def max_steps(self) -> int:
        """Planner steps in the task's time limit."""
        return int(round(self.stack.task.time_limit_s / self.cfg.timing.plan_dt))

    def _perturbation_note(self) -> str | None:
        """Why the episode's perturbation can never fire (None when it can, or there is none)."""
        if self.perturbation is None:
            return None
        return self.perturbation.cannot_apply(self.stack.task, self.stack.planner, self.max_steps - 1)

    def _detector_stop(self, step: int) -> bool:
        """stop_on = detector: ask the failure detector on the observation at ``step`` (once the supervisor's frozen
        global phase is over: supervisor.t_f);
        True once it has judged the task successful on ``stop_hold_steps`` consecutive calls. The predicate is
        logged beside each call (``true_success``) for the detector's figures, never used to stop."""
        s, cfg = self.stack, self.cfg
        if self.supervisor.in_global_phase(step, s.executor):
            return False
        p, rejected = self.supervisor.detect(lambda: self.observe(step))
        ok = rejected is None and p >= cfg.supervisor.success_threshold
        self._stop_hold = self._stop_hold + 1 if ok else 0
        s.executor.event("stop_check", step=step, p_success=round(float(p), 4), hold=self._stop_hold,
                         true_success=bool(s.task.success(s.sim.world)), **({"rejected": rejected} if rejected else {}))
        return self._stop_hold >= cfg.stop_hold_steps

    def run(self, progress=None, *, steps_after_success: int = 0, probe_detector: bool = False,
            finish_plan_steps: int = 0) -> dict:
        """Run until the episode ends: the task's success predicate holds (``stop_on`` simulator or either) or the
        failure detector says so (``stop_on`` detector or either; success is then the predicate on the final state), the time
        limit, or a fault. ``steps_after_success`` keeps stepping (the arm holds its last plan) a few planner
        steps past a simulator-judged success, e.g. to record success frames; with ``probe_detector`` the
        planner's failure detector is asked at each of those steps (its false-alarm rate is measured on them).
        ``finish_plan_steps`` first lets the executor carry its plan out past a simulator-judged success reached with
        the gripper closed, for at most that many planner steps: a demonstration then shows the release that follows
        a success reached while the object is still held."""
        s, cfg = self.stack, self.cfg
        t0 = time.perf_counter()
        max_steps = self.max_steps
        self.perturbation_note = self._perturbation_note()  # the time limit may have been changed since __init__
        by_detector = self.stop_on == "detector"
        either = self.stop_on == "either"
        for w in self.reach_warnings:
            s.executor.event("unreachable_target", **w)
        self.settle()
        self.go_to_home()
        s.planner.prepare()
        step = 0
        try:
            while step + self.homing_steps < max_steps:
                self._step_once(step, may_plan=True)
                if self.frame_hook is not None:
                    self.frame_hook(self, step)
                if progress is not None:
                    progress.update(1)
                step += 1
                if s.sim.fault is not None:
                    self.fault = f"sim_fault:{s.sim.fault.warning}"
                    s.executor.event("sim_fault", warning=s.sim.fault.warning, count=s.sim.fault.count)
                    self.stopped_by = "fault"
                    break
                if not by_detector and s.task.success(s.sim.world):
                    self.success = True
                    self.stopped_by = "simulator"
                    break
                if (by_detector or either) and step + self.homing_steps < max_steps and self._detector_stop(step):
                    self.stopped_by = "detector"
                    break
            if self.stopped_by is None:
                self.stopped_by = "time_limit"
            if (by_detector or self.stopped_by == "detector") and self.fault is None:
                self.success = bool(s.task.success(s.sim.world))  # judged afterwards, on the state it stopped in
            self.success_time_s = s.sim.time_s if self.success else None
            held = self.success and not by_detector and s.sim.gripper_closed_cmd()
            finishing = finish_plan_steps if held else 0
            while finishing > 0 and not s.executor.plan_finished and s.sim.fault is None:
                self._step_once(step, may_plan=False)
                step += 1
                finishing -= 1
            for _ in range(steps_after_success if self.success and not by_detector else 0):
                if probe_detector:
                    p = s.planner.success_probability(self.observe(step))
                    s.executor.event("detector", step=step, p_success=round(float(p), 4),
                                     true_success=bool(s.task.success(s.sim.world)))
                self._step_once(step, may_plan=False)
                step += 1
            if self.pre_step_hook is not None:  # the final state, after the last step
                self.pre_step_hook(self, step)
        except SimulationError as exc:
            self.fault = f"sim_fault:{exc}"
            self.stopped_by = "fault"
        finally:
            if self.perturbation is not None:
                self.perturbation.undo(self)
        wall = time.perf_counter() - t0
        return self.record(wall)

    def perturbation_summary(self) -> dict:
        """Whether the episode's perturbation fired (None without one) and, if it did not, why."""
        pert = self.perturbation
        if pert is None:
            return {"perturbation_fired": None, "perturbation_note": None}
        note = None
        if not pert.fired:
            note = self.perturbation_note or "its condition never held in this episode"
        return {"perturbation_fired": bool(pert.fired), "perturbation_note": note}

    def record(self, wall_time_s: float) -> dict:
        s, cfg = self.stack, self.cfg
        ex = s.executor
        ck = getattr(s.planner, "checkpoint_path", None)
        success = bool(self.success and self.fault is None and s.sim.fault is None)
        return {
            "task": cfg.task, "suite": s.task.suite, "instruction": s.task.instruction,
            "robot": cfg.robot, "controller": cfg.controller, "ik": cfg.ik, "planner": cfg.planner,
            "mode": cfg.supervisor.mode, "seed": cfg.seed, "init": s.task.init,
            **({"init_note": s.task.init_note} if s.task.init_note else {}),
            **({"fixture_seed": s.task.fixture_seed} if s.task.fixture_seed is not None else {}),
            "success": success, "fault": self.fault,
            "success_time_s": self.success_time_s if success else None,
            "sim_time_s": round(s.sim.time_s, 4), "wall_time_s": round(wall_time_s, 4),
            "steps": self.steps, "plans": len(self.plans), "perturb": cfg.perturb.name,
            **self.perturbation_summary(),
            "stop_on": self.stop_on, "stopped_by": self.stopped_by,
            "premature_stop": bool(self.stopped_by == "detector" and not success),
            "replans": self.supervisor.replans, "resets": self.supervisor.resets,
            "detector_overruled": self.supervisor.overruled, "empty_grasps": self.supervisor.empty_grasps,
            "homes": self.supervisor.homes, "homing_steps": self.homing_steps,
            "grasps_tracked": self.supervisor.tracked["grasp"],
            "releases_tracked": self.supervisor.tracked["release"],
            "camera_calibration": s.planner.calibration.summary() if hasattr(s.planner, "calibration") else None,
            "max_joint_limit_violation_rad": float(ex.max_joint_limit_violation),
            "max_reference_limit_excess_rad": float(ex.max_reference_limit_excess),
            "max_velocity_ratio": float(ex.max_velocity_ratio),
            "max_tracking_error_rad": float(ex.tracking_err_max),
            "ik_failures": ex.ik_failures,
            "plans_infeasible": ex.plans_infeasible,
            "tracking_reflexes": ex.tracking_reflexes,
            "safety": ex.safety.summary(),
            "events": ex.events + ex.safety.event_dicts(),
            "config": cfg.to_dict(), "config_hash": cfg.digest(),
            "robot_model_hash": file_digest(s.robot.mjcf_path),
            "checkpoint": str(ck) if ck is not None else None,  # the file actually loaded (default or --checkpoint)
            "checkpoint_hash": file_digest(ck) if ck is not None else None,
            "versions": run_environment(),
        }


def run_environment() -> dict:
    """What an episode ran on: the package versions and the CPU. LIBERO episodes repeat exactly on one machine, not
    across machines (docs/libero-planner.md, "What is left": the same code on a new machine), so a record names its
    machine's CPU model and whether it has AVX-512. Read once per process; each record gets its own copy."""
    return dict(_run_environment())


@functools.cache
def _run_environment() -> dict:
    from importlib import metadata

    try:
        info = dict(line.split(":", 1) for line in Path("/proc/cpuinfo").read_text().splitlines() if ":" in line)
    except OSError:  # not Linux: the names platform knows
        info = {}
    info = {k.strip(): v.strip() for k, v in info.items()}  # every CPU repeats the same lines: the last is kept
    cpu = info.get("model name") or platform.processor() or platform.machine()
    avx512 = "avx512f" in info["flags"].split() if "flags" in info else None
    out = {"tcot_hybrid": __version__, "mujoco": mujoco.__version__, "numpy": np.__version__,
           "python": platform.python_version(), "cpu": cpu, "avx512": avx512}
    try:
        out["torch"] = metadata.version("torch")  # without importing it (an oracle run never loads torch)
    except metadata.PackageNotFoundError:
        pass
    return out


def write_record(record: dict, out_dir: str | Path) -> Path:
    """Write ``out_dir/episode.json`` atomically (never cut off, never through a symlink)."""
    from tcot_hybrid.jsonio import atomic_write_text, check_output_dir

    out = check_output_dir(out_dir) if not Path(out_dir).is_dir() else Path(out_dir)
    return atomic_write_text(out / "episode.json", json.dumps(record, indent=2, default=_json_default))

