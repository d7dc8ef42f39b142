"""Online refinement of the planner camera's pose from where the planner sees the hand.

Every learned plan starts at the hand: the first waypoint of a global window's future (k = 0) and of a local
window is the TCP now, a pixel and a height the network reads off the image. The TCP's true position is known
from the measured joints (forward kinematics), so each plan gives a 2D-3D correspondence. With the nominal
calibration those agree to 1-2 px; a camera knocked by a few centimetres and degrees after calibration
(LIBERO-Plus's camera shift, the ``camera_shift`` perturbation) puts them 6-10 px apart, and every lifted
waypoint then lands centimetres off.

:class:`CameraSelfCalibration` gathers the correspondences of an episode and, once the nominal camera's median
reprojection error exceeds ``trigger_px`` (a camera that has moved, not network noise), solves for the camera
pose that best explains them: a robust (soft-L1) least-squares fit of the pose correction (a rotation vector and
a shift in the camera frame) with a Gaussian prior on its size, the pixel and height residuals weighted by the
network's measured noise (scipy's ``least_squares``). A fit is taken only when it explains the sightings with a
plausible correction; a hand the network cannot see (inside a cabinet) gives sightings no pose explains. Below the
trigger the nominal camera is returned unchanged, so undisturbed episodes run exactly as without it.
"""
from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.config import require_bool, require_int, require_positive
from tcot_hybrid.errors import PlanningError


@dataclass(frozen=True, kw_only=True)
class SelfCalibrationConfig:
    """When and how far the planner camera's pose is re-estimated during an episode.

    enabled:        refine the camera from the planner's own hand sightings (False: the nominal calibration
                    always, as before).
    trigger_px:     refine only once the median distance between where the planner sees the hand and where the
                    nominal camera projects it exceeds this [px]. Measured on development layouts: 1-2 px with
                    the nominal camera, 6-10 px under a 3 cm / 3 deg shift. Down: reacts to smaller shifts,
                    and sooner to network noise.
    pixel_sigma_px: the network's noise on the hand's pixel [px], the weight of a pixel residual.
    height_sigma_m: the network's noise on the hand's height below the camera [m], the weight of a height
                    residual (its heights are measured from the camera's height: a camera moved up reads every
                    height higher).
    prior_turn_deg, prior_shift_m: 1-sigma sizes of the pose correction the fit is drawn towards zero with
                    [deg, m]: how far a fixed camera is believed to be knocked. Up: trusts the sightings more.
    max_points:     sightings kept (the newest); one per planner step at most.
    min_points, home_tol_rad: a fit needs ``min_points`` sightings, unless one of them was taken with the arm at
                    its home posture (every joint within ``home_tol_rad`` [rad]), where every demonstration starts
                    (exactly: a sampled layout starts 0 rad from it) and the network reads the hand best. Elsewhere
                    one sighting cannot tell a knocked camera from a hand read wrongly: an arm started 0.2 rad off its
                    posture (``init_posture``) was read 5-9 px off, and arms on LIBERO's shipped init states, whose
                    joints start 0.01-0.05 rad off home, up to 5 px; a one-sighting fit on them sent every plan
                    astray. Up: one sighting trusted further from where the network learned the hand.
    consistent_px, max_turn_deg, max_shift_m: a fitted pose is taken only when it explains the sightings (their
                    median distance from its projection of the TCP at most ``consistent_px`` [px]) with a correction
                    no larger than ``max_turn_deg`` [deg] and ``max_shift_m`` [m]; otherwise the disagreement is not
                    a knocked camera (a hand hidden inside a cabinet or a microwave, read wrongly by the network, was
                    seen on development layouts) and the camera stays as it was. Up: accepts more fits.
    """

    enabled: bool = True
    trigger_px: float = 4.0
    pixel_sigma_px: float = 2.0
    height_sigma_m: float = 0.01
    prior_turn_deg: float = 5.0
    prior_shift_m: float = 0.05
    max_points: int = 40
    min_points: int = 3
    home_tol_rad: float = 0.005
    consistent_px: float = 3.0
    max_turn_deg: float = 10.0
    max_shift_m: float = 0.10

    def __post_init__(self) -> None:
        require_bool("self_calibration.enabled", self.enabled)
        for name in ("trigger_px", "pixel_sigma_px", "height_sigma_m", "prior_turn_deg", "prior_shift_m",
                     "consistent_px", "max_turn_deg", "max_shift_m", "home_tol_rad"):
            require_positive(f"self_calibration.{name}", getattr(self, name))
        require_int("self_calibration.max_points", self.max_points, minimum=1)
        require_int("self_calibration.min_points", self.min_points, minimum=1)


