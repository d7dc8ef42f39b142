"""MujocoArmDynamics: arm-block indexing inside a larger scene, lazy kinematics, split stepping."""
from __future__ import annotations

import warnings
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from tcot_hybrid.dynamics import MujocoArmDynamics
from tcot_hybrid.errors import RobotModelError
from tcot_hybrid.robot import build_pinocchio_model, load_robot_spec, robot_mjspec

ROBOTS = ("panda", "ur5e")


def _cube(body_parent, name, pos):
    b = body_parent.add_body()
    b.name = name
    b.pos = pos
    b.add_freejoint()
    g = b.add_geom()
    g.type = mujoco.mjtGeom.mjGEOM_BOX
    g.size = [0.02, 0.02, 0.02]
    g.mass = 0.1
    return b


def scene(spec, *, cube_first: bool = True, sim_dt: float = 0.002):
    """Robot + floor + free cubes. ``cube_first`` puts the free bodies before the robot so the arm's
    qpos/dof addresses do not start at 0 (the fingers come after the arm)."""
    robot = robot_mjspec(spec)
    if cube_first:
        world = mujoco.MjSpec()
        for name in ("cone", "impratio"):
            setattr(world.option, name, getattr(robot.option, name))
        _cube(world.worldbody, "cube_first", [0.5, 0.2, 0.05])
    else:
        world = robot
    world.option.timestep = sim_dt
    world.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    floor = world.worldbody.add_geom()
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = [2, 2, 0.1]
    floor.pos = [0, 0, -0.01]
    _cube(world.worldbody, "cube_last", [0.55, -0.2, 0.05])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "empty prefix may prevent saving": we never save this model
        if cube_first:
            world.attach(robot, frame=world.worldbody.add_frame(), prefix="")
        m = world.compile()
    return m, mujoco.MjData(m)


def full_M(m, d):
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    return M


def random_state(spec, m, d, dyn, rng):
    d.qpos[dyn.qpos_adr] = rng.uniform(spec.q_min, spec.q_max)
    d.qvel[:] = rng.normal(0, 0.5, m.nv)


@pytest.mark.parametrize("robot", ROBOTS)
def test_arm_block_matches_full_model(robot):
    spec = load_robot_spec(robot)
    m, d = scene(spec)
    dyn = MujocoArmDynamics(m, d, spec)
    assert dyn.dof_adr[0] >= 6, "free cubes come before the robot"
    rng = np.random.default_rng(0)
    for _ in range(5):
        random_state(spec, m, d, dyn, rng)
        mujoco.mj_step1(m, d)
        dyn.update()
        M = full_M(m, d)
        idx = np.ix_(dyn.dof_adr, dyn.dof_adr)
        np.testing.assert_array_equal(dyn.M, M[idx])
        np.testing.assert_array_equal(dyn.q, d.qpos[dyn.qpos_adr])
        np.testing.assert_array_equal(dyn.qd, d.qvel[dyn.dof_adr])
        np.testing.assert_array_equal(dyn.bias, d.qfrc_bias[dyn.dof_adr])
        np.testing.assert_array_equal(dyn.passive, d.qfrc_passive[dyn.dof_adr])
        np.testing.assert_allclose(dyn.bias_net, dyn.bias - dyn.passive)
        assert dyn.t == d.time
        assert np.all(np.diag(dyn.M) >= m.dof_armature[dyn.dof_adr]), "armature is part of M"


