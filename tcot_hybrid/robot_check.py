"""``tcot robot check``: is a robot (bundled name or a robot.toml of your own) usable here, and where can it
grasp?

1. The spec and the MJCF (``load_robot_spec``: names, types, limits, sanity bounds).
2. Pinocchio against MuJoCo (TCP pose and mass matrix at two postures), always, whatever IK backend
   a run later uses: the controllers' dynamics and the Pinocchio IK both depend on it.
3. The gripper: the opening it can reach, collision pads on each finger (its joint's body or the bodies
   under it), and that every actuator moving the fingers is driven (``gripper_actuator`` and an optional
   mirrored ``gripper_mirror_actuator``).
4. Reach: a top-down grasp (TCP pointing down, fingers closing along world y, as every plan uses) and its
   approach point above it, solved by IK on a grid over the task workspace and at every grasp and release
   point of every task over a set of seeded layouts. ``reachable_fraction`` is the workspace share; a PNG
   draws the map with the task points on it.

The same reach test runs before every episode (:func:`unreachable_targets`): a run whose robot cannot reach
its task's grasp or release points warns before stepping and records ``unreachable_target`` events.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from tcot_hybrid.errors import RobotModelError, TcotError
from tcot_hybrid.robot import R_DOWN, RobotSpec, build_pinocchio_model, load_robot_spec

WORKSPACE = {"x": (0.3, 0.7), "y": (-0.3, 0.3)}
"""Task workspace [m] (docs/robot_spec.md, Conventions): where task objects and targets lie."""
GRASP_Z = 0.02  # [m] TCP height of a grasp on a 4 cm cube (the tasks' common grasp)
APPROACH_DZ = 0.08  # [m] the approach point above each grasp (tasks.base.APPROACH_DZ)
GRID_STEP_M = 0.02
REACH_TOL_M = 0.005  # [m] a grasp solves when the TCP is this close ...
REACH_TOL_RAD = 0.05  # [rad] ... and this close in orientation
MIN_OPENING_M = 0.05  # [m] the tasks' objects are up to ~4.5 cm wide across the grasp


@dataclass(frozen=True)
class Check:
    name: str
    ok: bool
    detail: str
    severity: str = "error"  # "error" (the robot cannot be used) or "warning"

    def as_dict(self) -> dict:
        return {"name": self.name, "ok": self.ok, "severity": self.severity, "detail": self.detail}


# --- reach --------------------------------------------------------------------------------------------------

class ReachSolver:
    """Top-down grasp IK for one robot (Pinocchio DLS, arm only), with approach-point seeding."""

    def __init__(self, spec: RobotSpec):
        from tcot_hybrid.ik import IKConfig, make_ik

        self.spec = spec
        self.ik = make_ik("pinocchio", spec, IKConfig(max_iters=300, posture_cost=0.0))

    def solve(self, pos, seed=None, rot=R_DOWN) -> tuple[bool, np.ndarray, float]:
        """(reachable, q, position error [m]) of the TCP pose (``pos`` [m], ``rot``) in the robot's base frame."""
        from tcot_hybrid.ik import IKTarget

        best = None
        seeds = [self.spec.home_q] if seed is None else [seed, self.spec.home_q]
        for s in seeds:
            res = self.ik.solve(IKTarget(pos=np.asarray(pos, dtype=float), rot=np.asarray(rot, dtype=float)),
                                np.asarray(s, dtype=float))
            ok = res.pos_err <= REACH_TOL_M and res.rot_err <= REACH_TOL_RAD
            if ok:
                return True, res.q, float(res.pos_err)
            if best is None or res.pos_err < best[2]:
                best = (False, res.q, float(res.pos_err))
        return best

    def grasp(self, pos, seed=None, rot=R_DOWN) -> tuple[bool, np.ndarray, float]:
        """A grasp at ``pos`` counts when its approach point (APPROACH_DZ back along the TCP's approach axis:
        above it, for a top-down grasp) and the grasp itself solve. Base frame."""
        p, R = np.asarray(pos, dtype=float), np.asarray(rot, dtype=float)
        ok_a, qa, ea = self.solve(p - APPROACH_DZ * R[:, 2], seed, R)
        ok_g, qg, eg = self.solve(p, qa, R)
        return ok_a and ok_g, qg, max(ea, eg)


