"""The learned TCoT planner: image + instruction + robot state → waypoint plan (global/local) or p(success).

It runs the checkpointed network (see :mod:`tcot_hybrid.learning.model`) and turns its outputs into
the same :class:`WaypointPlan` the oracle emits, so the classical half of the stack is unchanged:

* global: the network predicts the whole global window (L_g points, past and future: eq. 4's time stride
  or event-spaced, as the checkpoint's windows say); only the points from the current step on (k >= 0) are
  returned, the past ones are the model's progress context;
* local: all L_l + 1 points of the eq.-5 window;
* every waypoint carries the predicted TCP height ``z_m`` [m]; the plan's ``depth_m`` is where the
  pixel's viewing ray meets the plane z = z_m (:func:`tcot_hybrid.camera.depth_at_height`). The checkpoint's
  ``height_ref`` says what the network's heights are measured from: world z (the workcell) or the planner
  camera's height (LIBERO, whose tables stand at different heights); the plan is in world z either way;
* a checkpoint with a rotation head (LIBERO) also gives every waypoint a TCP orientation, predicted in the
  planner camera's frame and turned into the world with the camera's calibration: ``WaypointPlan.tcp_rot``.

Inputs and outputs are checked: a wrong-size, wrong-dtype or blank image, non-finite joints, an
instruction with too many unknown words, and non-finite outputs or probabilities outside [0, 1] all
raise :class:`PlanningError` (nothing is clipped or guessed).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tcot_hybrid.calibration import CameraSelfCalibration, SelfCalibrationConfig
from tcot_hybrid.camera import CameraModel, depth_at_height
from tcot_hybrid.config import require_choice
from tcot_hybrid.data.labels import GLOBAL_SPACINGS
from tcot_hybrid.errors import LiftError, PlanningError
from tcot_hybrid.plan import WaypointPlan
from tcot_hybrid.planners.base import MODES, Observation, Planner

BLANK_STD = 1.0  # an image whose pixel values vary less than this (0-255 scale) shows nothing
SIDE_GRASP_MAX_ELEVATION_DEG = 30.0  # approach axes this close to horizontal are side grasps (handles, bars)


@dataclass(frozen=True, kw_only=True)
class LearnedPlannerConfig:
    """How the network's waypoints become a plan.

    switch_window:    gripper switches are moved to the lowest waypoint within this many waypoints of where
                      the gripper head put them (0 = off). The height and gripper heads are separate, and a far
                      future switch predicted one waypoint late closes the fingers half-way up after the
                      descent; in every demonstration grasps and releases happen at the bottom of a descent.
                      Up: corrects larger timing slips, but may pull a switch into a neighbouring descent.
                      Local and time-spaced (eq. 4) global plans only: an event-spaced global plan ends every
                      piece on its switch by construction.
    switch_min_rise_m: move a switch only when its waypoint is this much higher than that lowest one [m]
                      (horizontal pulls, e.g. a drawer, keep their switch). Down: moves more switches.
    dwell_leave_m, dwell_step_m: a global plan's switch that the arm leaves at once (the next waypoint more than
                      ``dwell_leave_m`` away) is moved to the nearest waypoint within ``switch_window`` where the
                      arm dwells (the next waypoint closer than ``dwell_step_m``) [m]. Every demonstration
                      switches where the arm has stopped (it waits ``gripper_settle_s``); a far-future release
                      predicted one waypoint early let go of the stick half-way through the drag. Time-spaced
                      (eq. 4) global plans only: local plans span 1.6 s, where the heads hardly disagree on
                      timing, and event-spaced plans end every piece on its switch and show no dwells.
                      dwell_leave_m None = off. Down: moves more switches.
    min_height_m:     a plan with a waypoint's TCP height below this is refused (``PlanningError``), not
                      executed [m]: the fingers would be inside the table. Measured from the table top (z = 0) with
                      a ``height_ref: world`` checkpoint (the workcell); with ``height_ref: camera`` (LIBERO: tables
                      at 0, 0.42 or 0.9 m, the planner knows only its camera) from the lowest TCP height the
                      checkpoint's training demonstrations reached under the training camera nearest the run's
                      (``lowest_tcp_by_camera``, 1-3 cm above the table top: grasps; :func:`lowest_plan_height`).
                      Demonstrated grasps are at 1-2 cm; late in failed episodes the local prompt was seen to answer
                      -0.5 m. Up: refuses more plans with low points; down: lets the arm try to push into the table.
    side_grasp_depth_m: a grasp (a waypoint where the gripper closes) made with the hand approaching sideways
                      (approach axis, TCP z, within ``SIDE_GRASP_MAX_ELEVATION_DEG`` of horizontal) is moved this far
                      further along the approach [m]. A pixel of the 128 px planner image is ~6 mm across the
                      table; a drawer handle pinched 6 mm short held it by the fingertips, which slid off
                      half-way through the pull. 6 mm by measurement on development layouts for the networks
                      shipped now, which learned the commanded path (12 mm for the observed-path network before
                      them; docs/libero-planner.md, "How deep a side grasp goes"). Needs the rotation head (LIBERO
                      checkpoints; workcell plans are top-down); 0 = off. Up: firmer hold on handles, the fingers
                      nearer what stands behind the handle.
    self_calibration: re-estimating the planner camera's pose from where the network sees the hand, once it
                      disagrees with the nominal calibration (a camera knocked after calibration):
                      :class:`tcot_hybrid.calibration.SelfCalibrationConfig`.
    """

    switch_window: int = 2
    switch_min_rise_m: float = 0.015
    dwell_leave_m: float | None = 0.03
    dwell_step_m: float = 0.01
    min_height_m: float = -0.02
    side_grasp_depth_m: float = 0.006
    self_calibration: SelfCalibrationConfig = field(default_factory=SelfCalibrationConfig)

    def __post_init__(self) -> None:
        from tcot_hybrid.config import require_finite, require_int, require_nonnegative, require_positive

        require_int("learned.switch_window", self.switch_window, minimum=0)
        require_nonnegative("learned.switch_min_rise_m", self.switch_min_rise_m)
        if self.dwell_leave_m is not None:
            require_positive("learned.dwell_leave_m (or null: off)", self.dwell_leave_m)
        require_positive("learned.dwell_step_m", self.dwell_step_m)
        require_finite("learned.min_height_m", self.min_height_m)
        require_nonnegative("learned.side_grasp_depth_m", self.side_grasp_depth_m)


def _move_switches(closed: np.ndarray, window: int, choose) -> np.ndarray:
    """Gripper bits with each switch i moved to ``choose(i, lo, hi)``: an index in lo..hi (within ``window`` of i
    and strictly between its neighbouring switches, so none moves onto or across another) or None (stay)."""
    out = np.asarray(closed, bool).copy()
    if window <= 0:
        return out
    flips = np.flatnonzero(out[1:] != out[:-1]) + 1
    prev = 0  # where the previous switch ended up
    for k, i in enumerate(flips):
        lo = max(i - window, prev + 1)
        hi = min(i + window, (flips[k + 1] - 1) if k + 1 < len(flips) else len(out) - 1)
        j = choose(i, lo, hi)
        if j is not None and j != i:
            new, old = out[i], out[i - 1]
            if j < i:
                out[j:i] = new
            else:
                out[i:j] = old
            i = j
        prev = i
    return out


def align_gripper_switches(z_m: np.ndarray, closed: np.ndarray, *, window: int, min_rise_m: float) -> np.ndarray:
    """Gripper bits with every switch moved to the lowest waypoint within ``window`` of it, when the switch's
    own waypoint is more than ``min_rise_m`` higher (see :class:`LearnedPlannerConfig`). Pure function."""
    z = np.asarray(z_m, float)

    def lowest(i, lo, hi):
        j = lo + int(np.argmin(z[lo:hi + 1]))
        return j if z[i] - z[j] > min_rise_m else None

    return _move_switches(closed, window, lowest)


def align_switches_to_dwells(points: np.ndarray, closed: np.ndarray, *, window: int, leave_m: float,
                             dwell_m: float) -> np.ndarray:
    """Gripper bits with every switch whose waypoint the arm leaves at once (next waypoint more than ``leave_m``
    away) moved to the nearest waypoint within ``window`` where it dwells (next waypoint closer than
    ``dwell_m``); switches never move onto or across their neighbours. Pure function."""
    p = np.asarray(points, float)
    step = np.r_[np.linalg.norm(np.diff(p, axis=0), axis=1), 0.0]  # step[k]: distance from waypoint k to k + 1

    def nearest_dwell(i, lo, hi):
        dwells = [j for j in range(lo, hi + 1) if step[j] < dwell_m] if step[i] > leave_m else []
        return min(dwells, key=lambda j: (abs(j - i), j)) if dwells else None

    return _move_switches(closed, window, nearest_dwell)


def height_plan(camera: CameraModel, uv_px: np.ndarray, z_m: np.ndarray, closed: np.ndarray, *, kind: str,
                step: int, config: LearnedPlannerConfig, global_spacing: str, meta: dict | None = None,
                tcp_rot: np.ndarray | None = None, refined: bool = False) -> WaypointPlan:
    """The plan for waypoints given as pixel + TCP height + gripper bit (the learned planner's output form):
    ``depth_m`` where each pixel's ray meets z = z_m; gripper switches aligned to the bottom of their descent
    and, in time-spaced global plans (``global_spacing`` of the windows the points follow), to where the arm
    dwells. ``refined``: ``camera`` is a re-estimated calibration the plan must be lifted with
    (:mod:`tcot_hybrid.calibration`)."""
    require_choice("global_spacing", global_spacing, GLOBAL_SPACINGS)
    try:
        depth = depth_at_height(camera, uv_px, z_m)
    except LiftError as exc:
        raise PlanningError(f"planner output cannot be lifted: {exc}") from exc
    # local plans follow eq. 5; an event-spaced global plan ends every piece on its switch: no timing slip to fix
    time_spaced = kind != "global" or global_spacing == "time"
    if time_spaced:
        closed = align_gripper_switches(z_m, closed, window=config.switch_window, min_rise_m=config.switch_min_rise_m)
    if kind == "global" and time_spaced and config.dwell_leave_m is not None:
        closed = align_switches_to_dwells(camera.unproject(uv_px, depth), closed, window=config.switch_window,
                                          leave_m=config.dwell_leave_m, dwell_m=config.dwell_step_m)
    if config.side_grasp_depth_m > 0 and tcp_rot is not None:
        points = deepen_side_grasps(camera.unproject(uv_px, depth), closed, tcp_rot, config.side_grasp_depth_m)
        uv_px, depth = camera.project(points)
    return WaypointPlan(uv_px=uv_px, depth_m=depth, gripper_closed=closed, camera=camera.name, kind=kind,
                        step=step, tcp_rot=tcp_rot, meta=meta or {}, calibration=camera if refined else None)


def deepen_side_grasps(points: np.ndarray, closed: np.ndarray, tcp_rot: np.ndarray, depth_m: float) -> np.ndarray:
    """Waypoints (N, 3) with every grasp (a waypoint where the gripper bit turns closed; a plan that starts
    closed is already holding) whose approach axis (``tcp_rot[i][:, 2]``) lies within
    ``SIDE_GRASP_MAX_ELEVATION_DEG`` of horizontal moved ``depth_m`` along that axis. Pure function."""
    out = np.array(points, float)
    c = np.asarray(closed, bool)
    max_sin = np.sin(np.radians(SIDE_GRASP_MAX_ELEVATION_DEG))
    for i in np.flatnonzero(c[1:] & ~c[:-1]) + 1:
        approach = np.asarray(tcp_rot[i], float)[:, 2]
        approach = approach / np.linalg.norm(approach)
        if abs(approach[2]) < max_sin:
            out[i] += depth_m * approach
    return out


def check_image(image, camera: CameraModel) -> np.ndarray:
    """The planner image as (H, W, 3) uint8 matching ``camera``, else PlanningError saying what is wrong."""
    if image is None:
        raise PlanningError("the learned planner needs the planner camera image; got None")
    if not isinstance(image, np.ndarray):
        raise PlanningError(f"planner image must be a numpy array, got {type(image).__name__}")
    want = (camera.height, camera.width, 3)
    if image.shape != want:
        raise PlanningError(f"planner image has shape {image.shape}, expected {want} (camera {camera.name!r})")
    if image.dtype != np.uint8:
        if np.issubdtype(image.dtype, np.floating) and not np.isfinite(image).all():
            raise PlanningError("planner image contains NaN or inf values")
        raise PlanningError(f"planner image must be uint8 RGB (0-255), got dtype {image.dtype}")
    if float(image.std()) < BLANK_STD:
        raise PlanningError(f"planner image is blank (all pixels ~{int(image.mean())}); refusing to plan from it")
    return image


def check_state(q, gripper_closed, dof: int) -> np.ndarray:
    try:
        qa = np.asarray(q, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise PlanningError(f"joint positions must be numeric, got {q!r}") from exc
    if qa.shape != (dof,):
        raise PlanningError(f"joint positions have shape {qa.shape}, the checkpoint expects ({dof},)")
    if not np.isfinite(qa).all():
        raise PlanningError(f"joint positions are not finite: {qa.tolist()}")
    return np.r_[qa, np.float32(bool(gripper_closed))]


def check_outputs(uv_px: np.ndarray, z_m: np.ndarray, grip_prob: np.ndarray, success_prob=None, *,
                  min_height_m: float | None = None, floor_note: str = "learned.min_height_m; table top at 0") -> None:
    """Refuse non-finite waypoints/heights, heights below ``min_height_m`` [m, world z] (when given; ``floor_note``
    says where that bound comes from) and probabilities that are not finite or outside [0, 1]."""
    uv, z, g = np.asarray(uv_px, float), np.asarray(z_m, float), np.asarray(grip_prob, float)
    bad = np.flatnonzero(~(np.isfinite(uv).all(-1) & np.isfinite(z)))
    if bad.size:
        i = int(bad[0])
        raise PlanningError(f"planner output waypoint {i} is not finite: uv_px={uv[i].tolist()}, z_m={z[i]} "
                            f"({bad.size} of {len(uv)} bad)")
    if min_height_m is not None:
        bad = np.flatnonzero(z < min_height_m)
        if bad.size:
            i = int(bad[0])
            raise PlanningError(f"planner output waypoint {i} has TCP height z_m = {z[i]:.4f} m, below the lowest "
                                f"allowed {min_height_m:.4f} m ({floor_note}); "
                                f"{bad.size} of {len(z)} waypoints too low")
    bad = np.flatnonzero(~((g >= 0) & (g <= 1)))
    if bad.size:
        i = int(bad[0])
        raise PlanningError(f"planner output gripper probability {g[i]} at waypoint {i} is outside [0, 1]")
    if success_prob is not None and not (0.0 <= float(success_prob) <= 1.0):
        raise PlanningError(f"planner output success probability {success_prob} is outside [0, 1]")


YAW_DEFINED_MIN = 0.5  # closing axis' horizontal length below which a hand has no yaw (within 60 deg of vertical)


def canonical_hand(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) world TCP orientations of one plan, in order, each replaced by the same parallel-jaw grasp turned 180
    degrees about its approach axis (x and y columns negated) when its yaw from the home hand lies outside the range
    the LIBERO oracle keeps, (YAW_MIN - 180, YAW_MIN] degrees (docs/libero-oracle.md: the other half trips joint 7's
    tracking reflex). The rotation head is trained up to that symmetry, so either of the two may come out.

    A hand whose closing axis is near vertical (horizontal part below ``YAW_DEFINED_MIN``: a drawer handle taken from
    the front) has no yaw; rounding noise decided its turn, and consecutive waypoints asked the wrist for a half turn
    that IK could not find (docs/libero-planner.md, "Side grasps and the wrist"). Such a hand takes the one of the
    two whose x axis is nearer the previous waypoint's (the first waypoint: the home hand's, world +x)."""
    from tcot_hybrid.libero.grasps import R_DOWN, YAW_MIN_RAD

    R = np.array(R, dtype=float)
    yaw = np.arctan2(R[:, 0, 1], -R[:, 1, 1])  # yaw_from_home: the closing (y) axis from the home hand's -y
    flip = (yaw > YAW_MIN_RAD) | (yaw <= YAW_MIN_RAD - np.pi)
    R[flip, :, :2] *= -1.0
    for i in np.flatnonzero(np.hypot(R[:, 0, 1], R[:, 1, 1]) < YAW_DEFINED_MIN):
        previous_x = R[i - 1, :, 0] if i > 0 else R_DOWN[:, 0]
        if R[i, :, 0] @ previous_x < 0.0:
            R[i, :, :2] *= -1.0
    return R


CAMERA_MATCH_M = 0.10  # a run camera this close to a training camera [m] is that camera (pose shifts are a few cm)


def lowest_plan_height(meta: dict, camera: CameraModel, min_height_m: float) -> tuple[float, str]:
    """(world z below which a planned TCP height is refused, where that bound comes from) for a checkpoint's
    ``meta`` and the run's planner ``camera``. ``height_ref: world``: ``min_height_m`` itself (table top at z = 0).
    ``height_ref: camera``: from the checkpoint's ``lowest_tcp_by_camera`` entry of the training camera within
    CAMERA_MATCH_M of the run's (the lowest of all of them when none is): the support surface its demonstrations
    recorded (``support_z_m``, from the camera: the table top, as on the workcell), or in checkpoints written before
    that was recorded the lowest TCP height they reached (``lowest_z_m``: grasps 1-3 cm above the table, so the bound
    sat up to 1 cm *above* the table and refused plans a centimetre low: docs/libero-planner.md, "Failure analysis");
    plus the camera's height and ``min_height_m``. A camera-referenced checkpoint that records neither keeps the
    world bound."""
    entries = meta.get("lowest_tcp_by_camera")
    if meta.get("height_ref", "world") != "camera" or not entries:
        return float(min_height_m), "learned.min_height_m; table top at 0"
    pos = np.asarray(camera.T_world_cam, dtype=float)[:3, 3]
    dist = np.array([np.linalg.norm(np.asarray(e["camera_pos_m"], float) - pos) for e in entries])
    near = dist <= CAMERA_MATCH_M
    chosen = [e for e, n in zip(entries, near) if n or not near.any()]
    which = "under this camera" if near.any() else "under any training camera (none within 10 cm of this one)"
    if all("support_z_m" in e for e in chosen):  # the support surface the demonstrations recorded: the table top
        low = float(min(e["support_z_m"] for e in chosen))
        return float(pos[2]) + low + float(min_height_m), (
            f"learned.min_height_m {min_height_m} m from the support surface the training demonstrations recorded "
            f"{which}, {low:+.4f} m from the camera")
    low = float(min(e["lowest_z_m"] for e in chosen))
    z = float(pos[2]) + low + float(min_height_m)
    return z, (f"learned.min_height_m {min_height_m} m from the lowest TCP height the training demonstrations "
               f"reached {which}, {low:+.4f} m from the camera")


class NetworkPlanner(Planner):
    """Shared part of the learned and direct planners: checkpoint, input checks, one forward pass."""

    kind = "trajectory"

    def __init__(self, checkpoint, camera: CameraModel):
        import torch

        from tcot_hybrid.learning.vocab import Vocabulary

        self.torch = torch
        self.checkpoint = checkpoint
        # the image arrives HWC, i.e. channels_last once viewed as NCHW: keep the weights in that layout too
        self.model = checkpoint.model.eval().to(memory_format=torch.channels_last)
        self.meta = checkpoint.meta
        self.cfg = self.model.cfg
        self.camera = camera
        self.vocab = Vocabulary(tuple(self.meta["vocabulary"]))
        self.max_unknown_fraction = float(self.meta.get("max_unknown_fraction", 0.5))
        self._tokens: dict[str, object] = {}

    @property
    def checkpoint_path(self) -> Path:
        return self.checkpoint.path

    def tokens(self, instruction: str):
        if instruction not in self._tokens:
            ids = self.vocab.encode_checked(instruction, self.cfg.max_tokens,
                                            max_unknown_fraction=self.max_unknown_fraction)
            self._tokens[instruction] = self.torch.from_numpy(ids)[None]
        return self._tokens[instruction]

    def infer(self, obs: Observation, mode: str, *, waypoints: bool | slice = True) -> dict[str, np.ndarray]:
        """Raw network outputs for ``obs`` in ``mode`` (batch of one), as numpy arrays; ``waypoints=False``
        leaves out the waypoint decoder (p(success) only), a slice computes only those waypoints
        (:meth:`PlannerNet.forward`)."""
        from tcot_hybrid.learning.model import MODE_IDS

        torch = self.torch
        img = check_image(obs.image, self.camera)
        prop = check_state(obs.q, obs.gripper_closed, self.cfg.dof)
        tok = self.tokens(obs.instruction)
        x = torch.from_numpy(np.ascontiguousarray(img)).permute(2, 0, 1)[None].float().div_(255.0)
        with torch.inference_mode():
            out = self.model(x, tok, torch.tensor([MODE_IDS[mode]]), torch.from_numpy(prop)[None], waypoints=waypoints)
        return {k: v[0].float().numpy() for k, v in out.items() if k != "heat_logits"}


class LearnedPlanner(NetworkPlanner):
    """TCoT planner: global / local waypoint plans and success detection from one network."""

    name = "learned"
    needs_image = True
    has_detector = True
    kind = "trajectory"

    def __init__(self, checkpoint, camera: CameraModel, *, config: LearnedPlannerConfig = LearnedPlannerConfig(),
                 home_q: np.ndarray | None = None):
        super().__init__(checkpoint, camera)
        from tcot_hybrid.data.labels import windows_from_meta

        self.config = config
        w = self.meta["windows"]
        self.windows = windows_from_meta(w)
        if self.windows.L_g != self.cfg.n_global or self.windows.L_l + 1 != self.cfg.n_local:
            raise PlanningError(f"checkpoint windows {w} do not match its model ({self.cfg.n_global} global, "
                                f"{self.cfg.n_local} local waypoints)")
        from tcot_hybrid.learning.data import height_reference

        self.height_reference = height_reference  # imported here, not at the first plan: inside its latency budget
        self.height_ref = self.meta.get("height_ref", "world")
        height_reference(camera, self.height_ref)  # an unknown height_ref is refused here, not at the first plan
        self.min_z_m, self.floor_note = lowest_plan_height(self.meta, camera, config.min_height_m)
        self.calibration = CameraSelfCalibration(camera, config.self_calibration, height_ref=self.height_ref,
                                                 home_q=home_q)

    @classmethod
    def from_context(cls, ctx) -> LearnedPlanner:
        from tcot_hybrid.learning.checkpoint import load_checkpoint
        from tcot_hybrid.planners import context_checkpoint

        path = context_checkpoint(cls.name, ctx)
        ck = load_checkpoint(path, robot=ctx.robot_name, camera=ctx.camera, kind=cls.kind, robot_spec=ctx.robot,
                             world=ctx.world_kind)
        return cls(ck, ctx.camera, config=ctx.options.get("learned", LearnedPlannerConfig()),
                   home_q=getattr(ctx.robot, "home_q", None))

    def plan(self, obs: Observation, *, mode: str) -> WaypointPlan:
        if mode not in MODES:
            raise PlanningError(f"learned planner mode {mode!r} is not one of {', '.join(MODES)}")
        ng = self.cfg.n_global
        sl = slice(self.windows.global_center, ng) if mode == "global" else slice(ng, self.cfg.n_waypoints)
        if self.cfg.head == "heatmap":  # only the executed waypoints' maps are computed
            out, sl = self.infer(obs, mode, waypoints=sl), slice(None)
        else:
            out = self.infer(obs, mode)
        uv, height = out["uv_px"][sl].astype(float), out["z_m"][sl].astype(float)
        camera = self.camera_for(obs, uv[0], height[0])  # both windows' first point is the hand now
        z = height + self.height_reference(camera, self.height_ref)
        with np.errstate(over="ignore"):
            prob = 1.0 / (1.0 + np.exp(-out["grip_logit"][sl].astype(float)))
        check_outputs(uv, z, prob, min_height_m=self.min_z_m, floor_note=self.floor_note)  # a world floor
        tcp_rot = self.orientations(out["rot6"][sl], camera) if "rot6" in out else None
        return height_plan(camera, uv, z, prob > 0.5, kind=mode, step=obs.step, config=self.config,
                           global_spacing=self.windows.global_spacing, meta={"z_m": z, "gripper_prob": prob},
                           tcp_rot=tcp_rot, refined=camera is not self.camera)

    def camera_for(self, obs: Observation, hand_uv_px: np.ndarray, hand_height_m: float) -> CameraModel:
        """The calibration to lift this plan with: the nominal one, or re-estimated from the network's sightings of
        the hand so far against the TCP's measured position (``obs.tcp_pos_m``; None: the nominal one)."""
        if obs.tcp_pos_m is None or not (np.all(np.isfinite(hand_uv_px)) and np.isfinite(hand_height_m)):
            return self.calibration.camera  # a non-finite output is refused by check_outputs, not taken as a sighting
        return self.calibration.add(obs.step, hand_uv_px, hand_height_m, obs.tcp_pos_m, q=obs.q)

    def orientations(self, rot6: np.ndarray, camera: CameraModel | None = None) -> np.ndarray:
        """(N, 3, 3) world TCP orientations of the rotation head's (N, 6) camera-frame outputs, each turned 180
        degrees about its approach axis when that brings the hand's yaw into the oracle's range (the network is
        trained up to that parallel-jaw symmetry; :func:`canonical_hand`)."""
        from tcot_hybrid.learning.model import rot6_to_matrix

        try:
            R_cam = rot6_to_matrix(rot6)
        except ValueError as exc:
            raise PlanningError(f"planner orientation output cannot be made a rotation: {exc}") from exc
        R_world_cam = np.asarray((camera or self.camera).T_world_cam, dtype=float)[:3, :3]
        return canonical_hand(R_world_cam @ R_cam)

    def success_probability(self, obs: Observation) -> float:
        """p(task succeeded) from the detect prompt (paper eq. 7), in [0, 1]."""
        out = self.infer(obs, "detect", waypoints=False)
        logit = float(out["success_logit"])
        if not np.isfinite(logit):
            raise PlanningError(f"planner success logit is not finite: {logit}")
        p = 1.0 / (1.0 + np.exp(-logit)) if logit > -700 else 0.0
        check_outputs(np.zeros((0, 2)), np.zeros(0), np.zeros(0), p)
        return float(p)
