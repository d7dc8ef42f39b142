"""RELIABILITY.md, row by row: each test is named ``test_rowNN_…`` after the row it asserts.

Rows whose figure is already asserted (with its count) by a sibling test are not repeated here;
docs/reliability.md maps every row to the test node ids that assert it, the figure and the count.
Episodes here are short (oracle planner, task time limits cut where the row does not need a whole
episode) so the file stays well under a minute on two shared cores.
"""
from __future__ import annotations

import copy
import dataclasses
import importlib.util
import json
import math
import os
import subprocess
import sys
import textwrap
import time
import tomllib
import typing
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest
import yaml

from tcot_hybrid.episode import EpisodeRunner, validate_names
from tcot_hybrid.errors import CheckpointError, ConfigError, PlanningError, RobotModelError, TcotError
from tcot_hybrid.executor import ExecutorConfig
from tcot_hybrid.lift import lift_waypoints
from tcot_hybrid.perturbations import PerturbConfig
from tcot_hybrid.plan import WaypointPlan
from tcot_hybrid.planners import Planner
from tcot_hybrid.robot import load_robot_spec
from tcot_hybrid.run_config import RunConfig, from_mapping, load_config_file
from tcot_hybrid.supervision import Supervisor, SupervisorConfig

ROOT = Path(__file__).resolve().parents[1]
HAVE_LEARNED = importlib.util.find_spec("tcot_hybrid.planners.learned") is not None


# --- helpers ----------------------------------------------------------------------------------------


class ScriptedPlanner(Planner):
    """Wraps the oracle; ``on_plan(call, make_good, obs, mode)`` decides what each plan call returns or
    raises, ``on_p(obs)`` what the failure detector says. Every returned plan is kept (``returned``)."""

    name = "scripted"
    needs_image = False

    def __init__(self, inner, *, on_plan=None, on_p=None):
        self.inner, self.on_plan, self.on_p = inner, on_plan, on_p
        self.calls = 0
        self.returned: list[WaypointPlan] = []

    def plan(self, obs, *, mode):
        i = self.calls
        self.calls += 1
        if self.on_plan is None:
            plan = self.inner.plan(obs, mode=mode)
        else:
            plan = self.on_plan(i, lambda: self.inner.plan(obs, mode=mode), obs, mode)
        self.returned.append(plan)
        return plan

    def success_probability(self, obs):
        return self.inner.success_probability(obs) if self.on_p is None else self.on_p(obs)


def make_runner(*, task="goal_cube_on_plate", seed=0, time_limit_s=None, pre_step_hook=None, **cfg) -> EpisodeRunner:
    r = EpisodeRunner(RunConfig(task=task, seed=seed, **cfg), pre_step_hook=pre_step_hook)
    if time_limit_s is not None:  # shorter episode for rows that only need the first seconds
        r.stack.task.time_limit_s = time_limit_s
    return r


def use_planner(runner: EpisodeRunner, planner: Planner) -> Planner:
    runner.stack.planner = planner
    runner.supervisor.planner = planner
    return planner


def spy_torques(runner: EpisodeRunner) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every torque written to the arm actuators, with the measured q at that tick."""
    applied: list[tuple[np.ndarray, np.ndarray]] = []
    dyn = runner.stack.executor.dyn
    write = dyn.write_ctrl

    def spy(tau):
        applied.append((np.array(tau, dtype=float), np.array(dyn.q, dtype=float)))
        write(tau)

    dyn.write_ctrl = spy
    return applied


def spy_ik_targets(runner: EpisodeRunner) -> list[np.ndarray]:
    targets: list[np.ndarray] = []
    ik = runner.stack.executor.ik
    solve = ik.solve

    def spy(target, seed):
        targets.append(np.array(target.pos, dtype=float))
        return solve(target, seed)

    ik.solve = spy
    return targets


def events(rec: dict, kind: str) -> list[dict]:
    return [e for e in rec["events"] if e["kind"] == kind]


def warnings_total(runner: EpisodeRunner) -> int:
    return int(runner.stack.sim.data.warning.number.sum())


def save_test_checkpoint(path: Path, camera, *, robot: str = "panda", instruction: str) -> Path:
    """An untrained, narrow planner checkpoint for ``camera`` (the plumbing is under test, not the skill)."""
    import torch

    from tcot_hybrid.learning.checkpoint import camera_meta, save_checkpoint, versions
    from tcot_hybrid.learning.model import ModelConfig, PlannerNet
    from tcot_hybrid.learning.vocab import Vocabulary

    vocab = Vocabulary.build([instruction])
    torch.manual_seed(0)
    model = PlannerNet(ModelConfig(kind="trajectory", width=8, vocab_size=len(vocab))).eval()
    meta = {"robot": robot, "camera": camera_meta(camera), "vocabulary": list(vocab.tokens),
            "windows": {"L_g": 51, "n_g": 4, "L_l": 8, "n_l": 2}, "data_hash": "reliability-test", "metrics": {},
            "versions": versions()}
    return save_checkpoint(path, model, meta)


def learned_runner(tmp_path: Path, **cfg) -> EpisodeRunner:
    """An episode whose planner is the learned one, with a checkpoint made for this run's camera."""
    oracle_run = make_runner()
    path = save_test_checkpoint(tmp_path / "planner.safetensors", oracle_run.stack.camera,
                                instruction=oracle_run.stack.task.instruction)
    return make_runner(planner="learned", checkpoint=str(path), **cfg)


# --- row 1: bad images / a planner that cannot plan ----------------------------------------------------


def fuzzed_images(rng: np.random.Generator, n: int, px: int) -> list[tuple[str, object]]:
    """Bad planner images: NaN/inf floats, blank, wrong shape, wrong dtype, wrong channel count."""
    out = []
    for i in range(n):
        kind = i % 10
        if kind == 0:  # float image with NaN
            img = rng.random((px, px, 3)).astype(np.float32)
            img[rng.integers(px), rng.integers(px), rng.integers(3)] = np.nan
        elif kind == 1:  # float image with +-inf
            img = rng.random((px, px, 3))
            img[rng.integers(px), rng.integers(px)] = rng.choice([np.inf, -np.inf])
        elif kind == 2:  # blank (constant) uint8 image
            img = np.full((px, px, 3), rng.choice([0, 255, int(rng.integers(256))]), np.uint8)
        elif kind == 3:  # wrong size
            h, w = (int(v) for v in rng.integers(1, 3 * px, 2))
            img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        elif kind == 4:  # wrong channel count
            img = rng.integers(0, 256, (px, px, int(rng.choice([1, 2, 4, 6]))), dtype=np.uint8)
        elif kind == 5:  # wrong rank
            shape = [(px, px), (px,), (), (1, px, px, 3), (3, px, px)][int(rng.integers(5))]
            img = rng.integers(0, 256, shape, dtype=np.uint8)
        elif kind == 6:  # wrong dtype, right shape
            dt = [np.int64, np.int8, np.uint16, np.float16, np.bool_, np.complex64][int(rng.integers(6))]
            img = (rng.random((px, px, 3)) * 2).astype(dt)
        elif kind == 7:  # float values far outside any image range
            img = rng.normal(0, 1e6, (px, px, 3))
        elif kind == 8:  # empty
            img = np.zeros((0, px, 3), np.uint8) if rng.random() < 0.5 else np.zeros((px, 0, 3), np.uint8)
        else:  # not an array at all
            img = [None, "image.png", [[1, 2], [3, 4]], {"rgb": 1}, 3.5][int(rng.integers(5))]
        out.append((f"kind{kind}", img))
    return out