_SOLVERS: dict[tuple, ReachSolver] = {}


def reach_solver(spec: RobotSpec) -> ReachSolver:
    """One solver per robot model and process (episodes of an evaluation share it)."""
    key = (str(spec.mjcf_path), spec.mjcf_path.stat().st_mtime_ns, spec.arm_joints, spec.ee_site,
           spec.q_min.tobytes(), spec.q_max.tobytes(), spec.v_max.tobytes())
    if key not in _SOLVERS:
        if len(_SOLVERS) >= 8:
            _SOLVERS.clear()
        _SOLVERS[key] = ReachSolver(spec)
    return _SOLVERS[key]


def workspace_map(solver: ReachSolver, *, step_m: float = GRID_STEP_M, z: float = GRASP_Z) -> dict:
    """Reachability of top-down grasps on a grid over WORKSPACE (serpentine walk, each solve seeded from
    the previous one and from home)."""
    xs = np.round(np.arange(WORKSPACE["x"][0], WORKSPACE["x"][1] + 1e-9, step_m), 4)
    ys = np.round(np.arange(WORKSPACE["y"][0], WORKSPACE["y"][1] + 1e-9, step_m), 4)
    ok = np.zeros((len(xs), len(ys)), dtype=bool)
    err = np.zeros_like(ok, dtype=float)
    seed = None
    for i, x in enumerate(xs):
        cols = range(len(ys)) if i % 2 == 0 else range(len(ys) - 1, -1, -1)
        for j in cols:
            good, q, e = solver.grasp((x, ys[j], z), seed)
            ok[i, j], err[i, j] = good, e
            seed = q if good else None
    return {"x": xs, "y": ys, "z": z, "reachable": ok, "pos_err_m": err}


def task_points(task_name: str, spec: RobotSpec, seeds) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Grasp points (gripper closes) and release points (gripper opens) of the task's oracle script over
    the seeded layouts, from each layout's initial state, as (position, rotation) in the robot's base frame."""
    from tcot_hybrid.config import TimingConfig
    from tcot_hybrid.scene import SceneConfig
    from tcot_hybrid.sim import Simulation
    from tcot_hybrid.tasks import make_task

    task = make_task(task_name)
    task.set_episode(seed=0, init=None)
    sim = Simulation(spec, task, timing=TimingConfig(), scene=SceneConfig())
    out: dict[str, list] = {"grasp": [], "release": []}
    try:
        for seed in seeds:
            task.set_episode(seed=seed, init=None)
            sim.reset(np.random.default_rng(seed))
            g, r = layout_points(task, sim.world, sim.T_base_world)
            out["grasp"] += g
            out["release"] += r
    finally:
        sim.close()
    return out


def layout_points(task, world, T_base_world=None) -> tuple[list, list]:
    """(grasp points, release points) of ``task``'s script in the current layout of ``world``, each a
    (position [m], rotation) pair in the robot's base frame (``T_base_world``; identity in the workcell)."""
    T = np.eye(4) if T_base_world is None else np.asarray(T_base_world, dtype=float)
    grasps, releases = [], []
    closed = False
    for skill in task.skills():
        try:
            kfs = skill.keyframes(world)
        except Exception:  # noqa: BLE001 - a skill that needs an earlier one done first: skip its points
            continue
        for kf in kfs:
            rot = R_DOWN if getattr(kf, "rot", None) is None else np.asarray(kf.rot, dtype=float)
            point = (T[:3, :3] @ np.asarray(kf.pos, dtype=float) + T[:3, 3], T[:3, :3] @ rot)
            if kf.closed and not closed:
                grasps.append(point)
            elif closed and not kf.closed:
                releases.append(point)
            closed = kf.closed
    return grasps, releases


