"""Camera geometry against what mujoco.Renderer actually draws."""
from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tcot_hybrid.camera import CameraModel, triangulate  # noqa: E402
from tcot_hybrid.errors import ConfigError, LiftError  # noqa: E402

W, H = 160, 120
MARKER_R = 0.02
MARKERS = np.array(
    [
        [0.50, 0.00, 0.02],
        [0.35, -0.20, 0.02],
        [0.65, 0.22, 0.02],
        [0.40, 0.15, 0.25],  # in the air
        [0.60, -0.12, 0.15],
    ]
)


def _xyaxes(pos, target) -> str:
    """MJCF xyaxes of a camera at ``pos`` looking at ``target`` with world z up (MuJoCo looks along -z)."""
    fwd = np.asarray(target, float) - np.asarray(pos, float)
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(x, fwd)
    return " ".join(f"{v:.9f}" for v in (*x, *y))


def _scene_xml() -> str:
    markers = "\n".join(
        f'<geom name="m{i}" type="sphere" size="{MARKER_R}" pos="{p[0]} {p[1]} {p[2]}" '
        f'rgba="1 {0.2 * i} 0 1" material="bright"/>'
        for i, p in enumerate(MARKERS)
    )
    front_pos, side_pos = (1.3, 0.05, 0.7), (0.5, -1.0, 0.6)
    return f"""
<mujoco>
  <visual>
    <global offwidth="{W}" offheight="{H}"/>
    <quality shadowsize="0" offsamples="0"/>
    <headlight ambient="0.5 0.5 0.5" diffuse="0.4 0.4 0.4" specular="0 0 0"/>
  </visual>
  <asset><material name="bright" emission="1" specular="0" reflectance="0"/></asset>
  <worldbody>
    <geom name="table" type="plane" size="1.5 1.5 0.01" rgba="0.3 0.3 0.3 1"/>
    {markers}
    <camera name="front" pos="{' '.join(map(str, front_pos))}" xyaxes="{_xyaxes(front_pos, (0.5, 0.0, 0.05))}" fovy="50"/>
    <camera name="side" pos="{' '.join(map(str, side_pos))}" xyaxes="{_xyaxes(side_pos, (0.5, 0.0, 0.05))}" fovy="60"/>
    <camera name="intrinsic" pos="1.2 -0.4 0.8" xyaxes="{_xyaxes((1.2, -0.4, 0.8), (0.5, 0.0, 0.05))}"
            sensorsize="0.0064 0.0048" focal="0.005 0.0052" principal="0.0002 -0.0001" resolution="{W} {H}"/>
    <camera name="ortho" pos="0.5 0 2" projection="orthographic" fovy="1"/>
  </worldbody>
</mujoco>"""


@pytest.fixture(scope="module")
def scene():
    model = mujoco.MjModel.from_xml_string(_scene_xml())
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    renderer = mujoco.Renderer(model, H, W)
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
    out = {}
    for cam in ("front", "side", "intrinsic"):
        renderer.disable_depth_rendering()
        renderer.enable_segmentation_rendering()
        renderer.update_scene(data, cam)
        seg = renderer.render().copy()
        renderer.disable_segmentation_rendering()
        renderer.enable_depth_rendering()
        renderer.update_scene(data, cam)
        depth = renderer.render().astype(float)
        out[cam] = (CameraModel.from_mujoco(model, data, cam, width=W, height=H), seg, depth)
    renderer.close()
    return model, data, out


def _geom_mask(model, seg, name):
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
    return (seg[..., 0] == gid) & (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM))


@pytest.mark.parametrize("cam_name", ["front", "side", "intrinsic"])
def test_projection_matches_rendered_marker_centroids(scene, cam_name):
    model, _, cams = scene
    cam, seg, _ = cams[cam_name]
    uv, depth = cam.project(MARKERS)
    offsets = []
    for i in range(len(MARKERS)):
        mask = _geom_mask(model, seg, f"m{i}")
        assert mask.sum() >= 5, f"marker {i} barely visible in {cam_name} ({mask.sum()} px)"
        v, u = np.nonzero(mask)
        offsets.append([u.mean() - uv[i, 0], v.mean() - uv[i, 1]])
    offsets = np.array(offsets)
    errors = np.linalg.norm(offsets, axis=1)
    bias = offsets.mean(axis=0)
    print(
        f"{cam_name}: projected centre vs rendered centroid, max {errors.max():.3f} px over {len(errors)} markers, "
        f"mean offset {bias.round(3).tolist()} px"
    )
    assert errors.max() <= 1.0, errors
    # A wrong pixel-centre convention (cx = W/2 instead of (W-1)/2) would show as a ~0.5 px bias.
    assert np.all(np.abs(bias) <= 0.25), bias
    assert np.all(depth > cam.near_m)


