"""Lifting image waypoints to 3D: round trips and refusal of every bad input (RELIABILITY rows 3, 4)."""
from __future__ import annotations

import os

# Before anything imports mujoco (GL backend is chosen at import; tcot_hybrid.camera/robot import it).
os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.errors import ConfigError, LiftError
from tcot_hybrid.lift import LiftConfig, lift_two_view, lift_waypoints

W = H = 128
WORKSPACE_LO = np.array([0.3, -0.3, 0.0])
WORKSPACE_HI = np.array([0.7, 0.3, 0.4])


def look_at(name: str, pos, target, *, fovy_deg: float = 60.0, width: int = W, height: int = H) -> CameraModel:
    """A fovy camera (same intrinsics convention as CameraModel.from_mujoco) looking at ``target``."""
    pos = np.asarray(pos, float)
    z = np.asarray(target, float) - pos
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])  # OpenCV x right when z forward, y down
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.c_[x, y, z]
    T[:3, 3] = pos
    f = (height / 2) / np.tan(np.deg2rad(fovy_deg) / 2)
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    return CameraModel(name=name, width=width, height=height, K=K, T_world_cam=T, near_m=0.01, far_m=5.0)


FRONT = look_at("front", (1.3, 0.0, 0.9), (0.5, 0.0, 0.1))
SIDE = look_at("side", (0.5, -1.0, 0.7), (0.5, 0.0, 0.1))


def test_cameras_see_the_whole_workspace():
    corners = np.array([[x, y, z] for x in (0.3, 0.7) for y in (-0.3, 0.3) for z in (0.0, 0.4)])
    for cam in (FRONT, SIDE):
        uv, depth = cam.project(corners)
        assert cam.in_image(uv).all() and np.all(depth > cam.near_m), cam.name


def test_project_lift_round_trip_property():
    tried = {"examples": 0, "points": 0, "max_px": 0.0, "max_m": 0.0, "max_m_f32": 0.0}

    @settings(max_examples=400, deadline=None, database=None)
    @given(unit=st.integers(1, 32).flatmap(lambda n: arrays(np.float64, (n, 3), elements=st.floats(0.0, 1.0))))
    def check(unit):
        points = WORKSPACE_LO + unit * (WORKSPACE_HI - WORKSPACE_LO)
        tried["examples"] += 1
        tried["points"] += len(points)
        for cam in (FRONT, SIDE):
            uv, depth = cam.project(points)
            lifted = lift_waypoints(uv, depth, cam)
            uv_back, _ = cam.project(lifted)
            px = np.abs(uv_back - uv).max()
            m = np.linalg.norm(lifted - points, axis=1).max()
            # Rendered depth images are float32: the lift must survive that quantisation too.
            m32 = np.linalg.norm(lift_waypoints(uv, depth.astype(np.float32), cam) - points, axis=1).max()
            tried["max_px"] = max(tried["max_px"], px)
            tried["max_m"] = max(tried["max_m"], m)
            tried["max_m_f32"] = max(tried["max_m_f32"], m32)
            msg = f"{cam.name} after {tried['examples']} examples / {tried['points']} points"
            assert px <= 0.5, f"reprojection {px} px, {msg}"
            assert m <= 0.01, f"3D error {m} m, {msg}"
            assert m32 <= 0.01, f"3D error with float32 depth {m32} m, {msg}"

    check()
    print(
        f"lift round trip: {tried['examples']} examples, {tried['points']} points x 2 cameras; max reprojection "
        f"{tried['max_px']:.2g} px, max 3D {tried['max_m']:.2g} m (float32 depth: {tried['max_m_f32']:.2g} m)"
    )
    assert tried["examples"] >= 100, f"hypothesis only tried {tried['examples']} examples"


def _good(n: int = 4):
    points = np.linspace(WORKSPACE_LO, WORKSPACE_HI, n)
    uv, depth = FRONT.project(points)
    return uv, depth


BAD_PIXELS = [
    ([np.nan, 10.0], "not finite"),
    ([10.0, np.inf], "not finite"),
    ([-np.inf, 10.0], "not finite"),
    ([-0.51, 10.0], "outside"),
    ([W - 0.49, 10.0], "outside"),
    ([10.0, -3.0], "outside"),
    ([10.0, H + 100.0], "outside"),
    ([1e9, -1e9], "outside"),
]


@pytest.mark.parametrize("pixel,what", BAD_PIXELS)
def test_bad_pixel_rejected_with_index_and_range(pixel, what):
    uv, depth = _good()
    uv[2] = pixel
    with pytest.raises(LiftError, match=what) as info:
        lift_waypoints(uv, depth, FRONT)
    msg = str(info.value)
    assert "waypoint 2" in msg
    if what == "outside":
        assert f"u in [-0.5, {W - 0.5}]" in msg and "v in" in msg


@pytest.mark.parametrize("value", [0.0, -0.5, np.nan, np.inf, -np.inf, 0.01, 0.005, 5.0001, 100.0])
def test_bad_depth_rejected_with_index_and_range(value):
    uv, depth = _good()
    depth[3] = value
    with pytest.raises(LiftError) as info:
        lift_waypoints(uv, depth, FRONT)
    msg = str(info.value)
    assert "waypoint 3" in msg and "(near_m, far_m] = (0.01, 5] m" in msg and "depth_m" in msg


