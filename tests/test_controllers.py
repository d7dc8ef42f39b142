"""Low-level torque controllers: registry, hold, tracking, bumpless switching, torque limits, MPC fallback.

Each test builds a minimal scene (robot via ``robot_mjspec`` + floor plane + a free cube) and runs a
minimal tick loop (``mj_step1`` → ``dyn.update()`` → controller → safety → ``mj_step2`` → substeps)
mirroring the real one. Run with ``-s`` to see the measured figures.
"""
from __future__ import annotations

import statistics
import time

import mujoco
import numpy as np
import pytest

from tcot_hybrid.controllers import Command, list_controllers, make_controller
from tcot_hybrid.controllers.base import STATUS_BLENDING, STATUS_FALLBACK, STATUS_OK
from tcot_hybrid.controllers.mpc import JointMPC
from tcot_hybrid.dynamics import MujocoArmDynamics
from tcot_hybrid.errors import ConfigError, ControllerError
from tcot_hybrid.robot import load_robot_spec, robot_mjspec
from tcot_hybrid.safety import SafetyLayer
from tcot_hybrid.smoothing import JointReference

ROBOTS = ("panda", "ur5e")
CONTROLLERS = ("computed_torque", "joint_pd", "mpc", "osc")
CTRL_DTS = (0.002, 0.004, 0.01)


# --- minimal scene and tick loop ---------------------------------------------------------------------
class Rig:
    """Robot + floor + free cube, the arm dynamics view, a safety layer and a tick loop."""

    _specs: dict = {}

    def __init__(self, robot: str, *, ctrl_dt: float = 0.01, sim_dt: float = 0.002, q0=None):
        if robot not in Rig._specs:
            Rig._specs[robot] = load_robot_spec(robot)
        self.spec = spec = Rig._specs[robot]
        s = robot_mjspec(spec)
        s.option.timestep = sim_dt
        s.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        floor = s.worldbody.add_geom()
        floor.type = mujoco.mjtGeom.mjGEOM_PLANE
        floor.size = [2, 2, 0.1]
        cube = s.worldbody.add_body()
        cube.name = "cube"
        cube.pos = [0.5, 0.25, 0.02]
        cube.add_freejoint()
        g = cube.add_geom()
        g.type = mujoco.mjtGeom.mjGEOM_BOX
        g.size = [0.02, 0.02, 0.02]
        g.mass = 0.1
        self.m = m = s.compile()
        self.d = d = mujoco.MjData(m)
        self.dyn = MujocoArmDynamics(m, d, spec)
        d.qpos[self.dyn.qpos_adr] = spec.home_q if q0 is None else q0
        d.ctrl[m.actuator(spec.gripper_actuator).id] = spec.gripper_open
        mujoco.mj_forward(m, d)
        self.ctrl_dt = ctrl_dt
        self.substeps = round(ctrl_dt / sim_dt)
        self.safety = SafetyLayer(spec)
        self.last_tau = None

    @property
    def q(self) -> np.ndarray:
        return self.d.qpos[self.dyn.qpos_adr].copy()

    def tick(self, controller, ref_fn, *, preview=True):
        """One control period; returns (reference, Command, SafeCommand)."""
        m, d, dyn = self.m, self.d, self.dyn
        mujoco.mj_step1(m, d)
        dyn.update()
        ref = ref_fn(d.time)
        pv = None
        if preview and controller.preview_horizon:
            pv = np.array([ref_fn(d.time + (j + 1) * self.ctrl_dt).q for j in range(controller.preview_horizon)])
        cmd = controller.compute(dyn, ref, preview=pv)
        safe = self.safety.filter(cmd, dyn, ref)
        assert np.all(np.isfinite(safe.tau)) and np.all(np.abs(safe.tau) <= self.spec.tau_max)
        dyn.write_ctrl(safe.tau)
        mujoco.mj_step2(m, d)
        for _ in range(self.substeps - 1):
            mujoco.mj_step(m, d)
        self.last_tau = safe.tau
        return ref, cmd, safe

    def assert_no_sim_warnings(self):
        assert not any(self.d.warning[w].number for w in range(len(self.d.warning)))


def make(name, spec, ctrl_dt, **params):
    """Controller for the nominal tests. MPC gets no wall-clock deadline: solve times on a shared
    machine spike under load, and these tests check control, not the scheduler (the deadline has its
    own test)."""
    if name == "mpc":
        params.setdefault("time_limit_fraction", None)
    return make_controller(name, spec, ctrl_dt=ctrl_dt, params=params)