@pytest.mark.skipif(not HAVE_LEARNED, reason="tcot_hybrid.planners.learned (the learned planner) has not landed")
def test_row01_fuzzed_images_refused_by_the_learned_planner(tmp_path):
    """>= 1,000 fuzzed images -> PlanningError (a clear error), 0 other exceptions."""
    runner = learned_runner(tmp_path)
    planner = runner.stack.planner
    obs = runner.observe(0)
    assert planner.name == "learned" and obs.image is not None
    rng = np.random.default_rng(1)
    tried, refused, planned, crashes = 0, 0, {}, []
    for label, img in fuzzed_images(rng, 1000, runner.cfg.scene.planner_image_px):
        bad = dataclasses.replace(obs, image=img)
        for call in ("global", "local", "detect"):
            tried += 1
            try:
                if call == "detect":
                    planner.success_probability(bad)
                else:
                    planner.plan(bad, mode=call)
                planned[label] = planned.get(label, 0) + 1
            except PlanningError:
                refused += 1
            except Exception as exc:  # noqa: BLE001 - counting every other exception is the point
                crashes.append((label, call, repr(exc)[:200]))
    print(f"row 1: {tried} planner calls on 1000 fuzzed images: {refused} PlanningError, {len(crashes)} other "
          f"exceptions, accepted: {planned}")
    assert tried >= 1000 and not crashes, crashes[:5]
    assert not planned, planned  # blank images included: refused, not planned on


@pytest.mark.skipif(not HAVE_LEARNED, reason="tcot_hybrid.planners.learned (the learned planner) has not landed")
def test_row01_learned_planner_with_a_broken_camera_holds_position(tmp_path):
    """The learned planner in a running episode whose camera delivers NaN float images: every plan is
    refused, the arm holds home, 0 non-finite torques."""
    r = learned_runner(tmp_path, time_limit_s=2.0, supervisor=SupervisorConfig(mode="local", t_l=1))
    sim = r.stack.sim
    sim.render = lambda *a, **k: np.full((128, 128, 3), np.nan, np.float32)
    applied = spy_torques(r)
    rec = r.run()
    rejected = events(rec, "plan_rejected")
    qs = np.array([q for _, q in applied])
    assert len(rejected) == 20 and all("NaN" in e["reason"] for e in rejected) and rec["plans"] == 0
    assert np.isfinite(np.array([t for t, _ in applied])).all()
    assert float(np.abs(qs - r.stack.robot.home_q).max()) < 2e-3
    assert rec["safety"]["faults"] == 0 and rec["fault"] is None and rec["checkpoint_hash"]


def test_row01_planner_that_cannot_plan_keeps_the_robot_holding():
    """A planner that refuses every call (as on a broken image): plan_rejected each time, the arm holds
    home, 0 non-finite torques, no safety fault."""
    r = make_runner(time_limit_s=4.0, supervisor=SupervisorConfig(mode="local", t_l=1))

    def refuse(i, good, obs, mode):
        raise PlanningError("image has NaN pixels")

    planner = use_planner(r, ScriptedPlanner(r.stack.planner, on_plan=refuse))
    applied = spy_torques(r)
    home = r.stack.robot.home_q
    rec = r.run()
    taus = np.array([t for t, _ in applied])
    qs = np.array([q for _, q in applied])
    drift = float(np.abs(qs - home).max())
    print(f"row 1: {planner.calls} refused plans, {len(taus)} ticks, max |q - home| {drift:.2e} rad")
    assert planner.calls == 40 and len(events(rec, "plan_rejected")) == planner.calls
    assert rec["plans"] == 0 and not rec["success"] and rec["fault"] is None
    assert np.isfinite(taus).all() and len(taus) >= 400
    assert drift < 2e-3
    assert rec["safety"]["faults"] == 0 and rec["max_joint_limit_violation_rad"] == 0.0


# --- row 2: planner output NaN, p(success) outside [0, 1] ------------------------------------------------


def bad_plan_kwargs(rng: np.random.Generator, good: WaypointPlan) -> dict:
    """One malformed planner output derived from a good plan."""
    uv, depth, grip = good.uv_px.copy(), good.depth_m.copy(), good.gripper_closed.copy()
    n = len(good)
    i = int(rng.integers(n))
    kind = int(rng.integers(9))
    if kind == 0:
        uv[i, rng.integers(2)] = rng.choice([np.nan, np.inf, -np.inf])
    elif kind == 1:
        depth[i] = rng.choice([np.nan, np.inf, -np.inf])
    elif kind == 2:
        uv[:] = np.nan
    elif kind == 3:  # wrong shapes
        uv = [uv[:, :1], uv.ravel(), uv[:0], np.stack([uv, uv])][int(rng.integers(4))]
    elif kind == 4:
        depth = np.append(depth, 1.0) if rng.random() < 0.5 else depth[:, None]
    elif kind == 5:
        grip = grip[:-1] if n > 1 else np.append(grip, True)
    elif kind == 6:  # gripper bit not a bit
        grip = grip.astype(float)
        grip[i] = rng.choice([np.nan, 0.5, 2.0, -1.0])
    elif kind == 7:  # not numbers at all
        uv = [["a", "b"]] * n if rng.random() < 0.5 else np.array([[object(), 1.0]] * n, dtype=object)
    else:
        return dict(uv_px=uv, depth_m=depth, gripper_closed=grip, camera=good.camera,
                    kind=str(rng.choice(["sideways", "", "GLOBAL"])))
    return dict(uv_px=uv, depth_m=depth, gripper_closed=grip, camera=good.camera, kind=good.kind)


def test_row02_malformed_planner_outputs_all_rejected():
    """1,000 malformed outputs (NaN/inf pixels or depths, wrong shapes, non-bit gripper, non-numbers,
    bad kind): 100 % PlanningError, 0 accepted, 0 other exceptions."""
    r = make_runner()
    good = r.stack.planner.plan(r.observe(0), mode="global")
    rng = np.random.default_rng(2)
    outcome = {"rejected": 0, "accepted": 0, "other": []}
    for _ in range(1000):
        try:
            WaypointPlan(**bad_plan_kwargs(rng, good))
            outcome["accepted"] += 1
        except PlanningError:
            outcome["rejected"] += 1
        except Exception as exc:  # noqa: BLE001
            outcome["other"].append(repr(exc))
    print(f"row 2: 1000 malformed planner outputs: {outcome['rejected']} rejected, {outcome['accepted']} accepted, "
          f"{len(outcome['other'])} other exceptions")
    assert outcome["rejected"] == 1000, outcome["other"][:5]


