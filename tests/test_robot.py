"""Robot specs and models: Pinocchio agrees with MuJoCo, specs are validated, robots hold and grasp."""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from tcot_hybrid.errors import RobotModelError
from tcot_hybrid.robot import (
    R_DOWN,
    build_pinocchio_model,
    list_robots,
    load_robot_spec,
    mj_full_mass_matrix,
    mj_robot_indices,
    robot_mjspec,
)
from tcot_hybrid.robots.compute_home import solve_home

ROBOTS = ["panda", "ur5e"]
HOME_TCP = np.array([0.45, 0.0, 0.35])
TOL = 1e-9


def _rot_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(R_a.T @ R_b) - 1.0) / 2.0, -1.0, 1.0)))


def _compare_with_mujoco(spec, n: int = 20, seed: int = 0) -> dict[str, float]:
    """Max abs differences Pinocchio vs MuJoCo over n random states within limits."""
    robot = build_pinocchio_model(spec)
    pm, pdata = robot.model, robot.model.createData()
    m = mujoco.MjModel.from_xml_path(str(spec.mjcf_path))
    d = mujoco.MjData(m)
    ix = mj_robot_indices(spec, m)
    rng = np.random.default_rng(seed)
    err = dict(pos=0.0, rot=0.0, M=0.0, bias=0.0, gravity=0.0)
    for _ in range(n):
        d.qpos[:] = rng.uniform(m.jnt_range[:, 0], m.jnt_range[:, 1])  # every joint is limited
        d.qpos[ix.arm_qpos] = rng.uniform(spec.q_min, spec.q_max)
        d.qvel[:] = rng.normal(scale=1.0, size=m.nv)
        mujoco.mj_forward(m, d)
        q, v = d.qpos[robot.mj_qpos_idx], d.qvel[robot.mj_dof_idx]
        pin.framesForwardKinematics(pm, pdata, q)
        T = pdata.oMf[robot.tcp_frame_id]
        err["pos"] = max(err["pos"], np.abs(T.translation - d.site_xpos[ix.ee_site]).max())
        err["rot"] = max(err["rot"], np.abs(T.rotation - d.site_xmat[ix.ee_site].reshape(3, 3)).max())
        M = pin.crba(pm, pdata, q)
        M = np.triu(M) + np.triu(M, 1).T
        err["M"] = max(err["M"], np.abs(M - mj_full_mass_matrix(m, d)).max())
        err["bias"] = max(err["bias"], np.abs(pin.rnea(pm, pdata, q, v, np.zeros(m.nv)) - d.qfrc_bias).max())
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)
        err["gravity"] = max(err["gravity"], np.abs(pin.computeGeneralizedGravity(pm, pdata, q) - d.qfrc_bias).max())
    return err


# --------------------------------------------------------------------------------------------------
# bundled robots


def test_list_robots() -> None:
    assert set(ROBOTS) <= set(list_robots())


def test_unknown_robot_lists_valid() -> None:
    with pytest.raises(RobotModelError, match=r"unknown robot 'nope'.*panda.*ur5e"):
        load_robot_spec("nope")


@pytest.mark.parametrize("name", ROBOTS)
def test_spec_fields(name: str) -> None:
    spec = load_robot_spec(name)
    assert spec.name == name and spec.mjcf_path.is_absolute() and spec.mjcf_path.is_file()
    assert spec.dof == len(spec.arm_joints) == len(spec.arm_actuators) == {"panda": 7, "ur5e": 6}[name]
    for fld in ("home_q", "q_min", "q_max", "v_max", "a_max", "j_max", "tau_max", "kp", "kd"):
        arr = getattr(spec, fld)
        assert arr.dtype == float and arr.shape == (spec.dof,)
        with pytest.raises(ValueError):  # read-only
            arr[0] = 1.0
    assert np.all(spec.q_min < spec.home_q) and np.all(spec.home_q < spec.q_max)
    assert spec.gripper_open == 0.04 and spec.gripper_closed == 0.0


@pytest.mark.parametrize("name", ROBOTS)
def test_pinocchio_matches_mujoco(name: str) -> None:
    err = _compare_with_mujoco(load_robot_spec(name), n=25)
    print(name, {k: f"{v:.1e}" for k, v in err.items()})
    assert all(v <= TOL for v in err.values()), err