def hold_ref(q):
    q = np.array(q, dtype=float)
    z = np.zeros_like(q)
    return lambda t: JointReference(q, z, z)


def quintic_ref(q0, q1, t0, duration):
    """Rest-to-rest quintic from q0 (before t0) to q1 (after t0 + duration)."""
    q0, q1 = np.array(q0, dtype=float), np.array(q1, dtype=float)
    dq = q1 - q0

    def ref(t):
        s = min(max((t - t0) / duration, 0.0), 1.0)
        p = 10 * s**3 - 15 * s**4 + 6 * s**5
        v = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
        a = (60 * s - 180 * s**2 + 120 * s**3) / duration**2
        return JointReference(q0 + dq * p, dq * v, dq * a)

    return ref


def multisine_ref(q0, amp=0.3, freq_hz=0.3):
    """Continuous motion through every joint (phases spread), starting at q0 at t = 0."""
    q0 = np.array(q0, dtype=float)
    ph = np.linspace(0.0, np.pi, q0.size)
    w = 2 * np.pi * freq_hz

    def ref(t):
        return JointReference(q0 + amp * (np.sin(w * t + ph) - np.sin(ph)), amp * w * np.cos(w * t + ph),
                              -amp * w * w * np.sin(w * t + ph))

    return ref


def move_target(spec, dist=0.3):
    """A pose `dist` rad from home on every joint (alternating signs), kept inside the limits."""
    sign = np.where(np.arange(spec.dof) % 2 == 0, 1.0, -1.0)
    q1 = spec.home_q + dist * sign
    inside = (q1 > spec.q_min + 0.05) & (q1 < spec.q_max - 0.05)
    return np.where(inside, q1, spec.home_q - dist * sign)


# --- registry and configuration ---------------------------------------------------------------------
def test_registry_lists_every_controller_and_refuses_unknown_names():
    assert set(CONTROLLERS) <= set(list_controllers())
    spec = load_robot_spec("panda")
    with pytest.raises(ControllerError) as exc:
        make_controller("no_such_controller", spec, ctrl_dt=0.01)
    for name in CONTROLLERS:
        assert name in str(exc.value)


def test_config_defaults_params_and_errors():
    spec = load_robot_spec("panda")
    ct = make_controller("computed_torque", spec, ctrl_dt=0.01)
    np.testing.assert_array_equal(ct.kp, spec.kp)  # defaults derived from the robot spec
    np.testing.assert_array_equal(ct.kd, spec.kd)
    ct2 = make_controller("computed_torque", spec, ctrl_dt=0.01, params={"kp_scale": 0.5})
    np.testing.assert_allclose(ct2.kp, 0.5 * spec.kp)
    cfg = type(ct).Config(kd_scale=0.5)
    ct3 = make_controller("computed_torque", spec, ctrl_dt=0.01, config=cfg, params={"kp_scale": 0.25})
    np.testing.assert_allclose(ct3.kd, 0.5 * spec.kd)
    np.testing.assert_allclose(ct3.kp, 0.25 * spec.kp)
    with pytest.raises(ConfigError, match="no_such_field"):
        make_controller("osc", spec, ctrl_dt=0.01, params={"no_such_field": 1.0})
    with pytest.raises(ConfigError, match="kp_scale"):
        make_controller("joint_pd", spec, ctrl_dt=0.01, params={"kp_scale": -1.0})
    with pytest.raises(ConfigError, match="MPCConfig"):
        make_controller("mpc", spec, ctrl_dt=0.01, config=ct.config)
    with pytest.raises(ConfigError, match=r"kp needs 7 values"):
        make_controller("joint_pd", spec, ctrl_dt=0.01, params={"kp": (100.0, 100.0)})
    # Gains too high to be sampled at ctrl_dt are refused with the field and the figure.
    with pytest.raises(ConfigError, match=r"kp.*ctrl_dt"):
        make_controller("computed_torque", spec, ctrl_dt=0.01, params={"kp_scale": 10.0})
    make_controller("computed_torque", spec, ctrl_dt=0.002, params={"kp_scale": 10.0})  # fine at 2 ms
    with pytest.raises(ConfigError, match=r"kd.*ctrl_dt"):
        make_controller("osc", spec, ctrl_dt=0.01, params={"pos_kd": 200.0})
    with pytest.raises(ConfigError, match="torque_nodes"):
        make_controller("mpc", spec, ctrl_dt=0.01, params={"horizon": 4, "torque_nodes": 5})
    with pytest.raises(ConfigError, match="ctrl_dt"):
        make_controller("mpc", spec, ctrl_dt=0.0)
    # A CLI that types every parameter as float: lossless conversions only.
    mpc = make_controller("mpc", spec, ctrl_dt=0.01, params={"horizon": 12.0, "compensate_passive": 0.0})
    assert mpc.horizon == 12 and mpc.config.compensate_passive is False
    with pytest.raises(ConfigError, match="horizon"):
        make_controller("mpc", spec, ctrl_dt=0.01, params={"horizon": 12.5})