def test_row02_bad_plans_in_an_episode_are_counted_and_replanned():
    """Every other planner call returns NaN waypoints: each is rejected (plan_rejected event), none is
    adopted, the supervisor's next period replans, and the task still succeeds on the good plans."""
    r = make_runner(supervisor=SupervisorConfig(mode="local", t_l=3))

    def alternate(i, good, obs, mode):
        plan = good()
        if i % 2 == 0:
            return WaypointPlan(uv_px=np.full_like(plan.uv_px, np.nan), depth_m=plan.depth_m,
                                gripper_closed=plan.gripper_closed, camera=plan.camera, kind=mode, step=obs.step)
        return plan

    planner = use_planner(r, ScriptedPlanner(r.stack.planner, on_plan=alternate))
    rec = r.run()
    rejected = events(rec, "plan_rejected")
    n_bad = (planner.calls + 1) // 2
    print(f"row 2: {planner.calls} planner calls, {len(rejected)} rejected, {rec['plans']} adopted, "
          f"success={rec['success']}")
    assert len(rejected) == n_bad and rec["plans"] == planner.calls - n_bad
    assert all("not finite" in e["reason"] for e in rejected)
    assert rec["success"] and rec["fault"] is None


BAD_P = [math.nan, math.inf, -math.inf, -1e-9, 1.0 + 1e-9, 2.0, -5.0, 1e300, None, "0.7", np.array([0.2, 0.9]),
         np.float32("nan")]


def test_row02_unusable_success_probability_means_not_successful():
    """1,000 unusable detector answers (NaN, inf, outside [0, 1], not a number, PlanningError): every one
    counts as 'not successful' and the supervisor replans at its period; 100 % rejected."""
    answers = [BAD_P[i % len(BAD_P)] for i in range(990)] + ["raise"] * 10

    class Fake:
        replan_every_step = False
        i = 0

        def success_probability(self, obs):
            a = answers[self.i]
            self.i += 1
            if isinstance(a, str) and a == "raise":
                raise PlanningError("detector input refused")
            return a

    class Ex:
        ik_failures = 0
        plan_finished = False

    sup = Supervisor(SupervisorConfig(mode="glsr", t_f=0, t_l=1), Fake())
    sup.decide(0, observe=lambda: None, executor=Ex())
    decisions = [sup.decide(t, observe=lambda: None, executor=Ex()) for t in range(1, len(answers) + 1)]
    rejected = [d for d in decisions if d.event and d.event.get("reason") == "detector_rejected"]
    print(f"row 2: {len(answers)} unusable p(success) answers, {len(rejected)} rejected -> local replan")
    assert len(rejected) == len(answers)
    assert all(d.plan_mode == "local" and d.event["p_success"] == 0.0 for d in decisions)


def test_row02_nan_detector_in_glsr_episode_replans_and_still_finishes():
    r = make_runner(task="goal_cube_in_bowl", supervisor=SupervisorConfig(mode="glsr", t_f=10, t_l=4))
    use_planner(r, ScriptedPlanner(r.stack.planner, on_p=lambda obs: math.nan))
    rec = r.run()
    sup = [e for e in events(rec, "supervisor") if "p_success" in e]
    replans = [e for e in sup if e.get("plan") == "local"]
    print(f"row 2: NaN detector, {len(sup)} detector calls, {len(replans)} local replans, success={rec['success']}")
    assert sup and all(e["p_success"] == 0.0 for e in sup)
    assert replans and all(e["reason"] == "detector_rejected" for e in replans)
    assert rec["success"] and rec["fault"] is None


# --- row 3: waypoint outside the image --------------------------------------------------------------


def outside(rng: np.random.Generator, uv: np.ndarray, w: int, h: int) -> np.ndarray:
    uv = uv.copy()
    i, axis = int(rng.integers(len(uv))), int(rng.integers(2))
    size = w if axis == 0 else h
    uv[i, axis] = rng.choice([-0.5 - 10 ** rng.uniform(-6, 3), size - 0.5 + 10 ** rng.uniform(-6, 3)])
    return uv


def test_row03_waypoint_outside_the_image_is_never_executed():
    """Planner calls alternate between a plan with one pixel outside the image and a good plan: every bad
    plan is rejected (LiftError -> plan_rejected), the executor keeps the last good plan object, and every
    IK target ever solved is a point of an adopted plan: 0 clipped points executed."""
    rng = np.random.default_rng(3)
    r = make_runner(supervisor=SupervisorConfig(mode="local", t_l=3))
    cam = r.stack.camera
    bad_plans: list[WaypointPlan] = []

    def alternate(i, good, obs, mode):
        plan = good()
        if i % 2 == 0:
            plan = dataclasses.replace(plan, uv_px=outside(rng, plan.uv_px, cam.width, cam.height))
            bad_plans.append(plan)
        return plan

    use_planner(r, ScriptedPlanner(r.stack.planner, on_plan=alternate))
    targets = spy_ik_targets(r)
    held_plan = []
    r.pre_step_hook = lambda runner, step: held_plan.append(runner.stack.executor.plan)
    rec = r.run()
    rejected = events(rec, "plan_rejected")
    assert len(rejected) == len(bad_plans) and all("outside" in e["reason"] for e in rejected)
    assert not any(p is b for p in r.plans for b in bad_plans)
    assert not any(p is b for p in held_plan for b in bad_plans)
    adopted = np.vstack([lift_waypoints(p.uv_px, p.depth_m, cam) for p in r.plans])
    assert all(np.any(np.all(t == adopted, axis=1)) for t in targets)
    # Step 0's plan was bad: nothing to follow, so nothing solved before the first good plan (step 3).
    assert held_plan[1] is None and held_plan[4] is r.plans[0]
    print(f"row 3: {len(bad_plans)} plans with a pixel outside the image, {len(rejected)} rejected; "
          f"{len(targets)} IK targets, all from adopted plans; success={rec['success']}")
    assert rec["success"]
    # The executor refuses them directly too, and keeps its current plan and points untouched.
    ex = r.stack.executor
    kept, points = ex.plan, ex.points.copy()
    for _ in range(500):
        bad = dataclasses.replace(kept, uv_px=outside(rng, kept.uv_px, cam.width, cam.height))
        assert ex.set_plan(bad) is False
        assert ex.plan is kept and np.array_equal(ex.points, points)


# --- row 5: unreachable waypoint -> best effort, status, supervisor replans ---------------------------------


def test_row05_unreachable_waypoint_is_best_effort_and_replanned():
    r = make_runner(supervisor=SupervisorConfig(mode="glsr", t_f=60, t_l=8, geometric_checks=True))
    cam = r.stack.camera
    far = np.array([[0.9, 0.3, 0.2]])  # in the planner image, ~0.95 m from the base: out of reach
    uv_far, d_far = cam.project(far)
    assert cam.in_image(uv_far).all()

    def first_unreachable(i, good, obs, mode):
        plan = good()
        if i == 0:
            return dataclasses.replace(plan, uv_px=uv_far, depth_m=d_far, gripper_closed=np.array([False]))
        return plan

    use_planner(r, ScriptedPlanner(r.stack.planner, on_plan=first_unreachable))
    rec = r.run()
    not_conv = events(rec, "ik_not_converged")
    replan = [e for e in events(rec, "supervisor") if e.get("reason") == "ik_not_converged"]
    print(f"row 5: {len(not_conv)} IK not converged ({not_conv[0]['status']}, {not_conv[0]['pos_err_m']} m), "
          f"replanned at step {replan[0]['step']}, success={rec['success']}, "
          f"limit violation {rec['max_joint_limit_violation_rad']} rad")
    assert not_conv and not_conv[0]["status"] == "max_iters"
    assert replan and replan[0]["plan"] == "local" and replan[0]["step"] == 1
    assert rec["max_joint_limit_violation_rad"] == 0.0 and rec["safety"]["position_violations"] == 0
    assert rec["success"]


