"""Camera self-calibration: a knocked camera is recovered from hand sightings; an undisturbed one is left alone."""
from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

from test_lift import look_at
from tcot_hybrid.calibration import CameraSelfCalibration, SelfCalibrationConfig, corrected_camera
from tcot_hybrid.camera import depth_at_height
from tcot_hybrid.errors import ConfigError, PlanningError
from tcot_hybrid.plan import WaypointPlan

NOMINAL = look_at("agentview", (1.0, 0.0, 1.2), (0.1, 0.0, 0.85), fovy_deg=45.0)
# a knock like the camera_shift perturbation's: ~3 cm and 3 degrees
KNOCK = np.r_[np.deg2rad(3.0) * np.array([0.6, -0.64, 0.48]), 0.02, -0.015, 0.015]


def _hand_path(n: int, rng) -> np.ndarray:
    """TCP positions over a table at z = 0.85 m: the arm moving about the workspace."""
    return np.c_[rng.uniform(-0.2, 0.25, n), rng.uniform(-0.25, 0.25, n), rng.uniform(0.87, 1.1, n)]


def _sightings(camera, tcp, rng, px_noise=1.0, height_noise=0.004):
    uv, _ = camera.project(tcp)
    height = tcp[:, 2] - camera.T_world_cam[2, 3]  # the network's heights are from the camera's height
    return uv + rng.normal(0, px_noise, uv.shape), height + rng.normal(0, height_noise, len(tcp))


def _lift_error_m(true_cam, used_cam, points) -> float:
    """Median 3D error [m] of table points seen by ``true_cam`` and lifted with ``used_cam`` at their true height."""
    uv, _ = true_cam.project(points)
    depth = depth_at_height(used_cam, uv, points[:, 2])
    return float(np.median(np.linalg.norm(used_cam.unproject(uv, depth) - points, axis=1)))


def test_a_knocked_camera_is_recovered_from_hand_sightings():
    rng = np.random.default_rng(0)
    true = corrected_camera(NOMINAL, KNOCK)
    tcp = _hand_path(12, rng)
    uv, height = _sightings(true, tcp, rng)
    cal = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(), height_ref="camera")
    for i in range(len(tcp)):
        cam = cal.add(i, uv[i], height[i], tcp[i])
    assert cal.summary()["refined"] and cal.summary()["nominal_error_px"] > 4.0
    table = np.c_[rng.uniform(-0.15, 0.2, 50), rng.uniform(-0.2, 0.2, 50), np.full(50, 0.87)]
    before, after = _lift_error_m(true, NOMINAL, table), _lift_error_m(true, cam, table)
    assert before > 0.03  # the knock puts every lifted grasp centimetres off
    assert after < 0.01 and after < before / 4


def test_one_sighting_already_corrects_most_of_the_error():
    """The first (global) plan has one sighting: the hand at home, where the network reads it best; it takes most of
    the knock out. The same sighting with the arm elsewhere waits for min_points (a hand read wrongly, not a knock)."""
    rng = np.random.default_rng(1)
    true = corrected_camera(NOMINAL, KNOCK)
    home = np.array([[-0.05, 0.0, 1.05]])
    uv, height = _sightings(true, home, rng, px_noise=0.0, height_noise=0.0)
    home_q = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.8])
    away = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(), height_ref="camera", home_q=home_q)
    elsewhere = home_q + np.array([0.0, 0.0, 0.0, 0.03, 0.0, 0.0, 0.0])  # one joint past home_tol_rad (0.005)
    assert away.add(0, uv[0], height[0], home[0], q=elsewhere) is NOMINAL  # away from home one is not enough
    # a LIBERO shipped init state: every joint 0.01-0.05 rad off home (its joint noise), which no demonstration shows
    shipped = home_q + np.array([0.033, 0.007, 0.032, 0.025, -0.003, 0.003, -0.027])
    assert not away.at_home(shipped)
    assert not away.at_home(None) and not away.at_home(home_q[:6])  # unknown or another arm: not at home
    cam = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(), height_ref="camera",
                                home_q=home_q).add(0, uv[0], height[0], home[0], q=home_q + 0.004)
    table = np.c_[rng.uniform(-0.1, 0.1, 50), rng.uniform(-0.15, 0.15, 50), np.full(50, 0.87)]
    assert _lift_error_m(true, cam, table) < 0.5 * _lift_error_m(true, NOMINAL, table)