# --- hold and tracking -----------------------------------------------------------------------------
CASES = [(r, c, 0.01) for r in ROBOTS for c in CONTROLLERS] + [("panda", c, dt) for c in CONTROLLERS for dt in (0.002, 0.004)]


@pytest.mark.parametrize("robot,name,ctrl_dt", CASES)
def test_holds_home_pose(robot, name, ctrl_dt):
    """Start 10 mrad off home (cube on the floor); after 2 s every joint is within 2 mrad of home."""
    spec = load_robot_spec(robot)
    offset = 0.01 * np.where(np.arange(spec.dof) % 2 == 0, 1.0, -1.0)
    rig = Rig(robot, ctrl_dt=ctrl_dt, q0=spec.home_q + offset)
    ctrl = make(name, rig.spec, ctrl_dt)
    ctrl.reset(rig.dyn, None)
    ref = hold_ref(spec.home_q)
    for _ in range(round(2.0 / ctrl_dt)):
        _, cmd, safe = rig.tick(ctrl, ref)
        assert cmd.status == STATUS_OK, cmd.detail
    err = np.abs(rig.q - spec.home_q).max()
    assert err <= 2e-3, f"{robot}/{name}: {err * 1e3:.3f} mrad from home after 2 s"
    assert rig.safety.faults == 0 and rig.safety.saturations == 0
    rig.assert_no_sim_warnings()


@pytest.mark.parametrize("robot,name,ctrl_dt", CASES)
def test_tracks_a_move_of_0p3_rad(robot, name, ctrl_dt):
    """A 1 s quintic move 0.3 rad on every joint: bounded error in motion, settled after."""
    spec = load_robot_spec(robot)
    rig = Rig(robot, ctrl_dt=ctrl_dt)
    ctrl = make(name, rig.spec, ctrl_dt)
    ctrl.reset(rig.dyn, None)
    q1 = move_target(spec)
    ref_fn = quintic_ref(spec.home_q, q1, 0.1, 1.0)
    errs = []
    for _ in range(round(1.6 / ctrl_dt)):
        ref, cmd, safe = rig.tick(ctrl, ref_fn)
        errs.append(np.abs(ref.q - rig.dyn.q).max())  # error at the tick the command was computed
        assert cmd.status == STATUS_OK and safe.status == "ok", (cmd.detail, safe.events)
    max_err = max(errs)
    final = np.abs(rig.q - q1).max()
    print(f"\n{robot}/{name} ctrl_dt={ctrl_dt}: max tracking error {max_err * 1e3:.2f} mrad, "
          f"final {final * 1e3:.3f} mrad")
    assert max_err <= 5e-3
    assert final <= 1e-3
    rig.assert_no_sim_warnings()


def test_mpc_uses_the_preview():
    """With the reference preview MPC anticipates the motion; extrapolating it (no preview) lags more."""
    spec = load_robot_spec("panda")
    errs = {}
    for use_preview in (True, False):
        rig = Rig("panda")
        ctrl = make("mpc", rig.spec, 0.01)
        ref_fn = quintic_ref(spec.home_q, move_target(spec), 0.1, 1.0)
        e = []
        for _ in range(130):
            ref, cmd, _ = rig.tick(ctrl, ref_fn, preview=use_preview)
            e.append(np.abs(ref.q - rig.dyn.q).max())
        errs[use_preview] = max(e)
    print(f"\nMPC max tracking error: {errs[True] * 1e3:.2f} mrad with preview, {errs[False] * 1e3:.2f} without")
    assert errs[True] < errs[False] <= 10e-3
    ctrl = make_controller("mpc", spec, ctrl_dt=0.002)
    assert ctrl.node_ticks == 5 and ctrl.preview_horizon == 1 + (ctrl.horizon - 1) * 5