@pytest.mark.parametrize("name", ROBOTS)
def test_index_maps_and_reduced_model(name: str) -> None:
    spec = load_robot_spec(name)
    full = build_pinocchio_model(spec)
    assert full.nq == spec.dof + len(spec.gripper_joints)
    assert np.array_equal(full.mj_qpos_idx, np.arange(full.nq))  # plain serial chain: orders coincide
    assert full.joint_names[: spec.dof] == spec.arm_joints
    assert np.allclose(full.model.armature[: spec.dof], 0.1)
    red = build_pinocchio_model(spec, lock_gripper=True)
    assert red.nq == spec.dof and red.joint_names == spec.arm_joints and red.gripper_locked
    assert np.array_equal(red.model.lowerPositionLimit, spec.q_min)
    assert np.array_equal(red.model.upperPositionLimit, spec.q_max)
    assert np.array_equal(red.model.velocityLimit, spec.v_max)
    assert np.array_equal(red.model.effortLimit, spec.tau_max)
    # same TCP pose in the reduced and the full model (TCP is not on the fingers)
    rng = np.random.default_rng(1)
    df, dr = full.model.createData(), red.model.createData()
    for _ in range(10):
        qa = rng.uniform(spec.q_min, spec.q_max)
        qf = np.concatenate([qa, rng.uniform(0.0, 0.04, len(spec.gripper_joints))])
        pin.framesForwardKinematics(full.model, df, qf)
        pin.framesForwardKinematics(red.model, dr, qa)
        assert df.oMf[full.tcp_frame_id].isApprox(dr.oMf[red.tcp_frame_id], 1e-12)


@pytest.mark.parametrize("name", ROBOTS)
def test_home_pose(name: str) -> None:
    spec = load_robot_spec(name)
    red = build_pinocchio_model(spec, lock_gripper=True)
    data = red.model.createData()
    pin.framesForwardKinematics(red.model, data, spec.home_q)
    T = data.oMf[red.tcp_frame_id]
    print(name, "home TCP", T.translation, "rot err", _rot_angle(T.rotation, R_DOWN))
    assert np.linalg.norm(T.translation - HOME_TCP) <= 0.01
    assert _rot_angle(T.rotation, R_DOWN) <= 0.05
    # TCP axis convention: z (approach) points down, y (closing) along world y
    assert T.rotation[:, 2] @ [0, 0, -1] > 0.99 and abs(T.rotation[:, 1] @ [0, 1, 0]) > 0.99


@pytest.mark.parametrize("name", ROBOTS)
def test_mjcf_conventions(name: str) -> None:
    spec = load_robot_spec(name)
    ms = robot_mjspec(spec)
    assert not ms.lights and not ms.cameras
    bodies = [b for b in ms.bodies if b.name != "world"]
    assert all(b.explicitinertial for b in bodies), [b.name for b in bodies if not b.explicitinertial]
    m = ms.compile()
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert m.nmesh == 0 and m.ntex == 0  # simple geoms only: software rendering stays fast
    ix = mj_robot_indices(spec, m)
    assert np.all(m.dof_armature[ix.arm_dof] > 0)
    # no self-collision possible, but collides with default (contype=1) geoms like tables/objects
    for i in range(m.ngeom):
        for j in range(m.ngeom):
            assert not (m.geom_contype[i] & m.geom_conaffinity[j])
        assert m.geom_conaffinity[i] & 1
    # finger pads: boxes, torsional friction, high sliding friction
    pads = [i for i in range(m.ngeom) if "pad" in m.geom(i).name]
    assert len(pads) == 2
    for g in pads:
        assert m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX and m.geom_condim[g] >= 4
        assert m.geom_friction[g, 0] >= 1.0
    g = ix.gripper_actuator
    assert m.actuator_forcelimited[g] and 40 <= m.actuator_forcerange[g, 1] <= 70


@pytest.mark.parametrize("name", ROBOTS)
def test_gravity_compensated_hold(name: str) -> None:
    spec = load_robot_spec(name)
    m = mujoco.MjModel.from_xml_path(str(spec.mjcf_path))
    d = mujoco.MjData(m)
    ix = mj_robot_indices(spec, m)
    d.qpos[ix.arm_qpos] = spec.home_q
    d.qpos[ix.gripper_qpos] = spec.gripper_open
    d.ctrl[ix.gripper_actuator] = spec.gripper_open
    mujoco.mj_forward(m, d)
    assert d.ncon == 0  # no self-contact at home
    drift = 0.0
    while d.time < 1.0:
        d.ctrl[ix.arm_actuators] = d.qfrc_bias[ix.arm_dof]
        mujoco.mj_step(m, d)
        drift = max(drift, np.abs(d.qpos[ix.arm_qpos] - spec.home_q).max())
    print(name, f"hold drift {drift:.2e} rad")
    assert drift < 1e-3
    assert all(w.number == 0 for w in d.warning)


