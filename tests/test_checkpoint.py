"""Checkpoints: safetensors + JSON round trip, and every hostile or mismatched file refused with
CheckpointError before anything in it could run (RELIABILITY rows 19 and 21)."""
import json
import os
import pickle
import struct

import numpy as np
import pytest
import torch
from learning_synth import agentview_camera
from safetensors.torch import load as st_load
from safetensors.torch import save as st_save

from tcot_hybrid.camera import CameraModel
from tcot_hybrid.errors import CheckpointError
from tcot_hybrid.learning.checkpoint import (
    camera_meta,
    default_checkpoint,
    load_checkpoint,
    meta_path,
    read_safetensors_header,
    save_checkpoint,
    sha256_bytes,
    stamp_metadata,
    versions,
)
from tcot_hybrid.learning.model import ModelConfig, PlannerNet
from tcot_hybrid.learning.vocab import Vocabulary

VOCAB = Vocabulary.build(["put the cube on the plate"])


@pytest.fixture(scope="module")
def camera():
    return agentview_camera()


def _meta(camera, robot="panda"):
    return {"robot": robot, "camera": camera_meta(camera), "vocabulary": list(VOCAB.tokens),
            "windows": {"L_g": 51, "n_g": 4, "L_l": 8, "n_l": 2}, "data_hash": "test", "metrics": {},
            "versions": versions()}


def _model(kind="trajectory", width=8):
    torch.manual_seed(0)
    return PlannerNet(ModelConfig(kind=kind, width=width, vocab_size=len(VOCAB))).eval()


@pytest.fixture()
def ckpt(tmp_path, camera):
    path = tmp_path / "planner.safetensors"
    save_checkpoint(path, _model(), _meta(camera))
    return path


def _inputs(b=2):
    g = torch.Generator().manual_seed(1)
    return (torch.rand(b, 3, 128, 128, generator=g), torch.tensor([[2, 3, 4, 0]] * b), torch.tensor([0, 1][:b]),
            torch.rand(b, 8, generator=g))


def _rewrite(path, state=None, blob=None, meta_update=None):
    """Replace the weights (and fix the recorded hashes so only the intended fault remains)."""
    if blob is None:
        blob = st_save(state)
    path.write_bytes(blob)
    meta = json.loads(meta_path(path).read_text())
    meta["weights_sha256"] = sha256_bytes(blob)
    meta.update(meta_update or {})
    meta_path(path).write_text(json.dumps(stamp_metadata(meta)))


def test_round_trip_gives_identical_outputs(tmp_path, camera):
    model = _model()
    path = save_checkpoint(tmp_path / "a.safetensors", model, _meta(camera))
    ck = load_checkpoint(path, robot="panda", camera=camera, kind="trajectory")
    x = _inputs()
    with torch.inference_mode():
        a, b = model(*x), ck.model(*x)
    for k in ("uv_px", "z_m", "grip_logit", "success_logit"):
        assert torch.equal(a[k], b[k]), k
    meta = json.loads(meta_path(path).read_text())
    for key in ("model", "robot", "camera", "vocabulary", "windows", "data_hash", "metrics", "versions",
                "weights_sha256"):
        assert key in meta
    assert meta["camera"]["K"] == camera.K.tolist() and meta["camera"]["width"] == 128


def _pickle_bomb(marker):
    class Boom:
        def __reduce__(self):
            return (open, (str(marker), "w"))
    return pickle.dumps({"weights": Boom()})


@pytest.mark.parametrize("suffix", [".safetensors", ".pt", ".pth", ".ckpt"])
def test_pickle_payload_refused_and_never_executed(tmp_path, ckpt, suffix):
    marker = tmp_path / "PWNED"
    bomb = _pickle_bomb(marker)
    target = tmp_path / f"evil{suffix}"
    target.write_bytes(bomb)
    meta_path(target).write_text(meta_path(ckpt).read_text())
    with pytest.raises(CheckpointError, match="pickle|only .safetensors"):
        load_checkpoint(target)
    assert not marker.exists()


def test_torch_save_zip_renamed_refused(tmp_path, ckpt):
    target = tmp_path / "zip.safetensors"
    torch.save(_model().state_dict(), target)  # zip + pickle inside
    meta_path(target).write_text(meta_path(ckpt).read_text())
    with pytest.raises(CheckpointError, match="zip archive"):
        load_checkpoint(target)


