"""Why executed learned plans fail on LIBERO (docs/libero-planner.md, "Failure analysis"), on development layouts:

    .venv/bin/python docs/libero-planner/failures.py --seeds 20000-20001 --plans-only      # every task: t = 0 plans
    .venv/bin/python docs/libero-planner/failures.py --seeds 20000 --tasks-per-suite 3 --modes global,glsr
    .venv/bin/python docs/libero-planner/failures.py --summarize   # -> failures.json + docs/libero-planner.md

Sampled layouts on development seeds (docs/seeds.md: 0-49999 is training and tuning; the demonstrations use
seeds 0-49 per task, so 20000+ is a layout no checkpoint has seen; never the shipped init states, never 90000+).

Per layout, at step 0 (after the scene settled), the learned planner's global plan is compared with the oracle's
plan on the same scene (privileged: its script's keyframes): gripper switches in order (grasps and releases), the
position of each (lateral and height error [cm]) and the hand's orientation there (up to the parallel-jaw symmetry),
and the height the planner camera's rendered depth gives at the learned switch's pixel (what an RGB-D camera
would measure there: "camera geometry"). With ``--modes`` the episode is also executed (learned planner, the given
supervisor modes) and, when it fails, classified by the first oracle step that is not done at the end:

* ``plan refused``: the first plan was refused (floor, output checks) and nothing ran;
* ``grasp: lateral`` / ``grasp: height`` / ``grasp: orientation``: the object of that step was never held, and the
  t = 0 plan's matching grasp was off by more than ``LATERAL_TOL_M`` sideways / ``HEIGHT_TOL_M`` in height /
  ``ROT_TOL_DEG`` in orientation (checked in that order);
* ``grasp: missing``: the t = 0 plan has fewer grasps than the oracle's script up to that step;
* ``grasp: execution``: never held although the t = 0 plan's grasp was within all three tolerances;
* ``place/release``: the object was held at some time but the step is not done (dropped, or put down off target);
* ``articulation``: a drawer/door/knob step not done;
* ``other``: every oracle step done, the goal still false (or no step to blame).

GLSR episodes also record the detector's false positives (a "judged successful" call while the task was not done)
and whether the episode ended waiting on one. One worker, niced by the caller; resumable (``--out`` keeps finished
episodes). Every record carries the hash of the checkpoint it ran with; a new checkpoint runs every layout again, and
``--summarize`` shows the shipped checkpoint's records only (earlier ones stay in the file).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
LATERAL_TOL_M = 0.02  # [m] a grasp this far off sideways misses (DESIGN.md: a grasp tolerates about 1 cm)
HEIGHT_TOL_M = 0.015  # [m]
ROT_TOL_DEG = 20.0  # [deg]
DEV_RANGE = (10000, 49999)  # development seeds this script accepts (docs/seeds.md; demos use 0-49 per task)
SECTION = "libero-failures"


def parse_seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        try:
            a, b = int(lo), int(hi or lo)
        except ValueError:
            raise SystemExit(f"--seeds {text!r}: expected numbers or ranges like 20000-20004") from None
        out += list(range(a, b + 1))
    bad = [s for s in out if not DEV_RANGE[0] <= s <= DEV_RANGE[1]]
    if bad:
        raise SystemExit(f"--seeds {bad[:3]}: not development seeds; this analysis takes seeds in "
                         f"{DEV_RANGE[0]}-{DEV_RANGE[1]} (docs/seeds.md)")
    return out


def pick_tasks(per_suite: int | None, suites: tuple[str, ...] = SUITES) -> list[str]:
    from tcot_hybrid.libero.tasks import list_libero_tasks

    bad = [s for s in suites if s not in SUITES]
    if bad:
        raise SystemExit(f"--suites {bad[0]!r}: choose from {', '.join(SUITES)}")
    by = defaultdict(list)
    for info in list_libero_tasks():
        if info.suite in suites:
            by[info.suite].append(info.name)
    out = []
    for s in suites:
        names = by[s]
        if per_suite is None or per_suite >= len(names):
            out += names
        else:  # spread over the suite: tasks 0, k, 2k, ... (fixed before any run)
            step = len(names) // per_suite
            out += [names[i * step] for i in range(per_suite)]
    return out


def switches(closed: np.ndarray) -> list[tuple[int, bool]]:
    """(index, new state) of every gripper switch along a plan's bits."""
    c = np.asarray(closed, bool)
    return [(int(i), bool(c[i])) for i in np.flatnonzero(c[1:] != c[:-1]) + 1]