def test_fovy_camera_intrinsics_are_symmetric_pixel_centred(scene):
    _, _, cams = scene
    cam = cams["front"][0]
    f = (H / 2) / np.tan(np.deg2rad(50) / 2)
    np.testing.assert_allclose(cam.K, [[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]], rtol=1e-6)
    # The optical axis projects to the principal point.
    axis_point = cam.T_world_cam[:3, 3] + 0.8 * cam.T_world_cam[:3, 2]
    uv, depth = cam.project(axis_point[None])
    np.testing.assert_allclose(uv[0], [(W - 1) / 2, (H - 1) / 2], atol=1e-9)
    np.testing.assert_allclose(depth, [0.8], atol=1e-12)
    model = scene[0]
    assert cam.near_m == pytest.approx(model.vis.map.znear * model.stat.extent)
    assert cam.far_m == pytest.approx(model.vis.map.zfar * model.stat.extent)


@pytest.mark.parametrize("cam_name", ["front", "side", "intrinsic"])
def test_depth_image_back_projection_hits_true_geometry(scene, cam_name):
    model, _, cams = scene
    cam, seg, depth = cams[cam_name]
    vv, uu = np.mgrid[0:H, 0:W]
    uv_all = np.c_[uu.ravel(), vv.ravel()].astype(float)

    table = _geom_mask(model, seg, "table").ravel()
    assert table.sum() > 0.3 * W * H
    pts = cam.unproject(uv_all[table], depth.ravel()[table])
    table_err = np.abs(pts[:, 2]).max()

    marker_err = 0.0
    n_marker_px = 0
    for i, centre in enumerate(MARKERS):
        m = _geom_mask(model, seg, f"m{i}").ravel()
        p = cam.unproject(uv_all[m], depth.ravel()[m])
        marker_err = max(marker_err, np.abs(np.linalg.norm(p - centre, axis=1) - MARKER_R).max())
        n_marker_px += int(m.sum())
    print(
        f"{cam_name}: depth back-projection error, table max {table_err * 1e3:.3f} mm over {table.sum()} px, "
        f"markers max {marker_err * 1e3:.3f} mm over {n_marker_px} px"
    )
    assert table_err <= 1e-3
    assert marker_err <= 1e-3


def test_triangulation_of_exact_points_front_and_side(scene):
    _, _, cams = scene
    front, side = cams["front"][0], cams["side"][0]
    rng = np.random.default_rng(0)
    pts = rng.uniform([0.3, -0.3, 0.0], [0.7, 0.3, 0.4], size=(500, 3))
    uv_f, _ = front.project(pts)
    uv_s, _ = side.project(pts)
    est = triangulate(front, uv_f, side, uv_s)
    err = np.linalg.norm(est - pts, axis=1).max()
    print(f"triangulation of {len(pts)} exact points: max error {err:.3g} m")
    assert err <= 1e-3


def test_triangulation_of_rendered_marker_centroids(scene):
    """Real pipeline figure: centroids of rendered markers (no exact projection) from two views."""
    model, _, cams = scene
    (front, seg_f, _), (side, seg_s, _) = cams["front"], cams["side"]
    uv = {}
    for key, seg in (("f", seg_f), ("s", seg_s)):
        rows = []
        for i in range(len(MARKERS)):
            v, u = np.nonzero(_geom_mask(model, seg, f"m{i}"))
            rows.append([u.mean(), v.mean()])
        uv[key] = np.array(rows)
    est = triangulate(front, uv["f"], side, uv["s"])
    err = np.linalg.norm(est - MARKERS, axis=1)
    print(f"triangulation of rendered centroids: max {err.max() * 1e3:.2f} mm, mean {err.mean() * 1e3:.2f} mm")
    assert err.max() <= 0.01