def test_an_undisturbed_camera_is_left_exactly_as_it_is():
    rng = np.random.default_rng(2)
    tcp = _hand_path(30, rng)
    uv, height = _sightings(NOMINAL, tcp, rng, px_noise=1.5)
    cal = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(), height_ref="camera")
    for i in range(len(tcp)):
        assert cal.add(i, uv[i], height[i], tcp[i]) is NOMINAL
    assert cal.summary()["refined"] is False and cal.summary()["points"] == 30


def test_disabled_keeps_the_nominal_camera_and_one_sighting_per_step():
    rng = np.random.default_rng(3)
    true = corrected_camera(NOMINAL, KNOCK)
    tcp = _hand_path(5, rng)
    uv, height = _sightings(true, tcp, rng)
    off = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(enabled=False), height_ref="camera")
    assert all(off.add(i, uv[i], height[i], tcp[i]) is NOMINAL for i in range(5)) and off.n_points == 0
    on = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(max_points=3), height_ref="camera")
    for i in range(5):
        on.add(i, uv[i], height[i], tcp[i])
        on.add(i, uv[i], height[i], tcp[i])  # a second plan at the same step adds nothing
    assert on.n_points == 3


def test_bad_sightings_and_settings_are_refused_by_name():
    cal = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(), height_ref="camera")
    with pytest.raises(PlanningError, match="non-finite sighting"):
        cal.add(0, [np.nan, 3.0], 0.1, [0.0, 0.0, 1.0])
    for field, value in (("trigger_px", 0.0), ("prior_shift_m", -1.0), ("max_points", 0), ("enabled", "yes")):
        with pytest.raises(ConfigError, match=field):
            SelfCalibrationConfig(**{field: value})


def test_a_plan_carries_its_calibration_to_the_lift():
    moved = corrected_camera(NOMINAL, KNOCK)
    plan = WaypointPlan(uv_px=[[60.0, 70.0]], depth_m=[1.0], gripper_closed=[False], camera="agentview",
                        kind="local", calibration=moved)
    assert plan.lift_camera(NOMINAL) is moved
    assert WaypointPlan(uv_px=[[60.0, 70.0]], depth_m=[1.0], gripper_closed=[False], camera="agentview",
                        kind="local").lift_camera(NOMINAL) is NOMINAL
    with pytest.raises(PlanningError, match="calibration is of camera 'agentview'.*camera 'frontview'"):
        WaypointPlan(uv_px=[[60.0, 70.0]], depth_m=[1.0], gripper_closed=[False], camera="frontview", kind="local",
                     calibration=moved)


def test_sightings_no_camera_pose_explains_are_not_taken_for_a_knock():
    """A hand the network cannot see (inside a cabinet) gives pixels scattered far from the TCP's projection: the
    trigger fires, but no small pose change explains them, so the camera stays the nominal one."""
    rng = np.random.default_rng(4)
    tcp = _hand_path(12, rng)
    uv, height = _sightings(NOMINAL, tcp, rng)
    uv += rng.normal(0.0, 15.0, uv.shape)
    cal = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(), height_ref="camera")
    for i in range(len(tcp)):
        cam = cal.add(i, uv[i], height[i], tcp[i])
    assert cal.nominal_error_px() > 4.0 and cal.rejected_fits > 0
    assert cam is NOMINAL and cal.summary()["refined"] is False and cal.summary()["fit_error_px"] is None


def test_away_from_home_a_fit_waits_for_min_points():
    rng = np.random.default_rng(5)
    true = corrected_camera(NOMINAL, KNOCK)
    tcp = _hand_path(3, rng)
    uv, height = _sightings(true, tcp, rng, px_noise=0.5)
    cal = CameraSelfCalibration(NOMINAL, SelfCalibrationConfig(min_points=3), height_ref="camera")
    assert [cal.add(i, uv[i], height[i], tcp[i]) is NOMINAL for i in range(3)] == [True, True, False]