def rot_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle between two hand orientations, up to the parallel-jaw symmetry (180 degrees about the approach)."""
    flip = np.diag([-1.0, -1.0, 1.0])
    best = np.inf
    for F in (np.eye(3), flip):
        R = Ra.T @ (Rb @ F)
        best = min(best, float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))))
    return best


def oracle_script(runner) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, list[dict]]:
    """The oracle's dense path from the current TCP (points, bits, rotations) and per script step its kind, object
    and how many grasps (open -> closed switches) the path has up to and including it."""
    from tcot_hybrid.libero.skills import PickPlace
    from tcot_hybrid.planners.oracle import OraclePlanner

    s = runner.stack
    oracle = OraclePlanner(s.task, s.sim.world, s.camera, config=runner.cfg.oracle)
    points, grip, rots = oracle.path_posed(gripper_closed=s.sim.gripper_closed_cmd())
    steps, closed, grasps = [], False, 0
    for skill in s.task.skills():
        if skill.done(s.sim.world):
            continue
        for k in skill.keyframes(s.sim.world):
            if k.closed and not closed:
                grasps += 1
            closed = bool(k.closed)
        steps.append({"kind": "pick_place" if isinstance(skill, PickPlace) else "articulation",
                      "object": str(skill.obj), "grasps_through": grasps,
                      "dest": None if not isinstance(skill, PickPlace) else str(skill.dest.target or "aside")})
    return points, grip, rots, steps


def compare(points_o, grip_o, rots_o, points_l, grip_l, rots_l, depth_z_l, depth_z_o) -> list[dict]:
    """Per gripper switch in order (oracle's k-th against learned k-th): errors of the learned one."""
    so, sl = switches(grip_o), switches(grip_l)
    out = []
    for k, (io, state) in enumerate(so):
        row = {"k": k, "closes": state, "oracle_pos": np.round(points_o[io], 4).tolist()}
        if k < len(sl) and sl[k][1] == state:
            il = sl[k][0]
            d = points_l[il] - points_o[io]
            row.update(lateral_m=float(np.linalg.norm(d[:2])), dz_m=float(d[2]),
                       learned_pos=np.round(points_l[il], 4).tolist())
            if rots_o is not None and rots_l is not None:
                row["rot_deg"] = rot_angle_deg(rots_o[io], rots_l[il])
            if depth_z_l is not None:
                row["depth_surface_z_m"] = float(depth_z_l[il])  # rendered surface at the learned pixel
                row["depth_surface_z_oracle_px_m"] = float(depth_z_o[io])  # ... and at the oracle's pixel
        out.append(row)
    return out


def surface_z(runner, uv: np.ndarray) -> np.ndarray:
    """World z of the surface the planner camera sees at each pixel (rendered depth, nearest pixel)."""
    s = runner.stack
    cam = s.camera
    depth = s.sim.render(runner.cfg.scene.planner_camera, cam.width, cam.height, depth=True)
    u = np.clip(np.round(uv[:, 0]).astype(int), 0, cam.width - 1)
    v = np.clip(np.round(uv[:, 1]).astype(int), 0, cam.height - 1)
    z_range = depth[v, u].astype(float)  # MuJoCo depth: distance along the optical axis [m]
    return cam.unproject(np.stack([u, v], 1).astype(float), z_range)[:, 2]


def run_one(task: str, seed: int, mode: str | None, confirm: str = "off", stop_on: str = "auto", *,
            checkpoint_hash: str) -> dict:
    """One layout: the t = 0 comparison, and with ``mode`` the executed episode and its classification."""
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.planners import Observation
    from tcot_hybrid.run_config import RunConfig
    from tcot_hybrid.supervision import SupervisorConfig

    from tcot_hybrid.learning.checkpoint import default_checkpoint

    # the four-suite model, named: a suite that ships its own model would otherwise load that one
    cfg = RunConfig(task=task, seed=seed, init="sampled", planner="learned", stop_on=stop_on,
                    checkpoint=str(default_checkpoint("libero_panda")),
                    supervisor=SupervisorConfig(mode=mode or "global", confirm_success=confirm))
    info: dict = {"task": task, "suite": task.split(":")[0], "seed": seed, "mode": mode,
                  "confirm": confirm if mode and mode.startswith("glsr") else None,
                  "checkpoint_hash": checkpoint_hash}
    held: dict[str, bool] = {}
    t0 = time.perf_counter()

    def pre(runner, step):
        if step != 0 or "steps" in info:
            return
        pts, grip, rots, steps = oracle_script(runner)
        info["steps"], info["_oracle"] = steps, (pts, grip, rots)

    def frame(runner, step):
        w = runner.stack.sim.world
        for st in info.get("steps", ()):
            if st["kind"] == "pick_place" and not held.get(st["object"]) and w.is_held(st["object"]):
                held[st["object"]] = True

    runner = EpisodeRunner(cfg, frame_hook=frame, pre_step_hook=pre)
    s = runner.stack
    if mode is None:  # plans only: settle, then the t = 0 plans
        runner.settle()
        s.planner.prepare()
        pre(runner, 0)
        obs = runner.observe(0)
        from tcot_hybrid.errors import PlanningError
        try:
            plan = s.planner.plan(obs, mode="global")
        except PlanningError as exc:
            plan, info["refused"] = None, str(exc)
        rec = None
    else:
        rec = runner.run()
        plan = runner.plans[0] if runner.plans and runner.plans[0].step == 0 else None
        info["refused"] = next((e["reason"] for e in rec["events"] if e.get("kind") == "plan_rejected"
                                and e.get("step") == 0), None)
    pts_o, grip_o, rots_o = info.pop("_oracle")
    info["oracle_switches"] = len(switches(grip_o))
    if plan is not None:
        pts_l = s.camera.unproject(plan.uv_px, plan.depth_m)
        if mode is None:
            zl, zo = surface_z(runner, plan.uv_px), surface_z(runner, s.camera.project(pts_o)[0])
        else:
            zl = zo = None
        info["learned_switches"] = len(switches(plan.gripper_closed))
        info["switches"] = compare(pts_o, grip_o, rots_o, pts_l, plan.gripper_closed, plan.tcp_rot, zl, zo)
    if rec is not None:
        w = s.sim.world
        info.update(success=bool(rec["success"]), fault=rec["fault"], replans=rec["replans"], stop_on=rec["stop_on"],
                    max_reference_limit_excess_rad=rec.get("max_reference_limit_excess_rad"),
                    stopped_by=rec["stopped_by"], steps_run=rec["steps"],
                    max_joint_limit_violation_rad=rec["max_joint_limit_violation_rad"],
                    plans_rejected=Counter(e["reason"].split(":")[0][:80] for e in rec["events"]
                                           if e.get("kind") == "plan_rejected"),
                    plans_infeasible=rec["plans_infeasible"], ik_failures=rec["ik_failures"],
                    detector_overruled=rec.get("detector_overruled", 0))
        sup = [e for e in rec["events"] if e.get("kind") == "supervisor" and "p_success" in e]
        fp = [e for e in sup if e["p_success"] >= cfg.supervisor.success_threshold and not e.get("true_success")]
        info["detector_calls"] = len(sup)
        info["detector_false_positives"] = len(fp)
        info["first_false_positive_step"] = fp[0]["step"] if fp else None
        last = sup[-20:]
        info["ended_waiting_on_false_positive"] = bool(
            not rec["success"] and len(last) == 20 and all(e.get("reason") == "judged_successful" for e in last))
        info["limit_events"] = [e for e in rec["events"] if e.get("kind") in ("position_limit", "tracking_reflex")][:5]
        done = []
        for st in info.get("steps", ()):
            skill_done = None
            for skill in s.task.skills():
                if str(skill.obj) == st["object"]:
                    skill_done = bool(skill.done(w))
            done.append(skill_done)
        info["steps_done"] = done
        info["held"] = held
        info["cause"] = classify(info)
    info["wall_s"] = round(time.perf_counter() - t0, 1)
    s.task.release_scene() if hasattr(s.task, "release_scene") else None
    return info


def classify(info: dict) -> str | None:
    if info.get("success"):
        return None
    if info.get("fault"):
        return "fault"
    if info.get("refused") and "switches" not in info:
        return "plan refused"
    steps = info.get("steps") or []
    done = info.get("steps_done") or []
    sw = info.get("switches") or []
    for st, ok in zip(steps, done):
        if ok:
            continue
        if st["kind"] == "articulation":
            return "articulation"
        if info["held"].get(st["object"]):
            return "place/release"
        grasps = [r for r in sw if r["closes"]]
        g = st["grasps_through"] - 1
        if g < 0 or g >= len(grasps) or "lateral_m" not in grasps[g]:
            return "grasp: missing"
        r = grasps[g]
        if r["lateral_m"] > LATERAL_TOL_M:
            return "grasp: lateral"
        if abs(r["dz_m"]) > HEIGHT_TOL_M:
            return "grasp: height"
        if r.get("rot_deg", 0.0) > ROT_TOL_DEG:
            return "grasp: orientation"
        return "grasp: execution"
    return "other"


def key(r: dict) -> tuple:
    return (r["task"], r["seed"], label(r), r.get("checkpoint_hash"))


def shipped_checkpoint_hash() -> str:
    """Hash of the four-suite checkpoint these records study (records are kept per checkpoint)."""
    from tcot_hybrid.episode import file_digest
    from tcot_hybrid.learning.checkpoint import default_checkpoint

    return file_digest(default_checkpoint("libero_panda"))


def label(r: dict) -> str | None:
    """The row an episode belongs to: its supervisor mode, and for GLSR how success verdicts were confirmed
    (records written before ``confirm_success`` existed ran Algorithm 1 as written: off)."""
    if r["mode"] is None or not r["mode"].startswith("glsr"):
        return r["mode"]
    return f"{r['mode']} (confirm {r.get('confirm') or 'off'}, stop on {r.get('stop_on') or 'simulator'})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="20000", help="development seeds, e.g. 20000-20001 (10000-49999)")
    ap.add_argument("--tasks-per-suite", type=int, default=None, help="spread over each suite (default: all 10)")
    ap.add_argument("--suites", default=",".join(SUITES), help="comma-separated suites (default: the four)")
    ap.add_argument("--modes", default=None, help="global,glsr: execute the episodes (default: plans only)")
    ap.add_argument("--plans-only", action="store_true", help="compare t = 0 plans only (the default without --modes)")
    ap.add_argument("--confirm", default="off", help="GLSR: supervisor.confirm_success (off, local_plan, auto)")
    ap.add_argument("--stop-on", default="auto", help="stop_on (auto, simulator, detector, either)")
    ap.add_argument("--out", default=str(HERE / "failures" / "records.jsonl"))
    ap.add_argument("--summarize", action="store_true", help="write failures.json and the docs section, run nothing")
    a = ap.parse_args()
    out = Path(a.out)
    if a.summarize:
        summarize(out)
        return
    from tcot_hybrid.supervision import SUPERVISOR_MODES

    modes: list[str | None] = [None]
    if a.modes and not a.plans_only:
        modes = a.modes.split(",")
        bad = [m for m in modes if m not in SUPERVISOR_MODES]
        if bad:
            raise SystemExit(f"--modes {bad[0]!r}: choose from {', '.join(SUPERVISOR_MODES)}")
    from tcot_hybrid.supervision import CONFIRM_SUCCESS

    from tcot_hybrid.run_config import STOP_ON

    if a.confirm not in CONFIRM_SUCCESS:
        raise SystemExit(f"--confirm {a.confirm!r}: choose from {', '.join(CONFIRM_SUCCESS)}")
    if a.stop_on not in STOP_ON:
        raise SystemExit(f"--stop-on {a.stop_on!r}: choose from {', '.join(STOP_ON)}")
    seeds = parse_seeds(a.seeds)
    out.parent.mkdir(parents=True, exist_ok=True)
    have = {key(json.loads(line)) for line in out.read_text().splitlines()} if out.is_file() else set()
    torch_threads = os.environ.get("TCOT_THREADS", "1")
    import torch

    torch.set_num_threads(int(torch_threads))
    ckpt = shipped_checkpoint_hash()
    for task in pick_tasks(a.tasks_per_suite, tuple(x for x in a.suites.split(",") if x)):
        for seed in seeds:
            for mode in modes:
                want = label({"mode": mode, "confirm": a.confirm,
                              "stop_on": ("either" if a.stop_on == "auto" else a.stop_on)})
                if (task, seed, want, ckpt) in have:
                    continue
                r = run_one(task, seed, mode, a.confirm, a.stop_on, checkpoint_hash=ckpt)
                with out.open("a") as f:
                    f.write(json.dumps(r, default=_default) + "\n")
                print(f"{task} seed {seed} {mode}: {r.get('cause', '-') if mode else r.get('learned_switches')} "
                      f"({r['wall_s']} s)", flush=True)


def _default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def _median(xs) -> str:
    return f"{np.median(xs):.1f}" if len(xs) else "-"


def depth_lift_lines(first: list[dict]) -> list[str]:
    """Would the rendered depth at the predicted pixel ("camera geometry") give better grasp heights than the network?
    The grasp height an RGB-D lift would give: the surface seen at the pixel minus the median depth of oracle grasps
    below the surface seen at the oracle's own pixel (one offset for all; a rim or a handle is grasped below the
    top)."""
    rows = [w for w in first if "depth_surface_z_m" in w]
    if not rows:
        return []
    dz = np.array([w["dz_m"] for w in rows])
    lat = np.array([w["lateral_m"] for w in rows])
    z_o = np.array([w["oracle_pos"][2] for w in rows])
    below = float(np.median(z_o - np.array([w["depth_surface_z_oracle_px_m"] for w in rows])))
    lift = np.array([w["depth_surface_z_m"] for w in rows]) + below - z_o  # error of the depth-lifted height
    ceiling = np.array([w["depth_surface_z_oracle_px_m"] for w in rows]) + below - z_o
    near = lat <= LATERAL_TOL_M

    def cm(x, q=50):
        return f"{np.percentile(np.abs(x), q) * 100:.1f}" if len(x) else "-"

    return ["", f"Grasp heights from the camera's rendered depth instead of the network ({len(rows)} first grasps; the "
            f"depth-lifted height is the surface seen at the pixel {below * 100:+.1f} cm, the median offset of oracle "
            f"grasps from the surface seen at their own pixel): median / p90 height error, network "
            f"{cm(dz)} / {cm(dz, 90)} cm, depth at the learned pixel {cm(lift)} / {cm(lift, 90)} cm, depth at the oracle's "
            f"pixel (the ceiling) {cm(ceiling)} / {cm(ceiling, 90)} cm; where the learned grasp is within "
            f"{LATERAL_TOL_M * 100:.0f} cm sideways ({int(near.sum())}): network {cm(dz[near])} cm, depth "
            f"{cm(lift[near])} cm.", ""]


def summarize(path: Path) -> None:
    from tcot_hybrid.markdown import update_readme_section

    recs = [json.loads(line) for line in path.read_text().splitlines()] if path.is_file() else []
    ckpt = shipped_checkpoint_hash()
    older = sum(r.get("checkpoint_hash") != ckpt for r in recs)  # earlier checkpoints' records: kept, not shown
    recs = [r for r in recs if r.get("checkpoint_hash") == ckpt]
    plans = [r for r in recs if r["mode"] is None]
    eps = [r for r in recs if r["mode"] is not None]
    lines = [f"Shipped checkpoint {ckpt} (`tcot_hybrid/checkpoints/libero_panda_default.safetensors`, sha256 prefix); "
             f"{older} records of earlier checkpoints in `{path.relative_to(HERE.parent.parent)}` are not shown.", ""]
    def seeds_of(rs):
        ss = sorted({r["seed"] for r in rs})
        return f"{ss[0]}-{ss[-1]}" if ss[0] != ss[-1] else f"{ss[0]}"

    if plans:
        lines.append(f"**t = 0 global plans against the oracle's script** (`failures.py --plans-only`; {len(plans)} "
                     f"layouts: sampled development seeds {seeds_of(plans)}, the four suites' tasks; per gripper "
                     f"switch in order, the learned plan's k-th against the oracle's k-th; medians, cm / deg):")
        lines.append("")
        lines.append("| suite | layouts | same switch count | first grasp lateral | first grasp height (learned - oracle) "
                     "| first grasp orientation | first grasp within 2 cm / 1.5 cm / 20 deg | later grasps lateral | "
                     "releases lateral | rendered surface at the learned grasp pixel minus oracle grasp z |")
        lines.append("|---|---|---|---|---|---|---|---|---|---|")
        for suite in SUITES + ("all",):
            rs = [r for r in plans if suite in ("all", r["suite"])]
            if not rs:
                continue
            same = sum(r.get("learned_switches") == r["oracle_switches"] for r in rs)
            first = [next((w for w in r.get("switches", []) if w["closes"]), None) for r in rs]
            first = [w for w in first if w and "lateral_m" in w]
            later = [w["lateral_m"] * 100 for r in rs for w in [x for x in r.get("switches", []) if x["closes"]][1:]
                     if "lateral_m" in w]
            rel = [w["lateral_m"] * 100 for r in rs for w in r.get("switches", []) if not w["closes"] and "lateral_m" in w]
            ok = sum(w["lateral_m"] <= LATERAL_TOL_M and abs(w["dz_m"]) <= HEIGHT_TOL_M
                     and w.get("rot_deg", 0) <= ROT_TOL_DEG for w in first)
            lat = [w["lateral_m"] * 100 for w in first]
            dz = [w["dz_m"] * 100 for w in first]
            rot = [w["rot_deg"] for w in first if "rot_deg" in w]
            dsurf = [(w["depth_surface_z_m"] - w["oracle_pos"][2]) * 100 for w in first if "depth_surface_z_m" in w]
            lines.append(f"| {suite} | {len(rs)} | {same}/{len(rs)} | {_median(lat)} | {_median(dz)} "
                         f"(abs {_median(np.abs(dz))}) | {_median(rot)} | {ok}/{len(rs)} | {_median(later)} | "
                         f"{_median(rel)} | {_median(dsurf)} |")
        first = [next((w for w in r.get("switches", []) if w["closes"]), None) for r in plans]
        first = [w for w in first if w and "lateral_m" in w]
        lat_bad = sum(w["lateral_m"] > LATERAL_TOL_M for w in first)
        h_bad = sum(w["lateral_m"] <= LATERAL_TOL_M and abs(w["dz_m"]) > HEIGHT_TOL_M for w in first)
        r_bad = sum(w["lateral_m"] <= LATERAL_TOL_M and abs(w["dz_m"]) <= HEIGHT_TOL_M
                    and w.get("rot_deg", 0) > ROT_TOL_DEG for w in first)
        lines.append("")
        refused = Counter((r["task"].split(":")[1], "a waypoint below the floor (learned.min_height_m)"
                           if "lowest allowed" in r["refused"] else r["refused"][:80]) for r in plans if r.get("refused"))
        lines += ["", f"t = 0 plans refused by the planner's output checks: {sum(refused.values())} of {len(plans)}"
                  + "".join(f"; {n} x {task}: {why}" for (task, why), n in refused.items()) + "."]
        lines += depth_lift_lines(first)
        lines.append(f"First grasps outside a tolerance, first failing check ({len(first)} with a matching grasp; "
                     f"{len(plans) - len(first)} plans without one): lateral > {LATERAL_TOL_M * 100:.0f} cm "
                     f"{lat_bad}, else height > {HEIGHT_TOL_M * 100:.1f} cm {h_bad}, else orientation > "
                     f"{ROT_TOL_DEG:.0f} deg {r_bad}.")
    if eps:
        lines.append("")
        lines.append(f"**Executed episodes** (`failures.py --modes ...`; {len(eps)} episodes, sampled development "
                     f"seeds {seeds_of(eps)}, {len({r['task'] for r in eps})} tasks of the four suites; cause = the "
                     f"first oracle step not done at the end, see the script's docstring):")
        lines.append("")
        causes = sorted({r.get("cause") or "success" for r in eps})
        lines.append("| mode | episodes | " + " | ".join(causes) + " | episodes with detector false positives "
                     "| ended waiting on one | ended by the detector (not done) | verdicts overruled / episode "
                     "| replans / episode | mean episode [planner steps] | worst joint-limit excess [rad] |")
        lines.append("|---|---|" + "---|" * len(causes) + "---|---|---|---|---|---|---|")
        for mode in sorted({label(r) for r in eps}):
            rs = [r for r in eps if label(r) == mode]
            c = Counter(r.get("cause") or "success" for r in rs)
            fp = sum(r.get("detector_false_positives", 0) > 0 for r in rs)
            wait = sum(bool(r.get("ended_waiting_on_false_positive")) for r in rs)
            lines.append(f"| {mode} | {len(rs)} | " + " | ".join(str(c.get(k, 0)) for k in causes)
                         + f" | {fp if mode.startswith('glsr') else '-'} | {wait if mode.startswith('glsr') else '-'} "
                         f"| {sum(r.get('stopped_by') == 'detector' for r in rs) if mode.startswith('glsr') else '-'} "
                         f"| {np.mean([r.get('detector_overruled', 0) for r in rs]):.1f} "
                         f"| {np.mean([r['replans'] for r in rs]):.1f} | {np.mean([r['steps_run'] for r in rs]):.0f} | "
                         f"{max(r['max_joint_limit_violation_rad'] for r in rs):.4f} |")
    glsr = [r for r in eps if r["mode"].startswith("glsr")]
    if glsr:
        lines.append("")
        for mode in sorted({label(r) for r in glsr}):
            rs = [r for r in glsr if label(r) == mode]
            calls = sum(r.get("detector_calls", 0) for r in rs)
            fp = sum(r.get("detector_false_positives", 0) for r in rs)
            first = [r["first_false_positive_step"] for r in rs if r.get("first_false_positive_step") is not None]
            lines.append(f"- {mode}: {fp} of {calls} detector calls ({100 * fp / max(calls, 1):.0f} %) judged the task "
                         f"done while it was not" + (f"; the first such call at planner step {int(np.median(first))} "
                                                     f"(median over {len(first)} episodes)" if first else "")
                         + f"; {sum(r['success'] for r in rs)}/{len(rs)} successes.")
        pairs = {}
        for r in eps:
            pairs.setdefault((r["task"], r["seed"]), {})[label(r)] = r["success"]
        modes = sorted({label(r) for r in eps})
        both = {k: v for k, v in pairs.items() if len(v) == len(modes)}
        if both and len(modes) > 1:
            lines.append(f"- Same layouts in every row ({len(both)}): " + ", ".join(
                f"{m} {sum(v[m] for v in both.values())}" for m in modes) + " successes.")
        for m in modes:
            pair = [v for v in pairs.values() if m in v and "global" in v]
            if m != "global" and len(pair) > len(both):
                lines.append(f"- Layouts run both global-only and {m} ({len(pair)}): global {sum(v['global'] for v in pair)}, "
                             f"{m} {sum(v[m] for v in pair)} successes; both {sum(v['global'] and v[m] for v in pair)}.")
    ref = [r.get("max_reference_limit_excess_rad") for r in eps if r.get("max_reference_limit_excess_rad") is not None]
    if ref:
        lines.append(f"- Commanded joint positions past a limit: worst {max(ref):.4f} rad over the {len(ref)} episodes "
                     f"that record it (measured positions: the table's last column).")
    summary = {"records": len(recs), "lines": lines}
    (HERE / "failures.json").write_text(json.dumps(summary, indent=1) + "\n")
    if lines:
        update_readme_section(HERE.parent / "libero-planner.md", SECTION, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