def test_project_unproject_round_trip(scene):
    _, _, cams = scene
    rng = np.random.default_rng(1)
    for cam_name, (cam, _, _) in cams.items():
        pts = rng.uniform([-1.0, -1.0, -0.5], [2.0, 1.0, 1.5], size=(2000, 3))
        uv, depth = cam.project(pts)
        # Behind-camera pixels are meaningless by contract; grazing points have huge uv, so keep d > 0.1 m.
        ok = depth > 0.1
        back = cam.unproject(uv[ok], depth[ok])
        err = np.abs(back - pts[ok]).max()
        assert err <= 1e-9, f"{cam_name}: round trip error {err:.3g} m over {ok.sum()} points"
        uv2, depth2 = cam.project(back)
        uv_err = np.abs(uv2 - uv[ok]).max()
        print(f"{cam_name}: round trip over {ok.sum()} points: {err:.2g} m, {uv_err:.2g} px")
        assert uv_err <= 1e-9
        assert np.abs(depth2 - depth[ok]).max() <= 1e-9


def test_in_image_bounds(scene):
    cam = scene[2]["front"][0]
    uv = np.array([[-0.5, -0.5], [W - 0.5, H - 0.5], [-0.51, 10], [10, H - 0.49], [np.nan, 3.0], [3.0, np.inf]])
    np.testing.assert_array_equal(cam.in_image(uv), [True, True, False, False, False, False])
    np.testing.assert_array_equal(cam.in_image(np.array([[1.0, 1.0]]), margin_px=2.0), [False])


def test_from_mujoco_refuses_bad_cameras(scene):
    model, data, _ = scene
    with pytest.raises(ConfigError, match="valid cameras: front, intrinsic, ortho, side"):
        CameraModel.from_mujoco(model, data, "nope", width=W, height=H)
    with pytest.raises(ConfigError, match="orthographic"):
        CameraModel.from_mujoco(model, data, "ortho", width=W, height=H)
    with pytest.raises(ConfigError, match="offscreen buffer"):
        CameraModel.from_mujoco(model, data, "front", width=W * 2, height=H)
    with pytest.raises(ConfigError, match="width"):
        CameraModel.from_mujoco(model, data, "front", width=0, height=H)


def test_camera_model_validates_fields(scene):
    cam = scene[2]["front"][0]
    base = dict(name="c", width=W, height=H, K=cam.K, T_world_cam=cam.T_world_cam, near_m=0.01, far_m=10.0)
    bad_T = cam.T_world_cam.copy()
    bad_T[:3, :3] *= 2.0
    mirror_T = cam.T_world_cam.copy()
    mirror_T[:3, 0] *= -1.0
    bad_K = cam.K.copy()
    bad_K[0, 0] = -1.0
    for override in (
        dict(K=np.eye(2)),
        dict(K=bad_K),
        dict(K=np.full((3, 3), np.nan)),
        dict(T_world_cam=bad_T),
        dict(T_world_cam=mirror_T),
        dict(T_world_cam=np.eye(3)),
        dict(near_m=0.0),
        dict(near_m=5.0, far_m=1.0),
        dict(far_m=np.inf),
        dict(width=0),
        dict(height=1.5),
    ):
        with pytest.raises(ConfigError):
            CameraModel(**{**base, **override})
    ok = CameraModel(**base)
    assert not ok.K.flags.writeable and not ok.T_world_cam.flags.writeable


def test_geometry_inputs_validated(scene):
    cam = scene[2]["front"][0]
    for bad in (np.zeros(3), np.zeros((2, 2)), np.zeros((0, 3)), [[np.nan, 0, 0]], [["a", "b", "c"]], None):
        with pytest.raises(LiftError):
            cam.project(bad)
    with pytest.raises(LiftError, match="depth_m"):
        cam.unproject(np.zeros((2, 2)), np.ones(3))
    with pytest.raises(LiftError, match="not finite"):
        cam.unproject(np.zeros((2, 2)), np.array([1.0, np.nan]))
    with pytest.raises(LiftError, match="baseline"):
        triangulate(cam, np.zeros((1, 2)), cam, np.zeros((1, 2)))
    with pytest.raises(LiftError, match="same shape"):
        triangulate(cam, np.zeros((1, 2)), scene[2]["side"][0], np.zeros((2, 2)))