@pytest.mark.parametrize("robot", ROBOTS)
def test_mpc_keeps_joint_limits_that_the_reference_breaks(robot):
    """A reference driving one joint 50 mrad past q_max: MPC stops inside (position margin), computed
    torque follows it out and the safety layer records the position-limit event."""
    spec = load_robot_spec(robot)
    j = int(np.argmin(spec.q_max - spec.home_q))  # the joint closest to its upper limit
    q1 = spec.home_q.copy()
    q1[j] = spec.q_max[j] + 0.05
    overshoot = {}
    for name in ("mpc", "computed_torque"):
        rig = Rig(robot)
        ctrl = make(name, spec, 0.01)
        ref_fn = quintic_ref(spec.home_q, q1, 0.0, 1.0)
        worst = -np.inf
        for _ in range(150):
            rig.tick(ctrl, ref_fn)
            worst = max(worst, rig.q[j] - spec.q_max[j])
        overshoot[name] = worst
        events = [e for e in rig.safety.events if e.kind == "position_limit"]
        assert bool(events) == (worst > 0)
        if events:
            assert events[0].joint == spec.arm_joints[j] and events[0].limit == spec.q_max[j]
    assert overshoot["mpc"] <= 0.0 < overshoot["computed_torque"]


def test_osc_equals_computed_torque_on_the_reference():
    """With zero joint and Cartesian error the OSC task force vanishes: same torque as computed torque."""
    rig = Rig("panda")
    spec = rig.spec
    ct = make_controller("computed_torque", spec, ctrl_dt=0.01)
    osc = make_controller("osc", spec, ctrl_dt=0.01)
    rng = np.random.default_rng(0)
    d, dyn = rig.d, rig.dyn
    for _ in range(5):
        d.qpos[dyn.qpos_adr] = rng.uniform(spec.q_min + 0.1, spec.q_max - 0.1)
        d.qvel[dyn.dof_adr] = rng.normal(0, 0.3, spec.dof)
        mujoco.mj_step1(rig.m, d)
        dyn.update()
        ref = JointReference(dyn.q.copy(), dyn.qd.copy(), rng.normal(0, 1, spec.dof))
        p_ref, R_ref, twist = osc.reference_pose(ref.q, ref.qd)
        p, R = dyn.ee_pose()
        np.testing.assert_allclose(p_ref, p, atol=1e-9)
        np.testing.assert_allclose(R_ref, R, atol=1e-9)
        np.testing.assert_allclose(twist, dyn.ee_jacobian() @ dyn.qd, atol=1e-9)
        np.testing.assert_allclose(osc.compute(dyn, ref).tau, ct.compute(dyn, ref).tau, atol=1e-6)


def test_computed_torque_pinocchio_model_matches_mujoco():
    rig = Rig("ur5e")
    spec = rig.spec
    mj = make_controller("computed_torque", spec, ctrl_dt=0.01)
    pn = make_controller("computed_torque", spec, ctrl_dt=0.01, params={"model": "pinocchio"})
    d, dyn = rig.d, rig.dyn
    finger_q = [rig.m.jnt_qposadr[rig.m.joint(j).id] for j in spec.gripper_joints]
    rng = np.random.default_rng(1)
    for _ in range(5):
        d.qpos[finger_q] = rig.m.qpos0[finger_q]  # Pinocchio locks the fingers at qpos0
        d.qpos[dyn.qpos_adr] = rng.uniform(spec.q_min, spec.q_max)
        d.qvel[:] = 0
        d.qvel[dyn.dof_adr] = rng.normal(0, 0.3, spec.dof)
        mujoco.mj_step1(rig.m, d)
        dyn.update()
        ref = JointReference(rng.uniform(spec.q_min, spec.q_max), rng.normal(0, 1, spec.dof), rng.normal(0, 1, spec.dof))
        np.testing.assert_allclose(pn.compute(dyn, ref).tau, mj.compute(dyn, ref).tau, atol=1e-6)