def test_row09_retarget_ruckig_refuses_mid_episode_brakes_and_carries_on():
    """A segment Ruckig refuses while the arm is moving (measured: a GLSR replan heading past a joint
    limit) brakes the reference inside the limits and the episode goes on; it never crashes."""
    from tcot_hybrid.errors import TrajectoryError

    r = make_runner()
    sm = r.stack.executor.smoother
    real, calls = sm.set_target, {"n": 0}

    def refuse_fourth(q, *a, **k):
        calls["n"] += 1
        if calls["n"] == 4:
            raise TrajectoryError("set_target: joint 5 would reach 3.76 rad, outside [q_min, q_max]")
        return real(q, *a, **k)

    sm.set_target = refuse_fourth
    rec = r.run()
    brakes = events(rec, "reference_brake")
    assert len(brakes) == 1 and "joint 5" in brakes[0]["reason"] and brakes[0]["waypoint"] == 3
    assert rec["fault"] is None and rec["max_joint_limit_violation_rad"] == 0.0
    assert rec["success"]  # the waypoint logic moved on from rest


# --- row 14: simulation divergence --------------------------------------------------------------------


def _gripper_ctrl(value, *, unlimited=False):
    def inject(sim):
        if unlimited:
            sim.model.actuator_ctrllimited[sim.gripper_act] = 0
        sim.data.ctrl[sim.gripper_act] = value
    return inject


def _timestep(dt):
    def inject(sim):
        sim.model.opt.timestep = dt
    return inject


def _qvel(value):
    def inject(sim):
        sim.data.qvel[sim.arm_dof] = value
    return inject


def _qpos_nan(sim):
    sim.data.qpos[sim.arm_qpos[2]] = np.nan


def _object_qvel(sim):
    adr = sim.model.jnt_dofadr[sim.model.joint(sim.world.objects["cube"].joint).id]
    sim.data.qvel[adr:adr + 3] = 1e12


def _push(sim):
    sim.data.xfrc_applied[sim.model.site_bodyid[sim.ee_site], :3] = 1e12


DIVERGENCES = {
    "nan_ctrl": (_gripper_ctrl(np.nan), "mjWARN_BADCTRL"),
    "inf_ctrl_unlimited": (_gripper_ctrl(np.inf, unlimited=True), "mjWARN_BADCTRL"),
    "huge_ctrl_unlimited": (_gripper_ctrl(1e12, unlimited=True), "mjWARN_BADCTRL"),
    "timestep_5s": (_timestep(5.0), "mjWARN_BADQACC"),
    "arm_qvel_1e9": (_qvel(1e9), "mjWARN_BADQACC"),
    "arm_qvel_1e11": (_qvel(1e11), "mjWARN_BADQVEL"),
    "arm_qpos_nan": (_qpos_nan, "mjWARN_BADQPOS"),
    "object_qvel_1e12": (_object_qvel, "mjWARN_BADQVEL"),
    "huge_external_force": (_push, "mjWARN_BADQACC"),
}


def test_row14_injected_divergence_is_detected_and_never_a_success():
    """Each injected divergence fires a MuJoCo warning that the stack polls: the episode stops within the
    same planner step as a sim fault, success false, the fault is in the record. 100 % detected."""
    detected = {}
    for name, (inject, warning) in DIVERGENCES.items():
        at = 20  # cube grasped and lifted by now
        hook = lambda runner, step, inject=inject, at=at: inject(runner.stack.sim) if step == at else None  # noqa: E731
        r = make_runner(pre_step_hook=hook)
        rec = r.run()
        faults = events(rec, "sim_fault")
        assert rec["success"] is False and rec["fault"] == f"sim_fault:{warning}", (name, rec["fault"])
        assert len(faults) == 1 and faults[0]["warning"] == warning, name
        assert rec["steps"] == at + 1, (name, rec["steps"])  # aborted in the injected step
        detected[name] = warning
    print(f"row 14: {len(detected)}/{len(DIVERGENCES)} injected divergences detected: {detected}")


def test_row14_divergence_on_the_step_that_would_succeed_is_not_a_success():
    ref = make_runner().run()
    assert ref["success"]
    last = ref["steps"] - 1  # the planner step after which the task is judged successful
    hook = lambda runner, step: _qvel(1e11)(runner.stack.sim) if step == last else None  # noqa: E731
    rec = make_runner(pre_step_hook=hook).run()
    assert rec["success"] is False and rec["fault"].startswith("sim_fault:") and rec["steps"] == ref["steps"]


def test_row14_deep_penetration_is_never_a_success():
    """A cube teleported into the table. MuJoCo's soft contacts push it out without a warning (no
    divergence); pushed out below the table it falls, which the simulation reports as an
    OBJECT_BELOW_TABLE fault. Either way: state finite, never a success, and a fault is reported only
    with a warning or a fallen object behind it."""
    outcomes = {}
    for depth in (0.02, 0.04, 0.1):
        def hook(runner, step, depth=depth):
            if step == 20:  # while the cube is held: under the fingers now
                w = runner.stack.sim.world
                p = w.pos("cube")
                w.set_pose("cube", (p[0], p[1], -depth), 0.0)

        r = make_runner(pre_step_hook=hook, time_limit_s=8.0)
        rec = r.run()
        d = r.stack.sim.data
        assert np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()
        assert not rec["success"]
        fell = float(r.stack.sim.world.pos("cube")[2]) < -0.05
        assert (rec["fault"] is None) == (warnings_total(r) == 0 and not fell)
        if fell:
            assert "OBJECT_BELOW_TABLE" in rec["fault"]
        outcomes[depth] = (rec["fault"], round(float(r.stack.sim.world.pos("cube")[2]), 2))
    print(f"row 14: cube teleported into the table (depth: (fault, final cube z [m])): {outcomes}")


# Every task once, robots alternating, the four controllers in turn: the nominal batch that must raise
# no MuJoCo warning (the perturbed and replayed episodes below are checked for warnings too).
NOMINAL = [(t, ("panda", "ur5e")[i % 2], ("computed_torque", "osc", "joint_pd", "mpc")[i % 4]) for i, t in enumerate([
    "spatial_left_cube_on_plate", "spatial_near_cube_in_bowl", "object_blue_cube_in_basket",
    "object_green_cylinder_in_basket", "object_red_cube_in_basket", "goal_cube_in_bowl", "goal_cube_on_plate",
    "goal_open_drawer", "long_both_cubes_in_bowl", "long_open_drawer_put_cube", "long_stack_three_blocks",
    "tool_pull_cube_with_stick"])]


