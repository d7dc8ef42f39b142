"""Meshes a camera cannot see are left out of its render: the frustum test is conservative and the image is the same
pixel for pixel; the colours come back; shadows, reflections and off-centre or orthographic cameras turn it off."""
import mujoco
import numpy as np
import pytest

from tcot_hybrid.frustum import OffscreenMeshCulling, outside_frustum

CAM_POS = np.zeros(3)
CAM_MAT = np.eye(3)  # MuJoCo camera at the origin looking along -z, y up


def _outside(centers, radii, *, fovy=90.0, aspect=1.0):
    return outside_frustum(CAM_POS, CAM_MAT, fovy, aspect, np.atleast_2d(centers), np.atleast_1d(radii))


def test_spheres_in_view_behind_and_beside_the_camera():
    got = _outside([[0, 0, -2],        # straight ahead
                    [0, 0, 2],         # behind
                    [5, 0, -2],        # far right (90 deg field: |x| <= z)
                    [0, -5, -2],       # far below
                    [2.5, 0, -2]],     # just outside the right plane by 0.35 m, radius 0.5: touches the view
                   [0.1, 0.1, 0.1, 0.1, 0.5])
    assert got.tolist() == [False, True, True, True, False]


def test_a_sphere_around_the_eye_is_always_visible():
    assert not _outside([[0, 0, 0.05]], [0.1])[0]


def test_the_aspect_ratio_widens_the_horizontal_field_only():
    point = [[1.5, 0, -1]]  # 56 deg off axis horizontally
    assert _outside(point, [0.01], aspect=1.0)[0]
    assert not _outside(point, [0.01], aspect=2.0)[0]
    assert _outside([[0, 1.5, -1]], [0.01], aspect=2.0)[0]


def test_conservative_against_sampled_surface_points():
    """A sphere called outside has no point of its surface inside the frustum."""
    rng = np.random.default_rng(0)
    fovy, aspect = 45.0, 1.5
    ty = np.tan(np.deg2rad(fovy) / 2)
    centers = rng.uniform(-3, 3, size=(400, 3))
    radii = rng.uniform(0.01, 1.0, size=400)
    out = outside_frustum(CAM_POS, CAM_MAT, fovy, aspect, centers, radii)
    dirs = rng.normal(size=(64, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for c, r in zip(centers[out], radii[out]):
        p = c + r * dirs
        z = -p[:, 2]
        inside = (z > 0) & (np.abs(p[:, 0]) <= ty * aspect * z) & (np.abs(p[:, 1]) <= ty * z)
        assert not inside.any()
    assert 0 < out.sum() < len(out)


@pytest.mark.parametrize(("fovy", "aspect", "match"), [(0.0, 1.0, "fovy_deg"), (180.0, 1.0, "fovy_deg"),
                                                       (45.0, 0.0, "aspect"), (45.0, -1.0, "aspect")])
def test_bad_camera_names_the_value(fovy, aspect, match):
    with pytest.raises(ValueError, match=match):
        _outside([[0, 0, -1]], [0.1], fovy=fovy, aspect=aspect)


SCENE = """
<mujoco>
  <asset>
    <mesh name="tetra" vertex="0 0 0  0.2 0 0  0 0.2 0  0 0 0.2"/>
  </asset>
  <worldbody>
    <light pos="0 0 3" dir="0 0 -1" castshadow="{shadow}"/>
    <geom type="plane" size="2 2 0.1" rgba="0.3 0.3 0.3 1"/>
    <geom name="seen" type="mesh" mesh="tetra" pos="0 0 0.3" rgba="0.9 0.2 0.2 1"/>
    <geom name="behind" type="mesh" mesh="tetra" pos="0 -3 0.5" rgba="0.2 0.9 0.2 1"/>
    <geom name="aside" type="mesh" mesh="tetra" pos="4 1 0.5" rgba="0.2 0.2 0.9 0.5"/>
    <camera name="cam" pos="0 -1.5 1.0" xyaxes="1 0 0 0 0.55 0.83" fovy="45"/>
    <camera name="ortho" pos="0 -1.5 1.0" xyaxes="1 0 0 0 0.55 0.83" fovy="1" projection="orthographic"/>
  </worldbody>
</mujoco>
"""


def _scene(shadow="false"):
    model = mujoco.MjModel.from_xml_string(SCENE.format(shadow=shadow))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def _render(model, data, renderer, culling=None):
    cam = model.camera("cam").id
    if culling is not None:
        assert culling.applies(cam, renderer.scene)
        hidden = culling.hide(data, cam, renderer.width, renderer.height)
    renderer.update_scene(data, camera="cam")
    if culling is not None:
        culling.restore()
    return renderer.render().copy(), renderer.scene.ngeom, (hidden if culling is not None else 0)


def test_culled_render_is_the_same_image_and_colours_come_back():
    model, data = _scene()
    rgba = model.geom_rgba.copy()
    with mujoco.Renderer(model, 96, 128) as renderer:
        full, n_full, _ = _render(model, data, renderer)
        culled, n_culled, hidden = _render(model, data, renderer, OffscreenMeshCulling(model))
    assert hidden == 2 and n_culled == n_full - 2
    np.testing.assert_array_equal(culled, full)
    np.testing.assert_array_equal(model.geom_rgba, rgba)
    assert full.std() > 0  # something was drawn


def test_off_where_an_unseen_mesh_can_still_change_the_image():
    model, _ = _scene(shadow="true")
    culling = OffscreenMeshCulling(model)
    with mujoco.Renderer(model, 64, 64) as renderer:
        cam, ortho = model.camera("cam").id, model.camera("ortho").id
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 1
        assert not culling.applies(cam, renderer.scene)  # a mesh out of view can cast a shadow into it
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        assert culling.applies(cam, renderer.scene)
        assert not culling.applies(ortho, renderer.scene)
        assert not culling.applies(-1, renderer.scene)  # the free camera