def test_truncated_and_garbage_refused(tmp_path, ckpt):
    blob = ckpt.read_bytes()
    for n in (0, 5, 8, 100, len(blob) // 2, len(blob) - 1):
        ckpt.write_bytes(blob[:n])
        with pytest.raises(CheckpointError):
            load_checkpoint(ckpt)
    ckpt.write_bytes(blob + b"\0" * 16)
    with pytest.raises(CheckpointError, match="trailing|truncated"):
        load_checkpoint(ckpt)
    ckpt.write_bytes(struct.pack("<Q", 10**12) + blob[8:])
    with pytest.raises(CheckpointError, match="header length"):
        load_checkpoint(ckpt)


def test_fuzzed_files_all_refused_nothing_executed(tmp_path, ckpt):
    """RELIABILITY #19: >= 50 hostile files, 100 % refused."""
    rng = np.random.default_rng(0)
    blob = bytearray(ckpt.read_bytes())
    marker = tmp_path / "PWNED"
    variants = [bytes(_pickle_bomb(marker))]
    for _ in range(60):
        b = bytearray(blob)
        kind = rng.integers(4)
        if kind == 0:  # cut
            b = b[: int(rng.integers(0, len(b)))]
        elif kind == 1:  # flip bytes anywhere (header or data)
            for i in rng.integers(0, len(b), size=int(rng.integers(1, 8))):
                b[i] ^= int(rng.integers(1, 256))
        elif kind == 2:  # random bytes of the same length
            b = bytearray(rng.integers(0, 256, size=len(b), dtype=np.uint8).tobytes())
        else:  # pickle payload after a plausible header
            b = b[:8] + bytearray(_pickle_bomb(marker))
        variants.append(bytes(b))
    refused = 0
    for i, v in enumerate(variants):
        p = tmp_path / f"f{i}.safetensors"
        p.write_bytes(v)
        meta_path(p).write_text(meta_path(ckpt).read_text())
        with pytest.raises(CheckpointError):
            load_checkpoint(p, robot="panda")
        refused += 1
    print(f"hostile checkpoints refused: {refused}/{len(variants)}")
    assert refused == len(variants) >= 50
    assert not marker.exists()


def test_nan_weights_refused(ckpt):
    state = st_load(ckpt.read_bytes())
    state["stem.weight"][0, 0, 0, 0] = float("nan")
    _rewrite(ckpt, state)
    with pytest.raises(CheckpointError, match="stem.weight.*NaN"):
        load_checkpoint(ckpt)


def test_inf_weights_refused(ckpt):
    state = st_load(ckpt.read_bytes())
    state["maps.bias"][0] = float("inf")
    _rewrite(ckpt, state)
    with pytest.raises(CheckpointError, match="NaN or inf"):
        load_checkpoint(ckpt)


def test_wrong_shape_missing_and_extra_keys_refused(ckpt):
    good = st_load(ckpt.read_bytes())
    state = dict(good)
    state["maps.weight"] = torch.zeros(3, 3, 1, 1)
    _rewrite(ckpt, state)
    with pytest.raises(CheckpointError, match="maps.weight.*shape"):
        load_checkpoint(ckpt)
    state = dict(good)
    del state["stem.bias"]
    _rewrite(ckpt, state)
    with pytest.raises(CheckpointError, match="missing.*stem.bias"):
        load_checkpoint(ckpt)
    state = dict(good)
    state["evil"] = torch.zeros(1)
    _rewrite(ckpt, state)
    with pytest.raises(CheckpointError, match="unexpected.*evil"):
        load_checkpoint(ckpt)


def test_weights_not_matching_metadata_refused(ckpt):
    state = st_load(ckpt.read_bytes())
    state["stem.bias"] += 1.0
    ckpt.write_bytes(st_save(state))  # hash not updated
    with pytest.raises(CheckpointError, match="SHA-256"):
        load_checkpoint(ckpt)


def test_metadata_missing_or_malformed_refused(ckpt):
    mp = meta_path(ckpt)
    text = mp.read_text()
    mp.write_text("{not json")
    with pytest.raises(CheckpointError, match="not valid JSON"):
        load_checkpoint(ckpt)
    meta = json.loads(text)
    del meta["robot"]
    mp.write_text(json.dumps(stamp_metadata(meta)))
    with pytest.raises(CheckpointError, match="lacks"):
        load_checkpoint(ckpt)
    meta = json.loads(text)
    meta["model"]["width"] = -3
    mp.write_text(json.dumps(stamp_metadata(meta)))
    with pytest.raises(CheckpointError, match="model config"):
        load_checkpoint(ckpt)
    for key, bad in (("global_spacing", "event"), ("segment_points", "corner"), ("local_path", "command")):
        meta = json.loads(text)
        meta["windows"].update({"global_spacing": "events", "points_per_segment": 6, key: bad})
        mp.write_text(json.dumps(stamp_metadata(meta)))
        with pytest.raises(CheckpointError, match=f"windows.{key} must be one of .*, got '{bad}'"):
            load_checkpoint(ckpt)
    mp.unlink()
    with pytest.raises(CheckpointError, match="no metadata"):
        load_checkpoint(ckpt)


def test_other_robot_camera_image_size_or_kind_refused(ckpt, camera):
    with pytest.raises(CheckpointError, match="robot 'panda'.*'ur5e'"):
        load_checkpoint(ckpt, robot="ur5e", camera=camera)
    moved = np.array(camera.T_world_cam)
    moved[0, 3] += 0.05
    other = CameraModel(name=camera.name, width=128, height=128, K=camera.K, T_world_cam=moved,
                        near_m=camera.near_m, far_m=camera.far_m)
    with pytest.raises(CheckpointError, match="T_world_cam"):
        load_checkpoint(ckpt, robot="panda", camera=other)
    K = np.array(camera.K)
    K[0, 0] *= 1.1
    other = CameraModel(name=camera.name, width=128, height=128, K=K, T_world_cam=camera.T_world_cam,
                        near_m=camera.near_m, far_m=camera.far_m)
    with pytest.raises(CheckpointError, match="K"):
        load_checkpoint(ckpt, camera=other)
    other = CameraModel(name=camera.name, width=96, height=96, K=camera.K, T_world_cam=camera.T_world_cam,
                        near_m=camera.near_m, far_m=camera.far_m)
    with pytest.raises(CheckpointError, match="128x128 px.*96x96"):
        load_checkpoint(ckpt, camera=other)
    other = CameraModel(name="sideview", width=128, height=128, K=camera.K, T_world_cam=camera.T_world_cam,
                        near_m=camera.near_m, far_m=camera.far_m)
    with pytest.raises(CheckpointError, match="sideview"):
        load_checkpoint(ckpt, camera=other)
    with pytest.raises(CheckpointError, match="'direct'"):
        load_checkpoint(ckpt, kind="direct")


def test_header_parser_accepts_real_files(ckpt):
    header = read_safetensors_header(ckpt.read_bytes(), "x")
    assert "stem.weight" in header


def test_missing_default_checkpoint_names_robot():
    with pytest.raises(CheckpointError, match="robot 'ur5e'.*tcot train"):
        default_checkpoint("ur5e")


def test_nonexistent_file(tmp_path):
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "nope.safetensors")
    assert not os.path.exists(tmp_path / "nope.safetensors")