def unreachable_targets(spec: RobotSpec, task, world, T_base_world=None) -> list[dict]:
    """Grasp and release points of this episode's layout that the robot cannot reach (checked before the
    episode; empty when all are reachable). Positions in the report are world coordinates."""
    solver = reach_solver(spec)
    grasps, releases = layout_points(task, world, T_base_world)
    T_wb = np.eye(4) if T_base_world is None else np.linalg.inv(np.asarray(T_base_world, dtype=float))
    bad = []
    for kind, pts in (("grasp", grasps), ("release", releases)):
        for p, R in pts:
            ok, _, err = solver.grasp(p, rot=R)
            if not ok:
                pw = T_wb[:3, :3] @ p + T_wb[:3, 3]
                bad.append({"target": kind, "pos": [round(float(v), 4) for v in pw], "pos_err_m": round(err, 4)})
    return bad


# --- the other checks ------------------------------------------------------------------------------------------

def gripper_checks(spec: RobotSpec) -> list[Check]:
    m = mujoco.MjModel.from_xml_path(str(spec.mjcf_path))
    checks = []
    jids = [m.joint(j).id for j in spec.gripper_joints]
    opening = 0.0
    for j in jids:
        lo, hi = m.jnt_range[j]
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE:
            opening += float(hi - lo)
    slide = all(m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE for j in jids)
    if slide:
        checks.append(Check("gripper opening", opening >= MIN_OPENING_M,
                            f"finger travel adds up to {opening * 100:.1f} cm (the tasks' objects need "
                            f">= {MIN_OPENING_M * 100:.0f} cm)"))
    else:
        checks.append(Check("gripper opening", True, "hinge fingers: opening not computed from joint ranges",
                            severity="warning"))
    for name, j in zip(spec.gripper_joints, jids):
        body = m.jnt_bodyid[j]

        def in_subtree(b: int) -> bool:
            while b > 0 and b != body:
                b = int(m.body_parentid[b])
            return b == body

        pads = [g for g in range(m.ngeom) if in_subtree(int(m.geom_bodyid[g]))
                and (m.geom_contype[g] or m.geom_conaffinity[g])]
        if not any(m.geom_contype[g] or m.geom_conaffinity[g] for g in range(m.ngeom)):
            checks.append(Check(f"finger pads ({name})", False, "the MJCF has no collision geoms at all: a kinematic "
                                "model whose scene brings the geometry (e.g. libero_panda)? pads not checked",
                                severity="warning"))
            continue
        checks.append(Check(f"finger pads ({name})", bool(pads),
                            f"finger joint {name!r}: {len(pads)} collision geom(s) on its body {m.body(body).name!r} "
                            f"and the bodies under it" + ("" if pads else ": the finger cannot touch an object")))
    movers = []
    for a in range(m.nu):
        trn = m.actuator_trntype[a]
        if trn == mujoco.mjtTrn.mjTRN_JOINT and m.actuator_trnid[a, 0] in jids:
            movers.append(m.actuator(a).name)
        elif trn == mujoco.mjtTrn.mjTRN_TENDON:
            t = m.actuator_trnid[a, 0]
            adr, num = m.tendon_adr[t], m.tendon_num[t]
            if any(m.wrap_objid[k] in jids for k in range(adr, adr + num)):
                movers.append(m.actuator(a).name)
    driven = [a for a in (spec.gripper_actuator, spec.gripper_mirror_actuator) if a]
    extra = [a for a in movers if a not in driven]
    checks.append(Check("finger actuators", not extra,
                        f"actuators moving the fingers: {movers or 'none'}; the stack drives {driven}"
                        + (f", so {extra} would stay at ctrl 0: couple the fingers (tendon + equality) under one "
                           f"actuator, or name a mirrored second one as gripper_mirror_actuator" if extra else "")))
    return checks