@pytest.mark.parametrize("robot", ROBOTS)
def test_mass_matrix_and_bias_match_pinocchio(robot):
    """Cross-check the MuJoCo arm block against Pinocchio (gripper at the MJCF qpos0, fingers still)."""
    import pinocchio as pin

    spec = load_robot_spec(robot)
    m, d = scene(spec, cube_first=False)
    dyn = MujocoArmDynamics(m, d, spec)
    pr = build_pinocchio_model(spec, lock_gripper=True)
    pd = pr.model.createData()
    rng = np.random.default_rng(1)
    for _ in range(3):
        d.qpos[:] = m.qpos0
        d.qvel[:] = 0
        d.qpos[dyn.qpos_adr] = rng.uniform(spec.q_min, spec.q_max)
        d.qvel[dyn.dof_adr] = rng.normal(0, 0.5, spec.dof)
        mujoco.mj_step1(m, d)
        dyn.update()
        M_pin = pin.crba(pr.model, pd, dyn.q)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        # The locked fingers add no dof but their (zero) velocity coupling is the same; M of the
        # arm block is independent of finger velocities.
        np.testing.assert_allclose(dyn.M, M_pin, atol=1e-9)
        np.testing.assert_allclose(dyn.bias, pin.rnea(pr.model, pd, dyn.q, dyn.qd, np.zeros(spec.dof)), atol=1e-9)


@pytest.mark.parametrize("robot", ROBOTS)
def test_jacobian_and_pose_are_lazy_and_correct(robot, monkeypatch):
    spec = load_robot_spec(robot)
    m, d = scene(spec)
    dyn = MujocoArmDynamics(m, d, spec)
    d.qpos[dyn.qpos_adr] = spec.home_q
    mujoco.mj_step1(m, d)
    dyn.update()
    calls = []
    real = mujoco.mj_jacSite
    monkeypatch.setattr(mujoco, "mj_jacSite", lambda *a: (calls.append(1), real(*a))[1])
    J1 = dyn.ee_jacobian()
    J2 = dyn.ee_jacobian()
    assert J1 is J2 and len(calls) == 1, "computed at most once per tick"
    p, R = dyn.ee_pose()
    assert np.allclose(p, d.site_xpos[dyn.ee_site_id]) and np.allclose(R @ R.T, np.eye(3))
    # Home: TCP ~ (0.45, 0, 0.35) pointing down (robot spec convention).
    np.testing.assert_allclose(p, [0.45, 0.0, 0.35], atol=2e-3)
    np.testing.assert_allclose(R, np.diag([1.0, -1.0, -1.0]), atol=2e-3)
    # Finite differences of the pose along each arm joint give the Jacobian columns.
    eps = 1e-6
    d2 = mujoco.MjData(m)
    for i in range(spec.dof):
        d2.qpos[:] = d.qpos
        d2.qpos[dyn.qpos_adr[i]] += eps
        mujoco.mj_kinematics(m, d2)
        dp = (d2.site_xpos[dyn.ee_site_id] - p) / eps
        dR = d2.site_xmat[dyn.ee_site_id].reshape(3, 3) @ R.T
        w = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]]) / (2 * eps)
        np.testing.assert_allclose(J1[:3, i], dp, atol=1e-5)
        np.testing.assert_allclose(J1[3:, i], w, atol=1e-5)
    # A new tick invalidates the cache.
    mujoco.mj_step2(m, d)
    mujoco.mj_step1(m, d)
    dyn.update()
    dyn.ee_jacobian()
    assert len(calls) == 2


def test_update_reuses_read_only_buffers():
    spec = load_robot_spec("panda")
    m, d = scene(spec)
    dyn = MujocoArmDynamics(m, d, spec)
    ids = [id(a) for a in (dyn.q, dyn.qd, dyn.M, dyn.bias, dyn.bias_net)]
    for _ in range(3):
        mujoco.mj_step1(m, d)
        dyn.update()
        mujoco.mj_step2(m, d)
    assert ids == [id(a) for a in (dyn.q, dyn.qd, dyn.M, dyn.bias, dyn.bias_net)]
    for a in (dyn.q, dyn.qd, dyn.M, dyn.bias, dyn.ee_jacobian(), dyn.ee_pose()[0]):
        with pytest.raises(ValueError):
            a[0] = 1.0
    q_before = dyn.q.copy()
    d.qpos[dyn.qpos_adr] += 0.1  # values are copies of the tick, not live views of MjData
    np.testing.assert_array_equal(dyn.q, q_before)