def test_checkpoint_records_its_world_and_is_refused_in_another(tmp_path, camera):
    """A LIBERO checkpoint is refused on a workcell task and the other way round, before the robot is compared,
    with a message naming both worlds; checkpoints saved before the field existed are workcell ones."""
    lib = tmp_path / "libero.safetensors"
    save_checkpoint(lib, _model(), {**_meta(camera), "world": "libero"})
    assert json.loads(meta_path(lib).read_text())["world"] == "libero"
    load_checkpoint(lib, world="libero")
    with pytest.raises(CheckpointError, match="trained in the 'libero' world.*task is in the 'workcell' world"):
        load_checkpoint(lib, robot="panda", camera=camera, world="workcell")
    old = tmp_path / "old.safetensors"
    save_checkpoint(old, _model(), _meta(camera))  # no "world": the workcell
    load_checkpoint(old, world="workcell")
    with pytest.raises(CheckpointError, match="'workcell' world.*'libero' world.*worlds: workcell, libero"):
        load_checkpoint(old, world="libero")
    _rewrite(old, blob=old.read_bytes(), meta_update={"world": "mars"})
    with pytest.raises(CheckpointError, match="world must be one of workcell, libero"):
        load_checkpoint(old)
    _rewrite(old, blob=old.read_bytes(), meta_update={"world": "workcell", "height_ref": "sky"})
    with pytest.raises(CheckpointError, match="height_ref must be one of world, camera"):
        load_checkpoint(old)


