"""GLSR supervisor (Algorithm 1) as a state machine, driven with the privileged oracle."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

from tcot_hybrid.episode import EpisodeRunner
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.executor import ExecutorConfig
from tcot_hybrid.perturbations import PerturbConfig
from tcot_hybrid.run_config import RunConfig
from tcot_hybrid.supervision import Supervisor, SupervisorConfig


class FakePlanner:
    replan_every_step = False

    def __init__(self, p):
        self.p = p

    def success_probability(self, obs):
        return self.p


class FakeExecutor:
    ik_failures = 0
    plan_finished = False
    plan = None
    releases = 0


def decisions(cfg, p, steps):
    sup = Supervisor(cfg, FakePlanner(p))
    return [sup.decide(t, observe=lambda: None, executor=FakeExecutor()) for t in range(steps)]


def test_algorithm1_global_then_frozen_then_local_every_t_l_when_not_successful():
    cfg = SupervisorConfig(mode="glsr", t_f=10, t_l=4)
    ds = decisions(cfg, 0.1, 25)
    planned = {t: d.plan_mode for t, d in enumerate(ds) if d.plan_mode}
    assert planned == {0: "global", 12: "local", 16: "local", 20: "local", 24: "local"}
    # frozen until t_f: no detector calls, no events
    assert all(d.event is None for d in ds[1:11])
    # from t_f on every step logs the detector's probability
    assert all(d.event and d.event["p_success"] == 0.1 for d in ds[11:])


def test_frozen_phase_ends_when_the_global_plan_has_been_carried_out():
    class DoneAfter5(FakeExecutor):
        def __init__(self):
            self.t = 0

        @property
        def plan_finished(self):
            return self.t > 5

    sup, ex = Supervisor(SupervisorConfig(mode="glsr", t_f=50, t_l=4), FakePlanner(0.1)), DoneAfter5()
    ds = []
    for t in range(14):
        ex.t = t
        ds.append(sup.decide(t, observe=lambda: None, executor=ex))
    assert all(d.event is None for d in ds[1:6])  # still following the frozen plan
    assert ds[6].event["state"] == "detect" and ds[6].event["p_success"] == 0.1  # detection from here
    assert [t for t, d in enumerate(ds) if d.plan_mode] == [0, 8, 12]


@pytest.mark.parametrize("t_f, world, first_detection", [("plan", "workcell", 30), ("auto", "libero", 30),
                                                        ("auto", "workcell", 17), (8, "libero", 9)])
def test_t_f_plan_keeps_the_global_phase_until_the_plan_is_carried_out(t_f, world, first_detection):
    """A step t_f freezes the global plan through step t_f; "plan" (LIBERO's "auto") until it has been carried out."""
    class DoneAfter30(FakeExecutor):
        t = 0

        @property
        def plan_finished(self):
            return self.t >= 30

    cfg = SupervisorConfig(mode="glsr", t_f=t_f, t_l=4, empty_grasp="off")
    sup, ex = Supervisor(cfg, FakePlanner(0.1), world_kind=world), DoneAfter30()
    first_detect = None
    for t in range(40):
        ex.t = t
        in_phase = sup.in_global_phase(t, ex)
        d = sup.decide(t, observe=lambda: None, executor=ex)
        if first_detect is None and d.event and "p_success" in d.event:
            first_detect = t
            assert not in_phase  # --stop-on detector's checks have started by then too
    assert first_detect == first_detection


def test_t_f_local_mode_has_no_global_phase():
    sup = Supervisor(SupervisorConfig(mode="local", t_f="plan"), FakePlanner(0.1))
    sup.decide(0, observe=lambda: None, executor=FakeExecutor())
    assert not sup.in_global_phase(1, FakeExecutor())


def test_no_replan_while_judged_successful():
    ds = decisions(SupervisorConfig(mode="glsr", t_f=3, t_l=2), 0.9, 12)
    assert [t for t, d in enumerate(ds) if d.plan_mode] == [0]
    assert ds[6].event["reason"] == "judged_successful"


def test_global_and_local_modes():
    assert [t for t, d in enumerate(decisions(SupervisorConfig(mode="global"), 0.0, 30)) if d.plan_mode] == [0]
    local = decisions(SupervisorConfig(mode="local", t_l=5), 0.0, 16)
    assert [(t, d.plan_mode) for t, d in enumerate(local) if d.plan_mode] == [(0, "local"), (5, "local"),
                                                                            (10, "local"), (15, "local")]


def test_reset_variant_resets_once_then_plans_locally():
    ds = decisions(SupervisorConfig(mode="glsr_reset", t_f=4, t_l=2, max_resets=1), 0.0, 12)
    assert [t for t, d in enumerate(ds) if d.reset] == [6]
    assert [t for t, d in enumerate(ds) if d.plan_mode == "local"] == [6, 8, 10]


@pytest.mark.parametrize("kw", [dict(mode="sometimes"), dict(t_l=0), dict(t_f=-1), dict(success_threshold=1.5),
                                dict(t_f="whenever"), dict(t_f=2.5)])
def test_bad_supervisor_config(kw):
    with pytest.raises(ConfigError) as e:
        SupervisorConfig(**kw)
    if kw.get("t_f") == "whenever":
        assert "'whenever'" in str(e.value) and "auto, plan" in str(e.value)


def test_glsr_recovers_where_frozen_global_plan_fails():
    """A moved object defeats the frozen global plan; GLSR's local replans recover (oracle planner)."""
    out = {}
    for mode in ("global", "glsr"):
        cfg = RunConfig(task="goal_cube_in_bowl", seed=1, supervisor=SupervisorConfig(mode=mode, t_f=30),
                        perturb=PerturbConfig(name="object_moved"))
        rec = EpisodeRunner(cfg).run()
        out[mode] = rec
        assert any(e["kind"] == "perturbation" for e in rec["events"])
    assert not out["global"]["success"] and out["glsr"]["success"]
    reasons = [e.get("reason") for e in out["glsr"]["events"] if e["kind"] == "supervisor"]
    assert "not_successful" in reasons


def test_stop_match_radius_is_validated():
    with pytest.raises(ConfigError, match="stop_match_m"):
        ExecutorConfig(stop_match_m=0.0)


@pytest.mark.parametrize("seed", [500, 501, 502])  # development (tuning) seeds, docs/seeds.md
def test_glsr_hands_a_drawer_pull_over_to_local_plans(seed):
    """Regression: when every replan (each t_l steps) restarted the wait at a stop its local plan had moved by
    1-4 cm, GLSR's first local plan (approaching the handle) left the arm hovering above the handle without
    ever closing the gripper (shipped checkpoint; ExecutorConfig.stop_match_m): 21.8 s or never, where the
    hand-over takes under 5 s."""
    cfg = RunConfig(task="goal_open_drawer", seed=seed, planner="learned", supervisor=SupervisorConfig(mode="glsr"))
    rec = EpisodeRunner(cfg).run()
    assert rec["success"] and rec["fault"] is None
    assert rec["success_time_s"] < 10.0  # not hovering
    assert any(e.get("plan") == "local" for e in rec["events"] if e["kind"] == "supervisor")


class StraightCamera:
    """A camera whose 'unprojection' is the pixel (in cm) at the given depth: enough to measure a plan's reach."""

    def unproject(self, uv, depth):
        import numpy as np

        return np.c_[np.asarray(uv, float) / 100.0, np.asarray(depth, float)]


class SaysDonePlanner(FakePlanner):
    """Detector: always done. Local prompt: a plan reaching ``reach_m`` (and switching the gripper if asked)."""

    def __init__(self, reach_m, switch=False):
        super().__init__(0.99)
        self.reach_m, self.switch, self.local_calls = reach_m, switch, 0

    def plan(self, obs, *, mode):
        import numpy as np

        from tcot_hybrid.plan import WaypointPlan

        self.local_calls += 1
        uv = np.zeros((9, 2))
        uv[:, 0] = np.linspace(0, self.reach_m * 100, 9)
        grip = np.zeros(9, bool)
        grip[5:] = self.switch
        return WaypointPlan(uv_px=uv, depth_m=np.ones(9), gripper_closed=grip, camera="c", kind=mode, step=0)


class CameraExecutor(FakeExecutor):
    camera = StraightCamera()

    def __init__(self):
        self.sim = GripperSim([0.08])  # an open hand (LIBERO's empty-grasp check reads it)
        self.sim.closed = False
        self.grasp_tcp_z = None


def confirm_decisions(cfg, planner, steps, world_kind="libero"):
    sup = Supervisor(cfg, planner, world_kind=world_kind)
    return sup, [sup.decide(t, observe=lambda: None, executor=CameraExecutor()) for t in range(steps)]


def test_a_success_verdict_the_local_plan_contradicts_is_overruled_and_that_plan_followed():
    cfg = SupervisorConfig(mode="glsr", t_f=3, t_l=4, confirm_success="local_plan")
    planner = SaysDonePlanner(reach_m=0.20)
    sup, ds = confirm_decisions(cfg, planner, 13)
    over = {t: d for t, d in enumerate(ds) if d.plan is not None}
    assert sorted(over) == [4, 8, 12] and planner.local_calls == 3  # only at the local period, one call each
    d = over[4]
    assert d.plan_mode == "local" and d.plan.kind == "local" and d.event["reason"] == "detector_overruled"
    assert d.event["plan_motion_m"] == pytest.approx(0.20) and sup.overruled == 3 and sup.replans == 3
    assert ds[5].event["reason"] == "judged_successful" and ds[5].plan is None  # between periods: verdict stands
    # a plan that stays put (within confirm_motion_m) confirms the verdict; a gripper switch overrules it
    _, ds = confirm_decisions(cfg, SaysDonePlanner(reach_m=0.02), 13)
    assert all(d.plan is None for d in ds) and ds[8].event["reason"] == "judged_successful"
    _, ds = confirm_decisions(cfg, SaysDonePlanner(reach_m=0.02, switch=True), 13)
    assert [t for t, d in enumerate(ds) if d.plan is not None] == [4, 8, 12]


def test_confirm_success_auto_is_on_for_libero_only_and_off_is_algorithm1():
    cfg = SupervisorConfig(mode="glsr", t_f=3, t_l=4)
    assert cfg.confirm_success == "auto"
    for world, expect in (("libero", [4, 8]), ("workcell", [])):
        planner = SaysDonePlanner(reach_m=0.20)
        _, ds = confirm_decisions(cfg, planner, 10, world_kind=world)
        assert [t for t, d in enumerate(ds) if d.plan is not None] == expect
    planner = SaysDonePlanner(reach_m=0.20)
    _, ds = confirm_decisions(SupervisorConfig(mode="glsr", t_f=3, t_l=4, confirm_success="off"), planner, 10)
    assert planner.local_calls == 0 and all(d.plan_mode is None for d in ds[1:])
    with pytest.raises(ConfigError, match="confirm_success.*'sometimes'.*auto.*off.*local_plan"):
        SupervisorConfig(confirm_success="sometimes")
    with pytest.raises(ConfigError, match="confirm_motion_m"):
        SupervisorConfig(confirm_motion_m=0.0)


@pytest.mark.parametrize("value, expect", [("plan", "plan"), ("auto", "auto"), (12, 12), ("whenever", None),
                                           (True, None), (2.5, None)])
def test_t_f_from_a_config_file(value, expect):
    from tcot_hybrid.run_config import from_mapping

    if expect is None:
        with pytest.raises(ConfigError) as e:
            from_mapping(RunConfig, {"task": "goal_cube_on_plate", "supervisor": {"t_f": value}})
        assert "supervisor.t_f" in str(e.value) and "auto, plan" in str(e.value)
    else:
        cfg = from_mapping(RunConfig, {"task": "goal_cube_on_plate", "supervisor": {"t_f": value}})
        assert cfg.supervisor.t_f == expect


class GripperSim:
    def __init__(self, openings, heights=(0.0, 0.1)):
        self.openings, self.heights, self.t, self.closed = openings, heights, 0, True

    def tcp_pos(self):  # [m]; the hand closes at the first height and lifts to the second from step 2 on
        return np.array([0.0, 0.0, self.heights[0] if self.t < 2 else self.heights[1]])

    def gripper_closed_cmd(self):
        return self.closed

    def gripper_opening_m(self):
        return self.openings[min(self.t, len(self.openings) - 1)]


class GripperExecutor(FakeExecutor):
    def __init__(self, openings, put_down=None):
        self.sim, self.opened, self.events = GripperSim(openings), [], []
        # how far the plan that closed the hand lowers it before it opens it again (None: never, or another plan)
        self.closed_put_down_m, self.closes = put_down, 1

    def event(self, kind, **info):
        self.events.append({"kind": kind, **info})

    @property
    def grasp_tcp_z(self):  # where the plan closed the hand: the first height
        return self.sim.heights[0] if self.sim.closed else None

    def open_empty_gripper(self, opening_m):
        self.sim.closed = False
        self.opened.append(opening_m)


@pytest.mark.parametrize("world, setting, fires", [("libero", "auto", True), ("workcell", "auto", False),
                                                   ("workcell", "on", True), ("libero", "off", False)])
def test_an_empty_grasp_reopens_the_gripper_and_replans_locally_at_once(world, setting, fires):
    """Fingers that met (opening below empty_grasp_m for empty_grasp_steps steps) inside the frozen global phase:
    the gripper opens and a local plan follows, before the detector is asked (the hand is observed open)."""
    cfg = SupervisorConfig(mode="glsr", t_f="plan", empty_grasp=setting, empty_grasp_m=0.0025, empty_grasp_steps=3,
                           confirm_success="off", home_retries=0)
    # closing: 40 mm, 10 mm, then 1.2 mm from step 3 on (nothing between the fingers)
    ex = GripperExecutor([0.04, 0.01, 0.01, 0.0012])
    sup = Supervisor(cfg, FakePlanner(0.1), world_kind=world)
    ds = []
    for t in range(10):
        ex.sim.t = t
        ds.append(sup.decide(t, observe=lambda: None, executor=ex))
    planned = [(t, d.plan_mode, d.event["reason"]) for t, d in enumerate(ds) if d.plan_mode]
    if fires:
        # steps 3, 4, 5 below 2.5 mm; then Algorithm 1 goes on from the local phase (t_l = 8)
        assert planned == [(0, "global", "start"), (5, "local", "grasp_empty"), (8, "local", "not_successful")]
        assert ex.opened == [0.0012] and ds[5].event["opening_m"] == 0.0012 and sup.empty_grasps == 1
        assert sup.state == "local_follow"
    else:
        assert planned == [(0, "global", "start")] and ex.opened == [] and sup.empty_grasps == 0


def test_a_held_object_is_not_an_empty_grasp():
    ex = GripperExecutor([0.04, 0.01, 0.0038])  # a bowl's rim between the fingers
    sup = Supervisor(SupervisorConfig(mode="glsr", t_f="plan", empty_grasp="on"), FakePlanner(0.1))
    for t in range(20):
        ex.sim.t = t
        d = sup.decide(t, observe=lambda: None, executor=ex)
        assert t == 0 or d.plan_mode is None
    assert ex.opened == []


@pytest.mark.parametrize("kw", [dict(empty_grasp="maybe"), dict(empty_grasp_m=0.0), dict(empty_grasp_steps=0)])
def test_bad_empty_grasp_settings(kw):
    with pytest.raises(ConfigError) as e:
        SupervisorConfig(**kw)
    assert "supervisor.empty_grasp" in str(e.value)


def test_an_empty_hand_that_keeps_low_is_left_alone_and_a_lost_object_is_noticed_once_lifted():
    """Closed fingers that measure empty while the hand stays where it closed (a knob turned, a door pushed) are left
    alone; once the hand is empty_grasp_lift_m above that point (a miss lifted, an object dropped in transport), the
    gripper reopens."""
    def reopenings(heights, openings=(0.0012,), steps=12):
        ex = GripperExecutor(list(openings))
        ex.sim.heights = heights
        sup = Supervisor(SupervisorConfig(mode="glsr", t_f="plan", empty_grasp="on", confirm_success="off",
                                          empty_grasp_lift_m=0.04), FakePlanner(0.1))
        out = []
        for t in range(steps):
            ex.sim.t = t
            d = sup.decide(t, observe=lambda: None, executor=ex)
            if d.event and d.event.get("reason") == "grasp_empty":
                out.append(t)
        return out

    assert reopenings((0.90, 0.91)) == []  # 1 cm up: a push or a turn
    assert reopenings((0.90, 0.95)) == [4]  # lifted 5 cm from step 2: steps 2, 3, 4
    assert reopenings((0.90, 0.95), openings=(0.004,)) == []  # lifted, holding 4 mm: a held object


@pytest.mark.parametrize("put_down, setting, reopened", [
    (None, 0.03, [4]),  # the plan carries the closed hand to its end: a lost object
    (0.10, 0.03, [4]),  # it lowers 10 cm to open: it puts the missing object down
    (0.0, 0.03, []),  # it opens in the air: the hand was closed empty on purpose
    (0.02, 0.03, []),
    (0.03, 0.03, [4]),  # exactly the setting: a put-down
    (0.0, None, [4]),  # the check before stop 42: every lifted empty hand counts
])
def test_a_plan_that_opens_the_lifted_empty_hand_in_the_air_meant_it_empty(put_down, setting, reopened):
    """The stove knob turned with closed fingers, then the closed hand carried up and over to the next grasp (the
    oracle's commanded path): lifted and empty, but the plan puts nothing down before it opens the hand."""
    ex = GripperExecutor([0.0012], put_down=put_down)
    ex.sim.heights = (0.90, 0.95)
    sup = Supervisor(SupervisorConfig(mode="glsr", t_f="plan", empty_grasp="on", confirm_success="off",
                                      empty_grasp_put_down_m=setting), FakePlanner(0.1))
    got = []
    for t in range(12):
        ex.sim.t = t
        d = sup.decide(t, observe=lambda: None, executor=ex)
        if d.event and d.event.get("reason") == "grasp_empty":
            got.append(t)
    assert got == reopened and sup.empty_grasps == len(reopened)
    planned = [e for e in ex.events if e["kind"] == "empty_hand_planned"]
    assert len(planned) == (0 if reopened else 1)  # once a grasp, not every step
    if planned:
        assert planned[0]["put_down_m"] == put_down and ex.opened == []


def test_a_closed_hand_on_purpose_is_reported_once_a_grasp_and_another_plan_is_not_exempt():
    ex = GripperExecutor([0.0012], put_down=0.0)
    ex.sim.heights = (0.90, 0.95)
    sup = Supervisor(SupervisorConfig(mode="glsr", t_f="plan", empty_grasp="on", confirm_success="off"),
                     FakePlanner(0.1))
    reopened = []
    for t in range(30):
        ex.sim.t = t
        if t == 10:  # the plan closes the hand a second time, again to open it in the air
            ex.closes += 1
        if t == 20:  # another plan takes over the closed hand
            ex.closed_put_down_m = None
        d = sup.decide(t, observe=lambda: None, executor=ex)
        if d.event and d.event.get("reason") == "grasp_empty":
            reopened.append(t)
    assert [e["kind"] for e in ex.events] == ["empty_hand_planned"] * 2
    assert reopened == [22]  # steps 20, 21, 22 empty and not exempt


def test_put_down_setting_from_a_config_file():
    from tcot_hybrid.run_config import from_mapping

    for value in (None, 0.05):
        cfg = from_mapping(RunConfig, {"task": "goal_cube_on_plate", "supervisor": {"empty_grasp_put_down_m": value}})
        assert cfg.supervisor.empty_grasp_put_down_m == value


@pytest.mark.parametrize("value", [0.0, -0.01, float("nan"), True])
def test_bad_put_down_settings_are_refused(value):
    with pytest.raises(ConfigError) as e:
        SupervisorConfig(empty_grasp_put_down_m=value)
    assert "supervisor.empty_grasp_put_down_m" in str(e.value)


class HomingExecutor(GripperExecutor):
    """A gripper executor that can go home: it takes ``home_steps`` planner steps to get there."""

    def __init__(self, openings, home_steps=3):
        super().__init__(openings)
        self.home_steps, self.homing_since, self.homes = home_steps, None, []
        self.plan = type("Plan", (), {"kind": "global"})()
        self.done_at = None  # step from which the current plan counts as carried out (None: never)
        self.releases = 0

    @property
    def plan_finished(self):
        if self.homing_since is not None:
            return self.sim.t >= self.homing_since + self.home_steps
        return self.done_at is not None and self.sim.t >= self.done_at

    def go_home(self, lift_m):
        self.homes.append((self.sim.t, lift_m))
        self.homing_since, self.plan = self.sim.t, None


def drive(sup, ex, steps, on_plan=None):
    planned = []
    for t in range(steps):
        ex.sim.t = t
        d = sup.decide(t, observe=lambda: None, executor=ex)
        if d.event and d.event.get("plan") == "home":
            planned.append((t, "home", d.event["reason"]))
        if d.plan_mode:
            planned.append((t, d.plan_mode, d.event["reason"]))
            if on_plan:
                on_plan(t, d.plan_mode)
    return planned


def test_an_empty_grasp_with_a_home_retry_goes_home_and_plans_globally_from_there():
    """With home_retries 1 the first empty grasp sends the arm home; nothing is planned on the way; on arrival a new
    global plan (reason home_reached) is followed frozen; the second empty grasp, retries used up, replans locally."""
    cfg = SupervisorConfig(mode="glsr", t_f="plan", empty_grasp="on", empty_grasp_steps=3, confirm_success="off",
                           home_retries=1, home_lift_m=0.08)
    ex = HomingExecutor([0.04, 0.01, 0.01, 0.0012])
    sup = Supervisor(cfg, FakePlanner(0.1), world_kind="workcell")

    def adopt(t, mode):  # the new global plan closes on nothing again from step 11 (its fingers at 1.2 mm)
        if mode == "global" and t > 0:
            ex.homing_since, ex.sim.closed = None, True
            ex.plan = type("Plan", (), {"kind": "global"})()
            ex.sim.openings = [0.04] * 11 + [0.0012]
    planned = drive(sup, ex, 16, adopt)
    assert planned == [(0, "global", "start"), (5, "home", "grasp_empty"), (8, "global", "home_reached"),
                       (13, "local", "grasp_empty")]
    assert ex.homes == [(5, 0.08)] and ex.opened == [0.0012, 0.0012] and sup.homes == 1


def test_a_global_plan_carried_out_with_an_open_hand_and_the_task_not_done_is_retried_from_home():
    cfg = SupervisorConfig(mode="glsr", t_f="plan", t_l=4, empty_grasp="off", confirm_success="off",
                           home_retries=1)
    ex = HomingExecutor([0.04])
    ex.sim.closed, ex.done_at = False, 6  # released, plan carried out at step 6
    sup = Supervisor(cfg, FakePlanner(0.1))
    planned = drive(sup, ex, 20, lambda t, m: setattr(ex, "homing_since", None) if t > 0 else None)
    # detection from step 6, the failure acted on at the local period (8): home; arrived at 11; then the new global
    # plan (kind "global", done at once here) ran out again: retries used up, local plans every t_l
    assert planned[:3] == [(0, "global", "start"), (8, "home", "not_successful"), (11, "global", "home_reached")]
    assert all(m == "local" for _, m, _ in planned[3:]) and planned[3][0] == 12


def test_a_global_plan_that_ends_holding_something_is_not_sent_home():
    cfg = SupervisorConfig(mode="glsr", t_f="plan", t_l=4, empty_grasp="off", confirm_success="off",
                           home_retries=1)
    ex = HomingExecutor([0.02])  # closed on an object
    ex.done_at = 6
    planned = drive(Supervisor(cfg, FakePlanner(0.1)), ex, 10)
    assert planned == [(0, "global", "start"), (8, "local", "not_successful")] and ex.homes == []


@pytest.mark.parametrize("mode, world, retries", [("glsr", "libero", "HOME_RETRIES_LIBERO"), ("glsr", "workcell", 0),
                                                  ("glsr_reset", "libero", 0), ("local", "libero", 0)])
def test_home_retries_auto_is_a_libero_default_of_glsr_only(mode, world, retries):
    from tcot_hybrid import supervision

    sup = Supervisor(SupervisorConfig(mode=mode), FakePlanner(0.1), world_kind=world)
    assert sup.home_retries_left == (getattr(supervision, retries) if isinstance(retries, str) else retries)
    sup = Supervisor(SupervisorConfig(mode=mode, home_retries=2), FakePlanner(0.1), world_kind=world)
    assert sup.home_retries_left == (2 if mode == "glsr" else 0)


def test_no_retry_from_home_once_a_plan_has_released_something():
    """A global plan starts the task over: after a release (a first object placed) an empty grasp replans locally."""
    cfg = SupervisorConfig(mode="glsr", t_f="plan", empty_grasp="on", empty_grasp_steps=3, confirm_success="off",
                           home_retries=1)
    ex = HomingExecutor([0.04, 0.01, 0.01, 0.0012])
    ex.releases = 1
    planned = drive(Supervisor(cfg, FakePlanner(0.1)), ex, 8)
    assert planned == [(0, "global", "start"), (5, "local", "grasp_empty")] and ex.homes == []


@pytest.mark.parametrize("kw", [dict(home_retries=-1), dict(home_retries="often"), dict(home_lift_m=0.0)])
def test_bad_home_retry_settings(kw):
    with pytest.raises(ConfigError) as e:
        SupervisorConfig(**kw)
    assert "supervisor.home_" in str(e.value)


class _TrackSim:
    def __init__(self, tcp):
        self.tcp = np.asarray(tcp, float)

    def tcp_pos(self):
        return self.tcp

    def gripper_closed_cmd(self):
        return False

    def gripper_opening_m(self):
        return 0.08


class _TrackExecutor(FakeExecutor):
    """What the supervisor's switch tracking reads of an executor following a global plan."""

    closes = 0
    plans_infeasible = 0
    grasp_tcp_z = None

    def __init__(self, plan, camera):
        self.camera = camera
        self.set_plan(plan)

    def set_plan(self, plan):
        self.plan = plan
        self.points = self.camera.unproject(plan.uv_px, plan.depth_m)
        self.grip = np.asarray(plan.gripper_closed, bool)
        self.point_source = np.arange(len(plan))
        self.index = 0
        self.sim = getattr(self, "sim", None) or _TrackSim(self.points[0])


PICK_AND_PLACE = np.array([[0.45, 0.0, 0.30], [0.55, 0.05, 0.12], [0.55, 0.05, 0.03], [0.55, 0.05, 0.03],
                           [0.55, 0.05, 0.20], [0.40, -0.15, 0.20], [0.40, -0.15, 0.05]])
PICK_AND_PLACE_GRIP = np.array([False, False, False, True, True, True, False])


def _tracking_run(slide, steps=8, closes_after_start=0, plate_slide=None, pts=PICK_AND_PLACE, track=None,
                  executor_takes=True):
    """GLSR following a frozen global plan (approach, grasp at 3, lift, carry, release at 6) while the object under
    its grasp slides by ``slide`` (and a plate under its release by ``plate_slide``) after the plan's image;
    ``executor_takes`` False: the executor refuses every plan the supervisor makes (as set_plan does one whose pixels
    leave the image or whose IK is infeasible)."""
    from test_anchors import OBJ, TABLE, plate
    from test_lift import FRONT

    from tcot_hybrid.plan import WaypointPlan

    grip = PICK_AND_PLACE_GRIP
    uv, depth = FRONT.project(pts)
    plan = WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=grip, camera=FRONT.name, kind="global")

    def pixel(at):
        return np.round(FRONT.project(np.asarray(at, float)[None])[0][0]).astype(int)

    def image(at, plate_at):
        img = TABLE.copy() if plate_at is None else plate(TABLE, pixel(plate_at))
        u, v = pixel(at)
        img[v - 4:v + 5, u - 4:u + 5] = OBJ
        return img

    class Obs:
        def __init__(self, img):
            self.image = img

    cfg = SupervisorConfig(mode="glsr") if track is None else SupervisorConfig(mode="glsr", track=track)
    sup = Supervisor(cfg, FakePlanner(0.0), world_kind="libero")
    ex = _TrackExecutor(plan, FRONT)
    plate_before = None if plate_slide is None else pts[6] - (0.0, 0.0, pts[6][2])
    plate_after = None if plate_slide is None else plate_before + plate_slide
    before, after = image(pts[3], plate_before), image(pts[3] + slide, plate_after)
    out = [sup.decide(0, observe=lambda: Obs(before), executor=ex)]
    for t in range(1, steps):
        out.append(sup.decide(t, observe=lambda: Obs(after), executor=ex))
        if t == 1:  # the anchors are made at the first step the plan is followed; then the hand may close
            ex.closes += closes_after_start
        if out[-1].plan is not None:  # adopted or refused, and the supervisor told, as EpisodeRunner does
            if executor_takes:
                ex.set_plan(out[-1].plan)
            sup.plan_outcome(out[-1].plan, executor_takes)
    return pts, out, sup