# --- bumpless switching ------------------------------------------------------------------------------
def euler_circuit(names):
    """A cyclic sequence of controller names containing every ordered pair exactly once (Hierholzer)."""
    adj = {a: [b for b in names if b != a] for a in names}
    stack, circuit = [names[0]], []
    while stack:
        v = stack[-1]
        if adj[v]:
            stack.append(adj[v].pop())
        else:
            circuit.append(stack.pop())
    return circuit[::-1]


def run_switching(robot, ctrl_dt, cycles, *, window=8, seed=0):
    """Switch controllers mid-motion through every ordered pair ``cycles`` times.

    For every switch the state is snapshotted and the next ``window`` ticks are run twice: once with
    the old controller (counterfactual) and once with the newly activated one (``reset(dyn, last_tau)``).
    Returns per-switch (pair, max torque step [Nm/ms], max position deviation from the counterfactual [rad]).
    """
    rig = Rig(robot, ctrl_dt=ctrl_dt)
    m, d, dyn = rig.m, rig.d, rig.dyn
    names = list(CONTROLLERS)
    ctrls = {n: make(n, rig.spec, ctrl_dt) for n in names}
    ref_fn = multisine_ref(rig.spec.home_q)
    rng = np.random.default_rng(seed)
    seq = euler_circuit(names)
    order = [seq[0]] + seq[1:] * cycles
    cur = ctrls[order[0]]
    cur.reset(dyn, None)
    for _ in range(30):
        rig.tick(cur, ref_fn)
    spare = mujoco.MjData(m)
    results = []
    for name in order[1:]:
        for _ in range(int(rng.integers(2, 8))):
            rig.tick(cur, ref_fn)
        mujoco.mj_copyData(spare, m, d)
        tau0 = rig.last_tau.copy()
        q_cf = []
        for _ in range(window):
            rig.tick(cur, ref_fn)
            q_cf.append(rig.q)
        mujoco.mj_copyData(d, m, spare)
        new = ctrls[name]
        new.reset(dyn, tau0)
        prev, rate, q_sw = tau0, 0.0, []
        for k in range(window):
            _, cmd, safe = rig.tick(new, ref_fn)
            if k == 0:
                assert cmd.status == STATUS_BLENDING and np.allclose(cmd.tau, tau0, atol=1e-9)
            rate = max(rate, float(np.abs(safe.tau - prev).max()) / (ctrl_dt * 1e3))
            prev = safe.tau
            q_sw.append(rig.q)
        jump = float(np.abs(np.array(q_sw) - np.array(q_cf)).max())
        results.append(((cur.name, name), rate, jump))
        cur = new
    assert rig.safety.faults == 0 and rig.safety.saturations == 0
    rig.assert_no_sim_warnings()
    return results


def test_bumpless_switching_between_every_pair():
    """>= 1,000 mid-motion switches over all ordered pairs: torque step <= 1 Nm/ms, position jump <= 1 mrad."""
    results = run_switching("panda", 0.01, 50) + run_switching("ur5e", 0.004, 35)
    pairs = {p for p, _, _ in results}
    assert len(results) >= 1000
    assert pairs == {(a, b) for a in CONTROLLERS for b in CONTROLLERS if a != b}
    worst_rate = max(r for _, r, _ in results)
    worst_jump = max(j for _, _, j in results)
    print(f"\n{len(results)} switches over {len(pairs)} ordered pairs: max torque step {worst_rate:.3f} Nm/ms, "
          f"max position deviation {worst_jump * 1e3:.3f} mrad")
    assert worst_rate <= 1.0
    assert worst_jump <= 1e-3