def test_per_scene_camera_checkpoint_accepts_other_poses_but_not_other_cameras(tmp_path, camera):
    """Trained on several scenes' camera poses (LIBERO's agentview takes four), a checkpoint is checked on the
    camera's name and image size only; a per-file one still needs the exact pose."""
    path = tmp_path / "scenes.safetensors"
    cam = {**camera_meta(camera), "per_scene": True}
    save_checkpoint(path, _model(), {**_meta(camera), "camera": cam, "world": "libero"})
    moved = np.array(camera.T_world_cam)
    moved[:3, 3] += (0.3, 0.0, -0.9)
    other = CameraModel(name=camera.name, width=128, height=128, K=camera.K, T_world_cam=moved,
                        near_m=camera.near_m, far_m=camera.far_m)
    load_checkpoint(path, camera=other)
    small = CameraModel(name=camera.name, width=96, height=96, K=camera.K, T_world_cam=moved,
                        near_m=camera.near_m, far_m=camera.far_m)
    with pytest.raises(CheckpointError, match="128x128 px.*96x96"):
        load_checkpoint(path, camera=small)
    _rewrite(path, blob=path.read_bytes(), meta_update={"camera": {**cam, "per_scene": "yes"}})
    with pytest.raises(CheckpointError, match="camera.per_scene must be true or false"):
        load_checkpoint(path)


def test_libero_robot_without_a_shipped_checkpoint_points_to_make_libero_planner(tmp_path, monkeypatch):
    import tcot_hybrid.learning.checkpoint as ck

    monkeypatch.setattr(ck, "checkpoints_dir", lambda: tmp_path)
    with pytest.raises(CheckpointError, match="libero_panda.*make libero-planner"):
        default_checkpoint("libero_panda")


def test_a_suite_with_its_own_shipped_model_gets_it_and_the_others_the_default(tmp_path, monkeypatch):
    """The paper's TCoT row is one model per suite: a task of a suite that ships ``<robot>_<suite>`` loads it, any
    other suite (or none) the robot's default; an explicit --checkpoint wins over both."""
    import tcot_hybrid.learning.checkpoint as ck
    from tcot_hybrid.planners import planner_checkpoint

    monkeypatch.setattr(ck, "checkpoints_dir", lambda: tmp_path)
    for stem in ("libero_panda_default", "libero_panda_libero_10", "libero_panda_direct_default"):
        (tmp_path / f"{stem}.safetensors").write_bytes(b"")
    assert default_checkpoint("libero_panda", suite="libero_10").name == "libero_panda_libero_10.safetensors"
    assert default_checkpoint("libero_panda", suite="libero_goal").name == "libero_panda_default.safetensors"
    assert default_checkpoint("libero_panda").name == "libero_panda_default.safetensors"
    assert default_checkpoint("libero_panda", "direct", suite="libero_10").name == \
        "libero_panda_direct_default.safetensors"
    assert planner_checkpoint("learned", "libero_panda", None, suite="libero_10").name == \
        "libero_panda_libero_10.safetensors"
    assert planner_checkpoint("learned", "libero_panda", tmp_path / "mine.safetensors", suite="libero_10") == \
        tmp_path / "mine.safetensors"
    assert planner_checkpoint("oracle", "libero_panda", None, suite="libero_10") is None


