"""Compute a robot's home_q: TCP at a target position pointing straight down (R_down), by a small
damped least-squares IK on the MuJoCo model, pulled toward a seed posture in the null space.

Run once when adding a robot and paste the printed values into robot.toml's home_q:

    python -m tcot_hybrid.robots.compute_home panda --seed 0 -0.3 0 -2.2 0 1.9 0.785
    python -m tcot_hybrid.robots.compute_home path/to/robot.toml --seed ...

The MJCF joint ranges bound the solve (not the spec limits, which may not exist yet).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import mujoco
import numpy as np

R_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


POS_TOL_M = 1e-3
ROT_TOL_RAD = 1e-2


def joint_bounds(m: mujoco.MjModel, jids: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """MJCF joint ranges [rad]; a continuous joint (``limited="false"``, or the range left at [0, 0]) is
    unbounded (it used to be clamped to 0, pinning the joint)."""
    lo = np.array([m.jnt_range[j, 0] for j in jids], dtype=float)
    hi = np.array([m.jnt_range[j, 1] for j in jids], dtype=float)
    free = np.array([not m.jnt_limited[j] or lo_ == hi_ == 0.0 for j, lo_, hi_ in zip(jids, lo, hi)])
    lo[free], hi[free] = -np.inf, np.inf
    return lo, hi


def solve_home(mjcf: Path, arm_joints: list[str], ee_site: str, seed: np.ndarray,
               target_pos: np.ndarray, *, target_rot: np.ndarray = R_DOWN, iters: int = 2000,
               damping: float = 1e-3, posture_gain: float = 0.05) -> tuple[np.ndarray, float, float]:
    """TCP to ``target_pos`` [m] / ``target_rot`` (default R_down) from ``seed`` [rad].

    Return (q [rad], position error [m], rotation error [rad]); not converged = large errors."""
    m = mujoco.MjModel.from_xml_path(str(mjcf))
    d = mujoco.MjData(m)
    jids = [m.joint(j).id for j in arm_joints]
    qadr = np.array([m.jnt_qposadr[j] for j in jids])
    dadr = np.array([m.jnt_dofadr[j] for j in jids])
    lo, hi = joint_bounds(m, jids)
    sid = m.site(ee_site).id
    q = np.array(seed, dtype=float)
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    for it in range(iters):
        w = posture_gain if it < iters // 2 else 0.0  # second half: exact task, no posture pull
        d.qpos[qadr] = q
        mujoco.mj_forward(m, d)
        R = d.site_xmat[sid].reshape(3, 3)
        e_pos = target_pos - d.site_xpos[sid]
        # rotation error as a world-frame rotation vector: log(R_target R^T)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, (target_rot @ R.T).ravel())
        e_rot = np.zeros(3)
        mujoco.mju_quat2Vel(e_rot, quat, 1.0)
        mujoco.mj_jacSite(m, d, jp, jr, sid)
        J = np.vstack([jp[:, dadr], jr[:, dadr]])
        e = np.concatenate([e_pos, e_rot])
        JJt = J @ J.T + damping * np.eye(6)
        dq = J.T @ np.linalg.solve(JJt, e)
        N = np.eye(len(q)) - J.T @ np.linalg.solve(JJt, J)
        dq += N @ (w * (np.asarray(seed) - q))
        q = np.clip(q + dq, lo, hi)
    cont = ~np.isfinite(hi)
    q[cont] = (q[cont] + np.pi) % (2 * np.pi) - np.pi  # a continuous joint: the equivalent angle in [-pi, pi)
    d.qpos[qadr] = q
    mujoco.mj_forward(m, d)
    R = d.site_xmat[sid].reshape(3, 3)
    pos_err = float(np.linalg.norm(target_pos - d.site_xpos[sid]))
    rot_err = float(np.arccos(np.clip((np.trace(target_rot.T @ R) - 1) / 2, -1, 1)))
    return q, pos_err, rot_err


def main() -> None:
    from tcot_hybrid.robot import _resolve_spec_path
    import tomllib

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("robot", help="bundled robot name or path to a robot.toml")
    ap.add_argument("--seed", type=float, nargs="+", required=True, help="posture seed [rad]")
    ap.add_argument("--target", type=float, nargs=3, default=[0.45, 0.0, 0.35], help="TCP position [m]")
    args = ap.parse_args()
    path = _resolve_spec_path(args.robot)
    raw = tomllib.loads(path.read_text())
    q, pe, re = solve_home(path.parent / raw["mjcf"], raw["arm_joints"], raw["ee_site"],
                           np.array(args.seed), np.array(args.target))
    print("home_q = [" + ", ".join(f"{v:.6f}" for v in q) + "]")
    print(f"position error {pe * 1e3:.3f} mm, rotation error {re * 1e3:.3f} mrad")
    if pe > POS_TOL_M or re > ROT_TOL_RAD:
        import sys

        print(f"warning: the pose is NOT met (tolerance {POS_TOL_M * 1e3:.0f} mm / {ROT_TOL_RAD * 1e3:.0f} mrad): the "
              f"target may be out of reach or the joint ranges too tight; try another --seed or --target",
              file=sys.stderr)
        raise SystemExit(1)


if __name__ == "__main__":
    main()
