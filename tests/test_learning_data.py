"""Training frames from files whose demos carry their own camera (LIBERO): per-demo cameras, heights measured from
the camera, orientation labels in the camera frame; files with one camera (the workcell) read as before."""
import numpy as np
import pytest
from learning_synth import agentview_camera, make_demo_file

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.data.dataset import env_difference, open_demos
from tcot_hybrid.data.labels import TrajectoryWindowConfig
from tcot_hybrid.errors import ConfigError, DatasetError
from tcot_hybrid.learning.data import camera_rot6, height_reference, load_frames, quat_wxyz_to_matrix, tasks_of
from tcot_hybrid.learning.model import rot6_to_matrix
from tcot_hybrid.learning.validation import lift_frames
from tcot_hybrid.learning.vocab import Vocabulary

KW = dict(windows=TrajectoryWindowConfig(), max_tokens=16, direct_horizon=3)
VOCAB = Vocabulary.build(["put the cube on the plate", "open the drawer"])


@pytest.fixture(scope="module")
def camera():
    return agentview_camera()


def _raised(camera, dz):
    T = np.array(camera.T_world_cam)
    T[2, 3] += dz
    return CameraModel(name=camera.name, width=camera.width, height=camera.height, K=camera.K, T_world_cam=T,
                       near_m=camera.near_m, far_m=camera.far_m)


@pytest.fixture(scope="module")
def scenes_file(tmp_path_factory, camera):
    """Even seeds: the camera as is, table at 0; odd seeds: everything 0.9 m up (a LIBERO tabletop)."""
    up = _raised(camera, 0.9)
    path = tmp_path_factory.mktemp("scenes") / "scenes.hdf5"
    quat = {0: [0, 1, 0, 0], 1: [0.0, 0.9238795, 0.3826834, 0.0]}  # top-down, and turned 45 degrees about z
    make_demo_file(path, camera, seeds=range(6), camera_for=lambda s: (up, 0.9) if s % 2 else (camera, 0.0),
                   quat_for=lambda s: quat[s % 2])
    return path, up


def test_each_demo_has_its_own_camera_and_the_file_says_so(scenes_file, camera):
    path, up = scenes_file
    with open_demos(path) as f:
        assert f.camera_per_demo
        np.testing.assert_allclose(f.camera_model("demo_0").T_world_cam, camera.T_world_cam)
        np.testing.assert_allclose(f.camera_model("demo_1").T_world_cam, up.T_world_cam)
        with pytest.raises(DatasetError, match="no demo 'demo_99'"):
            f.camera_model("demo_99")
        env = dict(f.env_args)
    # two per-demo files agree whatever their first demo's camera; a per-file one never matches a per-demo one
    assert env_difference(env, {**env, "T_world_cam": up.T_world_cam.tolist()}, ("robot",)) is None
    assert "camera_per_demo" in env_difference(env, {**env, "camera_per_demo": False}, ("robot",))


def test_camera_heights_make_scenes_at_different_table_heights_alike(scenes_file):
    path, _ = scenes_file
    world = load_frames(path, "all", VOCAB, **KW)
    cam = load_frames(path, "all", VOCAB, height_ref="camera", **KW)
    assert len(world.cameras) == 2 and set(np.unique(world.cam)) == {0, 1}
    cam_z = np.array([c.T_world_cam[2, 3] for c in world.cameras])[world.cam]
    lo, hi = cam_z < cam_z.mean(), cam_z > cam_z.mean()
    assert lo.any() and hi.any()
    # world heights differ by the 0.9 m the scene moved; camera-relative heights do not
    assert abs(world.g_z[hi].mean() - world.g_z[lo].mean() - 0.9) < 0.05
    assert abs(cam.g_z[hi].mean() - cam.g_z[lo].mean()) < 0.05
    # lifting the labels back through each frame's own camera gives the recorded TCP points
    rows = np.arange(len(cam))
    pts = lift_frames(cam, rows, cam.g_uv.numpy(), cam.g_z.numpy())
    np.testing.assert_allclose(pts, cam.g_xyz.numpy(), atol=2e-4)