def test_depth_at_far_plane_is_accepted_just_inside_near_is_not():
    uv, depth = _good(1)
    assert lift_waypoints(uv, np.array([FRONT.far_m]), FRONT).shape == (1, 3)
    with pytest.raises(LiftError):
        lift_waypoints(uv, np.array([FRONT.near_m]), FRONT)


def test_margin_refuses_points_near_the_border():
    uv = np.array([[2.0, 60.0]])  # 2.5 px from the left border (which is at u = -0.5)
    with pytest.raises(LiftError, match="margin_px = 3.0"):
        lift_waypoints(uv, np.array([1.0]), FRONT, config=LiftConfig(margin_px=3.0))
    assert lift_waypoints(uv, np.array([1.0]), FRONT, config=LiftConfig(margin_px=2.5)).shape == (1, 3)


@pytest.mark.parametrize(
    "uv,depth",
    [
        (np.zeros((3, 3)), np.ones(3)),
        (np.zeros(2), np.ones(1)),
        (np.zeros((0, 2)), np.ones(0)),
        (np.zeros((1, 2, 1)), np.ones(1)),
        (np.full((3, 2), 10.0), np.ones(2)),
        (np.full((3, 2), 10.0), np.ones((3, 1))),
        (np.full((3, 2), 10.0), 1.0),
        ([["a", "b"]], [1.0]),
        (None, [1.0]),
        (np.full((1, 2), 10.0), ["x"]),
    ],
)
def test_wrong_shapes_and_types_rejected(uv, depth):
    with pytest.raises(LiftError):
        lift_waypoints(uv, depth, FRONT)


def test_fuzzed_bad_inputs_all_rejected_never_clipped():
    rng = np.random.default_rng(0)
    n_tried = 0
    for _ in range(2000):
        n = int(rng.integers(1, 8))
        uv, depth = _good(n)
        i = int(rng.integers(n))
        kind = rng.integers(4)
        if kind == 0:
            uv[i, rng.integers(2)] = rng.choice([np.nan, np.inf, -np.inf])
        elif kind == 1:  # outside the image by at least 1e-6 px on a random side
            axis = rng.integers(2)
            size = W if axis == 0 else H
            uv[i, axis] = rng.choice([-0.5 - 10 ** rng.uniform(-6, 4), size - 0.5 + 10 ** rng.uniform(-6, 4)])
        elif kind == 2:
            depth[i] = rng.choice([np.nan, np.inf, -np.inf, 0.0, -rng.uniform(0, 10), rng.uniform(0, FRONT.near_m)])
        else:
            depth[i] = FRONT.far_m + 10 ** rng.uniform(-9, 3)
        n_tried += 1
        with pytest.raises(LiftError, match=f"waypoint {i}"):
            lift_waypoints(uv, depth, FRONT)
    print(f"lift fuzz: {n_tried} bad inputs, all rejected")


def test_lift_config_validated():
    for bad in (dict(margin_px=-1.0), dict(margin_px=np.nan), dict(max_reprojection_px=0.0), dict(max_reprojection_px=np.inf)):
        with pytest.raises(ConfigError):
            LiftConfig(**bad)


def test_two_view_lift_exact_points():
    rng = np.random.default_rng(2)
    points = rng.uniform(WORKSPACE_LO, WORKSPACE_HI, size=(200, 3))
    uv_a, _ = FRONT.project(points)
    uv_b, _ = SIDE.project(points)
    lifted = lift_two_view(uv_a, FRONT, uv_b, SIDE)
    err = np.linalg.norm(lifted - points, axis=1).max()
    print(f"two-view lift of {len(points)} exact points: max error {err:.2g} m")
    assert err <= 1e-6
    # With pixel noise below the reprojection gate the lift is still accepted and close.
    noisy = lift_two_view(uv_a + rng.uniform(-0.3, 0.3, uv_a.shape), FRONT, uv_b + rng.uniform(-0.3, 0.3, uv_b.shape), SIDE)
    assert np.linalg.norm(noisy - points, axis=1).max() <= 0.01


def test_two_view_lift_refuses_inconsistent_pixels():
    points = np.array([[0.4, -0.2, 0.05], [0.6, 0.2, 0.3]])
    uv_a, _ = FRONT.project(points)
    uv_b, _ = SIDE.project(points[::-1])  # swapped correspondences
    with pytest.raises(LiftError, match="waypoint 0"):
        lift_two_view(uv_a, FRONT, uv_b, SIDE)
    with pytest.raises(LiftError, match="outside"):
        lift_two_view(uv_a, FRONT, np.array([[-5.0, 3.0], [4.0, 4.0]]), SIDE)
    with pytest.raises(LiftError, match="same waypoints"):
        lift_two_view(uv_a, FRONT, uv_a[:1], SIDE)


def test_two_view_lift_refuses_point_behind_a_camera():
    behind_side = SIDE.T_world_cam[:3, 3] - 0.3 * SIDE.T_world_cam[:3, 2]
    watcher = look_at("watcher", behind_side + np.array([0.8, -0.2, 0.3]), behind_side)
    uv_w, depth_w = watcher.project(behind_side[None])
    uv_s, depth_s = SIDE.project(behind_side[None])
    assert depth_w[0] > 0 and depth_s[0] < 0 and SIDE.in_image(uv_s).all()  # the trap: pixel looks valid
    with pytest.raises(LiftError, match="outside camera 'side'.*depth range"):
        lift_two_view(uv_w, watcher, uv_s, SIDE)