def test_row14_no_warnings_in_nominal_episodes():
    """12 nominal episodes (every task, both robots, all four controllers): 0 MuJoCo warnings of any kind,
    0 faults. The >= 1,000-episode figure comes from `tcot eval` (faults per cell in
    docs/eval-foundation/*/eval.json, see docs/reliability.md)."""
    ok = 0
    for seed, (task, robot, ctrl) in enumerate(NOMINAL):
        r = make_runner(task=task, seed=seed, robot=robot, controller=ctrl)
        rec = r.run()
        assert warnings_total(r) == 0, (task, robot, ctrl, r.stack.sim.data.warning.number[:])
        assert rec["fault"] is None and rec["safety"]["faults"] == 0, (task, robot, ctrl)
        ok += rec["success"]
    print(f"row 14: {len(NOMINAL)} nominal episodes, 0 warnings, 0 faults, {ok} successes")


# --- rows 15-17: slip/drop, push, camera noise ------------------------------------------------------------


def assert_sound(r: EpisodeRunner, rec: dict) -> None:
    """No divergence, no safety fault, no joint-limit violation."""
    assert warnings_total(r) == 0 and rec["fault"] is None and rec["safety"]["faults"] == 0
    assert rec["max_joint_limit_violation_rad"] == 0.0


PERTURBED = [("arm_push", 40.0), ("arm_push", 120.0), ("camera_noise", 40.0)]


@pytest.mark.parametrize("name,strength", PERTURBED)
def test_rows16_17_push_and_camera_noise_never_diverge_or_break_limits(name, strength):
    """Rows 16/17 (object_drop, row 15, below): the perturbation fires, the episode never diverges, never
    faults and never leaves the joint limits, with a frozen global plan or with GLSR."""
    for mode in ("global", "glsr"):
        r = make_runner(task="goal_cube_in_bowl", perturb=PerturbConfig(name=name, strength=strength),
                        supervisor=SupervisorConfig(mode=mode, t_f=20),
                        planner="learned" if name == "camera_noise" else "oracle")  # the oracle sees no image
        rec = r.run()
        assert events(rec, "perturbation"), (name, mode)
        assert_sound(r, rec)
        print(f"rows 16-17: {name}({strength}) {mode}: success={rec['success']}, "
              f"max |qd|/v_max {rec['max_velocity_ratio']:.2f}, saturated ticks {rec['safety']['saturations']}")


def _held_back(force_n: float, *, reflex_rad: float | None) -> dict:
    """goal_cube_on_plate with the hand held back by an upward force for 1.5 s (planner steps 10-24), like
    an arm caught on an obstacle; the speed figure counts only from 0.1 s after the force ends."""
    def hook(r, step):
        sim = r.stack.sim
        sim.data.xfrc_applied[sim.model.site_bodyid[sim.ee_site], :3] = (0, 0, force_n) if 10 <= step < 25 else 0.0
        if step == 26:
            r.stack.executor.max_velocity_ratio = 0.0
    r = make_runner(task="goal_cube_on_plate", time_limit_s=5.0, pre_step_hook=hook,
                    executor=ExecutorConfig(reflex_tracking_rad=reflex_rad))
    return r.run()


def test_row16_held_back_arm_triggers_the_tracking_reflex_and_does_not_whip_when_freed():
    """Without the reflex the controller winds up against the obstacle and whips the arm past v_max when it
    comes free; with it the plan is dropped, the reference brakes where the arm is, and nothing whips."""
    off = _held_back(150.0, reflex_rad=None)
    on = _held_back(150.0, reflex_rad=0.25)
    assert off["tracking_reflexes"] == 0 and off["max_velocity_ratio"] > 1.0  # the failure the reflex prevents
    assert on["tracking_reflexes"] >= 1 and events(on, "tracking_reflex")[0]["error_rad"] > 0.25
    assert on["max_velocity_ratio"] < 1.0 and on["max_tracking_error_rad"] < 0.3 < off["max_tracking_error_rad"]
    assert on["fault"] is None and not on["success"]  # the plan was dropped: a held arm, never a false success
    print(f"row 16 (held back, 150 N): after release max |qd|/v_max {off['max_velocity_ratio']:.2f} without the "
          f"reflex, {on['max_velocity_ratio']:.2f} with it ({on['tracking_reflexes']} reflexes)")


def test_row20_tracking_reflex_setting_is_checked(tmp_path):
    for bad in (-0.1, 0.0, float("nan"), True):
        with pytest.raises(ConfigError, match="reflex_tracking_rad"):
            ExecutorConfig(reflex_tracking_rad=bad)
    f = tmp_path / "off.yaml"
    f.write_text("executor:\n  reflex_tracking_rad: null\n")
    assert load_config_file(f).executor.reflex_tracking_rad is None  # null switches the reflex off


def test_row15_glsr_recovers_a_dropped_object():
    """object_drop defeats the frozen global plan; GLSR (oracle detector) replans within t_l and re-grasps.
    No divergence, fault or limit violation either way."""
    t_l = 8
    for seed in (0, 1):
        recs = {}
        for mode in ("global", "glsr"):
            r = make_runner(task="goal_cube_on_plate", seed=seed, perturb=PerturbConfig(name="object_drop"),
                            supervisor=SupervisorConfig(mode=mode, t_f=20, t_l=t_l))
            recs[mode] = r.run()
            assert_sound(r, recs[mode])
        assert not recs["global"]["success"] and recs["glsr"]["success"], seed
        drop = events(recs["glsr"], "perturbation")[0]["step"]
        after = [e["step"] for e in events(recs["glsr"], "supervisor") if e.get("plan") == "local" and e["step"] > drop]
        latency = after[0] - drop
        grasps = [e for e in events(recs["glsr"], "gripper") if e["closed"]]
        print(f"row 15 seed {seed}: dropped at step {drop}, first local replan {latency} steps later, "
              f"{len(grasps)} grasps, success at {recs['glsr']['success_time_s']:.1f} s")
        assert 0 < latency <= t_l and len(grasps) >= 2


# --- row 18: planner latency spike ------------------------------------------------------------------------


def test_row18_stale_plan_is_dropped_and_the_last_valid_plan_kept():
    budget, spike = 0.3, 0.6  # [s]; the oracle plans in ~ms, so only the spiked call can be late
    r = make_runner(supervisor=SupervisorConfig(mode="local", t_l=4, max_plan_latency_s=budget))

    def slow_third(i, good, obs, mode):
        plan = good()
        if i == 2:
            time.sleep(spike)
        return plan

    planner = use_planner(r, ScriptedPlanner(r.stack.planner, on_plan=slow_third))
    following = {}
    r.pre_step_hook = lambda runner, step: following.__setitem__(step, runner.stack.executor.plan)
    rec = r.run()
    stale = events(rec, "plan_stale")
    stale_plan = planner.returned[2]
    assert len(stale) == 1 and stale[0]["step"] == 8 and stale[0]["latency_s"] > budget
    assert not any(p is stale_plan for p in r.plans)
    assert not any(p is stale_plan for p in following.values())
    # The plan adopted at step 4 is still followed through steps 9-12, until the next good plan at 12.
    assert all(following[s] is planner.returned[1] for s in range(5, 13))
    assert following[13] is planner.returned[3]
    adopted = [e["step"] for e in events(rec, "plan_adopted")]
    assert 8 not in adopted and {0, 4, 12} <= set(adopted)
    print(f"row 18: plan at step 8 took {stale[0]['latency_s']} s > {budget} s: dropped; 0 stale commands; "
          f"success={rec['success']}")
    assert rec["success"]