def test_a_grasp_whose_object_moved_is_shifted_with_it_once_two_looks_agree():
    from test_lift import FRONT

    slide = np.array([0.06, -0.05, 0.0])
    pts, ds, sup = _tracking_run(slide)
    shifted = [(t, d) for t, d in enumerate(ds) if d.plan is not None]
    assert [t for t, _ in shifted] == [4]  # looks at steps 2 and 4 (every_steps 2), confirmed by the second
    d = shifted[0][1]
    assert d.plan_mode == "global" and d.event["reason"] == "grasp_tracked" and sup.tracked == {"grasp": 1, "release": 0}
    got = FRONT.unproject(d.plan.uv_px, d.plan.depth_m)
    assert np.linalg.norm(got[3] - (pts[3] + slide)) < 0.02  # the grasp, within the two roundings to a pixel (1 cm here)
    assert np.allclose(got[6], pts[6])  # the release stays


def test_a_shift_the_executor_refuses_is_not_counted_and_not_offered_again():
    _, ds, sup = _tracking_run(np.array([0.06, -0.05, 0.0]), steps=16, executor_takes=False)
    assert [t for t, d in enumerate(ds) if d.plan is not None] == [4]  # once, not every second look after
    assert sup.tracked == {"grasp": 0, "release": 0}


