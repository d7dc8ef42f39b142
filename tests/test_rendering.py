"""The backdrop renderer draws exactly what one full render draws, redraws the backdrop only when it changes, renders
a frame whole where something translucent covers the backdrop (and moves the backdrop geom there to the frame layer),
and falls back to full renders where two layers could differ."""
import mujoco
import numpy as np
import pytest

from tcot_hybrid import rendering
from tcot_hybrid.rendering import BackdropRenderer, LayerGroups, layering_blocker, split_layers

PX = 64
GROUPS = LayerGroups(backdrop=4, translucent=3, frame=1)
XML = """
<mujoco>
  <visual><quality shadowsize="0" offsamples="0"/></visual>
  <asset><material name="wall" rgba="0.3 0.5 0.7 {wall_alpha}"/></asset>
  <worldbody>
    <light pos="0 0 3" castshadow="false"/>
    <camera name="cam" pos="0 -1.2 0.9" xyaxes="1 0 0 0 0.6 0.8"/>
    <geom name="floor" type="box" size="1 1 0.02" rgba="0.8 0.7 0.6 1"/>
    <geom name="wall" type="box" size="0.3 0.02 0.3" pos="0 0.3 0.3" material="wall" group="4"/>
    <geom name="pane" type="box" size="0.1 0.01 0.1" pos="0.7 0.1 0.3" rgba="1 1 1 0.4" group="3"/>
    <body name="ball" pos="0 0 0.2"><freejoint/><geom type="sphere" size="0.08" rgba="1 0 0 1"/>
      <site name="aim" type="cylinder" size="0.01 0.3" rgba="0 1 0 0.3"/></body>
    <body name="arm" pos="0.2 -0.2 0.1"><joint name="hinge" type="hinge" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0.25 0 0.1" size="0.03" rgba="0 1 0 1"/></body>
  </worldbody>
</mujoco>"""


def _world(wall_alpha=1.0):
    """A floor, a wall (the backdrop, grouped by hand: split_layers would take the floor too), a translucent pane, a
    ball with a translucent aiming line (a site, as robosuite's grip sites) and an arm."""
    model = mujoco.MjModel.from_xml_string(XML.format(wall_alpha=wall_alpha))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    option = mujoco.MjvOption()
    option.geomgroup[GROUPS.backdrop] = option.geomgroup[GROUPS.translucent] = 1
    return model, data, option


def _whole(renderer, data, option):
    renderer.update_scene(data, camera="cam", scene_option=option)
    return renderer.render().copy()


def _place(model, data, ball, hinge=0.0):
    data.qpos[:3] = ball
    data.qpos[7] = hinge
    mujoco.mj_forward(model, data)


@pytest.fixture
def world():
    model, data, option = _world()
    renderer = mujoco.Renderer(model, PX, PX)
    yield model, data, option, renderer
    renderer.close()


def test_layers_draw_the_full_render_pixel_for_pixel_and_the_backdrop_once(world):
    model, data, option, renderer = world
    layered = BackdropRenderer(renderer, model, "cam", option, GROUPS)
    rng = np.random.default_rng(0)
    for _ in range(6):  # the ball (and its aiming line) and the arm move over the floor, left of the wall
        _place(model, data, rng.uniform([-0.6, -0.3, 0.1], [-0.4, 0.2, 0.3]), rng.uniform(-3, 3))
        np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
    assert layered.layered, layered.fallback_reason
    assert layered.backdrop_renders == 1 and layered.whole_frames == 0


def test_something_translucent_over_the_backdrop_renders_that_frame_whole_and_moves_the_geom_there(world):
    model, data, option, renderer = world
    layered = BackdropRenderer(renderer, model, "cam", option, GROUPS)
    _place(model, data, [-0.5, 0.0, 0.2])
    layered.render(data)
    _place(model, data, [0.0, 0.6, 0.4])  # the aiming line behind the wall, hidden by it: composited
    np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
    assert layered.whole_frames == 0
    _place(model, data, [0.0, 0.1, 0.4])  # in front of it: blended over the wall, so that frame is whole ...
    np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
    assert layered.whole_frames == 1 and layered.layered
    assert model.geom_group[model.geom("wall").id] == GROUPS.frame  # ... and the wall is in the frame layer now
    np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
    assert layered.whole_frames == 1