def test_row18_stale_first_plan_leaves_the_robot_holding():
    r = make_runner(time_limit_s=1.0, supervisor=SupervisorConfig(mode="global", max_plan_latency_s=0.05))

    def slow(i, good, obs, mode):
        time.sleep(0.15)
        return good()

    use_planner(r, ScriptedPlanner(r.stack.planner, on_plan=slow))
    applied = spy_torques(r)
    rec = r.run()
    assert len(events(rec, "plan_stale")) == 1 and rec["plans"] == 0
    assert float(np.abs(np.array([q for _, q in applied]) - r.stack.robot.home_q).max()) < 2e-3


# --- row 20: malformed configs -------------------------------------------------------------------------


def _schema(cls, prefix=()) -> list[tuple[tuple[str, ...], object]]:
    """(path, type) of every field of the RunConfig tree; sections have the dataclass as type."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        tp, path = hints[f.name], prefix + (f.name,)
        out.append((path, tp))
        if dataclasses.is_dataclass(tp):
            out += _schema(tp, path)
    return out


SCHEMA = _schema(RunConfig)
SECTIONS = [p for p, tp in SCHEMA if dataclasses.is_dataclass(tp)]
LEAVES = [p for p, tp in SCHEMA if not dataclasses.is_dataclass(tp)]
NAME_FIELDS = [("task",), ("robot",), ("controller",), ("ik",), ("planner",), ("perturb", "name"),
               ("supervisor", "mode"), ("scene", "planner_camera"), ("ik_params", "solver"),
               ("ik_params", "posture_target"), ("checkpoint",)]
DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
HUGE_INT = 10 ** 400  # overflows a float
BAD_VALUES = [math.nan, math.inf, -math.inf, -1.0, 0.0, -1, 0, 1, 2.5, 1e308, HUGE_INT, "0.01", "abc", "", True,
              False, None, [0.01], [], {"v": 1}, {}]
GOOD_VALUES = {float: [0.004, 2, 0.5], int: [1, 3, 10], bool: [True, False], str: ["panda"]}
BAD_NAMES = ["", "no_such_name", "PANDA", " panda", "oracle ", "../robots/panda", "nope.safetensors", 5, None,
             ["panda"]]
BAD_PARAMS = [{"kp_scale": "x"}, {"bogus": 1.0}, {"kp_scale": math.nan}, {"kp_scale": -1.0}, {"kp_scale": 2.0},
              {"horizon": 12.0}, {"time_limit_fraction": None}, {1: 2.0}, [1, 2], "abc"]
UNKNOWN_KEYS = ["bogus", "sed", "ctrl-dt", "Timing", "__class__", "0"]
TAGS = ["!!python/object/apply:os.system ['touch {marker}']", "!!python/name:os.system",
        "!!python/object/new:tcot_hybrid.run_config.RunConfig {{}}", "!custom 3", "!!binary aGVsbG8=",
        "!!set {{a, b}}", "!!timestamp 2001-12-14", "!!float .nan", "!!str 0.01", "!!int 1", "!!null ''",
        "7" * 5000]  # the last: an integer literal beyond Python's int/str conversion limit



def _pick(rng, seq):
    return seq[int(rng.integers(len(seq)))]


def random_mutation(rng: np.random.Generator) -> tuple:
    kind = _pick(rng, ["delete", "unknown_key", "value", "good_value", "name", "params", "section", "tag"])
    if kind == "delete":
        return kind, _pick(rng, SECTIONS + LEAVES)
    if kind == "unknown_key":
        return kind, _pick(rng, [()] + SECTIONS), _pick(rng, UNKNOWN_KEYS)
    if kind == "value":
        return kind, _pick(rng, LEAVES), _pick(rng, BAD_VALUES)
    if kind == "good_value":
        return kind, _pick(rng, LEAVES), int(rng.integers(3))
    if kind == "name":
        return kind, _pick(rng, NAME_FIELDS), _pick(rng, BAD_NAMES)
    if kind == "params":
        return kind, ("controller_params",), _pick(rng, BAD_PARAMS)
    if kind == "section":
        return kind, _pick(rng, SECTIONS), _pick(rng, [5, "x", [], None, [1, 2], True])
    return kind, _pick(rng, LEAVES + SECTIONS), _pick(rng, TAGS)


BASE_NAMES = {"task": ["goal_cube_on_plate", "long_stack_three_blocks", "goal_open_drawer"],
              "robot": ["panda", "ur5e"], "controller": ["computed_torque", "joint_pd", "osc", "mpc"],
              "ik": ["mink", "pinocchio"]}


def _type_of(path):
    tp = dict(SCHEMA)[path]
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    return args[0] if args else tp


def _mutate(d: dict, m: tuple, placeholders: dict) -> set[str]:
    """Apply one mutation in place; return the words an error about it may name (empty: not applied)."""
    kind, path = m[0], m[1]
    parent = d
    for key in path[:-1]:
        if not isinstance(parent, dict) or not isinstance(parent.get(key), dict):
            return set()
        parent = parent[key]
    if kind == "unknown_key":
        target = parent.get(path[-1]) if path else d
        if not isinstance(target, dict):
            return set()
        target[m[2]] = 1
        return {repr(m[2])}
    if not isinstance(parent, dict) or (kind != "name" and path[-1] not in parent):
        return set()
    names = {path[-1], ".".join(path)} | ({path[-2]} if len(path) > 1 else set())
    if kind == "delete":
        del parent[path[-1]]
    elif kind == "good_value":
        pool = GOOD_VALUES.get(_type_of(path))
        if not pool:
            return set()
        parent[path[-1]] = pool[m[2] % len(pool)]
    elif kind == "params":
        parent[path[-1]] = m[2]
        names |= {str(k) for k in m[2]} if isinstance(m[2], dict) else set()
    elif kind == "tag":
        token = f"__TAG{len(placeholders)}__"
        placeholders[token] = m[2]
        parent[path[-1]] = token
        # A literal beyond Python's int parsing limit fails in the parser, before any field is known:
        # the message names the file and "value has 5000 digits".
        names |= {m[2].split()[0]} if len(m[2]) < 100 else {f"{len(m[2])} digits"}
    else:  # value, name, section
        parent[path[-1]] = m[2]
    return names


def _typed(obj, cls) -> None:
    """An accepted config is fully typed and finite: nothing unvalidated reaches a run."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        v, tp = getattr(obj, f.name), hints[f.name]
        if dataclasses.is_dataclass(tp):
            assert type(v) is tp, (f.name, v)
            _typed(v, tp)
            continue
        allowed = tuple(a for a in (typing.get_args(tp) or (tp,)) if a is not typing.Any)
        if typing.get_origin(tp) is dict:
            assert isinstance(v, dict) and all(isinstance(k, str) for k in v), (f.name, v)
            continue
        choices = [c for a in allowed if typing.get_origin(a) is typing.Literal for c in typing.get_args(a)]
        types = tuple(typing.get_origin(a) or a for a in allowed if typing.get_origin(a) is not typing.Literal)
        assert (v in choices and not isinstance(v, bool)) or isinstance(v, types), (f.name, v, tp)
        if isinstance(v, float):
            assert math.isfinite(v), (f.name, v)


