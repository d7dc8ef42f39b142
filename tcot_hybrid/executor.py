"""Motion stack: WaypointPlan → lift → IK → Ruckig → controller → safety → simulation, one tick at a time.

Data flows one way. The executor owns the current plan and the waypoint it is heading for:
- pass-through waypoints are blended: the next one is activated ``blend_time_s`` before the current
  Ruckig segment ends, and Ruckig retargets online from the moving reference state;
- a waypoint whose gripper bit differs from the current gripper command (and the last waypoint) is a
  stop: the arm arrives, the gripper switches, and the arm holds still for ``gripper_settle_s``.
Every anomaly (rejected plan, IK not converged, slow arrival, safety fault) becomes an event.
With a whole-plan IK backend (casadi) every waypoint's joint target is solved when the plan is adopted, at
planner rate and before any motion (never inside ``control_tick``); an infeasible plan is refused then.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.config import require_choice, require_nonnegative, require_positive
from tcot_hybrid.errors import ConfigError, LiftError, TcotError, TrajectoryError
from tcot_hybrid.ik import IKSolver, IKTarget, rotation_angle
from tcot_hybrid.lift import LiftConfig, lift_waypoints
from tcot_hybrid.plan import WaypointPlan
from tcot_hybrid.robot import R_DOWN
from tcot_hybrid.sim import EMPTY_HAND_OPENING_M, Simulation



@dataclass(frozen=True, kw_only=True)
class ExecutorConfig:
    """How plans are turned into motion.

    blend_time_s:     activate the next pass-through waypoint this long before the current segment
                      ends [s]. Up: smoother, faster, corners cut more; 0: stop at every waypoint.
    reach_tol_m:      TCP distance to a stop waypoint that counts as arrived [m]. Down: more precise
                      grasps, more waiting.
    reach_timeout_s:  after the reference has arrived, wait at most this long for the TCP [s]; then
                      go on anyway and log a ``slow_arrival`` event.
    stop_match_m:     a replan's waypoint within this distance of the stop the arm is waiting at is that
                      stop re-aimed, and the wait (``reach_timeout_s``) goes on [m].
                      Learned local plans move a stop by 1-4 cm from one replan to the next; with a match
                      radius of ``reach_tol_m`` every replan restarted the wait, and GLSR hovered above a drawer
                      handle for the rest of the episode without closing the gripper. Down: re-aimed stops
                      restart the wait; up: a stop that really moved (e.g. the object did) is waited at less.
    gripper_settle_s: hold still this long after switching the gripper [s]. Up: firmer grasps before
                      moving; down: faster episodes.
    resync_tol_rad:   if the reference and the measured joints differ by more than this when a new plan
                      arrives (e.g. after a push), restart the reference from the measured state [rad].
    reflex_tracking_rad: tracking reflex (a robot's collision reflex): when a measured joint lags its
                      reference by more than this, the arm is blocked (it hit something) or was knocked
                      far off; the plan is dropped and the reference brakes from the measured state, so the
                      controller stops pushing instead of winding up and whipping the arm when it comes
                      free. Event ``tracking_reflex``; the supervisor decides what next (GLSR and local
                      modes replan; a frozen global plan is not resumed, the arm holds). Nominal tracking
                      stays below 0.08 rad (docs/eval-*); None = off.
    transit_min_horizontal_m, transit_min_vertical_m: a plan segment that moves more than both sideways and
                      up or down is split at a corner: move over, then lower (or raise, then move over), the
                      sideways move at the higher end's height. Learned global plans are samples of a
                      track (0.4 s or a piece's path fraction apart); a straight line between two cuts the
                      corner of the demonstration's lower-after-moving-over, and a carried cube swept diagonally into the
                      drawer's far wall and pushed the drawer shut (docs/planner.md, "Square transits").
                      Oracle plans are never split: their points are at most ``OracleConfig.spacing_m``
                      (4 cm) apart; nor are direct plans (one waypoint: the baseline's action, not a
                      sampled track). Down: more segments squared, more time spent; up: fewer; None (YAML
                      null) = off. [m]
    switch_min_horizontal_m: the same for the segments into and out of a gripper switch (a grasp or release
                      point), with this smaller sideways threshold: the demonstrations of an upright hand come
                      straight down onto a grasp or place and leave it straight up (a leaning hand comes in along
                      its own axis: ``grasp_along_approach``). Event-spaced global plans have ~10 cm
                      between points, and a place descent starting 2-3 cm to the side brought a carried cube
                      down on the bowl's rim. Oracle stops are approached vertically, so their plans stay
                      unsplit. Down: squares smaller offsets; None (YAML null) = off. [m]
    grasp_along_approach: a descent onto a grasp that is squared, by a hand leaning from straight down (within
                      ``APPROACH_TILT_RANGE_RAD``), gets its corner on the line along the hand's approach axis into
                      the grasp instead of straight above it, as the oracle's leaning grasps come in. Off by default:
                      measured, not adopted (docs/libero-planner.md, "Grasps along their approach"). True: along.
    release_retreat_m: a plan whose last gripper switch is a release and which ends there (its last point within
                      ``RETREAT_NEAR_M`` above the release) gets one more point this far straight up from its last:
                      demonstrations end a few steps after the release, so learned plans do too, and the fingers
                      stay around what they let go (a sauce bottle released into a basket leant on them, tilted,
                      and stayed in the hand's grip to the time limit; docs/libero-planner.md, "The long suite:
                      its own model, and leaving a release"). Oracle plans already leave straight up. None (YAML
                      null) = off. [m]
    max_segment_m:    a plan segment longer than this (of the kind ``cut_segments`` names) is cut into equal pieces no
                      longer than it, each piece's end a pass-through waypoint (the gripper bit of the segment's start,
                      the orientation of its end), so the hand moves along the planned line: the smoother interpolates
                      joint targets, and between two far-apart targets a joint-space line bows away from the Cartesian
                      one (a learned 18 cm descent into the book caddy's back compartment bowed 2.9 cm sideways, and the
                      book landed on the compartment's wall; docs/libero-planner.md, "Straight segments"). Oracle
                      plans are at most ``OracleConfig.spacing_m`` (4 cm) apart already; direct plans (one waypoint: the
                      baseline's action) are not cut. "auto" (default): MAX_SEGMENT_LIBERO_M on LIBERO (with
                      ``cut_segments`` "holding_descents": judged on development layouts of all 40 tasks, docs/seeds.md,
                      stop 68; every long segment, or every closed descent, cut lost other libero_10 tasks as much as
                      the book gained), off on the workcell (its reporting tables were measured without it); None
                      (YAML null) = off. Down: straighter, more waypoints to solve, slower moves. [m]
    cut_segments:     which segments ``max_segment_m`` cuts: "holding_descents" (default), the descents within
                      VERTICAL_TILT_RAD (20 degrees) of straight down of a hand that, as the segment begins, holds
                      something (closed, its fingers more than EMPTY_HAND_OPENING_M apart: an object lowered onto its
                      place, the book's), decided then, not when the plan is adopted (not with a whole-plan IK solve);
                      "closed_descents", those of any closed hand, a hand closed on purpose for a push too (its
                      straighter descent to the push lost the bottom drawer and the stove's knob a layout or two);
                      "vertical", every segment that close to straight up or down (grasp descents, rises);
                      "all", the moves over too (cut everywhere, the hand's paths changed on tasks that had succeeded
                      and libero_10 lost more layouts than it won: docs/libero-planner.md, "Straight segments").
    start_home_tol_rad: an episode whose arm starts further than this from the robot's home posture on any joint
                      moves there in joint space before its first plan (the steps it takes count against the
                      time limit; event ``started_at_home``), and retries from home return there too. Every
                      demonstration starts at home, LIBERO's shipped init states 0.01-0.05 rad off it, and the
                      learned planner reads such starts worse: development layouts 20049-20050, global-only 51 of
                      80 from them, 62 from home, 61 sent home first (docs/libero-planner.md, "The arm's start").
                      Down: more starts sent home; None (YAML null) = off: plan from
                      where the arm stands, and a retry from home returns to that start. [rad]
    hand_twin:        the gripper is a parallel jaw, so a hand turned half a turn about its approach axis (TCP z)
                      is the same grasp. When a waypoint's IK did not converge, a joint limit shaped its solution, or
                      the hand is asked to turn more than ``TWIN_TURN_RAD`` (90 degrees) from the hand of the IK
                      seed (the previous waypoint's answer), the twin is solved from the same seed and taken when it
                      converges where the other missed by more than ``TWIN_MISS_M``, or moves the arm
                      ``TWIN_TRAVEL_MARGIN_RAD`` (0.5 rad, summed over the joints) less without converging less; the
                      waypoints after it are then asked turned too, until a twin is better again (event
                      ``hand_turned``). Learned plans choose between the two by the hand's yaw
                      (planners/learned.py ``canonical_hand``), which cannot see the arm: a level hand reaching for a
                      bottle by the robot's base was solved with joint 7 at its limit and the next waypoints stopped
                      8-12 cm short (docs/libero-planner.md, "Air drag and the wrist's half turn"); a side grasp of
                      the ketchup asked a 130-degree turn that IK made by swinging the whole arm over, from where the
                      carry could not reach the basket ("The hand the arm stands nearer"). False: orientations as
                      planned.
    touch_retry_depth_m: a grasp that retries where the gripper closed on nothing before (its point within
                      ``touch_retry_radius_m`` sideways of where an empty grasp closed this episode), by a hand
                      pointing down (within TOUCH_MAX_TILT_RAD), does not close where planned: the hand goes on
                      down in ``touch_step_m`` steps, at most this far, until the wrist's force sensor reads
                      ``touch_force_n`` more than at the grasp point (the fingertips met the table or the object),
                      and closes there (event ``touch``; plans that come meanwhile are refused, event
                      ``plan_refused``: GLSR asks again at its next period). Learned grasps that miss close in the
                      air over the object more often than beside it (docs/libero-planner.md, "Touching down on a
                      retry"). A robot without a wrist force
                      sensor closes where planned (event ``touch_unavailable``). Up: deeper search, more time;
                      None (YAML null) = off. [m]
    touch_retry_radius_m: how near an empty grasp's closing point a grasp counts as its retry [m]. Up: more grasps
                      touch down.
    touch_step_m:     the touch's step down [m], each from rest to rest and TOUCH_SLOWER times slower than a move
                      (a touch that meets nothing takes about 6 s for 8 cm): the force is read every control tick,
                      so this sets the descent's pace, not where it stops. At most ``touch_retry_depth_m``.
    touch_force_n:    how much more than at the grasp point the wrist must feel to have touched [N]. Down: stops
                      on the hand's own acceleration; up: presses harder before it closes.
    """

    blend_time_s: float = 0.15
    reach_tol_m: float = 0.008
    reach_timeout_s: float = 1.0
    stop_match_m: float = 0.05
    gripper_settle_s: float = 0.5
    resync_tol_rad: float = 0.01
    reflex_tracking_rad: float | None = 0.25
    transit_min_horizontal_m: float | None = 0.06
    transit_min_vertical_m: float = 0.02
    switch_min_horizontal_m: float | None = 0.005
    grasp_along_approach: bool = False
    release_retreat_m: float | None = 0.08
    max_segment_m: float | None | Literal["auto"] = "auto"
    cut_segments: str = "holding_descents"
    start_home_tol_rad: float | None = 0.002
    hand_twin: bool = True
    touch_retry_depth_m: float | None = None
    touch_retry_radius_m: float = 0.06
    touch_step_m: float = 0.01
    touch_force_n: float = 8.0

    def __post_init__(self) -> None:
        for name in ("blend_time_s", "reach_timeout_s", "gripper_settle_s", "transit_min_vertical_m"):
            require_nonnegative(name, getattr(self, name))
        if self.transit_min_horizontal_m is not None:
            require_positive("transit_min_horizontal_m (or null: off)", self.transit_min_horizontal_m)
        if self.switch_min_horizontal_m is not None:
            require_positive("switch_min_horizontal_m (or null: off)", self.switch_min_horizontal_m)
        if self.release_retreat_m is not None:
            require_positive("release_retreat_m (or null: off)", self.release_retreat_m)
        if self.start_home_tol_rad is not None:
            require_positive("start_home_tol_rad (or null: off)", self.start_home_tol_rad)
        require_choice("executor.cut_segments", self.cut_segments, CUT_SEGMENTS)
        if isinstance(self.max_segment_m, str):
            require_choice("executor.max_segment_m", self.max_segment_m, ("auto",))
        elif self.max_segment_m is not None:
            require_positive("max_segment_m (or null: off, or auto)", self.max_segment_m)
        require_positive("reach_tol_m", self.reach_tol_m)
        require_positive("stop_match_m", self.stop_match_m)
        require_positive("resync_tol_rad", self.resync_tol_rad)
        if self.reflex_tracking_rad is not None:  # None (YAML null) switches the reflex off
            require_positive("reflex_tracking_rad (or null: off)", self.reflex_tracking_rad)
        if self.touch_retry_depth_m is not None:
            require_positive("touch_retry_depth_m (or null: off)", self.touch_retry_depth_m)
        for name in ("touch_retry_radius_m", "touch_step_m", "touch_force_n"):
            require_positive(name, getattr(self, name))
        if self.touch_retry_depth_m is not None and self.touch_step_m > self.touch_retry_depth_m:
            raise ConfigError(f"touch_step_m = {self.touch_step_m} m is deeper than touch_retry_depth_m = "
                              f"{self.touch_retry_depth_m} m: a touch would not take a single step; choose a step "
                              f"<= the depth")


CUT_SEGMENTS = ("closed_descents", "holding_descents", "vertical", "all")  # executor.cut_segments
MAX_SEGMENT_LIBERO_M = 0.04  # executor.max_segment_m "auto" on LIBERO: the oracle's spacing (docs/seeds.md, stop 68)
VERTICAL_TILT_RAD = np.deg2rad(20.0)  # a segment this close to straight up or down is vertical (cut_segments)
TOUCH_MAX_TILT_RAD = np.deg2rad(30.0)  # a touch goes straight down: only for a hand this close to pointing down
TOUCH_SLOWER = 4.0  # a touch's steps are planned this many times slower than a move (it must not strike what it meets)


APPROACH_TILT_RANGE_RAD = (np.deg2rad(5.0), np.deg2rad(45.0))  # (least, most) lean from straight down


def _approach_corner(prev: np.ndarray, p: np.ndarray, approach: np.ndarray) -> np.ndarray | None:
    """Where the line along ``approach`` (the hand's TCP z, unit) into ``p`` reaches ``prev``'s height, for a hand
    whose lean from pointing down lies in APPROACH_TILT_RANGE_RAD, however far back that is; None for any other hand
    (straight down, or a side grasp's: its corner stays above the grasp)."""
    tilt = float(np.arccos(np.clip(-approach[2], -1.0, 1.0)))
    if not APPROACH_TILT_RANGE_RAD[0] <= tilt <= APPROACH_TILT_RANGE_RAD[1]:
        return None
    return p - approach * (float(prev[2] - p[2]) / -float(approach[2]))


def square_transits(start: np.ndarray, start_closed: bool, points: np.ndarray, grip: np.ndarray, *,
                    min_horizontal_m: float | None, min_vertical_m: float,
                    switch_min_horizontal_m: float | None = None, approach: np.ndarray | None = None,
                    return_source: bool = False):
    """Waypoints with every diagonal segment split into a sideways and a vertical move, the sideways one at the
    higher end's height: a segment that goes down gets a corner above its end (move over, then lower), one
    that goes up a corner above its start (raise, then move over). Diagonal = more than ``min_horizontal_m``
    sideways (or more than ``switch_min_horizontal_m`` for a segment into or out of a gripper switch) and more
    than ``min_vertical_m`` up or down; None thresholds are off. ``start`` and ``start_closed``
    are the TCP and the gripper command now (the first segment's start). A corner keeps the gripper bit of its
    segment's start, so grasps and releases still happen at the planned points. ``approach`` (N x 3, each
    point's approach axis, TCP z; None: not used): a descent onto a grasp that is squared, by a hand leaning
    within APPROACH_TILT_RANGE_RAD, gets its corner on the line along that axis into the grasp instead (move over,
    then come in along the approach, as the oracle's leaning grasps do), and none when that line meets the start's
    height within the threshold sideways of the start. A descent that starts within the threshold sideways of the
    grasp is not squared, so it stays straight down. Pure function; returns new arrays, and with ``return_source``
    also each output point's plan index (a corner's is its segment's end: it takes that waypoint's orientation)."""
    out_p, out_g, out_src = [], [], []
    prev = np.asarray(start, float)
    prev_g = bool(start_closed)
    prev_is_switch = False
    for i, (p, g) in enumerate(zip(points, grip)):
        is_switch = bool(g) != prev_g
        near_switch = is_switch or prev_is_switch
        thresholds = [t for t in (min_horizontal_m, switch_min_horizontal_m if near_switch else None) if t is not None]
        threshold = min(thresholds) if thresholds else None
        horizontal = float(np.linalg.norm(p[:2] - prev[:2]))
        dz = float(p[2] - prev[2])
        if threshold is not None and horizontal > threshold and abs(dz) > min_vertical_m:
            onto_grasp = approach is not None and is_switch and g and dz < 0
            along = _approach_corner(prev, np.asarray(p, float), np.asarray(approach[i], float)) if onto_grasp else None
            if along is not None:  # a leaning hand: no corner when the descent already runs along its axis
                corner = along if float(np.linalg.norm(along[:2] - prev[:2])) > threshold else None
            else:
                corner = np.array([p[0], p[1], prev[2]]) if dz < 0 else np.array([prev[0], prev[1], p[2]])
        else:
            corner = None
        if corner is not None:
            out_p.append(corner)
            out_g.append(prev_g)
            out_src.append(i)
        out_p.append(p)
        out_g.append(bool(g))
        out_src.append(i)
        prev, prev_g, prev_is_switch = p, bool(g), is_switch
    if return_source:
        return np.asarray(out_p), np.asarray(out_g, bool), np.asarray(out_src, int)
    return np.asarray(out_p), np.asarray(out_g, bool)


RETREAT_NEAR_M = 0.03  # a plan ending this close above its release has not left it [m]


def retreat_after_release(start_closed: bool, points: np.ndarray, grip: np.ndarray, *, lift_m: float | None):
    """``points`` and ``grip`` with one point ``lift_m`` straight above the last appended when the plan's last
    gripper switch is a release (closed to open; ``start_closed`` is the gripper command before the first point)
    and the plan ends within ``RETREAT_NEAR_M`` above where it released; also each output point's plan index (the
    added one takes the last point's orientation). Pure function; unchanged arrays when ``lift_m`` is None, the
    plan has no release or already leaves it."""
    points = np.asarray(points, float)
    grip = np.asarray(grip, bool)
    source = np.arange(len(points))
    if lift_m is None or not len(points):
        return points, grip, source
    prev = np.r_[bool(start_closed), grip[:-1]]
    switches = np.flatnonzero(prev != grip)
    if not len(switches) or grip[switches[-1]]:
        return points, grip, source
    released_at = points[switches[-1]]
    if points[-1, 2] - released_at[2] > RETREAT_NEAR_M:
        return points, grip, source
    above = points[-1] + np.array([0.0, 0.0, lift_m])
    return np.vstack([points, above]), np.r_[grip, False], np.r_[source, len(points) - 1]


def resolve_max_segment(max_segment_m: float | None | str, world_kind: str) -> float | None:
    """``executor.max_segment_m`` with "auto" made concrete for a world (see :class:`ExecutorConfig`)."""
    if max_segment_m == "auto":
        return MAX_SEGMENT_LIBERO_M if world_kind == "libero" else None
    return max_segment_m


def cut_long_segments(start: np.ndarray, start_closed: bool, points: np.ndarray, grip: np.ndarray, *,
                      max_segment_m: float | None, which: str = "all"):
    """Waypoints with every segment longer than ``max_segment_m`` cut into the fewest equal pieces no longer than it
    (``start`` and ``start_closed``: the TCP and the gripper command now, the first segment's start). A cut point
    keeps the gripper bit of its segment's start, so grasps and releases still happen at the planned points, and, as
    a corner of :func:`square_transits` does, its segment end's orientation: the hand turns on the first piece, and the
    half-turned twin is chosen on the same turn as without the cut (orientations slerped along the pieces turned the
    hand by less than a quarter turn at a time, the twin came mid-carry instead, and the wine bottle's carry to the
    rack tripped the tracking reflex: docs/libero-planner.md, "Straight segments"). ``which`` (CUT_SEGMENTS): "all";
    "vertical", only segments within VERTICAL_TILT_RAD of straight up or down (descents onto a grasp or a place, rises
    from them); "closed_descents", only the vertical descents of a closed hand (an object lowered onto its place, a
    closed hand pressing down); the others keep the smoother's joint-space path. Pure function; returns new arrays
    (points, grip) and each output point's index in the input (a cut point's is its segment's end); unchanged when
    ``max_segment_m`` is None."""
    points, grip = np.asarray(points, float), np.asarray(grip, bool)
    index = np.arange(len(points))
    if max_segment_m is None or not len(points):
        return points, grip, index
    out_p, out_g, out_i = [], [], []
    prev, prev_g = np.asarray(start, float), bool(start_closed)
    for i, p in enumerate(points):
        d = p - prev
        pieces = int(np.ceil(float(np.linalg.norm(d)) / max_segment_m - 1e-9))
        vertical = float(np.linalg.norm(d[:2])) <= np.tan(VERTICAL_TILT_RAD) * abs(float(d[2]))
        if (which == "vertical" and not vertical) or (which == "closed_descents"
                                                      and not (vertical and d[2] < 0 and prev_g)):
            pieces = 1
        if pieces > 1:
            f = np.arange(1, pieces) / pieces
            out_p.extend(prev + f[:, None] * (p - prev))
            out_g.extend([prev_g] * (pieces - 1))
            out_i.extend([i] * (pieces - 1))
        out_p.append(p)
        out_g.append(bool(grip[i]))
        out_i.append(i)
        prev, prev_g = p, bool(grip[i])
    return np.asarray(out_p), np.asarray(out_g, bool), np.asarray(out_i, int)


_HALF_TURN = np.diag([-1.0, -1.0, 1.0])  # about the TCP's z (approach) axis: a parallel-jaw hand's twin


TWIN_MISS_M = 0.03  # an IK answer this far from the waypoint is a miss the arm cannot make up for [m]
TWIN_TRAVEL_MARGIN_RAD = 0.5  # joint travel [rad, summed] the twin must save to be taken for travel alone
TWIN_TURN_RAD = np.pi / 2  # a hand asked to turn further than this from the IK seed's: its twin may be the nearer


def put_down_before_release(points: np.ndarray, grip: np.ndarray, closed_at: int) -> float | None:
    """How far a plan that closes the gripper at point ``closed_at`` lowers the hand before it next opens it [m]: the
    highest point of the closed stretch less the release point. None when the plan never opens it again."""
    ahead = np.flatnonzero(~np.asarray(grip[closed_at:], bool))
    if ahead.size == 0:
        return None
    release = closed_at + int(ahead[0])
    return float(points[closed_at:release + 1, 2].max() - points[release, 2])


def _twin_is_better(twin, other, seed: np.ndarray) -> bool:
    """The hand's twin solution beats the other: it converged where the other missed the point by more than
    TWIN_MISS_M; or it moves the arm less from the seed, by more than TWIN_TRAVEL_MARGIN_RAD, without converging
    less. (A twin that converges only by a long way round is not taken while the other is near: a wrist half turn
    under a carried object saturated joints 6 and 7 and tripped the tracking reflex where the unconverged answer,
    3-17 mm off, still placed it. Nor one that saves a few hundredths of a radian: mid-carry, both of a ketchup
    bottle's hands swung the arm 5.9 rad, the twin 0.06 rad less, and the turned one tripped the reflex.)"""
    if twin.converged and not other.converged and other.pos_err > TWIN_MISS_M:
        return True
    if other.converged and not twin.converged:
        return False
    return float(np.abs(twin.q - seed).sum()) < float(np.abs(other.q - seed).sum()) - TWIN_TRAVEL_MARGIN_RAD


class MotionExecutor:
    """Executes waypoint plans on the simulated robot at ``ctrl_dt``."""

    def __init__(self, sim: Simulation, *, ik: IKSolver, smoother, controller, safety, dynamics,
                 camera: CameraModel, config: ExecutorConfig = ExecutorConfig(),
                 lift_config: LiftConfig = LiftConfig(), world_kind: str = "workcell"):
        self.sim, self.ik, self.smoother, self.controller = sim, ik, smoother, controller
        self.safety, self.dyn, self.camera, self.config, self.lift_config = safety, dynamics, camera, config, lift_config
        self.max_segment_m = resolve_max_segment(config.max_segment_m, world_kind)  # "auto" made concrete
        self.substeps = sim.timing.substeps
        self.ctrl_dt = sim.timing.ctrl_dt
        self.events: list[dict] = []
        self.plan: WaypointPlan | None = None
        self.latest_points: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # last lifted plan per kind (videos)
        self.points: np.ndarray = np.zeros((0, 3))  # waypoints [m, world]
        self.rots: np.ndarray = np.zeros((0, 3, 3))  # TCP orientation per waypoint [world]
        self.grip: np.ndarray = np.zeros(0, bool)
        self.point_source: np.ndarray = np.zeros(0, int)  # plan waypoint index of each point
        self.index = -1
        self.phase = "idle"  # idle | move | touch | settle | done | home
        self._phase_until = 0.0
        self._arrived_at: float | None = None  # when the reference reached the current stop point [s]
        self._waiting_at: np.ndarray | None = None  # that stop point [m]
        self._ik_seed = sim.q
        self._hand_turned = False  # planned orientations are asked turned half a turn (config.hand_twin)
        self._last_tau = np.zeros(sim.robot.dof)
        self._faulted = False
        self.ik_failures = 0
        self.plans_infeasible = 0  # plans refused by a whole-plan IK solve (event ik_plan_infeasible)
        self._plan_q: np.ndarray | None = None  # joint targets of the current plan from a whole-plan solve
        self.tracking_reflexes = 0
        self.tracking_err_max = 0.0
        self.grasp_tcp_z: float | None = None  # TCP height where a plan last closed the gripper [m] (None: open)
        self._closed_at: np.ndarray | None = None  # the TCP where it closed [m, world] (None: open)
        self.empty_grasp_points: list[np.ndarray] = []  # where grasps that held nothing closed, this episode [m]
        self._touch_depth = 0.0  # how far below its grasp point the touching hand is asked [m]
        self._touch_force0: np.ndarray | None = None  # the wrist force where the touch began [N]
        self._touch_end: str | None = None  # why the touch can go no further down (None: it still can)
        self._touch_unavailable_said = False
        # put_down_before_release of the closed stretch the active plan is carrying out (None: open, the plan never
        # opens the hand again, or another plan took over from the one that closed it)
        self.closed_put_down_m: float | None = None
        self.closes = 0  # times a plan closed the gripper
        self.releases = 0  # times a plan opened the gripper at one of its stops (an object put down, a handle let go)
        self.max_joint_limit_violation = 0.0  # measured joint positions past [q_min, q_max] [rad]
        self.max_reference_limit_excess = 0.0  # commanded (reference) positions past them [rad]: should stay 0
        self.max_velocity_ratio = 0.0
        self._q_min, self._q_max, self._v_max = sim.robot.q_min, sim.robot.q_max, sim.robot.v_max
        self.home_q = sim.q  # the posture the scene starts from (go_home returns there)
        self._home_targets: list[np.ndarray] = []  # joint targets left on the way home

    # --- events -----------------------------------------------------------------------------------
    def event(self, kind: str, **info) -> None:
        self.events.append({"t": round(self.sim.time_s, 4), "kind": kind, **info})

    # --- plans ------------------------------------------------------------------------------------
    def set_plan(self, plan: WaypointPlan) -> bool:
        """Lift and adopt a plan; a plan that cannot be lifted is rejected and the old one kept, as is every plan
        while the hand touches down on a retried grasp (``touch_retry_depth_m``: refused, not queued)."""
        if self.phase == "touch":
            self.event("plan_refused", reason="touching down", plan_kind=plan.kind, step=plan.step)
            return False
        try:
            points = lift_waypoints(plan.uv_px, plan.depth_m, plan.lift_camera(self.camera), config=self.lift_config)
        except LiftError as exc:
            self.event("plan_rejected", reason=str(exc), plan_kind=plan.kind, step=plan.step)
            return False
        grip = np.asarray(plan.gripper_closed, bool)
        rots = np.broadcast_to(R_DOWN, (len(plan), 3, 3)) if plan.tcp_rot is None else plan.tcp_rot
        cfg = self.config
        retreat, corners = False, 0
        source = np.arange(len(plan))
        if plan.kind != "direct":  # square_transits leaves a plan alone when both thresholds are off
            points, grip, source = square_transits(
                self.sim.tcp_pos(), self.sim.gripper_closed_cmd(), points, grip,
                min_horizontal_m=cfg.transit_min_horizontal_m, min_vertical_m=cfg.transit_min_vertical_m,
                switch_min_horizontal_m=cfg.switch_min_horizontal_m,
                approach=np.asarray(rots)[:, :, 2] if cfg.grasp_along_approach else None, return_source=True)
            points, grip, last = retreat_after_release(self.sim.gripper_closed_cmd(), points, grip,
                                                       lift_m=cfg.release_retreat_m)
            retreat = len(last) > len(source)
            source = source[last]
            corners = len(points) - len(plan) - retreat
            points, grip, cut = cut_long_segments(
                self.sim.tcp_pos(), self.sim.gripper_closed_cmd(), points, grip,
                max_segment_m=None if cfg.cut_segments == "holding_descents" else self.max_segment_m,
                which=cfg.cut_segments)
            source = source[cut]
            rots = rots[source]
        rots = np.asarray(rots)
        q = self.sim.q
        ref_q = self.smoother.reference.q
        resync = np.max(np.abs(ref_q - q)) > self.config.resync_tol_rad
        plan_q = None
        if getattr(self.ik, "solves_plans", False):  # every waypoint solved (or the plan refused) before motion
            plan_q = self._solve_plan(points, rots, q if resync else self._ik_seed, plan)
            if plan_q is None:
                return False
        self.plan, self.points, self.grip, self.rots, self._plan_q = plan, points, grip, rots, plan_q
        self.point_source = source  # each point's waypoint index in the plan (corners and a retreat share one)
        self.closed_put_down_m = None  # what this plan does with a closed hand says nothing of why it closed
        self.latest_points[plan.kind] = (points, self.grip)
        if resync:
            self.event("reference_resynced", max_dev_rad=float(np.max(np.abs(ref_q - q))))
            try:
                self.smoother.reset(q, self.sim.qd)
            except TrajectoryError as exc:  # e.g. pushed slightly past a soft joint limit: brake from there
                self.event("reference_brake", reason=str(exc))
                self._brake_inside_limits(q, self.sim.qd, "resync")
            self._ik_seed = q
        self.event("plan_adopted", plan_kind=plan.kind, step=plan.step, waypoints=len(plan),
                   corners_added=corners, retreat_added=retreat, cuts_added=len(points) - len(plan) - retreat - corners)
        self._activate(0)
        return True

    def _solve_plan(self, points: np.ndarray, rots: np.ndarray, q_start: np.ndarray,
                    plan: WaypointPlan) -> np.ndarray | None:
        """Joint targets of every waypoint from one whole-plan solve (IK backends with ``solve_plan``), or None:
        an infeasible plan is refused before any motion with an ``ik_plan_infeasible`` event naming the waypoint
        farthest from its target and how far off the closest reachable pose stays; the old plan is kept and
        ``plans_infeasible`` tells the supervisor (GLSR replans on it). ``points``/``rots`` are in the world frame;
        the solve is in the robot's base frame, with the world's support surface as the height reference."""
        T = self.sim.T_base_world
        R_bw, p_bw = T[:3, :3], T[:3, 3]
        support_z = float(R_bw[2] @ np.array([0.0, 0.0, self.sim.support_z]) + p_bw[2])  # base upright: a plane z
        try:
            res = self.ik.solve_plan(points @ R_bw.T + p_bw, R_bw @ rots, q_start, support_z=support_z)
        except TcotError as exc:  # unusable input (e.g. a point out of range): refused like an unliftable plan
            self.event("plan_rejected", reason=str(exc), plan_kind=plan.kind, step=plan.step)
            return None
        if res.converged:
            return res.q
        self.plans_infeasible += 1
        w = res.worst if res.worst is not None else int(np.argmax(res.pos_err))
        self.event("ik_plan_infeasible", plan_kind=plan.kind, step=plan.step, waypoint=w, waypoints=len(points),
                   status=res.status, solver_status=res.solver_status, offending=list(res.offending[:10]),
                   pos_err_m=round(float(res.pos_err[w]), 5), rot_err_rad=round(float(res.rot_err[w]), 5),
                   target=[round(float(v), 4) for v in points[w]])
        return None

    def _is_stop(self, i: int) -> bool:
        return i == len(self.points) - 1 or bool(self.grip[i]) != self.sim.gripper_closed_cmd()

    def _cut_holding_descent(self, i: int) -> None:
        """``cut_segments`` "holding_descents": waypoint ``i``'s segment (from the point before it, or from the TCP),
        when a long closed descent begun by a hand that holds something, is cut now (see ExecutorConfig); the pieces
        are spliced in before ``i``, so waypoint ``i`` becomes the first of them (event ``segment_cut``)."""
        cfg, sim = self.config, self.sim
        if (cfg.cut_segments != "holding_descents" or self.max_segment_m is None or self._plan_q is not None
                or not sim.gripper_closed_cmd() or sim.gripper_opening_m() <= EMPTY_HAND_OPENING_M):
            return
        start = self.points[i - 1] if i > 0 else sim.tcp_pos()
        points, grip, _ = cut_long_segments(start, True, self.points[i:i + 1], self.grip[i:i + 1],
                                            max_segment_m=self.max_segment_m, which="closed_descents")
        if len(points) == 1:
            return
        self.points = np.concatenate([self.points[:i], points, self.points[i + 1:]])
        self.grip = np.concatenate([self.grip[:i], grip, self.grip[i + 1:]])
        self.rots = np.concatenate([self.rots[:i], np.repeat(self.rots[i:i + 1], len(points), axis=0),
                                    self.rots[i + 1:]])
        self.point_source = np.concatenate([self.point_source[:i], np.repeat(self.point_source[i:i + 1], len(points)),
                                            self.point_source[i + 1:]])
        self.event("segment_cut", waypoint=i, pieces=len(points), opening_m=round(sim.gripper_opening_m(), 5))

    def _activate(self, i: int) -> None:
        self._cut_holding_descent(i)
        # A replan that keeps heading for the stop we are already waiting at keeps the arrival clock:
        # otherwise replanning faster than reach_timeout_s would wait there forever.
        keep = (self._arrived_at is not None and self._waiting_at is not None
                and np.linalg.norm(self.points[i] - self._waiting_at) <= self.config.stop_match_m)
        self.index, self.phase = i, "move"
        if not keep:
            self._arrived_at = self._waiting_at = None
        if self._plan_q is not None:  # solved with the whole plan when it was adopted
            self._ik_seed = self._plan_q[i]
            self._set_target(self._plan_q[i], i)
            return
        target = self.ik_target(i, self._hand_turned)
        try:
            res = self.ik.solve(target, self._ik_seed)
            if self.config.hand_twin and (
                    not res.converged or res.limit_active
                    or rotation_angle(self.ik.tcp_pose(self._ik_seed)[1], target.rot) > TWIN_TURN_RAD):
                twin = self.ik.solve(self.ik_target(i, not self._hand_turned), self._ik_seed)
                if _twin_is_better(twin, res, self._ik_seed):
                    self._hand_turned = not self._hand_turned
                    self.event("hand_turned", waypoint=i, turned=self._hand_turned, converged=twin.converged,
                               other_converged=res.converged, other_limit_active=res.limit_active)
                    res = twin
        except TcotError as exc:  # bad input: keep holding, report
            self.event("ik_error", waypoint=i, reason=str(exc))
            self.phase = "done"
            return
        if not res.converged:
            self.ik_failures += 1
            self.event("ik_not_converged", waypoint=i, status=res.status, pos_err_m=round(res.pos_err, 5),
                       rot_err_rad=round(res.rot_err, 5))
        self._ik_seed = res.q
        self._set_target(res.q, i)

    def ik_target(self, i: int, turned: bool, *, below_m: float = 0.0) -> IKTarget:
        """Waypoint ``i`` as IK is asked it: in the robot's base frame (plans live in the world frame; identity in
        the workcell), its hand turned half a turn about the approach axis when ``turned``, ``below_m`` straight
        down (world z) from the waypoint (a touch)."""
        T = self.sim.T_base_world
        rot = T[:3, :3] @ self.rots[i]
        pos = self.points[i] - np.array([0.0, 0.0, below_m])
        return IKTarget(pos=T[:3, :3] @ pos + T[:3, 3], rot=rot @ _HALF_TURN if turned else rot)

    def _set_target(self, q: np.ndarray, i: int, *, slower: float = 1.0) -> None:
        try:
            self.smoother.set_target(q, slower=slower)
        except TrajectoryError as exc:  # e.g. retargeted while moving fast toward a joint limit
            self.event("reference_brake", waypoint=i, reason=str(exc))
            ref = self.smoother.reference  # stop inside the limits; the waypoint logic moves on from rest
            self._brake_inside_limits(ref.q, ref.qd, "retarget", qdd=ref.qdd)

    def _advance(self, t: float) -> None:
        if self.phase == "home":
            if self.smoother.done:
                if self._home_targets:
                    self._set_target(self._home_targets.pop(0), -1)
                else:
                    self.phase = "done"
                    self.event("home_reached", tcp=[round(float(v), 4) for v in self.sim.tcp_pos()])
            return
        if self.phase == "settle":
            if t >= self._phase_until:
                self._next()
            return
        if self.phase == "touch":
            self._touch_down(t)
            return
        if self.phase != "move":
            return
        i = self.index
        if not self._is_stop(i):
            if self.smoother.time_remaining <= self.config.blend_time_s:
                self._next()
            return
        if not self.smoother.done:
            return
        if self._arrived_at is None:
            self._arrived_at, self._waiting_at = t, self.points[i].copy()
        err = float(np.linalg.norm(self.sim.tcp_pos() - self.points[i]))
        if err > self.config.reach_tol_m and t - self._arrived_at < self.config.reach_timeout_s:
            return
        if err > self.config.reach_tol_m:
            self.event("slow_arrival", waypoint=i, tcp_err_m=round(err, 4))
            if bool(self.grip[i]) and not self.sim.gripper_closed_cmd():  # closing where the TCP never got
                self.event("unreachable_grasp", waypoint=i, tcp_err_m=round(err, 4),
                           target=[round(float(v), 4) for v in self.points[i]])
        if bool(self.grip[i]) != self.sim.gripper_closed_cmd():
            if self.grip[i] and self._retries_empty_grasp(i):
                self._start_touch()
                return
            self._switch_gripper(i, t)
        else:
            self.phase = "done"

    def _switch_gripper(self, i: int, t: float) -> None:
        """Switch the gripper to waypoint ``i``'s command, then settle before the next waypoint."""
        self.sim.set_gripper(bool(self.grip[i]))
        self._closed_at = self.sim.tcp_pos() if self.grip[i] else None
        self.grasp_tcp_z = float(self._closed_at[2]) if self.grip[i] else None
        self.closed_put_down_m = put_down_before_release(self.points, self.grip, i) if self.grip[i] else None
        self.closes += bool(self.grip[i])
        self.releases += not self.grip[i]
        self.event("gripper", closed=bool(self.grip[i]), waypoint=i)
        self._arrived_at = self._waiting_at = None  # this stop is done; the next one has its own wait
        self.phase, self._phase_until = "settle", t + self.config.gripper_settle_s

    def _retries_empty_grasp(self, i: int) -> bool:
        """Whether grasp ``i`` touches down first (``touch_retry_depth_m``): a hand pointing down, near where a
        grasp closed on nothing this episode, on a robot with a wrist force sensor."""
        cfg = self.config
        if cfg.touch_retry_depth_m is None or not self.empty_grasp_points:
            return False
        if float(self.rots[i][2, 2]) > -np.cos(TOUCH_MAX_TILT_RAD):  # the approach axis (TCP z) down: -1
            return False
        near = np.linalg.norm(np.asarray(self.empty_grasp_points)[:, :2] - self.points[i][:2], axis=1)
        if near.min() > cfg.touch_retry_radius_m:
            return False
        if self.sim.wrist_force() is None:
            if not self._touch_unavailable_said:
                self._touch_unavailable_said = True
                self.event("touch_unavailable", waypoint=i, reason="the robot has no wrist force sensor")
            return False
        return True

    def _start_touch(self) -> None:
        # the baseline is the wrist as the hand stands at the grasp point: a hand already pressing there feels more
        self.phase, self._touch_depth, self._touch_force0 = "touch", 0.0, self.sim.wrist_force()
        self._touch_end = self._touch_step()

    def _touch_step(self) -> str | None:
        """Ask the hand ``touch_step_m`` further down (same orientation, TOUCH_SLOWER times slower than a move); or
        why it cannot: "bottom" (past ``touch_retry_depth_m``), "ik" (IK does not reach it, or refuses the target)."""
        cfg, i = self.config, self.index
        depth = self._touch_depth + cfg.touch_step_m
        if depth > cfg.touch_retry_depth_m + 1e-9:
            return "bottom"
        target = self.ik_target(i, self._hand_turned, below_m=depth)
        try:
            res = self.ik.solve(target, self._ik_seed)
        except TcotError as exc:
            self.event("ik_error", waypoint=i, reason=str(exc))
            return "ik"
        if not res.converged:
            return "ik"
        self._touch_depth, self._ik_seed = depth, res.q
        self._set_target(res.q, i, slower=TOUCH_SLOWER)
        return None

    def _touch_down(self, t: float) -> None:
        """One control tick of a touch: close where the wrist feels the touch, or where the touch can go no further
        (event ``touch``: ``ended`` "touched", "bottom" or "ik"; "interrupted: ..." from _touch_interrupted)."""
        i = self.index
        pressed = float(np.linalg.norm(self.sim.wrist_force() - self._touch_force0))
        touched = pressed >= self.config.touch_force_n
        if touched:
            self._brake_inside_limits(self.sim.q, self.sim.qd, "touch")
            self._ik_seed = self.sim.q
        elif self._touch_end is None:
            if not self.smoother.done:
                return
            self._touch_end = self._touch_step()
            if self._touch_end is None:
                return
        self._touch_event(touched, "touched" if touched else self._touch_end, force_n=round(pressed, 2))
        self._switch_gripper(i, t)

    def _touch_interrupted(self, why: str) -> None:
        """A touch cut short before it closed (the hand stays open): said, so every touch ends in a ``touch`` event."""
        if self.phase == "touch":
            self._touch_event(False, f"interrupted: {why}")

    def _touch_event(self, touched: bool, ended: str, **info) -> None:
        i = self.index
        self.event("touch", waypoint=i, touched=touched, ended=ended, **info,
                   below_grasp_m=round(float(self.points[i][2] - self.sim.tcp_pos()[2]), 4))

    def _next(self) -> None:
        if self.index + 1 < len(self.points):
            self._activate(self.index + 1)
        else:
            self.phase = "done"

    def _drop_plan(self) -> None:
        """Forget the current plan and its waypoints (no waypoint active)."""
        self._touch_interrupted("the plan was dropped")
        self.plan, self.points, self.grip, self._plan_q = None, np.zeros((0, 3)), np.zeros(0, bool), None
        self.closed_put_down_m = None
        self.rots = np.zeros((0, 3, 3))
        self.index = -1

    def reset_after_scene_reset(self) -> None:
        """The simulator was reset (arm at home): drop the plan and restart the reference there."""
        self._drop_plan()
        self.phase, self.grasp_tcp_z, self._closed_at = "idle", None, None
        self.empty_grasp_points = []  # the objects stand where they started again
        self.smoother.reset(self.sim.q)
        self._ik_seed = self.sim.q
        self._hand_turned = False
        self._home_targets = []
        self.releases = 0
        self.controller.reset(self.dyn, self._last_tau)
        self.event("scene_reset")

    def go_home(self, lift_m: float | None) -> None:
        """Drop the plan and retreat to ``home_q`` with the hand as it is: first straight up ``lift_m`` from the TCP
        (IK from the measured posture, the hand's orientation kept; skipped when it does not converge, event
        ``going_home`` says so; None: no lift), then in joint space to home, so the arm does not sweep low through
        the scene. ``plan_finished`` turns true on arrival (event ``home_reached``); the next plan starts from home."""
        self._drop_plan()
        self._arrived_at = self._waiting_at = None
        q = self.sim.q
        if np.max(np.abs(self.smoother.reference.q - q)) > self.config.resync_tol_rad:  # e.g. after a reflex
            self.resync_to_measured("going_home")
        lifted = []
        if lift_m is not None:
            T = self.sim.T_base_world
            up = self.sim.tcp_pos() + np.array([0.0, 0.0, lift_m])
            lift = self.ik.solve(IKTarget(pos=T[:3, :3] @ up + T[:3, 3], rot=T[:3, :3] @ self.sim.world.tcp_rot()), q)
            lifted = [lift.q] if lift.converged else []
        self._home_targets = lifted + [self.home_q.copy()]
        self._hand_turned = False  # home is the nominal hand
        self._ik_seed = self.home_q.copy()
        self.phase = "home"
        self.event("going_home", lift_m=lift_m, lift_converged=bool(lifted) if lift_m is not None else None)
        self._set_target(self._home_targets.pop(0), -1)

    def start_from_home(self, home_q: np.ndarray) -> None:
        """Make ``home_q`` (the robot's home posture) the arm's home and go there in joint space, no lift: the start
        of an episode whose arm stands a few hundredths of a radian off it (``start_home_tol_rad``)."""
        self.home_q = np.asarray(home_q, dtype=float).copy()
        self.go_home(None)

    def resync_to_measured(self, reason: str) -> None:
        """The arm was moved from outside (e.g. a perturbed initial posture): restart the reference, the IK seed
        and the controller from the measured state, keeping the plan."""
        self.smoother.reset(self.sim.q)
        self._ik_seed = self.sim.q
        self.controller.reset(self.dyn, self._last_tau)
        self.event("reference_resynced", reason=reason)

    def open_empty_gripper(self, opening_m: float) -> None:
        """The closed gripper holds nothing (its fingers met): open it, so the next plan starts from an open hand."""
        self.sim.set_gripper(False)
        if self._closed_at is not None:
            self.empty_grasp_points.append(self._closed_at)
        self.grasp_tcp_z = self.closed_put_down_m = self._closed_at = None
        self.event("gripper", closed=False, reason="grasp_empty", opening_m=round(opening_m, 5))
        self.phase = "done"  # the plan's remaining stops assumed an object in the hand; a new plan follows

    @property
    def plan_finished(self) -> bool:
        return self.phase in ("done", "idle")

    # --- control ----------------------------------------------------------------------------------
    def switch_controller(self, controller) -> None:
        """Bumpless switch: the new controller starts from the measured state and the last torque."""
        controller.reset(self.dyn, self._last_tau)
        self.event("controller_switched", old=self.controller.name, new=controller.name)
        self.controller = controller

    def tick(self) -> None:
        """One control period: waypoint logic, then the control tick."""
        self._advance(float(self.sim.data.time))
        self.control_tick()

    def control_tick(self) -> None:
        """Reference (Ruckig sample), controller, safety, physics for one ctrl_dt — no IK or planning
        (this is what the bench compares with bare mj_step)."""
        sim, dyn = self.sim, self.dyn
        ref = self.smoother.step()
        over = max((self._q_min - ref.q).max(), (ref.q - self._q_max).max())  # the command, not the measurement
        if over > self.max_reference_limit_excess:
            self.max_reference_limit_excess = float(over)
        sim.step1()
        dyn.update()
        c = self.controller
        preview = self.smoother.preview(c.preview_horizon) if c.preview_horizon else None
        cmd = c.compute(dyn, ref, preview=preview)
        safe = self.safety.filter(cmd, dyn, ref)
        if safe.status == "fault":
            self._faulted = True
        elif self._faulted:  # resuming after a held fault: restart the controller from here, bumplessly
            self._faulted = False
            c.reset(dyn, self._last_tau)
        self._last_tau = safe.tau
        dyn.write_ctrl(safe.tau)
        sim.step2(self.substeps - 1)
        # Monitors on the measured state at the start of this tick (the next tick sees the result).
        q = dyn.q
        viol = max((self._q_min - q).max(), (q - self._q_max).max())
        if viol > self.max_joint_limit_violation:
            self.max_joint_limit_violation = float(viol)
        vr = (np.abs(dyn.qd) / self._v_max).max()
        if vr > self.max_velocity_ratio:
            self.max_velocity_ratio = float(vr)
        dev = np.abs(ref.q - q)
        err = dev.max()
        if err > self.tracking_err_max:
            self.tracking_err_max = float(err)
        limit = self.config.reflex_tracking_rad
        if limit is not None and err > limit:
            self._tracking_reflex(int(dev.argmax()), float(err), limit)

    def _brake_inside_limits(self, q: np.ndarray, qd: np.ndarray, why: str, qdd: np.ndarray | None = None) -> None:
        """Stop the reference from a state (measured, or the reference's own), never past a joint limit: a stop from
        (q, qd, qdd) that would leave [q_min, q_max] (a joint moving toward a limit it is near, or already pressed
        past a soft limit) is replaced by the reference at rest at that posture, each joint brought inside its
        limits, and the event ``reference_stopped_inside_limits`` records by how much (nothing is moved silently)."""
        info = self.smoother.brake(q, qd, qdd)
        if info.limit_excursion_rad <= 0.0:
            return
        hold = np.minimum(np.maximum(q, self._q_min), self._q_max)
        moved = np.abs(hold - q)
        self.smoother.reset(hold)
        self.event("reference_stopped_inside_limits", reason=why, stop_excursion_rad=round(info.limit_excursion_rad, 5),
                   joint=self.sim.robot.arm_joints[int(moved.argmax())] if moved.max() > 0 else None,
                   moved_inside_rad=round(float(moved.max()), 5))

    def _tracking_reflex(self, joint: int, err: float, limit: float) -> None:
        """Stop pushing: drop the plan, brake the reference from the measured state (see ExecutorConfig)."""
        self.tracking_reflexes += 1
        self.event("tracking_reflex", joint=self.sim.robot.arm_joints[joint], error_rad=round(err, 4),
                   limit_rad=limit, waypoint=self.index)
        self._touch_interrupted("tracking reflex")
        self._brake_inside_limits(self.sim.q, self.sim.qd, "tracking_reflex")
        self._ik_seed = self.sim.q
        self.phase = "done"
        self._arrived_at = self._waiting_at = None  # a replan to the same stop point starts a fresh wait
        self.controller.reset(self.dyn)  # no blend from the wound-up torque: stop pushing now