def _computed_torque(spec, m, d, ix, q_ref, v_ref) -> None:
    M = mj_full_mass_matrix(m, d)[np.ix_(ix.arm_dof, ix.arm_dof)]
    e, de = q_ref - d.qpos[ix.arm_qpos], v_ref - d.qvel[ix.arm_dof]
    tau = M @ (spec.kp * e + spec.kd * de) + d.qfrc_bias[ix.arm_dof]
    d.ctrl[ix.arm_actuators] = np.clip(tau, -spec.tau_max, spec.tau_max)


@pytest.mark.parametrize("name", ROBOTS)
def test_default_gains_stable_at_ctrl_dt(name: str) -> None:
    """Default kp/kd under computed torque, sampled at ctrl_dt = 0.01 s: a 0.02 rad step settles unsaturated."""
    spec = load_robot_spec(name)
    m = mujoco.MjModel.from_xml_path(str(spec.mjcf_path))
    d = mujoco.MjData(m)
    ix = mj_robot_indices(spec, m)
    q_goal = spec.home_q.copy()
    d.qpos[ix.arm_qpos] = np.clip(q_goal + 0.02 * np.resize([1, -1], spec.dof), spec.q_min, spec.q_max)
    mujoco.mj_forward(m, d)
    substeps = round(0.01 / m.opt.timestep)
    max_ratio = 0.0
    while d.time < 1.0:
        _computed_torque(spec, m, d, ix, q_goal, np.zeros(spec.dof))
        max_ratio = max(max_ratio, np.abs(d.ctrl[ix.arm_actuators] / spec.tau_max).max())
        for _ in range(substeps):
            mujoco.mj_step(m, d)
    err = np.abs(d.qpos[ix.arm_qpos] - q_goal).max()
    print(name, f"step residual {err:.1e} rad, max |tau|/tau_max {max_ratio:.2f}")
    assert err < 1e-3 and max_ratio < 1.0


@pytest.mark.parametrize("name", ROBOTS)
def test_grasp_and_lift_box(name: str) -> None:
    """Close on a 4.5 cm box resting on the floor, lift it 10 cm, hold: the friction grasp keeps it."""
    spec = load_robot_spec(name)
    ms = robot_mjspec(spec)
    ms.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.01])
    box = ms.worldbody.add_body(name="box", pos=[0.45, 0.0, 0.0225])
    box.add_freejoint()
    box.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.0225] * 3, mass=0.1)
    m = ms.compile()
    d = mujoco.MjData(m)
    ix = mj_robot_indices(spec, m)
    joints = list(spec.arm_joints)
    q_grasp, pe, _ = solve_home(spec.mjcf_path, joints, spec.ee_site, spec.home_q, np.array([0.45, 0, 0.0225]), iters=400)
    q_lift, pe2, _ = solve_home(spec.mjcf_path, joints, spec.ee_site, q_grasp, np.array([0.45, 0, 0.1225]), iters=400)
    assert pe < 1e-4 and pe2 < 1e-4
    d.qpos[ix.arm_qpos] = q_grasp
    d.qpos[ix.gripper_qpos] = spec.gripper_open
    mujoco.mj_forward(m, d)
    bid = m.body("box").id
    substeps = round(0.01 / m.opt.timestep)

    def run(duration: float, grip: float, ref) -> None:
        t0 = d.time
        while d.time - t0 < duration - 1e-9:
            _computed_torque(spec, m, d, ix, *ref(d.time - t0))
            d.ctrl[ix.gripper_actuator] = grip
            for _ in range(substeps):
                mujoco.mj_step(m, d)

    hold_grasp = lambda t: (q_grasp, np.zeros(spec.dof))  # noqa: E731

    def lift(t: float):
        a = min(t, 1.0)  # 1 s smoothstep
        return q_grasp + (3 * a**2 - 2 * a**3) * (q_lift - q_grasp), (6 * a - 6 * a**2) * (q_lift - q_grasp)

    run(0.3, spec.gripper_open, hold_grasp)
    run(0.5, spec.gripper_closed, hold_grasp)
    opening = d.qpos[ix.gripper_qpos].copy()
    assert np.allclose(opening, 0.0225, atol=1e-3)  # stopped by the box, symmetric
    rel0 = d.xpos[bid] - d.site_xpos[ix.ee_site]
    run(1.5, spec.gripper_closed, lift)
    run(1.0, spec.gripper_closed, lambda t: (q_lift, np.zeros(spec.dof)))
    rel1 = d.xpos[bid] - d.site_xpos[ix.ee_site]
    print(name, "box z", d.xpos[bid][2], "slip [mm]", 1e3 * (rel1 - rel0))
    assert d.xpos[bid][2] > 0.0225 + 0.095
    assert np.abs(rel1 - rel0).max() < 3e-3
    assert all(w.number == 0 for w in d.warning)