def test_row20_mutated_configs_are_valid_or_refused_naming_the_field(tmp_path):
    """>= 1,000 mutated configs (deleted/unknown keys, wrong types, NaN/inf/overflowing numbers, unknown
    names, bad controller parameters, YAML tags incl. python/object) loaded from a mapping, YAML or JSON,
    then checked like a run is before its first step (names, controller parameters): each is either
    valid (fully typed and finite) or a TcotError whose message names the mutated field. 0 other
    exceptions, 0 code executed by a tag, and accepted configs build their stack without error."""
    from tcot_hybrid.controllers import make_controller

    marker = tmp_path / "pwned"
    specs: dict[str, object] = {}
    tally = {"tried": 0, "valid": 0, "refused": 0, "built": 0}
    crashes, unnamed, built = [], [], set()

    def check(cfg: RunConfig) -> None:
        validate_names(cfg)
        spec = specs.get(cfg.robot) or specs.setdefault(cfg.robot, load_robot_spec(cfg.robot))
        make_controller(cfg.controller, spec, ctrl_dt=cfg.timing.ctrl_dt, params=cfg.controller_params)

    rng = np.random.default_rng(20)
    for _ in range(1000):
        d = copy.deepcopy(RunConfig().to_dict())
        d.update({k: _pick(rng, v) for k, v in BASE_NAMES.items()})
        mutations = [random_mutation(rng) for _ in range(int(rng.integers(1, 4)))]
        fmt = _pick(rng, ["map", "map", "map", "yaml", "json"])
        placeholders: dict[str, str] = {}
        names: set[str] = set()
        for m in mutations:
            names |= _mutate(d, m, placeholders)
        if placeholders:
            fmt = "yaml"
        tally["tried"] += 1
        try:
            if fmt == "map":
                cfg = from_mapping(RunConfig, d)
            else:
                path = tmp_path / f"run.{fmt}"
                text = yaml.dump(d, Dumper=DUMPER, sort_keys=False) if fmt == "yaml" else json.dumps(d)
                for token, tag in placeholders.items():
                    text = text.replace(token, tag.format(marker=marker))
                path.write_text(text)
                cfg = load_config_file(path)
            check(cfg)
        except TcotError as exc:
            tally["refused"] += 1
            if names and not any(n in str(exc) for n in names):
                unnamed.append((mutations, str(exc)[:300]))
            continue
        except Exception as exc:  # noqa: BLE001 - counting every other exception is the point
            crashes.append((mutations, fmt, f"{type(exc).__name__}: {exc}"[:300]))
            continue
        tally["valid"] += 1
        _typed(cfg, RunConfig)
        if cfg.digest() not in built and len(built) < 10:  # a sample is built for real: no late surprises
            built.add(cfg.digest())
            try:
                EpisodeRunner(cfg)
                tally["built"] += 1
            except TcotError as exc:
                unnamed.append((mutations, f"accepted but refused at build: {exc}"[:300]))
    print(f"row 20: {tally['tried']} mutated configs: {tally['valid']} valid ({tally['built']} built), "
          f"{tally['refused']} refused with a TcotError, {len(crashes)} other exceptions, "
          f"{len(unnamed)} errors not naming the field")
    for c in {c[2][:50]: c for c in crashes}.values():
        print("other exception:", c)
    for u in {u[1][:50]: u for u in unnamed}.values():
        print("not naming the field:", u)
    assert tally["tried"] >= 1000
    assert not crashes, crashes[:5]
    assert not unnamed, unnamed[:5]
    assert not marker.exists(), "a YAML tag executed code"
    # Regression: a checkpoint path that is not a file used to run the whole episode and then crash while
    # hashing it for the record (no record written); now it is refused up front.
    with pytest.raises(ConfigError, match="checkpoint"):
        validate_names(RunConfig(checkpoint=str(tmp_path / "missing.safetensors")))


# --- row 21: wrong robot model (or checkpoint for another robot/camera) ----------------------------------------


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else "inf" if v == math.inf else "-inf" if v == -math.inf else repr(v)
    if isinstance(v, int):
        return str(v)
    return "[" + ", ".join(_toml(x) for x in v) + "]"