def test_a_task_routed_to_another_shipped_model_gets_it_and_a_route_to_nothing_is_refused(tmp_path, monkeypatch):
    """task_models.json routes a task to a shipped model other than its suite's (trajectory planners only): that task
    loads it, its suite's other tasks keep the suite's model, --checkpoint still wins; a route to a checkpoint that
    is not shipped is refused naming the task and the shipped ones."""
    import tcot_hybrid.learning.checkpoint as ck
    from tcot_hybrid.planners import planner_checkpoint

    monkeypatch.setattr(ck, "checkpoints_dir", lambda: tmp_path)
    for stem in ("libero_panda_default", "libero_panda_libero_10", "libero_panda_direct_default"):
        (tmp_path / f"{stem}.safetensors").write_bytes(b"")
    routed = "libero_10:KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it"
    (tmp_path / ck.TASK_MODELS_FILE).write_text(json.dumps({"routes": {"libero_panda": {routed: "libero_panda_default"}}}))
    assert default_checkpoint("libero_panda", suite="libero_10", task=routed).name == "libero_panda_default.safetensors"
    assert default_checkpoint("libero_panda", suite="libero_10", task="libero_10:other").name == \
        "libero_panda_libero_10.safetensors"
    assert default_checkpoint("libero_panda", "direct", suite="libero_10", task=routed).name == \
        "libero_panda_direct_default.safetensors"
    assert planner_checkpoint("learned", "libero_panda", None, suite="libero_10", task=routed).name == \
        "libero_panda_default.safetensors"
    assert planner_checkpoint("learned", "libero_panda", tmp_path / "mine.safetensors", suite="libero_10",
                              task=routed) == tmp_path / "mine.safetensors"
    (tmp_path / ck.TASK_MODELS_FILE).write_text(json.dumps({"routes": {"libero_panda": {routed: "libero_panda_v99"}}}))
    with pytest.raises(CheckpointError, match="KITCHEN_SCENE3.*'libero_panda_v99'.*not shipped.*libero_panda_default"):
        default_checkpoint("libero_panda", suite="libero_10", task=routed)
    (tmp_path / ck.TASK_MODELS_FILE).write_text("{not json")
    with pytest.raises(CheckpointError, match="not a task-model table"):
        default_checkpoint("libero_panda", suite="libero_10", task=routed)
    (tmp_path / ck.TASK_MODELS_FILE).write_text(json.dumps({"routes": {"libero_panda": {routed: 3}}}))
    with pytest.raises(CheckpointError, match="must map task names to checkpoint stems"):
        default_checkpoint("libero_panda", suite="libero_10", task=routed)


def suite_models() -> list:
    """The shipped LIBERO suite models (``libero_panda_<suite>``; not the defaults, not a direct planner's)."""
    from tcot_hybrid.learning.checkpoint import checkpoints_dir

    return sorted(p for p in checkpoints_dir().glob("libero_panda_*.safetensors")
                  if not p.stem.endswith("default") and "_direct_" not in p.stem and "_tasks_" not in p.stem)


def test_every_shipped_task_model_is_routed_to_and_made_for_the_suites_of_its_tasks():
    """A ``libero_panda_tasks_<name>`` checkpoint is shipped for the tasks task_models.json routes to it alone (no
    suite loads it by default): some task must be routed to it, and it must be a small LIBERO trajectory checkpoint
    trained on those tasks' suites."""
    from tcot_hybrid.learning.checkpoint import checkpoints_dir, task_models
    from tcot_hybrid.robot import load_robot_spec

    routes = task_models("libero_panda")
    for p in sorted(checkpoints_dir().glob("libero_panda_tasks_*.safetensors")):
        tasks = [t for t, stem in routes.items() if stem == p.stem]
        assert tasks, f"{p.name} is shipped but no task is routed to it"
        assert p.stat().st_size < 10e6
        ck = load_checkpoint(p, robot_spec=load_robot_spec("libero_panda"), kind="trajectory", world="libero")
        assert ck.meta["height_ref"] == "camera" and ck.model.cfg.rot_head
        assert {t.split(":")[0] for t in tasks} <= set(ck.meta["train_config"]["suites"]), p.name


def test_every_shipped_suite_model_was_trained_on_that_suite_alone():
    """A shipped ``libero_panda_<suite>`` is what tasks of <suite> load by default: its training config must name
    that suite and no other (the file name is the only link between the two)."""
    own = suite_models()
    assert own, "no suite model is shipped"
    for p in own:
        suite = p.stem.removeprefix("libero_panda_")
        assert json.loads(meta_path(p).read_text())["train_config"]["suites"] == [suite], p.name


@pytest.mark.parametrize("suite", [None, *(p.stem.removeprefix("libero_panda_") for p in suite_models())])
def test_shipped_libero_checkpoint_is_small_and_made_for_libero(suite):
    """`--planner learned` on a LIBERO task loads its suite's model or the libero_panda default: each a LIBERO
    checkpoint (world, per-scene camera, heights from the camera, a rotation head) for the bundled libero_panda's
    model, under 10 MB."""
    from tcot_hybrid.robot import load_robot_spec

    path = default_checkpoint("libero_panda", suite=suite)
    assert path.stem == (f"libero_panda_{suite}" if suite else "libero_panda_default")
    assert path.stat().st_size < 10e6
    ck = load_checkpoint(path, robot_spec=load_robot_spec("libero_panda"), kind="trajectory", world="libero")
    assert ck.meta["camera"]["per_scene"] and ck.meta["height_ref"] == "camera" and ck.model.cfg.rot_head
    with pytest.raises(CheckpointError, match="'libero' world"):
        load_checkpoint(path, world="workcell")