# --------------------------------------------------------------------------------------------------
# spec validation


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v == math.inf else "-inf" if v == -math.inf else repr(v))
    if isinstance(v, int):
        return str(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(v)


def _write_spec(path: Path, raw: dict) -> Path:
    lines = [f"{k} = {_toml_value(v)}" for k, v in raw.items() if not isinstance(v, dict)]
    for k, v in raw.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            lines += [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def _panda_raw() -> dict:
    spec = load_robot_spec("panda")
    raw = tomllib.loads((spec.mjcf_path.parent / "robot.toml").read_text())
    raw["mjcf"] = str(spec.mjcf_path)  # absolute, so the copy in tmp_path finds it
    return raw


def _set(raw: dict, key: str, value) -> None:
    table = raw["limits"] if key in raw["limits"] else raw["gains"] if key in raw["gains"] else raw
    table[key] = value


def test_spec_from_path_roundtrip(tmp_path: Path) -> None:
    spec = load_robot_spec(_write_spec(tmp_path / "robot.toml", _panda_raw()))
    assert spec.name == "panda" and spec.dof == 7
    assert load_robot_spec(tmp_path).dof == 7  # a folder holding robot.toml works too


BAD_FIELDS = [
    # (field named in the message, mutation)
    ("ee_site", lambda r: r.pop("ee_site")),
    ("colour", lambda r: r.update(colour="red")),
    ("limits", lambda r: r["limits"].pop("j_max")),
    ("gains", lambda r: r["gains"].update(ki=[0.0] * 7)),
    ("home_q", lambda r: r.update(home_q=[0.0] * 6)),
    ("q_min", lambda r: _set(r, "q_min", [math.nan] + r["limits"]["q_min"][1:])),
    ("kd", lambda r: _set(r, "kd", [math.inf] * 7)),
    ("q_min", lambda r: _set(r, "q_min", [3.0] + r["limits"]["q_min"][1:])),
    ("v_max", lambda r: _set(r, "v_max", [0.0] * 7)),
    ("a_max", lambda r: _set(r, "a_max", [-1.0] * 7)),
    ("j_max", lambda r: _set(r, "j_max", [0.0] * 7)),
    ("tau_max", lambda r: _set(r, "tau_max", [-87.0] * 7)),
    ("kp", lambda r: _set(r, "kp", [True] * 7)),
    ("kp", lambda r: _set(r, "kp", "400")),
    ("kd", lambda r: _set(r, "kd", ["40"] * 7)),
    ("kd", lambda r: _set(r, "kd", [[40.0]] * 7)),
    ("home_q", lambda r: r.update(home_q=[0.0] * 7)),  # joint4 range is [-3.07, -0.07]
    ("arm_joints", lambda r: r.update(arm_joints=r["arm_joints"][:-1] + ["joint8"])),
    ("arm_joints", lambda r: r.update(arm_joints="joint1")),
    ("arm_actuators", lambda r: r.update(arm_actuators=r["arm_actuators"][:-1] + ["motor9"])),
    ("arm_actuators", lambda r: r.update(arm_actuators=r["arm_actuators"][:-1] + ["gripper"])),
    ("ee_site", lambda r: r.update(ee_site="flange")),
    ("gripper_joints", lambda r: r.update(gripper_joints=["finger_joint1", "finger_joint3"])),
    ("gripper_actuator", lambda r: r.update(gripper_actuator="hand")),
    ("gripper_open", lambda r: r.update(gripper_open=0.08)),
    ("gripper_closed", lambda r: r.update(gripper_closed="shut")),
    ("tau_max", lambda r: _set(r, "tau_max", [80.0] * 4 + [12.0] * 3)),
    ("q_min/q_max", lambda r: _set(r, "q_max", [3.0] + r["limits"]["q_max"][1:])),
    ("mjcf", lambda r: r.update(mjcf="missing.xml")),
    ("name", lambda r: r.update(name="")),
]


@pytest.mark.parametrize("field,mutate", BAD_FIELDS, ids=[f"{i}-{f}" for i, (f, _) in enumerate(BAD_FIELDS)])
def test_spec_validation_names_field(tmp_path: Path, field: str, mutate) -> None:
    raw = _panda_raw()
    mutate(raw)
    path = _write_spec(tmp_path / "robot.toml", raw)
    with pytest.raises(RobotModelError) as exc:
        load_robot_spec(path)
    msg = str(exc.value)
    print(msg)
    assert field in msg
    if field != "name":
        assert "'panda'" in msg  # names the robot


def test_unknown_names_list_valid_ones(tmp_path: Path) -> None:
    raw = _panda_raw()
    raw["ee_site"] = "flange"
    with pytest.raises(RobotModelError, match=r"flange.*valid sites: tcp"):
        load_robot_spec(_write_spec(tmp_path / "robot.toml", raw))
    raw = _panda_raw()
    raw["arm_joints"][0] = "shoulder"
    with pytest.raises(RobotModelError, match=r"'shoulder'.*valid joints:.*finger_joint1.*joint1"):
        load_robot_spec(_write_spec(tmp_path / "robot.toml", raw))


def test_non_hinge_arm_joint_rejected(tmp_path: Path) -> None:
    raw = _panda_raw()
    raw["arm_joints"][-1] = "finger_joint1"
    raw["gripper_joints"] = ["finger_joint2"]
    with pytest.raises(RobotModelError, match=r"arm_joints.*finger_joint1.*SLIDE.*hinge"):
        load_robot_spec(_write_spec(tmp_path / "robot.toml", raw))


def test_bad_toml_and_missing_file(tmp_path: Path) -> None:
    (tmp_path / "robot.toml").write_text("name = [unclosed\n")
    with pytest.raises(RobotModelError, match="not valid TOML"):
        load_robot_spec(tmp_path / "robot.toml")
    with pytest.raises(RobotModelError, match="not found"):
        load_robot_spec(tmp_path / "nothing" / "robot.toml")


# --------------------------------------------------------------------------------------------------
# a third, differently named arm proves the format is general

TOY_ARM_XML = """
<mujoco model="toy_arm">
  <compiler angle="radian" autolimits="true"/>
  <option integrator="implicitfast"/>
  <default>
    <joint armature="0.05" damping="0.2"/>
    <geom contype="2" conaffinity="1"/>
  </default>
  <worldbody>
    <body name="pedestal">
      <inertial mass="2" pos="0 0 0.05" diaginertia="0.01 0.01 0.01"/>
      <geom type="cylinder" size="0.06 0.05" pos="0 0 0.05"/>
      <body name="turret" pos="0 0 0.2">
        <inertial mass="1.5" pos="0.01 0 -0.03" fullinertia="0.004 0.005 0.003 0.0002 -0.0001 0.0003"/>
        <joint name="yaw" axis="0 0 1" range="-3 3"/>
        <geom type="capsule" size="0.04" fromto="0 0 -0.1 0 0 0"/>
        <body name="upper" quat="0.7071067811865476 0.7071067811865476 0 0">
          <inertial mass="1.2" pos="0.15 0.01 0" fullinertia="0.002 0.02 0.02 0.0001 0 -0.0002"/>
          <joint name="pitch_a" axis="0 0 1" range="-2 2"/>
          <geom type="capsule" size="0.035" fromto="0 0 0 0.3 0 0"/>
          <body name="lower" pos="0.3 0 0" euler="0 0 0.3">
            <inertial mass="0.8" pos="0.12 0 0.01" diaginertia="0.001 0.012 0.012"/>
            <joint name="pitch_b" axis="0 0 1" range="-2.5 2.5"/>
            <geom type="capsule" size="0.03" fromto="0 0 0 0.25 0 0"/>
            <body name="tool" pos="0.25 0 0" quat="0.5 0.5 0.5 0.5">
              <inertial mass="0.4" pos="0 0 0.04" diaginertia="0.0005 0.0004 0.0003"/>
              <joint name="roll" axis="0 0 1" range="-3 3"/>
              <geom type="box" size="0.02 0.05 0.02" pos="0 0 0.03"/>
              <site name="grip_point" pos="0.01 0 0.1" quat="0.9 0.1 0.3 0.2"/>
              <body name="jaw_l" pos="0 0 0.05">
                <inertial mass="0.02" pos="0 0 0.02" diaginertia="1e-5 1e-5 1e-6"/>
                <joint name="jaw_a" type="slide" axis="0 1 0" range="0 0.03"/>
                <geom type="box" size="0.005 0.005 0.02" pos="0 0.005 0.02"/>
              </body>
              <body name="jaw_r" pos="0 0 0.05" quat="0 0 0 1">
                <inertial mass="0.02" pos="0 0 0.02" diaginertia="1e-5 1e-5 1e-6"/>
                <joint name="jaw_b" type="slide" axis="0 1 0" range="0 0.03"/>
                <geom type="box" size="0.005 0.005 0.02" pos="0 0.005 0.02"/>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <equality><joint joint1="jaw_a" joint2="jaw_b"/></equality>
  <actuator>
    <motor name="t_yaw" joint="yaw" ctrlrange="-20 20"/>
    <motor name="t_pa" joint="pitch_a" ctrlrange="-20 20"/>
    <motor name="t_pb" joint="pitch_b" ctrlrange="-10 10"/>
    <motor name="t_roll" joint="roll" ctrlrange="-5 5"/>
    <position name="jaw" joint="jaw_a" kp="500" ctrlrange="0 0.03" forcerange="-40 40"/>
  </actuator>
</mujoco>
"""


def test_third_arm_from_path(tmp_path: Path) -> None:
    (tmp_path / "toy_arm.xml").write_text(TOY_ARM_XML)
    raw = {
        "name": "toy_arm", "mjcf": "toy_arm.xml",
        "arm_joints": ["yaw", "pitch_a", "pitch_b", "roll"],
        "arm_actuators": ["t_yaw", "t_pa", "t_pb", "t_roll"],
        "ee_site": "grip_point", "gripper_joints": ["jaw_a", "jaw_b"], "gripper_actuator": "jaw",
        "gripper_open": 0.03, "gripper_closed": 0.0, "home_q": [0.1, 0.5, -0.8, 0.2],
        "limits": {"q_min": [-3.0, -2.0, -2.5, -3.0], "q_max": [3.0, 2.0, 2.5, 3.0],
                   "v_max": [2.0] * 4, "a_max": [10.0] * 4, "j_max": [1000.0] * 4,
                   "tau_max": [20.0, 20.0, 10.0, 5.0]},
        "gains": {"kp": [100.0] * 4, "kd": [20.0] * 4},
    }
    spec = load_robot_spec(_write_spec(tmp_path / "robot.toml", raw))
    assert spec.dof == 4 and spec.ee_site == "grip_point"
    err = _compare_with_mujoco(spec, n=20, seed=3)
    print("toy_arm", {k: f"{v:.1e}" for k, v in err.items()})
    assert all(v <= TOL for v in err.values()), err
    red = build_pinocchio_model(spec, lock_gripper=True, gripper_q=np.array([0.01, 0.01]))
    assert red.joint_names == ("yaw", "pitch_a", "pitch_b", "roll")
    with pytest.raises(RobotModelError, match="gripper_q"):
        build_pinocchio_model(spec, lock_gripper=True, gripper_q=np.array([0.01]))


def test_fuzzed_specs_fail_cleanly(tmp_path: Path) -> None:
    """Mutated specs either load or raise RobotModelError: no other exception escapes."""
    rng = np.random.default_rng(7)
    junk = ["x", "", 1, -2.5, True, [], [1.0] * 3, [math.nan] * 7, [1e308] * 7, ["joint1"] * 7, [0] * 7]
    outcomes = {"loaded": 0, "refused": 0}
    for i in range(150):
        raw = _panda_raw()
        tables = [raw, raw["limits"], raw["gains"]]
        for _ in range(rng.integers(1, 3)):
            table = tables[rng.integers(len(tables))]
            key = list(table)[rng.integers(len(table))]
            if isinstance(table[key], dict):
                continue
            kind = rng.integers(4)
            if kind == 0:
                del table[key]
            elif kind == 1:
                table[key] = junk[rng.integers(len(junk))]
            elif kind == 2 and isinstance(table[key], list) and table[key]:
                j = rng.integers(len(table[key]))
                table[key][j] = [math.nan, math.inf, -1.0, 0.0, 1e6, "a"][rng.integers(6)]
            else:
                table[key] = f"name_{rng.integers(100)}"
        path = _write_spec(tmp_path / f"robot_{i}.toml", raw)
        try:
            load_robot_spec(path)
            outcomes["loaded"] += 1
        except RobotModelError:
            outcomes["refused"] += 1
    print(outcomes)
    assert outcomes["refused"] >= 100