def test_a_grasp_whose_object_stayed_is_left_alone():
    _, ds, sup = _tracking_run(np.zeros(3), steps=12)
    assert all(d.plan is None for d in ds) and sum(sup.tracked.values()) == 0


def test_nothing_is_tracked_once_the_hand_has_closed():
    # what the hand carries changes the view by itself (a drawer front pulled with its handle)
    _, ds, sup = _tracking_run(np.array([0.06, -0.05, 0.0]), steps=12, closes_after_start=1)
    assert all(d.plan is None for d in ds) and sum(sup.tracked.values()) == 0


def test_a_placement_whose_plate_moved_is_shifted_with_it_and_the_grasp_stays():
    from test_lift import FRONT

    plate_slide = np.array([-0.04, 0.09, 0.0])
    pts, ds, sup = _tracking_run(np.zeros(3), plate_slide=plate_slide)
    shifted = [(t, d) for t, d in enumerate(ds) if d.plan is not None]
    assert [t for t, _ in shifted] == [4] and sup.tracked == {"grasp": 0, "release": 1}
    d = shifted[0][1]
    assert d.event["reason"] == "release_tracked" and d.plan_mode == "global"
    got = FRONT.unproject(d.plan.uv_px, d.plan.depth_m)
    assert np.linalg.norm(got[5:] - (pts[5:] + plate_slide), axis=1).max() < 0.02  # above the plate, the release
    assert np.allclose(got[:5], pts[:5])  # the way there, the grasp and its lift stay