def test_blend_fades_a_large_torque_difference_at_the_configured_rate():
    """After reset(dyn, last_tau) the command is the controller's own law plus an offset that starts at
    last_tau - law (first tick = last_tau exactly) and shrinks linearly at <= blend_rate_nm_per_ms."""
    rig = Rig("panda")
    ctrl = make("computed_torque", rig.spec, 0.01)
    twin = make("computed_torque", rig.spec, 0.01)  # same law, never blends
    ref_fn = hold_ref(rig.spec.home_q)
    for _ in range(5):
        rig.tick(ctrl, ref_fn)
    delta = np.array([30.0, -10.0, 0, 0, 3.0, 0, 0])
    ctrl.reset(rig.dyn, rig.last_tau + delta)
    per_tick = ctrl.config.blend_rate_nm_per_ms * 1e3 * 0.01  # [Nm per tick]
    # The rate sets the window here (30 Nm / 5 Nm per tick = 6 ticks > blend_time_s = 5 ticks).
    n_blend = int(np.ceil(30.0 / per_tick - 1e-6))
    assert n_blend > round(ctrl.config.blend_time_s / 0.01)
    offsets, statuses = [], []
    for k in range(n_blend + 3):
        mujoco.mj_step1(rig.m, rig.d)
        rig.dyn.update()
        ref = ref_fn(rig.d.time)
        cmd = ctrl.compute(rig.dyn, ref)
        law = twin.compute(rig.dyn, ref).tau
        if k == 0:
            np.testing.assert_allclose(cmd.tau, rig.last_tau + delta, atol=1e-12)
            delta0 = cmd.tau - law
        offsets.append(cmd.tau - law)
        statuses.append(cmd.status)
        safe = rig.safety.filter(cmd, rig.dyn, ref)
        rig.dyn.write_ctrl(safe.tau)
        mujoco.mj_step2(rig.m, rig.d)
        for _ in range(rig.substeps - 1):
            mujoco.mj_step(rig.m, rig.d)
    for k, off in enumerate(offsets):
        np.testing.assert_allclose(off, delta0 * max(0.0, 1 - k / n_blend), atol=1e-9)
    assert np.abs(np.diff(offsets, axis=0)).max() <= per_tick + 1e-9
    assert statuses[:n_blend] == [STATUS_BLENDING] * n_blend and statuses[n_blend:] == [STATUS_OK] * 3
    assert not ctrl.blending
    for _ in range(100):  # the faded-out offset was a disturbance; the law brings the arm back
        rig.tick(ctrl, ref_fn)
    assert np.abs(rig.q - rig.spec.home_q).max() < 2e-3
    # Non-finite or cold starts do not blend; a wrong shape is a programming error.
    ctrl.reset(rig.dyn, np.full(rig.spec.dof, np.nan))
    assert rig.tick(ctrl, ref_fn)[1].status == STATUS_OK
    with pytest.raises(ControllerError, match="shape"):
        ctrl.reset(rig.dyn, np.zeros(3))


# --- torque limits under random references ----------------------------------------------------------
@pytest.mark.parametrize("name", CONTROLLERS)
def test_random_references_stay_within_torque_limits(name):
    """>= 10,000 steps per controller (over both robots): random states and references (most without
    physics stepping) plus closed-loop random moves; after the safety layer every torque is finite and
    within tau_max; the commanded max ratio is reported."""
    total = 0
    for robot in ROBOTS:
        rig = Rig(robot)
        spec, m, d, dyn = rig.spec, rig.m, rig.d, rig.dyn
        ctrl = make(name, spec, 0.01)
        safety = SafetyLayer(spec)
        rng = np.random.default_rng(7)
        steps = 0
        statuses: dict[str, int] = {}
        for _ in range(50):  # open loop: 50 random states x 90 random references
            d.qpos[dyn.qpos_adr] = rng.uniform(spec.q_min, spec.q_max)
            d.qvel[dyn.dof_adr] = rng.uniform(-spec.v_max, spec.v_max)
            mujoco.mj_step1(m, d)
            dyn.update()
            ctrl.reset(dyn, None)
            for _ in range(90):
                near = rng.random() < 0.5  # half near the state, half anywhere
                q_ref = dyn.q + rng.normal(0, 0.05, spec.dof) if near else rng.uniform(spec.q_min, spec.q_max)
                ref = JointReference(q_ref, rng.uniform(-spec.v_max, spec.v_max), rng.uniform(-spec.a_max, spec.a_max))
                pv = q_ref + np.outer(np.arange(1, ctrl.preview_horizon + 1) * 0.01, ref.qd) if ctrl.preview_horizon else None
                cmd = ctrl.compute(dyn, ref, preview=pv)
                safe = safety.filter(cmd, dyn, ref)
                assert np.all(np.isfinite(safe.tau)) and np.all(np.abs(safe.tau) <= spec.tau_max)
                statuses[cmd.status] = statuses.get(cmd.status, 0) + 1
                if name == "mpc" and cmd.status == STATUS_OK:
                    assert np.all(np.abs(cmd.tau) <= spec.tau_max), "MPC's torque constraint is hard"
                steps += 1
        # Closed loop: random rest-to-rest moves inside the limits, with physics.
        rig.d.qpos[dyn.qpos_adr] = spec.home_q
        rig.d.qvel[:] = 0
        mujoco.mj_forward(m, d)
        ctrl.reset(dyn, None)
        rig.safety = safety
        q0 = spec.home_q.copy()
        for _ in range(10):
            q1 = np.clip(q0 + rng.uniform(-0.5, 0.5, spec.dof), spec.q_min + 0.1, spec.q_max - 0.1)
            ref_fn = quintic_ref(q0, q1, d.time, 0.8)
            for _ in range(100):
                rig.tick(ctrl, ref_fn)
                steps += 1
            q0 = q1
        rig.assert_no_sim_warnings()
        s = safety.summary()
        print(f"\n{robot}/{name}: {steps} steps, max commanded torque ratio {s['max_torque_ratio']:.2f}, "
              f"{s['saturations']} saturated ticks (applied ratio <= 1), statuses {statuses}")
        assert s["faults"] == 0
        if name == "mpc":  # MPC's own plan respects the torque box whenever it solves
            assert statuses.get(STATUS_FALLBACK, 0) < 0.01 * steps
        total += steps
    assert total >= 10_000


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_reference_never_reaches_the_robot(bad):
    """Every controller survives a non-finite reference (no exception); the safety layer refuses it."""
    rig = Rig("ur5e")
    for name in CONTROLLERS:
        ctrl = make(name, rig.spec, 0.01)
        q = rig.spec.home_q.copy()
        q[2] = bad
        with np.errstate(all="ignore"):
            _, cmd, safe = rig.tick(ctrl, lambda t: JointReference(q, np.zeros(rig.spec.dof), np.zeros(rig.spec.dof)))
        assert safe.status == "fault" and "nonfinite_reference" in [e.kind for e in safe.events]
        assert cmd.status == (STATUS_FALLBACK if name == "mpc" else STATUS_OK)
    assert np.abs(rig.q - rig.spec.home_q).max() < 1e-3


