import os

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.scene import CAMERAS, SceneConfig, build_workcell, look_at_xyaxes


def test_look_at_axes_are_orthonormal_and_point_at_target():
    pos, target = np.array([1.0, 0.0, 1.0]), np.array([0.5, 0.0, 0.0])
    x, y = look_at_xyaxes(pos, target).reshape(2, 3)
    z = np.cross(x, y)  # MuJoCo cameras look along -z
    assert np.allclose([x @ x, y @ y, x @ y], [1, 1, 0])
    assert np.allclose(-z, (target - pos) / np.linalg.norm(target - pos))


def test_cameras_see_the_workspace_and_render_fast_settings():
    spec = mujoco.MjSpec.from_string("<mujoco><worldbody/></mujoco>")
    build_workcell(spec, config=SceneConfig(), sim_dt=0.002)
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    assert m.vis.quality.shadowsize == 0 and m.vis.quality.offsamples == 0
    corners = np.array([[x, y, 0.0] for x in (0.3, 0.65) for y in (-0.25, 0.25)])
    for name in CAMERAS:
        cam = CameraModel.from_mujoco(m, d, name, width=128, height=128)
        uv, depth = cam.project(corners)
        assert cam.in_image(uv).all() and (depth > 0).all(), name