def test_a_release_after_no_lift_is_no_placement_and_is_not_watched():
    # a drawer's handle, pulled at one height and let go: where it is let go the arm passes on its way
    pull = PICK_AND_PLACE.copy()
    pull[4:, 2] = 0.03
    _, ds, sup = _tracking_run(np.zeros(3), plate_slide=np.array([-0.04, 0.09, 0.0]), pts=pull)
    assert all(d.plan is None for d in ds) and sum(sup.tracked.values()) == 0


def test_a_moved_plate_is_left_alone_with_releases_off_or_once_the_hand_has_closed():
    from tcot_hybrid.anchors import TrackConfig

    plate_slide = np.array([-0.04, 0.09, 0.0])
    _, ds, sup = _tracking_run(np.zeros(3), steps=12, plate_slide=plate_slide, closes_after_start=1)
    assert all(d.plan is None for d in ds) and sum(sup.tracked.values()) == 0
    _, ds, sup = _tracking_run(np.zeros(3), steps=12, plate_slide=plate_slide,
                               track=TrackConfig(releases=False))
    assert all(d.plan is None for d in ds) and sum(sup.tracked.values()) == 0


def test_a_release_shift_counts_against_the_moves_budget():
    from tcot_hybrid.anchors import TrackConfig

    _, ds, sup = _tracking_run(np.zeros(3), steps=12, plate_slide=np.array([-0.04, 0.09, 0.0]),
                               track=TrackConfig(max_moves=0))
    assert all(d.plan is None for d in ds) and sum(sup.tracked.values()) == 0


def test_the_runner_tells_the_supervisor_whether_the_executor_took_its_plan():
    # a tracked shift is counted only once taken (Supervisor.plan_outcome): the runner must report refusals too
    import dataclasses

    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.run_config import RunConfig
    from tcot_hybrid.supervision import Decision

    r = EpisodeRunner(RunConfig(task="goal_cube_on_plate", seed=0))
    r.settle()
    r._step_once(0, may_plan=True)
    first = r.stack.executor.plan
    off_image = dataclasses.replace(first, uv_px=first.uv_px + 5000.0, step=1)  # cannot be lifted: refused
    again = dataclasses.replace(first, step=2)
    told = []
    r.supervisor.plan_outcome = lambda plan, taken: told.append((plan, taken))
    for step, plan in ((1, off_image), (2, again)):
        r.supervisor.decide = lambda *a, plan=plan, **k: Decision("global", False, None, plan)
        r._step_once(step, may_plan=True)
    assert [(p is off_image, p is again, taken) for p, taken in told] == [(True, False, False), (False, True, True)]
    assert r.stack.executor.plan is again
