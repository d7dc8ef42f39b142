"""Supervision on top of the motion stack: when to plan globally, when to check for failure, when to
replan locally — the paper's Algorithm 1 (GLSR) as an explicit state machine, plus its ablations.

Modes
- ``global``: one global plan at the first step, followed frozen (paper: global trajectory only).
- ``local``: a local plan every ``t_l`` steps from the first step (paper: local trajectory only).
- ``glsr``: Algorithm 1. Global plan at the first step, followed frozen until ``t_f`` (or until the executor
  has carried it out, if that comes first: a finished plan has nothing left to follow; ``t_f`` = "plan": until
  then, however long it takes); from then on
  failure detection every step; when ``t mod t_l == 0`` and the task is not judged successful, a local
  plan from the current image, which the motion stack retargets to smoothly.
- ``glsr_reset``: the paper's released-code variant: on the first detected failure after ``t_f`` the
  scene is reset to its initial state and the task is retried with local plans.
A planner with ``replan_every_step`` (the direct-action baseline) is asked every step whatever the mode.
Every decision is returned as an event (step, state, success probability, replan reason).

An empty grasp (``empty_grasp``): the gripper was closed and its fingers met (opening below ``empty_grasp_m`` for
``empty_grasp_steps`` planner steps: the object was missed, moved away or dropped). The gripper opens and a local
plan from the open hand follows at once, reason ``grasp_empty``, also inside the frozen global phase: the network's
proprioception is the gripper command, and with the gripper still closed its local plans carry the missing object
on. Only once the hand has lifted ``empty_grasp_lift_m`` above where it closed: plans close an empty hand on purpose
too (a knob turned, a drawer or door pushed with closed fingers: the LIBERO Panda's fingers then measure as little
as on nothing), and those motions keep low; and not while the plan that closed the hand carries it on and opens it
again without putting anything down (``empty_grasp_put_down_m``: the closed hand carried on purpose from a knob to
the next grasp). Non-privileged: the finger joints' measured positions, the TCP height from the arm's own
kinematics, and the plan.

A retry from home (``home_retries``): before any plan has released anything, when a global plan has been carried
out with the hand open and the task is judged not done, or an empty grasp reopened the hand, the arm goes back to the
posture the episode started from (straight up first) and a new global plan is made from there (reason
``home_reached``), at most ``home_retries`` times an episode; local plans as above once they are used up or once
something has been released. The view from home is the one the global prompt was trained on, with the arm out of
the way; but a global plan starts the task from its beginning, so after a release (the first object of a
two-object task placed) it would fetch what is already done.

Switch tracking (``track``, :mod:`tcot_hybrid.anchors`): while a frozen global plan approaches its next grasp, the
object, and the receptacle of the placement after it, are looked for in the current image against the plan's; when
one has moved, the plan is shifted with it (reason ``grasp_tracked`` or ``release_tracked``) and followed on, frozen
as before. Non-privileged: the planner camera and its calibration.

A detector that calls an unfinished task done leaves Algorithm 1 following a finished plan until the time limit
(LIBERO, a detector trained on demonstrations only: docs/libero-planner.md, "Failure analysis"). With
``confirm_success`` the planner's own local prompt must agree: at the local period, a success verdict is checked
against a local plan from the same image, and a plan that still moves the hand (``confirm_motion_m``) or switches the
gripper overrules it: the plan is followed like any local replan (reason ``detector_overruled``). Non-privileged: the
network's two outputs on the same observation, nothing from the simulator.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, NamedTuple

from tcot_hybrid.anchors import TrackConfig
from tcot_hybrid.config import require_choice, require_in_range, require_int, require_positive
from tcot_hybrid.sim import EMPTY_HAND_OPENING_M

SUPERVISOR_MODES = ("global", "local", "glsr", "glsr_reset")
CONFIRM_SUCCESS = ("auto", "off", "local_plan")
EMPTY_GRASP = ("auto", "on", "off")
T_F_WORDS = ("auto", "plan")
HOME_RETRIES_LIBERO = 1  # supervisor.home_retries "auto" on LIBERO (docs/libero-planner.md, "Retries from home")
T_F_WORKCELL = 16  # steps: docs/glsr.md, "Choosing t_f"


@dataclass(frozen=True, kw_only=True)
class SupervisorConfig:
    """GLSR parameters (steps are planner steps of plan_dt).

    mode:              global | local | glsr | glsr_reset (see module doc).
    t_f:               latest step at which the frozen global phase ends and failure detection starts; it
                       ends earlier when the executor has carried the whole global plan out. Up: fewer
                       needless replans of a slow but working plan; down: earlier recovery from a plan that
                       is still running but already wrong (e.g. the object moved under it). "plan": no step
                       limit, the phase ends when the global plan has been carried out. "auto" (default), by
                       measurement: 16 steps (1.6 s) on the workcell (docs/glsr.md, "Choosing t_f"), "plan" on
                       LIBERO, whose local prompt derails global plans that were working (docs/libero-planner.md,
                       "Choosing t_f on LIBERO").
    t_l:               local planning period [steps]. Down: reacts faster, more planner calls.
    success_threshold: p(success) at or above which the task is judged done (no replan). Up: replans
                       more readily (fewer missed failures, more false alarms).
    geometric_checks:  also replan (after the first step) when the current plan's IK did not converge or
                       the plan ran out while the task is not judged successful.
    max_resets:        glsr_reset only: how many times the scene may be reset.
    max_plan_latency_s: wall-clock budget for one planner call [s]; a plan that arrives later is stale
                       and dropped (the last valid plan is kept). None = no budget.
    confirm_success:   glsr modes: "off" (Algorithm 1 as written: a success verdict is trusted), "local_plan" (at the
                       local period a success verdict stands only when a local plan from the same image keeps the
                       hand within ``confirm_motion_m`` and switches no gripper; else that plan is followed), or
                       "auto": local_plan on LIBERO (its detector saw no rollouts and called unfinished tasks done on
                       nearly every step: docs/libero-planner.md), off on the workcell (its reporting tables were
                       measured without it).
    empty_grasp:       glsr modes: "on" (reopen a gripper that closed on nothing and replan locally, see the module
                       doc), "off", or "auto": on for LIBERO (docs/libero-planner.md, "Empty grasps"), off on the workcell
                       (its reporting tables were measured without it).
    empty_grasp_m:     finger opening [m, both fingers' travel] below which a closed gripper holds nothing. The
                       LIBERO Panda's fingers stop at 1.2 mm closing on nothing and at 3.5 mm or more on the thinnest
                       object grasped (a bowl's rim; docs/libero-planner.md). Up: thin objects count as missed; down:
                       a missed grasp may go unnoticed.
    empty_grasp_steps: consecutive planner steps the opening must stay below ``empty_grasp_m`` (fingers take
                       about 0.2 s to close).
    empty_grasp_lift_m: how far above the point where it closed the hand must be for an empty gripper to count as
                       a missed or lost object [m]. Down: reacts sooner after a miss, but may reopen a closed hand
                       that turns a knob or pushes a door; up: later.
    empty_grasp_put_down_m: while the plan that closed the gripper is still carrying it out, a closed empty hand
                       that lifted counts as a missed or lost object only when that plan lowers the hand at least this
                       much [m] over its closed stretch before it opens it again (it puts something down), or never
                       opens it: a plan that opens the hand in the air closed it empty on purpose (the oracle's
                       commanded path turns the stove knob with closed fingers, then carries the closed hand up and
                       over to the next grasp before opening it; docs/libero-planner.md, "Empty grasps"). Once
                       another plan has taken over, every lifted empty hand counts. None: every closed empty hand
                       that lifted counts (the check before stop 42). Up: more plans' empty hands left closed (a lost
                       object whose plan puts it down less than this is noticed only at the release); down: more
                       hands closed on purpose are reopened.
    home_retries:      glsr only: how many times an episode the arm may go home and plan globally again (see the
                       module doc), or "auto": HOME_RETRIES_LIBERO on LIBERO (by measurement on development layouts:
                       docs/libero-planner.md, "Retries from home"), 0 on the workcell (its reporting tables were
                       measured without it). 0: Algorithm 1 as written. Up: more retries of a plan that keeps failing,
                       less time left for local recovery.
    home_lift_m:       how far the hand rises straight up before it turns home [m].
    track:             glsr modes: watch a frozen global plan's next grasp and the placement after it in the planner
                       camera and shift the plan with the object or the receptacle when it moved
                       (:mod:`tcot_hybrid.anchors`; reasons ``grasp_tracked``, ``release_tracked``).
    confirm_motion_m:  a local plan whose waypoints reach farther than this from its first one [m] still has work to
                       do. Chosen on held-out LIBERO frames (docs/libero-planner/confirm.py: how far local plans reach
                       on success frames and on the others). Up: overrules fewer verdicts (more false successes
                       stand); down: overrules true ones too (a true success then waits for the predicate or the next
                       verdict; under simulator stopping the predicate ends the episode first).
    """

    mode: str = "global"
    t_f: int | Literal["auto", "plan"] = "auto"
    t_l: int = 8
    success_threshold: float = 0.5
    geometric_checks: bool = False
    max_resets: int = 1
    max_plan_latency_s: float | None = 1.0
    confirm_success: str = "auto"
    confirm_motion_m: float = 0.05
    empty_grasp: str = "auto"
    empty_grasp_m: float = EMPTY_HAND_OPENING_M
    empty_grasp_steps: int = 3
    empty_grasp_lift_m: float = 0.04
    empty_grasp_put_down_m: float | None = 0.03
    home_retries: int | Literal["auto"] = "auto"
    home_lift_m: float = 0.10
    track: TrackConfig = field(default_factory=TrackConfig)

    def __post_init__(self) -> None:
        require_choice("supervisor.mode", self.mode, SUPERVISOR_MODES)
        require_choice("supervisor.confirm_success", self.confirm_success, CONFIRM_SUCCESS)
        require_positive("supervisor.confirm_motion_m", self.confirm_motion_m)
        require_choice("supervisor.empty_grasp", self.empty_grasp, EMPTY_GRASP)
        require_positive("supervisor.empty_grasp_m", self.empty_grasp_m)
        require_int("supervisor.empty_grasp_steps", self.empty_grasp_steps, minimum=1)
        require_positive("supervisor.empty_grasp_lift_m", self.empty_grasp_lift_m)
        if self.empty_grasp_put_down_m is not None:
            require_positive("supervisor.empty_grasp_put_down_m (or null: off)", self.empty_grasp_put_down_m)
        if isinstance(self.home_retries, str):
            require_choice("supervisor.home_retries", self.home_retries, ("auto",))
        else:
            require_int("supervisor.home_retries", self.home_retries, minimum=0)
        require_positive("supervisor.home_lift_m", self.home_lift_m)
        if isinstance(self.t_f, str):
            require_choice("supervisor.t_f", self.t_f, T_F_WORDS)
        else:
            require_int("supervisor.t_f", self.t_f, minimum=0)
        require_int("supervisor.t_l", self.t_l, minimum=1)
        require_in_range("supervisor.success_threshold", self.success_threshold, 0.0, 1.0, low_closed=False)
        require_int("supervisor.max_resets", self.max_resets, minimum=0)
        if self.max_plan_latency_s is not None:
            require_positive("supervisor.max_plan_latency_s", self.max_plan_latency_s)


def resolve_t_f(t_f: int | str, world_kind: str) -> int | None:
    """``supervisor.t_f`` as a step (int), or None for "until the global plan has been carried out"."""
    if t_f == "auto":
        return None if world_kind == "libero" else T_F_WORKCELL
    return None if t_f == "plan" else t_f


class Decision(NamedTuple):
    plan_mode: str | None  # "global" | "local" | "direct" | None (keep following)
    reset: bool            # glsr_reset: restore the initial scene before planning
    event: dict | None
    plan: object = None    # a plan the supervisor already asked for (confirm_success): follow it, do not ask again


class Supervisor:
    """Decides, at the start of each planner step, whether and how to (re)plan."""

    def __init__(self, config: SupervisorConfig, planner, *, world_kind: str = "workcell"):
        self.cfg, self.planner = config, planner
        self.confirm = config.confirm_success == "local_plan" or (config.confirm_success == "auto"
                                                                  and world_kind == "libero")
        self.check_empty_grasp = config.empty_grasp == "on" or (config.empty_grasp == "auto" and world_kind == "libero")
        self._empty_steps = 0  # consecutive planner steps with a closed, empty, lifted gripper
        self._empty_planned_for = 0  # executor.closes of the grasp last found closed empty on purpose
        retries = config.home_retries
        if retries == "auto":
            retries = HOME_RETRIES_LIBERO if world_kind == "libero" else 0
        self.home_retries_left = retries if config.mode == "glsr" else 0
        self.homes = 0
        self._global_from = 0  # step of the global plan being followed: t_f counts from it
        self.empty_grasps = 0
        self.overruled = 0
        self.t_f = resolve_t_f(config.t_f, world_kind)  # None: the global phase lasts as long as its plan
        self.track = config.track.enabled(world_kind) and config.mode in ("glsr", "glsr_reset")
        self._plan_image = None  # the image the global plan being followed was made (or last shifted) from
        self._anchors: list = []  # its next grasp and placement (anchors.SwitchAnchor)
        self.tracked = {"grasp": 0, "release": 0}  # plans shifted (and taken by the executor), by what moved
        self._offered = None  # (shifted plan, its image, its anchor) until the runner says whether it was taken
        self.state = "start"
        self.resets = 0
        self.replans = 0
        self._ik_failures_at_plan = 0
        self._infeasible_at_plan = 0

    def _event(self, step, p=None, reason=None, plan=None) -> dict:
        ev = {"kind": "supervisor", "step": step, "state": self.state}
        if p is not None:
            ev["p_success"] = round(float(p), 4)
        if reason:
            ev["reason"] = reason
        if plan:
            ev["plan"] = plan
        return ev

    def decide(self, step: int, *, observe, executor) -> Decision:
        cfg = self.cfg
        if getattr(self.planner, "replan_every_step", False):
            self.state = "direct"
            return Decision("direct", False, self._event(step, plan="direct") if step == 0 else None)
        if step == 0:
            self.state = "local_follow" if cfg.mode == "local" else "global_follow"
            mode = "local" if cfg.mode == "local" else "global"
            self._remember_plan_image(observe)
            return self._plan(step, mode, "start", executor)
        if cfg.mode == "global":
            return Decision(None, False, None)
        if cfg.mode == "local" or (cfg.mode == "glsr_reset" and self.resets > 0):
            if step % cfg.t_l == 0:
                return self._plan(step, "local", "period", executor)
            return Decision(None, False, None)
        if self.state == "homing":
            if not executor.plan_finished:
                return Decision(None, False, None)
            self.state, self._global_from = "global_follow", step
            self._remember_plan_image(observe)
            return self._plan(step, "global", "home_reached", executor)
        opening = self._empty_grasp_opening(executor) if self.check_empty_grasp else None
        if opening is not None:  # before any observation of this step
            executor.open_empty_gripper(opening)
            self.empty_grasps += 1
            if self._may_go_home(executor):
                return self._go_home(step, "grasp_empty", executor, opening_m=round(opening, 5))
            self.state = "local_follow"
            d = self._plan(step, "local", "grasp_empty", executor)
            return Decision(d.plan_mode, False, {**d.event, "opening_m": round(opening, 5)})
        geometric = self._geometric_reason(executor) if cfg.geometric_checks else None
        frozen = (self.state == "global_follow" and (self.t_f is None or step - self._global_from <= self.t_f)
                  and not executor.plan_finished)
        if frozen and geometric is None:
            tracked = self._track_switches(step, observe, executor) if self.track else None
            return tracked or Decision(None, False, None)
        p, rejected = self.detect(observe)
        successful = (not rejected) and p >= cfg.success_threshold
        if self.state == "global_follow":
            self.state = "detect"
        if successful and self.confirm and step % cfg.t_l == 0:
            plan, motion = self._disagreeing_local_plan(observe, executor)
            if plan is not None:
                self.state, self.overruled, self.replans = "local_follow", self.overruled + 1, self.replans + 1
                self._ik_failures_at_plan = executor.ik_failures
                self._infeasible_at_plan = getattr(executor, "plans_infeasible", 0)
                ev = self._event(step, p=p, reason="detector_overruled", plan="local")
                return Decision("local", False, {**ev, "plan_motion_m": round(motion, 4)}, plan)
        if successful:
            return Decision(None, False, self._event(step, p=p, reason="judged_successful"))
        if step % cfg.t_l == 0 or geometric is not None:
            reason = geometric or ("detector_rejected" if rejected else "not_successful")
            if cfg.mode == "glsr_reset" and self.resets < cfg.max_resets:
                self.resets += 1
                self.state = "reset"
                return Decision("local", True, self._event(step, p=p, reason=reason, plan="reset+local"))
            if self._may_go_home(executor) and self._global_plan_ran_out_open(executor):
                return self._go_home(step, reason, executor, p_success=round(float(p), 4))
            self.state = "local_follow"
            d = self._plan(step, "local", reason, executor)
            return Decision(d.plan_mode, False, {**d.event, "p_success": round(float(p), 4)})
        return Decision(None, False, self._event(step, p=p))

    def _remember_plan_image(self, observe) -> None:
        if self.track:  # None for a planner that does not look (nothing to track)
            self._plan_image = getattr(observe(), "image", None)

    def _track_switches(self, step: int, observe, executor) -> Decision | None:
        """While a frozen global plan approaches its next grasp: a look every ``track.every_steps`` steps at whether the
        object, or the receptacle of the placement after it, moved (:meth:`tcot_hybrid.anchors.SwitchAnchor.look`),
        while the hand is still clear of it; once ``track.confirm_looks`` looks in a row agree, the plan is shifted
        with it (reason ``grasp_tracked`` or ``release_tracked``). None: keep following."""
        import numpy as np

        from tcot_hybrid.anchors import shift_on_plane, shifted_plan, switch_anchors

        tc = self.cfg.track
        plan = executor.plan
        if (plan is None or plan.kind != "global" or self._plan_image is None
                or sum(self.tracked.values()) >= tc.max_moves):
            return None
        if not self._anchors or self._anchors[0].plan is not plan:
            self._anchors = switch_anchors(plan, executor, self._plan_image, tc)
        if step % tc.every_steps:
            return None
        tcp = executor.sim.tcp_pos()
        live = [a for a in self._anchors if not a.done(executor) and not a.refused
                and np.linalg.norm(tcp - a.point_m) >= tc.hand_clear_m]
        if not live:
            return None
        image = observe().image
        for a in live:
            seen = a.look(image, tc)
            if seen is None or not seen.moved:
                a.candidate, a.seen = None, 0
                continue
            same = a.candidate is not None and np.linalg.norm(seen.uv_px - a.candidate) <= 2.0
            a.candidate, a.seen = seen.uv_px, (a.seen + 1 if same else 1)
            if a.seen < tc.confirm_looks:
                continue
            # a release's move is read at the release point's height, not the plate's: a few mm short on 10 cm
            shift = shift_on_plane(plan.lift_camera(executor.camera), a.point_m, seen.uv_px)
            start = int(executor.point_source[executor.index])
            moved = shifted_plan(plan, executor.camera, start, max(a.plan_index, start), shift, step,
                                 approach=a.kind == "grasp")
            a.candidate, a.seen = None, 0
            self._offered = (moved, image, a)  # counted once taken (plan_outcome)
            ev = self._event(step, reason=f"{a.kind}_tracked", plan="global")
            return Decision("global", False, {**ev, "shift_m": np.round(shift, 4).tolist(),
                                              "score_here": round(seen.here, 3), "score_found": round(seen.best, 3),
                                              "image_changed": round(seen.image_changed, 4)}, moved)
        return None

    def plan_outcome(self, plan, taken: bool) -> None:
        """The runner's word on a plan this supervisor made (a tracked shift, a local plan overruling the detector):
        whether the executor took it (``Executor.set_plan``). A shift is counted, and its image becomes what the
        anchors compare with, only once taken; one the executor refused (off the image, IK infeasible; its own event
        says why) is not offered again for that anchor."""
        if self._offered is None or self._offered[0] is not plan:
            return
        _, image, anchor = self._offered
        self._offered = None
        if taken:
            self.tracked[anchor.kind] += 1
            self._plan_image = image  # the shifted plan's anchors see the scene as it is now
        else:
            anchor.refused = True

    def in_global_phase(self, step: int, executor) -> bool:
        """Before failure detection starts (``--stop-on detector`` asks from then on): step < t_f, or with t_f "plan"
        while the first global plan is still being carried out (a local-only run has no global phase)."""
        if self.state == "homing":
            return True
        if self.t_f is not None:
            return step - self._global_from < self.t_f
        return self.state == "global_follow" and not executor.plan_finished

    def detect(self, observe) -> tuple[float, str | None]:
        """The detector's p(success) on ``observe()`` and why it was rejected (None if usable); an unusable
        answer (error, NaN, outside [0, 1]) counts as a failed detection, i.e. not successful, so the robot
        replans (or keeps going) rather than trusting it."""
        from tcot_hybrid.errors import PlanningError

        try:
            raw = self.planner.success_probability(observe())
        except PlanningError as exc:
            return 0.0, str(exc)
        scalar = getattr(raw, "shape", None) == () and getattr(raw, "dtype", None) is not None and raw.dtype.kind in "iuf"
        if not scalar and (isinstance(raw, (bool, str, bytes)) or not isinstance(raw, (int, float))):
            return 0.0, f"success probability {raw!r} is not a number"  # None, "0.7", arrays: never guessed
        p = float(raw)
        if not (0.0 <= p <= 1.0):  # also catches NaN
            return 0.0, f"success probability {p!r} outside [0, 1]"
        return p, None

    def _go_home(self, step, reason, executor, **info) -> Decision:
        """Send the arm home; the global plan follows on arrival (``decide`` in state "homing")."""
        self.home_retries_left -= 1
        self.homes += 1
        self.state = "homing"
        executor.go_home(self.cfg.home_lift_m)
        return Decision(None, False, {**self._event(step, reason=reason, plan="home"), **info})

    def _may_go_home(self, executor) -> bool:
        """A retry from home is left and no plan has released anything yet (the task is still at its start)."""
        return self.home_retries_left > 0 and executor.releases == 0

    @staticmethod
    def _global_plan_ran_out_open(executor) -> bool:
        """The executor has carried a global plan out and the hand is open: nothing in hand, nothing left to do."""
        plan = executor.plan
        return (executor.plan_finished and plan is not None and plan.kind == "global"
                and not executor.sim.gripper_closed_cmd())

    def _plan(self, step, mode, reason, executor) -> Decision:
        self.replans += step > 0
        self._ik_failures_at_plan = executor.ik_failures
        self._infeasible_at_plan = getattr(executor, "plans_infeasible", 0)
        return Decision(mode, False, self._event(step, reason=reason, plan=mode))

    def _disagreeing_local_plan(self, observe, executor):
        """(a local plan from the current image, how far it reaches [m]) when it still moves the hand farther than
        ``confirm_motion_m`` from its first waypoint or switches the gripper, else (None, 0): the success verdict
        stands. A refused plan (PlanningError, LiftError) or a stale one (``max_plan_latency_s``) leaves the verdict
        standing too."""
        import numpy as np

        from tcot_hybrid.errors import LiftError, PlanningError

        import time

        obs = observe()
        t0 = time.perf_counter()
        try:
            plan = self.planner.plan(obs, mode="local")
            pts = plan.lift_camera(executor.camera).unproject(plan.uv_px, plan.depth_m)
        except (PlanningError, LiftError):
            return None, 0.0
        budget = self.cfg.max_plan_latency_s
        if budget is not None and time.perf_counter() - t0 > budget:  # stale, like any late plan: not followed
            return None, 0.0
        motion = float(np.linalg.norm(pts - pts[0], axis=1).max())
        grip = np.asarray(plan.gripper_closed, bool)
        if motion > self.cfg.confirm_motion_m or bool((grip != grip[0]).any()):
            return plan, motion
        return None, motion

    def _empty_grasp_opening(self, executor) -> float | None:
        """The measured finger opening [m] once the closed gripper has measured empty for ``empty_grasp_steps`` steps
        while the hand is at least ``empty_grasp_lift_m`` above where a plan closed it, else None: a pick lifts what it
        holds, while a knob turned or a drawer or door pushed with closed fingers (an empty hand on purpose) keeps
        low. Not while the plan that closed the hand is still carrying it out and opens it again without putting
        anything down (``empty_grasp_put_down_m``): it meant the hand empty (event ``empty_hand_planned``, once a
        grasp). A plan that never opens it, or any plan after the one that closed it, is not asked."""
        sim = executor.sim
        closed_at = executor.grasp_tcp_z
        opening = sim.gripper_opening_m()
        empty = (sim.gripper_closed_cmd() and closed_at is not None and opening < self.cfg.empty_grasp_m
                 and float(sim.tcp_pos()[2]) - closed_at >= self.cfg.empty_grasp_lift_m)
        self._empty_steps = self._empty_steps + 1 if empty else 0
        if self._empty_steps < self.cfg.empty_grasp_steps:
            return None
        self._empty_steps = 0
        put_down = executor.closed_put_down_m
        if self.cfg.empty_grasp_put_down_m is not None and put_down is not None \
                and put_down < self.cfg.empty_grasp_put_down_m:
            if self._empty_planned_for != executor.closes:
                self._empty_planned_for = executor.closes
                executor.event("empty_hand_planned", opening_m=round(opening, 5), put_down_m=round(put_down, 4))
            return None
        return opening

    def _geometric_reason(self, executor) -> str | None:
        if getattr(executor, "plans_infeasible", 0) > self._infeasible_at_plan:
            return "ik_plan_infeasible"
        if executor.ik_failures > self._ik_failures_at_plan:
            return "ik_not_converged"
        if executor.plan_finished:
            return "plan_finished"
        return None