# --- MPC failures ----------------------------------------------------------------------------------
def test_mpc_fallback_never_applies_nan(monkeypatch):
    spec = load_robot_spec("panda")
    rig = Rig("panda")
    ref_fn = multisine_ref(spec.home_q)
    mpc = make("mpc", spec, 0.01)
    for _ in range(20):
        rig.tick(mpc, ref_fn)

    def tick_with(preview=None, expect=STATUS_FALLBACK, match=""):
        mujoco.mj_step1(rig.m, rig.d)
        rig.dyn.update()
        ref = ref_fn(rig.d.time)
        cmd = mpc.compute(rig.dyn, ref, preview=preview)
        safe = rig.safety.filter(cmd, rig.dyn, ref)
        assert np.all(np.isfinite(cmd.tau)) and np.all(np.isfinite(safe.tau))
        assert cmd.status == expect and match in cmd.detail, (cmd.status, cmd.detail)
        rig.dyn.write_ctrl(safe.tau)
        mujoco.mj_step2(rig.m, rig.d)
        for _ in range(rig.substeps - 1):
            mujoco.mj_step(rig.m, rig.d)
        return cmd

    # 1. NaN in the preview: refused before the solver sees it.
    bad = np.full((mpc.preview_horizon, spec.dof), np.nan)
    first = tick_with(bad, match="preview")
    np.testing.assert_allclose(first.tau, rig.last_tau)  # entering fallback is bumpless too
    tick_with(bad, match="preview")
    # 2. Solver failure status.
    real = JointMPC._solve_qp
    monkeypatch.setattr(JointMPC, "_solve_qp", lambda self, *a: (7, np.zeros(self._nx)))
    tick_with(match="max_iter_reached")
    # 3. "Solved" but NaN solution.
    monkeypatch.setattr(JointMPC, "_solve_qp", lambda self, *a: (1, np.full(self._nx, np.nan)))
    tick_with(match="non-finite")
    monkeypatch.setattr(JointMPC, "_solve_qp", real)
    # 4. Recovery: MPC resumes (blending out of the hold).
    cmd = tick_with(expect=STATUS_BLENDING)
    assert cmd.detail == ""
    # 5. Real OSQP failures: iteration cap and time limit.
    capped = make("mpc", spec, 0.01, max_iter=1, eps=1e-9)
    rig2 = Rig("panda")
    cmds = [rig2.tick(capped, quintic_ref(spec.home_q, move_target(spec), 0.0, 0.5))[1] for _ in range(5)]
    assert all(c.status == STATUS_FALLBACK and "max_iter" in c.detail for c in cmds)
    assert np.abs(rig2.q - spec.home_q).max() < 2e-3, "fallback holds position"
    slow = make_controller("mpc", spec, ctrl_dt=0.01, params={"time_limit_fraction": 1e-7})
    rig3 = Rig("panda")
    cmds = [rig3.tick(slow, hold_ref(spec.home_q))[1] for _ in range(3)]
    assert all(c.status == STATUS_FALLBACK and ("time_limit" in c.detail or "timeout" in c.detail) for c in cmds)