def test_a_translucent_geom_in_front_of_the_backdrop_is_caught_too(world):
    model, data, option, renderer = world
    layered = BackdropRenderer(renderer, model, "cam", option, GROUPS)
    _place(model, data, [-0.5, 0.0, 0.2])
    layered.render(data)
    model.geom_pos[model.geom("pane").id] = [0.0, 0.1, 0.3]  # the pane moved in front of the wall
    mujoco.mj_forward(model, data)
    np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
    assert layered.whole_frames == 1 and layered.layered


def test_a_moved_camera_or_a_recoloured_backdrop_redraws_the_backdrop(world):
    model, data, option, renderer = world
    layered = BackdropRenderer(renderer, model, "cam", option, GROUPS)
    _place(model, data, [-0.5, 0.0, 0.2])
    layered.render(data)
    model.cam_pos[0] += [0.05, 0.0, 0.02]  # the camera_shift perturbation moves the camera like this
    mujoco.mj_forward(model, data)
    np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
    model.mat_rgba[model.material("wall").id] = [0.9, 0.1, 0.1, 1.0]
    np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
    assert layered.backdrop_renders == 3 and layered.whole_frames == 0


def test_a_translucent_geom_outside_its_group_keeps_full_renders_and_says_why():
    model, data, option = _world(wall_alpha=0.5)
    with mujoco.Renderer(model, PX, PX) as renderer:
        assert layering_blocker(model, data, option, renderer.scene, GROUPS) == (
            "1 translucent geoms are outside the translucent group 3")
        layered = BackdropRenderer(renderer, model, "cam", option, GROUPS)
        np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
        assert not layered.layered


def test_layers_that_differ_on_the_first_frame_fall_back_to_full_renders(monkeypatch):
    """A difference no blocker foresaw (here a translucent wall the check is told to ignore) is caught by the
    first frame's comparison: that frame and every later one are full renders."""
    model, data, option = _world(wall_alpha=0.5)
    monkeypatch.setattr(rendering, "layering_blocker", lambda *a: None)
    with mujoco.Renderer(model, PX, PX) as renderer:
        layered = BackdropRenderer(renderer, model, "cam", option, GROUPS)
        _place(model, data, [-0.5, 0.6, 0.2])  # the ball behind the half-transparent wall
        np.testing.assert_array_equal(layered.render(data), _whole(renderer, data, option))
        assert not layered.layered
        assert layered.fallback_reason.startswith("the layers differed from a full render in ")


def test_shadows_multisampling_and_reflections_block_layering(world):
    model, data, option, renderer = world
    assert layering_blocker(model, data, option, renderer.scene, GROUPS) is None
    model.vis.quality.offsamples = 4
    assert "multisampling" in layering_blocker(model, data, option, renderer.scene, GROUPS)
    model.vis.quality.offsamples = 0
    model.mat_reflectance[0] = 0.5
    assert layering_blocker(model, data, option, renderer.scene, GROUPS) == "a material reflects"


def test_split_layers_groups_the_static_and_the_translucent_geoms():
    xml = """<mujoco><asset><material name="glass" rgba="1 1 1 0.3"/></asset><worldbody>
      <geom name="room" type="box" size="1 1 0.1"/><geom name="window" type="box" size="0.1 0.1 0.1" material="glass"/>
      <geom name="collision" type="box" size="0.1 0.1 0.1" group="0" rgba="1 1 1 0"/>
      <body name="moving"><freejoint/><geom name="held" type="sphere" size="0.1"/></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    split_layers(model, data, mujoco.MjvOption(), GROUPS)
    assert {model.geom(g).name: int(model.geom_group[g]) for g in range(model.ngeom)} == {
        "room": GROUPS.backdrop, "window": GROUPS.translucent, "collision": 0, "held": 0}
    with pytest.raises(ValueError, match=r"geom groups \[3, 4\] are in use already"):
        split_layers(model, data, mujoco.MjvOption(), GROUPS)


def test_bad_camera_or_a_hidden_layer_group_is_refused(world):
    model, _, option, renderer = world
    with pytest.raises(ValueError, match=r"camera 'top' is not in the model; its cameras: \['cam'\]"):
        BackdropRenderer(renderer, model, "top", option, GROUPS)
    with pytest.raises(ValueError, match=r"the render option hides layer groups \[4, 3\]"):
        BackdropRenderer(renderer, model, "cam", mujoco.MjvOption(), GROUPS)