def test_non_contiguous_joint_order_uses_the_gather_path():
    """A spec listing the arm joints in another order (not a slice) gives the permuted blocks."""
    spec = load_robot_spec("panda")
    m, d = scene(spec)
    perm = np.array([6, 0, 5, 1, 4, 2, 3])
    fake = SimpleNamespace(name="panda_permuted", arm_joints=tuple(spec.arm_joints[i] for i in perm),
                           arm_actuators=tuple(spec.arm_actuators[i] for i in perm), ee_site=spec.ee_site,
                           tau_max=spec.tau_max[perm])
    dyn = MujocoArmDynamics(m, d, spec)
    dyn_p = MujocoArmDynamics(m, d, fake)
    assert dyn_p._dsl is None and dyn_p._qsl is None and dyn_p._asl is None
    d.qpos[dyn.qpos_adr] = spec.home_q
    d.qvel[dyn.dof_adr] = np.arange(7) * 0.1
    mujoco.mj_step1(m, d)
    dyn.update()
    dyn_p.update()
    np.testing.assert_array_equal(dyn_p.q, dyn.q[perm])
    np.testing.assert_array_equal(dyn_p.qd, dyn.qd[perm])
    np.testing.assert_array_equal(dyn_p.M, dyn.M[np.ix_(perm, perm)])
    np.testing.assert_array_equal(dyn_p.bias_net, dyn.bias_net[perm])
    np.testing.assert_array_equal(dyn_p.ee_jacobian(), dyn.ee_jacobian()[:, perm])
    tau = np.arange(1.0, 8.0)
    dyn_p.write_ctrl(tau)
    np.testing.assert_array_equal(d.ctrl[dyn.actuator_ids][perm], tau)


def test_write_ctrl_touches_only_arm_actuators():
    spec = load_robot_spec("ur5e")
    m, d = scene(spec)
    dyn = MujocoArmDynamics(m, d, spec)
    grip = m.actuator(spec.gripper_actuator).id
    d.ctrl[grip] = 0.03
    dyn.write_ctrl(np.full(spec.dof, 2.5))
    assert d.ctrl[grip] == 0.03
    np.testing.assert_array_equal(d.ctrl[dyn.actuator_ids], 2.5)


def test_bad_robot_descriptions_are_refused():
    spec = load_robot_spec("panda")
    m, d = scene(spec)
    base = dict(name="bad", arm_joints=spec.arm_joints, arm_actuators=spec.arm_actuators, ee_site=spec.ee_site,
                tau_max=spec.tau_max)
    with pytest.raises(RobotModelError, match="no_such_joint"):
        MujocoArmDynamics(m, d, SimpleNamespace(**{**base, "arm_joints": spec.arm_joints[:-1] + ("no_such_joint",)}))
    with pytest.raises(RobotModelError, match="site"):
        MujocoArmDynamics(m, d, SimpleNamespace(**{**base, "ee_site": "nope"}))
    # The gripper's position actuator is not a torque motor on an arm joint.
    with pytest.raises(RobotModelError, match="gripper"):
        MujocoArmDynamics(m, d, SimpleNamespace(**{**base, "arm_actuators": spec.arm_actuators[:-1] + ("gripper",)}))
    # Actuator order must follow the joint order.
    swapped = (spec.arm_actuators[1], spec.arm_actuators[0]) + spec.arm_actuators[2:]
    with pytest.raises(RobotModelError, match="drive joint"):
        MujocoArmDynamics(m, d, SimpleNamespace(**{**base, "arm_actuators": swapped}))
    # tau_max beyond the ctrlrange would be clamped silently by MuJoCo.
    with pytest.raises(RobotModelError, match="clamp"):
        MujocoArmDynamics(m, d, SimpleNamespace(**{**base, "tau_max": spec.tau_max * 2}))