def test_orientation_labels_are_in_the_frames_camera(scenes_file, camera):
    path, up = scenes_file
    fs = load_frames(path, "all", VOCAB, height_ref="camera", **KW)
    for d, name in enumerate(fs.demos):
        seed = int(name.split("_")[1])  # demo_<i> holds seed i
        row = np.flatnonzero(fs.demo == d)[0]
        cam = fs.cameras[fs.cam[row]]
        np.testing.assert_allclose(cam.T_world_cam, (up if seed % 2 else camera).T_world_cam)
        R = cam.T_world_cam[:3, :3] @ rot6_to_matrix(fs.g_rot[row, 0].numpy().astype(float))
        q = [0, 1, 0, 0] if seed % 2 == 0 else [0.0, 0.9238795, 0.3826834, 0.0]
        np.testing.assert_allclose(R, quat_wxyz_to_matrix(np.array(q)), atol=1e-5)
    # the world's own axes seen from the camera: the rows of the camera's world rotation
    R_wc = camera.T_world_cam[:3, :3]
    np.testing.assert_allclose(camera_rot6(camera, np.eye(3)), np.r_[R_wc[0], R_wc[1]], atol=1e-6)


def test_single_camera_files_read_as_before(tmp_path, camera):
    path = tmp_path / "one.hdf5"
    make_demo_file(path, camera, seeds=range(3))
    with open_demos(path) as f:
        assert not f.camera_per_demo
        np.testing.assert_allclose(f.camera_model("demo_1").T_world_cam, camera.T_world_cam)
    fs = load_frames(path, "all", VOCAB, **KW)
    assert len(fs.cameras) == 1 and (fs.z_ref == 0).all()
    assert height_reference(camera, "world") == 0.0
    assert height_reference(camera, "camera") == pytest.approx(camera.T_world_cam[2, 3])
    with pytest.raises(ConfigError, match="height_ref = 'table' is not one of world, camera"):
        height_reference(camera, "table")


def test_per_demo_file_without_a_demo_camera_is_refused(tmp_path, camera):
    import h5py

    path = tmp_path / "broken.hdf5"
    make_demo_file(path, camera, seeds=range(2), camera_for=lambda s: (camera, 0.0))
    with h5py.File(path, "a") as h5:
        del h5["data/demo_1"].attrs["T_world_cam"]
    with pytest.raises(DatasetError, match=r"demo_1 lacks attribute\(s\) \['T_world_cam'\]"):
        open_demos(path)


def test_suites_keep_only_their_demos_and_a_missing_suite_is_named(tmp_path, camera):
    path = tmp_path / "two_suites.hdf5"
    make_demo_file(path, camera, seeds=range(12), episode=lambda s: {"suite": "libero_10" if s % 3 else "libero_goal"})
    every = load_frames(path, "all", VOCAB, **KW)
    long_only = load_frames(path, "all", VOCAB, suites=("libero_10",), **KW)
    with open_demos(path) as f:
        want = sorted(n for n in f.mask("train") + f.mask("valid") if f.info(n).suite == "libero_10")
    assert sorted(long_only.demos) == want and 0 < len(want) < len(every.demos)
    assert sorted(load_frames(path, "all", VOCAB, suites=("libero_10", "libero_goal"), **KW).demos) == sorted(every.demos)
    with pytest.raises(DatasetError, match=r"\['libero_spatial'\].*\['libero_10', 'libero_goal'\]"):
        load_frames(path, "train", VOCAB, suites=("libero_spatial",), **KW)


def test_exclude_tasks_leaves_out_only_their_demos(tmp_path, camera):
    path = tmp_path / "two_tasks.hdf5"
    make_demo_file(path, camera, seeds=range(12), episode=lambda s: {"task": "libero_object:ketchup" if s % 3 else
                                                                      "libero_object:milk"})
    assert tasks_of(path) == {"libero_object:ketchup", "libero_object:milk"}
    every = load_frames(path, "all", VOCAB, **KW)
    kept = load_frames(path, "all", VOCAB, exclude_tasks=frozenset({"libero_object:ketchup"}), **KW)
    with open_demos(path) as f:
        want = sorted(n for n in f.mask("train") + f.mask("valid") if f.info(n).task == "libero_object:milk")
    assert sorted(kept.demos) == want and 0 < len(want) < len(every.demos)
    assert sorted(load_frames(path, "all", VOCAB, exclude_tasks=frozenset({"other"}), **KW).demos) == sorted(every.demos)