def test_mpc_with_intermittent_failures_keeps_tracking(monkeypatch):
    """Every 5th solve fails: fallback ticks hold, the arm stays near the reference, nothing non-finite."""
    spec = load_robot_spec("panda")
    rig = Rig("panda")
    mpc = make("mpc", spec, 0.01)
    real = JointMPC._solve_qp
    calls = {"n": 0}

    def flaky(self, *a):
        calls["n"] += 1
        if calls["n"] % 5 == 0:
            return 3, np.full(self._nx, np.nan)  # primal infeasible with garbage
        return real(self, *a)

    monkeypatch.setattr(JointMPC, "_solve_qp", flaky)
    ref_fn = quintic_ref(spec.home_q, move_target(spec), 0.1, 1.0)
    n_fallback, errs = 0, []
    for _ in range(150):
        ref, cmd, safe = rig.tick(mpc, ref_fn)
        n_fallback += cmd.status == STATUS_FALLBACK
        errs.append(np.abs(ref.q - rig.dyn.q).max())
    assert n_fallback == 30
    assert max(errs) < 0.03
    assert rig.safety.faults == 0


def test_mpc_preview_shapes():
    spec = load_robot_spec("panda")
    rig = Rig("panda")
    mpc = make("mpc", spec, 0.01)
    mujoco.mj_step1(rig.m, rig.d)
    rig.dyn.update()
    ref = hold_ref(spec.home_q)(0.0)
    with pytest.raises(ControllerError, match="preview"):
        mpc.compute(rig.dyn, ref, preview=np.zeros((5, 3)))
    # A short preview (trajectory ending) holds its last row: same as a full preview of that row.
    short = np.tile(spec.home_q, (2, 1))
    full = np.tile(spec.home_q, (mpc.preview_horizon, 1))
    a = mpc.compute(rig.dyn, ref, preview=short).tau
    mpc.reset(rig.dyn, None)
    b = mpc.compute(rig.dyn, ref, preview=full).tau
    np.testing.assert_allclose(a, b, atol=1e-6)


# --- cost ------------------------------------------------------------------------------------------
def test_report_tick_compute_time():
    """Median compute() time per controller on the Panda while tracking (printed, not asserted)."""
    spec = load_robot_spec("panda")
    lines = []
    for name in CONTROLLERS:
        rig = Rig("panda")
        ctrl = make(name, spec, 0.01)
        ref_fn = quintic_ref(spec.home_q, move_target(spec), 0.1, 1.0)
        times, safety_times = [], []
        for _ in range(150):
            mujoco.mj_step1(rig.m, rig.d)
            rig.dyn.update()
            ref = ref_fn(rig.d.time)
            pv = np.array([ref_fn(rig.d.time + (j + 1) * 0.01).q for j in range(ctrl.preview_horizon)]) if ctrl.preview_horizon else None
            t0 = time.perf_counter()
            cmd = ctrl.compute(rig.dyn, ref, preview=pv)
            t1 = time.perf_counter()
            safe = rig.safety.filter(cmd, rig.dyn, ref)
            t2 = time.perf_counter()
            times.append(t1 - t0)
            safety_times.append(t2 - t1)
            rig.dyn.write_ctrl(safe.tau)
            mujoco.mj_step2(rig.m, rig.d)
            for _ in range(rig.substeps - 1):
                mujoco.mj_step(rig.m, rig.d)
        lines.append(f"{name}: compute {statistics.median(times) * 1e6:.1f} us, "
                     f"safety {statistics.median(safety_times) * 1e6:.1f} us (median)")
        assert isinstance(cmd, Command)
    print("\n" + "\n".join(lines))