@pytest.mark.parametrize("robot", ROBOTS)
def test_split_step_equals_mj_step_with_implicitfast(robot):
    """mj_step1 → set ctrl → mj_step2 is bit-identical to set ctrl → mj_step (implicitfast, contacts)."""
    spec = load_robot_spec(robot)
    m, d_a = scene(spec)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    d_b = mujoco.MjData(m)
    dyn = MujocoArmDynamics(m, d_a, spec)
    rng = np.random.default_rng(3)
    for d in (d_a, d_b):
        d.qpos[dyn.qpos_adr] = spec.home_q
    contacts = 0
    for k in range(300):  # 0.6 s: the cubes fall onto the floor meanwhile
        tau = rng.uniform(-0.3, 0.3, spec.dof) * spec.tau_max
        mujoco.mj_step1(m, d_a)
        dyn.update()
        # What the controller sees after mj_step1 is the dynamics of the current state.
        d_c = mujoco.MjData(m)
        d_c.qpos[:], d_c.qvel[:], d_c.time = d_a.qpos, d_a.qvel, d_a.time
        mujoco.mj_forward(m, d_c)
        np.testing.assert_allclose(dyn.M, full_M(m, d_c)[np.ix_(dyn.dof_adr, dyn.dof_adr)], rtol=0, atol=1e-12)
        np.testing.assert_allclose(dyn.bias, d_c.qfrc_bias[dyn.dof_adr], rtol=0, atol=1e-12)
        dyn.write_ctrl(tau)
        mujoco.mj_step2(m, d_a)
        d_b.ctrl[dyn.actuator_ids] = tau
        mujoco.mj_step(m, d_b)
        contacts += d_a.ncon
        np.testing.assert_array_equal(d_a.qpos, d_b.qpos)
        np.testing.assert_array_equal(d_a.qvel, d_b.qvel)
        assert d_a.time == d_b.time
    assert contacts > 0, "the comparison must include contacts"
    assert not any(d_a.warning[w].number for w in range(len(d_a.warning)))


@pytest.mark.parametrize("robot", ROBOTS)
def test_inverse_torques_match_mujoco_inverse_dynamics_with_air_drag(robot):
    """M qdd + bias - passive, armature and fluid drag included, equals MuJoCo's own inverse dynamics (constraints off:
    the planned motion's torques, no contacts); the live MjData is left untouched."""
    spec = load_robot_spec(robot)
    m, d = scene(spec)
    m.opt.density, m.opt.viscosity = 1.2, 2e-5  # robosuite's air: the passive forces include fluid drag
    dyn = MujocoArmDynamics(m, d, spec)
    rng = np.random.default_rng(3)
    n = 6
    q = rng.uniform(spec.q_min, spec.q_max, (n, dyn.n))
    qd, qdd = rng.normal(0, 1.0, (n, dyn.n)), rng.normal(0, 3.0, (n, dyn.n))
    before = d.qpos.copy(), d.qvel.copy()
    tau = dyn.inverse_torques(q, qd, qdd)
    np.testing.assert_array_equal(d.qpos, before[0])
    np.testing.assert_array_equal(d.qvel, before[1])
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    ref = mujoco.MjData(m)
    drag_seen = 0.0
    for k in range(n):
        ref.qpos[:] = d.qpos
        ref.qvel[:] = 0.0
        ref.qacc[:] = 0.0
        ref.qpos[dyn.qpos_adr], ref.qvel[dyn.dof_adr], ref.qacc[dyn.dof_adr] = q[k], qd[k], qdd[k]
        mujoco.mj_inverse(m, ref)
        np.testing.assert_allclose(tau[k], ref.qfrc_inverse[dyn.dof_adr], atol=1e-9)
        drag_seen = max(drag_seen, float(np.abs(ref.qfrc_fluid[dyn.dof_adr]).max()))
    assert drag_seen > 0.0, "the check covers the fluid drag term"