def check_robot(name_or_path: str | Path, *, tasks: list[str] | None = None, seeds: int = 10,
                step_m: float = GRID_STEP_M, png: str | Path | None = None) -> dict:
    """Every check above; returns the report (``ok``, ``checks``, ``reachable_fraction``, ``tasks``)."""
    report: dict = {"robot": str(name_or_path), "checks": [], "ok": False}
    try:
        spec = load_robot_spec(name_or_path)
    except RobotModelError as exc:
        report["checks"].append(Check("spec and MJCF", False, str(exc)).as_dict())
        return report
    report.update(robot=spec.name, mjcf=str(spec.mjcf_path), dof=spec.dof)
    checks = [Check("spec and MJCF", True, f"{spec.dof} arm joints, TCP site {spec.ee_site!r}, limits within "
                                          f"the MJCF ranges and the sanity bounds")]
    try:
        build_pinocchio_model(spec, check=True)
        build_pinocchio_model(spec, lock_gripper=True, check=True)
        checks.append(Check("Pinocchio vs MuJoCo", True, "TCP pose and mass matrix agree within 1e-6 at two postures"))
    except (RobotModelError, TcotError) as exc:
        checks.append(Check("Pinocchio vs MuJoCo", False, str(exc)))
        report["checks"] = [c.as_dict() for c in checks]
        return report
    checks += gripper_checks(spec)
    solver = ReachSolver(spec)
    grid = workspace_map(solver, step_m=step_m)
    frac = float(grid["reachable"].mean())
    report["reachable_fraction"] = round(frac, 4)
    report["workspace"] = {"x_m": list(WORKSPACE["x"]), "y_m": list(WORKSPACE["y"]), "z_m": GRASP_Z,
                           "step_m": step_m, "points": int(grid["reachable"].size),
                           "reachable": int(grid["reachable"].sum()),
                           "unreachable_examples": [[float(grid["x"][i]), float(grid["y"][j])]
                                                    for i, j in np.argwhere(~grid["reachable"])[:10]]}
    from tcot_hybrid.tasks import list_tasks

    names = tasks or [t.name for t in list_tasks()]
    per_task, marks = [], []
    for name in names:
        pts = task_points(name, spec, range(seeds))
        entry = {"task": name}
        for kind in ("grasp", "release"):
            res = [solver.grasp(p, rot=R) for p, R in pts[kind]]
            n_ok = sum(r[0] for r in res)
            entry[f"{kind}_points"] = len(res)
            entry[f"{kind}_reachable_fraction"] = round(n_ok / len(res), 4) if res else None
            marks += [(kind, p, r[0]) for (p, _), r in zip(pts[kind], res)]
        fr = [entry[f"{k}_reachable_fraction"] for k in ("grasp", "release") if entry[f"{k}_reachable_fraction"] is not None]
        entry["reachable_fraction"] = round(min(fr), 4) if fr else None
        per_task.append(entry)
    report["tasks"] = per_task
    short = [t["task"] for t in per_task if t["reachable_fraction"] is not None and t["reachable_fraction"] < 1.0]
    checks.append(Check("reach", frac >= 0.95 and not short,
                        f"top-down grasps reachable on {frac:.1%} of the workspace; tasks with unreachable grasp or "
                        f"release points: {short or 'none'}", severity="warning"))
    report["checks"] = [c.as_dict() for c in checks]
    report["ok"] = all(c.ok for c in checks if c.severity == "error")
    if png is not None:
        report["png"] = str(draw_map(grid, marks, png, title=f"{spec.name}: top-down grasp reach "
                                                              f"({frac:.1%} of the workspace)"))
    return report


def draw_map(grid: dict, marks, path: str | Path, *, title: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    p = Path(path)
    fig, ax = plt.subplots(figsize=(6.4, 5.2), dpi=110)
    xs, ys = grid["x"], grid["y"]
    step = float(xs[1] - xs[0]) if len(xs) > 1 else GRID_STEP_M
    ax.imshow(grid["reachable"].astype(float), origin="lower", cmap=ListedColormap(["#f4a6a6", "#bfe6bf"]),
              vmin=0, vmax=1, extent=(ys[0] - step / 2, ys[-1] + step / 2, xs[0] - step / 2, xs[-1] + step / 2),
              aspect="equal")
    for kind, marker in (("grasp", "o"), ("release", "x")):
        for good in (True, False):
            pts = np.array([m[1] for m in marks if m[0] == kind and m[2] == good]).reshape(-1, 3)
            if len(pts):
                ax.scatter(pts[:, 1], pts[:, 0], marker=marker, s=14, c="#1b5e20" if good else "#b71c1c",
                           label=f"task {kind} points, {'reachable' if good else 'UNREACHABLE'} ({len(pts)})")
    ax.set_xlabel("y [m] (robot's left +)")
    ax.set_ylabel("x [m] (forward)")
    ax.invert_xaxis()
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p)
    plt.close(fig)
    return p