def write_robot(path: Path, raw: dict) -> Path:
    lines = [f"{k} = {_toml(v)}" for k, v in raw.items() if not isinstance(v, dict)]
    for k, v in raw.items():
        if isinstance(v, dict):
            lines += [f"[{k}]"] + [f"{kk} = {_toml(vv)}" for kk, vv in v.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def _panda_raw() -> dict:
    raw = tomllib.loads((ROOT / "robots" / "panda" / "robot.toml").read_text())
    raw["mjcf"] = str(ROOT / "robots" / "panda" / "panda.xml")
    return raw


WRONG_MODELS = {
    "joint name not in the model": lambda r: r["arm_joints"].__setitem__(3, "elbow"),
    "6 joints for a 7-joint arm": lambda r: (r["arm_joints"].pop(), r["arm_actuators"].pop()),
    "joint count differs from actuators": lambda r: r["arm_actuators"].pop(),
    "joints in the wrong order": lambda r: r["arm_joints"].reverse(),
    "missing TCP frame": lambda r: r.pop("ee_site"),
    "TCP frame not in the model": lambda r: r.update(ee_site="flange"),
    "missing limits table": lambda r: r.pop("limits"),
    "missing q_max": lambda r: r["limits"].pop("q_max"),
    "NaN velocity limit": lambda r: r["limits"]["v_max"].__setitem__(2, math.nan),
    "6 torque limits for 7 joints": lambda r: r["limits"]["tau_max"].pop(),
    "limits beyond the model's joint range": lambda r: r["limits"]["q_max"].__setitem__(0, 3.5),
    "another robot's MJCF": lambda r: r.update(mjcf=str(ROOT / "robots" / "ur5e" / "ur5e.xml")),
    "gripper actuator missing": lambda r: r.update(gripper_actuator="hand"),
    "home outside the limits": lambda r: r["home_q"].__setitem__(3, 0.5),
}


def test_row21_wrong_robot_model_is_refused_before_stepping(tmp_path, monkeypatch):
    """Each wrong robot description given as the run's robot: RobotModelError naming the problem, raised
    before the simulation is even built (so nothing steps). 100 % rejected."""
    import tcot_hybrid.episode as episode

    built = []
    real = episode.Simulation
    monkeypatch.setattr(episode, "Simulation", lambda *a, **k: built.append(1) or real(*a, **k))
    rejected = {}
    for i, (what, mutate) in enumerate(WRONG_MODELS.items()):
        raw = _panda_raw()
        mutate(raw)
        path = write_robot(tmp_path / f"robot_{i}.toml", raw)
        with pytest.raises(RobotModelError) as exc:
            EpisodeRunner(RunConfig(task="goal_cube_on_plate", robot=str(path)))
        rejected[what] = str(exc.value).splitlines()[0][:110]
    assert not built, "a simulation was built for a wrong robot model"
    for what, msg in rejected.items():
        print(f"row 21: {what}: {msg}")
    print(f"row 21: {len(rejected)}/{len(WRONG_MODELS)} wrong robot models refused before stepping")
    assert len(rejected) == len(WRONG_MODELS)
    # The intact copy loads and runs: the refusals above are about the mutations, not the copy.
    EpisodeRunner(RunConfig(task="goal_cube_on_plate", robot=str(write_robot(tmp_path / "ok.toml", _panda_raw()))))
    assert built


@pytest.mark.skipif(not HAVE_LEARNED, reason="tcot_hybrid.planners.learned (the learned planner) has not landed")
def test_row21_checkpoint_for_another_robot_or_camera_is_refused_before_stepping(tmp_path, monkeypatch):
    """A checkpoint made for the panda and the agentview camera at 128 px, run with another robot, planner
    camera or image size: CheckpointError while the stack is built, 0 simulation steps."""
    import tcot_hybrid.sim as sim_module

    ref = make_runner()
    path = save_test_checkpoint(tmp_path / "panda.safetensors", ref.stack.camera,
                                instruction=ref.stack.task.instruction)
    steps = []
    real = sim_module.Simulation.step1
    monkeypatch.setattr(sim_module.Simulation, "step1", lambda self: steps.append(1) or real(self))
    from tcot_hybrid.scene import SceneConfig

    mismatches = {"robot": dict(robot="ur5e"), "camera": dict(scene=SceneConfig(planner_camera="sideview")),
                  "image size": dict(scene=SceneConfig(planner_image_px=96))}
    for what, kw in mismatches.items():
        with pytest.raises(CheckpointError) as exc:
            EpisodeRunner(RunConfig(task="goal_cube_on_plate", planner="learned", checkpoint=str(path), **kw))
        print(f"row 21: checkpoint for another {what}: {str(exc.value)[:160]}")
    assert not steps
    EpisodeRunner(RunConfig(task="goal_cube_on_plate", planner="learned", checkpoint=str(path)))  # matching: loads


# --- row 22: reproducibility and records ------------------------------------------------------------------


def trace(cfg: RunConfig) -> tuple[np.ndarray, dict]:
    """qpos, qvel and ctrl after every control tick of a whole episode, and the record."""
    r = EpisodeRunner(cfg)
    d, ex = r.stack.sim.data, r.stack.executor
    rows = []
    tick = ex.tick

    def logged():
        tick()
        rows.append(np.concatenate([d.qpos, d.qvel, d.ctrl, [d.time]]))

    ex.tick = logged
    rec = r.run()
    return np.array(rows), rec


REPLAYS = {
    "computed_torque, global": RunConfig(task="goal_cube_in_bowl", seed=5),
    "mpc (no wall-clock deadline), glsr + object_drop": RunConfig(
        task="goal_cube_in_bowl", seed=5, controller="mpc", controller_params={"time_limit_fraction": None},
        supervisor=SupervisorConfig(mode="glsr", t_f=20), perturb=PerturbConfig(name="object_drop")),
    "osc on ur5e, local + arm_push": RunConfig(
        task="goal_cube_on_plate", seed=6, robot="ur5e", controller="osc",
        supervisor=SupervisorConfig(mode="local"), perturb=PerturbConfig(name="arm_push", strength=80.0)),
}


@pytest.mark.parametrize("label", list(REPLAYS))
def test_row22_same_seed_same_config_replays_bit_identically(label):
    cfg = REPLAYS[label]
    a, rec_a = trace(cfg)
    b, rec_b = trace(cfg)
    assert a.shape == b.shape and np.array_equal(a, b), f"{label}: replay differs"
    strip = lambda rec: {k: v for k, v in rec.items() if k != "wall_time_s"}  # noqa: E731
    assert strip(rec_a) == strip(rec_b)
    assert rec_a["fault"] is None and rec_a["safety"]["faults"] == 0
    other, _ = trace(dataclasses.replace(cfg, seed=cfg.seed + 1))
    assert other.shape != a.shape or not np.array_equal(other, a), "the seed must matter"
    print(f"row 22: {label}: {len(a)} ticks x {a.shape[1]} values bit-identical over 2 runs; "
          f"success={rec_a['success']}")


ABORT_SCRIPT = textwrap.dedent("""
    import json, os, signal, sys
    os.environ.setdefault("MUJOCO_GL", "egl")
    from tcot_hybrid import cli
    from tcot_hybrid.planners import register_planner
    from tcot_hybrid.planners.oracle import OraclePlanner

    MODE = None
    # a shell that starts the tests in the background ignores SIGINT; Ctrl-C's handler is what is tested here
    signal.signal(signal.SIGINT, signal.default_int_handler)

    class Failing(OraclePlanner):
        name = "failing"

        def plan(self, obs, *, mode):
            self.calls = getattr(self, "calls", 0) + 1
            if self.calls == 3:  # mid-episode: two plans followed already
                if MODE == "sigint":
                    # to this thread (os.kill may reach another thread first and the RuntimeError win the race
                    # on a loaded machine): KeyboardInterrupt, as from Ctrl-C
                    signal.raise_signal(signal.SIGINT)
                raise RuntimeError("planner bug")
            return super().plan(obs, mode=mode)

    @register_planner("failing", privileged=True)  # an oracle subclass: reads the world
    def _failing(ctx):
        if MODE == "build":
            raise RuntimeError("planner could not be constructed")
        return Failing(ctx.task, ctx.world, ctx.camera)

    outcome = {}
    for MODE in ("exception", "sigint", "build"):
        args = ["run", "--task", "goal_cube_on_plate", "--seed", "4", "--planner", "failing",
                "--supervisor.mode", "local", "--supervisor.t-l", "4", "--out", os.path.join(sys.argv[1], MODE)]
        try:
            outcome[MODE] = f"returned {cli.main(args)}"
        except BaseException as exc:  # what would end the process
            outcome[MODE] = f"raised {type(exc).__name__}"
    print(json.dumps(outcome))
""")


def test_row22_aborted_run_still_writes_its_record(tmp_path):
    """`tcot run` (cli.main, in a subprocess) made to fail mid-episode by an unexpected exception in the
    planner or by Ctrl-C, or while building the stack: the run ends with the exception, and episode.json
    exists with success false, the fault, the config and robot-model hashes, the seed and the events."""
    script = tmp_path / "abort.py"
    script.write_text(ABORT_SCRIPT)
    r = subprocess.run([sys.executable, str(script), str(tmp_path)], capture_output=True, text=True, timeout=300,
                       env={**os.environ, "MUJOCO_GL": "egl"}, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    outcome = json.loads(r.stdout.strip().splitlines()[-1])
    assert outcome == {"exception": "raised RuntimeError", "sigint": "raised KeyboardInterrupt",
                       "build": "raised RuntimeError"}
    want_hash = RunConfig(task="goal_cube_on_plate", seed=4, planner="failing",
                          supervisor=SupervisorConfig(mode="local", t_l=4)).digest()
    for how in outcome:
        rec = json.loads((tmp_path / how / "episode.json").read_text())
        assert rec["success"] is False and rec["fault"]
        assert rec["seed"] == 4 and rec["task"] == "goal_cube_on_plate" and rec["planner"] == "failing"
        assert rec["config_hash"] == want_hash and rec["config"]["seed"] == 4
        assert rec["robot_model_hash"] and "events" in rec and rec["versions"]["cpu"]
        if how != "build":
            adopted = [e for e in rec["events"] if e["kind"] == "plan_adopted"]
            assert len(adopted) == 2 and rec["steps"] >= 8  # it really was mid-episode
        print(f"row 22: aborted ({how}): record written, fault={rec['fault']!r}, {len(rec['events'])} events")