def corrected_pose(T_nominal: np.ndarray, correction: np.ndarray) -> np.ndarray:
    """T_world_cam = T_nominal @ [R(rotvec) | shift] for ``correction`` = (rotation vector [rad], shift [m]), both
    in the nominal camera's frame."""
    c = np.asarray(correction, dtype=float)
    delta = np.eye(4)
    delta[:3, :3] = Rotation.from_rotvec(c[:3]).as_matrix()
    delta[:3, 3] = c[3:]
    return np.asarray(T_nominal, float) @ delta


def corrected_camera(nominal: CameraModel, correction: np.ndarray) -> CameraModel:
    """``nominal`` with its pose corrected by ``correction`` (:func:`corrected_pose`)."""
    return dataclasses.replace(nominal, T_world_cam=corrected_pose(nominal.T_world_cam, correction))


class Sighting(NamedTuple):
    """Where the planner saw the hand at a planner step, beside where the joints put it."""

    step: int
    uv_px: np.ndarray  # (2,) [px]
    height_m: float  # relative to the height reference [m]
    tcp_world: np.ndarray  # (3,) [m]
    at_home: bool  # the arm at its home posture


class CameraSelfCalibration:
    """One episode's camera estimate (see the module docstring). ``height_ref`` is what the planner's heights are
    measured from: "camera" (its height) or "world" (z = 0; then height residuals say nothing of the camera)."""

    def __init__(self, nominal: CameraModel, config: SelfCalibrationConfig, *, height_ref: str,
                 home_q: np.ndarray | None = None):
        self.nominal, self.config, self.height_ref = nominal, config, height_ref
        self.home_q = None if home_q is None else np.asarray(home_q, dtype=float)  # [rad] the robot's home posture
        self.camera = nominal
        self.correction = np.zeros(6)
        self.rejected_fits = 0  # fits that did not explain the sightings, or needed too large a correction
        self.fit_error_px: float | None = None  # the taken fit's median pixel residual
        self._sightings: deque[Sighting] = deque(maxlen=config.max_points)  # the newest

    @property
    def n_points(self) -> int:
        return len(self._sightings)

    def _arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The kept sightings' pixels (N, 2), TCP positions (N, 3) and heights (N,)."""
        return (np.array([s.uv_px for s in self._sightings]), np.array([s.tcp_world for s in self._sightings]),
                np.array([s.height_m for s in self._sightings]))

    def error_px(self, camera: CameraModel) -> float:
        """Median pixel distance between the sightings and ``camera``'s projection of the TCP [px]."""
        if not self._sightings:
            return 0.0
        uv, tcp, _ = self._arrays()
        return float(np.median(np.linalg.norm(camera.project(tcp)[0] - uv, axis=1)))

    def nominal_error_px(self) -> float:
        return self.error_px(self.nominal)

    def at_home(self, q: np.ndarray | None) -> bool:
        """Whether joint positions ``q`` [rad] are the home posture (every joint within ``home_tol_rad``)."""
        if q is None or self.home_q is None:
            return False
        q = np.asarray(q, dtype=float)
        return q.shape == self.home_q.shape and bool(np.all(np.abs(q - self.home_q) <= self.config.home_tol_rad))

    def add(self, step: int, uv_px: np.ndarray, height_m: float, tcp_world: np.ndarray, *,
            q: np.ndarray | None = None) -> CameraModel:
        """Record the planner's sighting of the hand at ``step`` (pixel, height relative to ``height_ref``) and the
        TCP's measured world position, with the arm's joint positions ``q`` [rad] (None: unknown, not at home);
        return the camera to lift this step's plan with."""
        at_home = self.at_home(q)
        uv = np.asarray(uv_px, dtype=float).reshape(2)
        tcp = np.asarray(tcp_world, dtype=float).reshape(3)
        if not (np.all(np.isfinite(uv)) and np.isfinite(height_m) and np.all(np.isfinite(tcp))):
            raise PlanningError(f"camera self-calibration at step {step}: non-finite sighting uv = {uv.tolist()}, "
                                f"height = {height_m}, TCP = {tcp.tolist()}")
        if not self.config.enabled:
            return self.camera
        if self._sightings and self._sightings[-1].step == step:  # a second plan at the same step sees the same image
            return self.camera
        self._sightings.append(Sighting(step, uv, float(height_m), tcp, bool(at_home)))
        if self.camera is self.nominal and self.nominal_error_px() <= self.config.trigger_px:
            return self.camera
        if self.n_points < self.config.min_points and not any(s.at_home for s in self._sightings):
            return self.camera
        self._fit()
        return self.camera

    def _fit(self) -> None:
        cfg = self.config
        uv, tcp, height = self._arrays()
        prior = np.r_[np.full(3, np.deg2rad(cfg.prior_turn_deg)), np.full(3, cfg.prior_shift_m)]

        T_nominal, K = np.asarray(self.nominal.T_world_cam, float), self.nominal.K

        def residuals(c):  # the projection of CameraModel.project, without building a camera per evaluation
            T = corrected_pose(T_nominal, c)
            pc = (tcp - T[:3, 3]) @ T[:3, :3]  # world -> camera: R^T (p - t)
            proj = pc[:, :2] / pc[:, 2:3] @ K[:2, :2].T + K[:2, 2]
            r = [((proj - uv) / cfg.pixel_sigma_px).ravel()]
            if self.height_ref == "camera":  # predicted TCP z = height + the camera's z
                r.append((height + T[2, 3] - tcp[:, 2]) / cfg.height_sigma_m)
            return np.concatenate(r)

        def objective(c):
            return np.concatenate([residuals(c), c / prior])

        # soft-L1 on the sightings only would need a split loss; scipy applies one loss to all residuals, and
        # the prior terms stay well inside its quadratic zone (|c / prior| ~ 1) for the corrections expected
        fit = least_squares(objective, self.correction, loss="soft_l1", f_scale=2.0, x_scale=prior)
        if not (fit.success and np.all(np.isfinite(fit.x))):
            self.rejected_fits += 1
            return
        camera = corrected_camera(self.nominal, fit.x)
        error = self.error_px(camera)
        turn = np.rad2deg(np.linalg.norm(fit.x[:3]))
        if error > cfg.consistent_px or turn > cfg.max_turn_deg or np.linalg.norm(fit.x[3:]) > cfg.max_shift_m:
            self.rejected_fits += 1
            return
        self.correction, self.camera, self.fit_error_px = fit.x, camera, error

    def summary(self) -> dict:
        """What the episode record keeps: sightings, the nominal camera's error, the correction applied."""
        turn = Rotation.from_rotvec(self.correction[:3])
        return {"points": self.n_points, "nominal_error_px": round(self.nominal_error_px(), 2),
                "refined": self.camera is not self.nominal, "rejected_fits": self.rejected_fits,
                "fit_error_px": None if self.fit_error_px is None else round(self.fit_error_px, 2),
                "turn_deg": round(float(np.rad2deg(turn.magnitude())), 3),
                "shift_m": np.round(self.correction[3:], 4).tolist()}
