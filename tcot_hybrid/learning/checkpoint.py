"""Planner checkpoints: safetensors weights + a JSON metadata file next to them. Never pickle.

``<name>.safetensors`` holds only tensors; ``<name>.json`` holds everything else (model config, robot,
planner camera with K / T_world_cam / image size, vocabulary, label windows, training data hash,
metrics, versions and the weights' SHA-256). Loading is validation first: nothing in either file is
ever executed (the header and the metadata are parsed with ``json``; tensors are copied out of the
byte buffer by ``safetensors``), and every problem is a :class:`CheckpointError` saying what is wrong:

* not a safetensors file (``.pt``/``.pth``/``.ckpt``, pickle or zip payloads, even when renamed),
* truncated or corrupt bytes, header offsets outside the file, unknown dtypes,
* weights that do not match their metadata (hash), NaN/inf values, missing/unexpected keys, wrong shapes,
* metadata that is not what was saved (``metadata_sha256``, a digest over every other metadata field,
  so a relabelled robot or camera is refused), malformed metadata (wrong types, nesting, size),
* a checkpoint made for another world (``world``: ``workcell`` or ``libero``; checkpoints written before the
  field existed are workcell ones), robot model (matched by :func:`tcot_hybrid.robot.robot_model_digest`, not
  by name), joint count, planner camera (name, K, pose; a checkpoint trained on several scenes' cameras,
  ``camera.per_scene``, only name and image size) or image size than the run, or for another planner kind
  (trajectory vs direct).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import platform
import struct
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from tcot_hybrid.errors import CheckpointError, ConfigError, short_repr
from tcot_hybrid.data.labels import WINDOW_CHOICES
from tcot_hybrid.jsonio import json_default as _json_default

FORMAT = "tcot-planner-v1"
SUFFIX = ".safetensors"
MAX_HEADER_BYTES = 16 * 1024 * 1024
MAX_FILE_BYTES = 512 * 1024 * 1024
_ALLOWED_DTYPES = {"F32": 4, "F16": 2, "BF16": 2, "I64": 8}
REQUIRED_META = ("format", "kind", "model", "robot", "robot_model_digest", "camera", "vocabulary", "windows",
                 "weights_sha256", "data_hash", "metrics", "versions", "metadata_sha256")
MAX_META_BYTES = 4 * 1024 * 1024  # the shipped metadata is ~5 kB
# What pickle / torch.save / numpy archives start with: refused with a message saying so.
_PICKLE_MAGIC = (b"\x80\x02", b"\x80\x03", b"\x80\x04", b"\x80\x05")
_ZIP_MAGIC = b"PK\x03\x04"
CAMERA_ATOL = {"K": 1e-6, "T_world_cam": 1e-6}
WORLDS = ("workcell", "libero")
HEIGHT_REFS = ("world", "camera")


def checkpoint_world(meta: dict) -> str:
    """The world a checkpoint was trained in (metadata written before ``world`` existed: the workcell)."""
    return meta.get("world", "workcell")


class Checkpoint(NamedTuple):
    """A loaded, validated checkpoint: the network (eval mode) and its metadata."""

    model: Any  # PlannerNet
    meta: dict
    path: Path


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def meta_path(path: str | Path) -> Path:
    """The metadata file that belongs to weights file ``path`` (same stem, ``.json``)."""
    return Path(path).with_suffix(".json")


def camera_meta(camera) -> dict:
    """Planner camera fields stored in (and checked against) a checkpoint."""
    return {"name": camera.name, "width": int(camera.width), "height": int(camera.height),
            "K": np.asarray(camera.K).tolist(), "T_world_cam": np.asarray(camera.T_world_cam).tolist()}


def metadata_digest(meta: dict) -> str:
    """SHA-256 over every metadata field but ``metadata_sha256`` itself (canonical JSON, sorted keys)."""
    body = {k: v for k, v in meta.items() if k != "metadata_sha256"}
    return sha256_bytes(json.dumps(body, sort_keys=True, separators=(",", ":"), default=_json_default).encode())


def stamp_metadata(meta: dict) -> dict:
    """``meta`` as JSON will store it (numpy values converted), with its ``metadata_sha256`` (re)computed."""
    plain = json.loads(json.dumps({k: v for k, v in meta.items() if k != "metadata_sha256"}, default=_json_default))
    plain["metadata_sha256"] = metadata_digest(plain)
    return plain


def versions() -> dict:
    import safetensors
    import torch

    from tcot_hybrid import __version__

    return {"tcot_hybrid": __version__, "torch": torch.__version__, "safetensors": safetensors.__version__,
            "numpy": np.__version__, "python": platform.python_version()}


# --- saving ---------------------------------------------------------------------------------------------

def save_checkpoint(path: str | Path, model, meta: dict) -> Path:
    """Write ``model``'s weights to ``path`` (.safetensors) and ``meta`` (+ model config, hash) next to it."""
    from safetensors.torch import save

    p = Path(path)
    if p.suffix != SUFFIX:
        raise CheckpointError(f"checkpoint path must end in {SUFFIX}, got {str(p)!r}")
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()
             if not k.endswith("num_batches_tracked")}
    for k, v in state.items():
        if v.is_floating_point():
            state[k] = v.float()
            if not bool(np.isfinite(state[k].numpy()).all()):
                raise CheckpointError(f"refusing to save: tensor {k!r} has non-finite values")
    blob = save(state)
    full = dict(meta)
    full.update(format=FORMAT, kind=model.cfg.kind, model=dataclasses.asdict(model.cfg),
                weights_sha256=sha256_bytes(blob))
    if "robot_model_digest" not in full and isinstance(full.get("robot"), str):
        from tcot_hybrid.robot import load_robot_spec, robot_model_digest

        full["robot_model_digest"] = robot_model_digest(load_robot_spec(full["robot"]))
    full = stamp_metadata(full)
    missing = [k for k in REQUIRED_META if k not in full]
    if missing:
        raise CheckpointError(f"checkpoint metadata lacks {missing}")
    from tcot_hybrid.jsonio import atomic_write_bytes, atomic_write_text

    p.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(p, blob)  # each file is replaced whole; weights and metadata are tied by weights_sha256
    atomic_write_text(meta_path(p), json.dumps(full, indent=1, default=_json_default) + "\n")
    return p



# --- validation -----------------------------------------------------------------------------------------

def read_safetensors_header(blob: bytes, where: str) -> dict:
    """Parse and check the safetensors header of ``blob`` without touching tensor data.

    Refuses pickle/zip payloads, header sizes outside the file, non-JSON headers, unknown dtypes,
    offsets that do not match shapes or fall outside the file, and files with missing or extra bytes.
    """
    if blob[:2] in _PICKLE_MAGIC:
        raise CheckpointError(f"{where} is a Python pickle (torch.save / .pt format), not safetensors; "
                              f"pickled checkpoints are refused because loading them can run code")
    if blob[:4] == _ZIP_MAGIC:
        raise CheckpointError(f"{where} is a zip archive (torch.save .pt/.pth format, contains a pickle), "
                              f"not safetensors; refused")
    if len(blob) < 8:
        raise CheckpointError(f"{where} is {len(blob)} bytes; too short to be a safetensors file (truncated?)")
    (n,) = struct.unpack("<Q", blob[:8])
    if n < 2 or n > MAX_HEADER_BYTES or 8 + n > len(blob):
        raise CheckpointError(f"{where}: safetensors header length {n} is impossible for a {len(blob)}-byte "
                              f"file (not a safetensors file, or truncated)")
    raw = blob[8:8 + n]
    if raw[:1] != b"{":
        raise CheckpointError(f"{where}: safetensors header does not start with '{{' (not a safetensors file)")
    try:
        header = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"{where}: safetensors header is not valid JSON ({exc}); file corrupt") from exc
    if not isinstance(header, dict):
        raise CheckpointError(f"{where}: safetensors header is not a JSON object")
    data_len = len(blob) - 8 - n
    end_max = 0
    spans = []
    for name, entry in header.items():
        if name == "__metadata__":
            continue
        if not isinstance(entry, dict) or set(entry) != {"dtype", "shape", "data_offsets"}:
            raise CheckpointError(f"{where}: header entry {name!r} is malformed: {entry!r}")
        dtype, shape, offs = entry["dtype"], entry["shape"], entry["data_offsets"]
        if dtype not in _ALLOWED_DTYPES:
            raise CheckpointError(f"{where}: tensor {name!r} has dtype {dtype!r}; allowed: "
                                  f"{', '.join(_ALLOWED_DTYPES)}")
        if (not isinstance(shape, list) or not all(isinstance(s, int) and s >= 0 for s in shape)
                or not isinstance(offs, list) or len(offs) != 2 or not all(isinstance(o, int) for o in offs)):
            raise CheckpointError(f"{where}: tensor {name!r} has a malformed shape {shape!r} or offsets {offs!r}")
        begin, end = offs
        if not 0 <= begin <= end or end - begin != math.prod(shape) * _ALLOWED_DTYPES[dtype]:
            raise CheckpointError(f"{where}: tensor {name!r} offsets {offs} do not match shape {shape} ({dtype})")
        if end > data_len:
            raise CheckpointError(f"{where}: tensor {name!r} ends at byte {end} but the file holds only "
                                  f"{data_len} data bytes (truncated)")
        spans.append((begin, end))
        end_max = max(end_max, end)
    if end_max != data_len:
        raise CheckpointError(f"{where}: {data_len} data bytes but the tensors use {end_max} "
                              f"(truncated or trailing garbage)")
    spans.sort()
    for (b0, e0), (b1, _) in zip(spans, spans[1:]):
        if b1 < e0:
            raise CheckpointError(f"{where}: tensor data regions overlap (corrupt header)")
    return header


def _read_weights(path: Path) -> tuple[bytes, dict]:
    if path.suffix != SUFFIX:
        raise CheckpointError(
            f"checkpoint {str(path)!r}: only {SUFFIX} weights are loaded (with a .json metadata file next to "
            f"them); {path.suffix or 'extension-less'} files such as .pt/.pth/.ckpt are pickles and are refused")
    if not path.is_file():
        raise CheckpointError(f"checkpoint {str(path)!r} does not exist")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise CheckpointError(f"checkpoint {str(path)!r} is {size} bytes; refusing files over {MAX_FILE_BYTES}")
    blob = path.read_bytes()
    header = read_safetensors_header(blob, f"checkpoint {str(path)!r}")
    return blob, header


def _read_meta(path: Path) -> dict:
    mp = meta_path(path)
    where = f"checkpoint metadata {str(mp)!r}"
    if not mp.is_file():
        raise CheckpointError(f"checkpoint {str(path)!r} has no metadata file {str(mp)!r} next to it")
    size = mp.stat().st_size
    if size > MAX_META_BYTES:
        raise CheckpointError(f"{where} is {size} bytes; refusing metadata over {MAX_META_BYTES} bytes")
    try:
        meta = json.loads(mp.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"{where} is not valid JSON ({exc})") from exc
    except RecursionError as exc:
        raise CheckpointError(f"{where} is nested too deep to be checkpoint metadata") from exc
    if not isinstance(meta, dict):
        raise CheckpointError(f"{where} is not a JSON object")
    missing = [k for k in REQUIRED_META if k not in meta]
    if missing:
        hint = (" (saved before metadata was hashed: re-save it with save_checkpoint)"
                if missing in (["metadata_sha256"], ["robot_model_digest", "metadata_sha256"]) else "")
        raise CheckpointError(f"{where} lacks {missing}{hint}")
    if meta["format"] != FORMAT:
        raise CheckpointError(f"{where} has format {short_repr(meta['format'])}, expected {FORMAT!r}")
    try:
        digest = metadata_digest(meta)
    except (RecursionError, ValueError, TypeError) as exc:
        raise CheckpointError(f"{where} cannot be hashed ({type(exc).__name__}); corrupt") from exc
    if meta["metadata_sha256"] != digest:
        raise CheckpointError(f"{where} does not match its metadata_sha256: the metadata was edited after saving "
                              f"(e.g. relabelled for another robot or camera) or is corrupt; refused")
    _check_meta_types(meta, where)
    return meta


def _check_meta_types(meta: dict, where: str) -> None:
    """Every field the loader and the planners read has the type they expect (a CheckpointError, never an
    AttributeError/ValueError deep inside a planner)."""
    def bad(key: str, want: str) -> CheckpointError:
        return CheckpointError(f"{where}: {key} must be {want}, got {short_repr(meta.get(key))}")

    def number(v) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    for key in ("kind", "robot", "robot_model_digest", "weights_sha256", "data_hash"):
        if not isinstance(meta[key], str) or not meta[key]:
            raise bad(key, "a non-empty string")
    for key in ("model", "camera", "metrics", "versions"):
        if not isinstance(meta[key], dict):
            raise bad(key, "a JSON object")
    if meta["kind"] not in ("trajectory", "direct"):
        raise bad("kind", "'trajectory' or 'direct'")
    vocab = meta["vocabulary"]
    if not isinstance(vocab, list) or not all(isinstance(w, str) and w for w in vocab) or len(set(vocab)) != len(vocab):
        raise bad("vocabulary", "a list of distinct non-empty words")
    cam = meta["camera"]
    if not isinstance(cam.get("name"), str):
        raise CheckpointError(f"{where}: camera.name must be a string, got {short_repr(cam.get('name'))}")
    for key in ("width", "height"):
        if not isinstance(cam.get(key), int) or isinstance(cam.get(key), bool) or cam[key] < 1:
            raise CheckpointError(f"{where}: camera.{key} must be a positive integer, got {short_repr(cam.get(key))}")
    for key, shape in (("K", (3, 3)), ("T_world_cam", (4, 4))):
        v = cam.get(key)
        if (not isinstance(v, list) or len(v) != shape[0]
                or not all(isinstance(r, list) and len(r) == shape[1] and all(number(x) for x in r) for r in v)):
            raise CheckpointError(f"{where}: camera.{key} must be a {shape[0]}x{shape[1]} list of numbers, "
                                  f"got {short_repr(v)}")
    w = meta["windows"]
    if meta["kind"] == "trajectory" or w is not None:
        if not isinstance(w, dict):
            raise bad("windows", "a JSON object")
        for k, v in w.items():
            choices = WINDOW_CHOICES.get(k)
            if choices is not None:
                if v not in choices:
                    raise CheckpointError(f"{where}: windows.{k} must be one of {', '.join(map(repr, choices))}, "
                                          f"got {short_repr(v)}")
            elif not isinstance(v, int) or isinstance(v, bool):
                raise CheckpointError(f"{where}: windows.{k} must be an integer, got {short_repr(v)}")
    if checkpoint_world(meta) not in WORLDS:
        raise bad("world", f"one of {', '.join(WORLDS)}")
    if meta.get("height_ref", "world") not in HEIGHT_REFS:
        raise bad("height_ref", f"one of {', '.join(HEIGHT_REFS)}")
    if not isinstance(cam.get("per_scene", False), bool):
        raise CheckpointError(f"{where}: camera.per_scene must be true or false, got {short_repr(cam.get('per_scene'))}")
    if "max_unknown_fraction" in meta and not (number(meta["max_unknown_fraction"])
                                               and 0 <= meta["max_unknown_fraction"] <= 1):
        raise bad("max_unknown_fraction", "a number in [0, 1]")


def check_compatible(meta: dict, *, robot: str | None = None, camera=None, kind: str | None = None,
                     where: str = "checkpoint", robot_spec=None, world: str | None = None) -> None:
    """Refuse a checkpoint made for another world, robot, planner camera, image size or planner kind.

    With ``robot_spec`` the robot is matched by its model digest (:func:`robot_model_digest`), not its name:
    a different arm under the same name is refused, the same model under another name accepted."""
    if kind is not None and meta.get("kind") != kind:
        raise CheckpointError(f"{where} is a {meta.get('kind')!r} planner checkpoint; this planner needs {kind!r}")
    if world is not None and checkpoint_world(meta) != world:
        raise CheckpointError(
            f"{where} was trained in the {checkpoint_world(meta)!r} world (robot {short_repr(meta.get('robot'))}), but "
            f"this run's task is in the {world!r} world (worlds: {', '.join(WORLDS)}); use that world's checkpoint "
            f"(leave --checkpoint out to get the shipped one for the robot) or train one there")
    if robot_spec is not None:
        from tcot_hybrid.robot import robot_model_digest

        have = robot_model_digest(robot_spec)
        if meta.get("robot_model_digest") != have:
            raise CheckpointError(
                f"{where} was trained for robot {short_repr(meta.get('robot'))} with model digest "
                f"{short_repr(meta.get('robot_model_digest'))}, but this run's robot {robot_spec.name!r} "
                f"({robot_spec.mjcf_path}) has model digest {have}: another arm (or an edited one), whatever its "
                f"name; train a checkpoint for it")
    elif robot is not None and meta.get("robot") != robot:
        raise CheckpointError(f"{where} was trained for robot {meta.get('robot')!r}, but this run uses {robot!r}")
    if camera is not None:
        cm = meta.get("camera")
        if not isinstance(cm, dict):
            raise CheckpointError(f"{where} metadata has no camera description")
        if cm.get("name") != camera.name:
            raise CheckpointError(f"{where} was trained on planner camera {cm.get('name')!r}, but this run's "
                                  f"planner camera is {camera.name!r}")
        if (cm.get("width"), cm.get("height")) != (camera.width, camera.height):
            raise CheckpointError(f"{where} was trained on {cm.get('width')}x{cm.get('height')} px images, but this "
                                  f"run's planner image is {camera.width}x{camera.height} px")
        # trained on several scenes' camera poses (LIBERO): the planner lifts with the run's own calibration
        for key, tol in ({} if cm.get("per_scene", False) else CAMERA_ATOL).items():
            try:
                ref = np.asarray(cm.get(key), dtype=float)
            except (TypeError, ValueError):
                ref = np.zeros(0)
            cur = np.asarray(getattr(camera, key), dtype=float)
            if ref.shape != cur.shape or not np.allclose(ref, cur, rtol=0, atol=tol * max(1.0, float(np.abs(cur).max()))):
                diff = float(np.max(np.abs(ref - cur))) if ref.shape == cur.shape else float("nan")
                raise CheckpointError(f"{where} was trained with a different planner camera {key} "
                                      f"(max difference {diff:.3g}); the camera must match the training data's")


def load_checkpoint(path: str | Path, *, robot: str | None = None, camera=None, kind: str | None = None,
                    robot_spec=None, world: str | None = None) -> Checkpoint:
    """Validate and load a checkpoint; ``robot``/``camera``/``kind`` (when given) must match its metadata.

    ``robot_spec`` (the run's RobotSpec) matches the robot by model digest and its joint count against the
    network's; with ``camera`` the image size must equal the network's input size too. Every mismatch is
    refused here, before a simulation step."""
    import torch
    from safetensors import SafetensorError
    from safetensors.torch import load as st_load

    from tcot_hybrid.learning.model import ModelConfig, PlannerNet
    from tcot_hybrid.config import from_mapping

    p = Path(path)
    where = f"checkpoint {str(p)!r}"
    blob, _ = _read_weights(p)
    meta = _read_meta(p)
    if sha256_bytes(blob) != meta["weights_sha256"]:
        raise CheckpointError(f"{where}: weights do not match the SHA-256 recorded in {meta_path(p).name} "
                              f"(modified or mixed-up files)")
    check_compatible(meta, robot=robot, camera=camera, kind=kind, where=where, robot_spec=robot_spec, world=world)
    try:
        cfg = from_mapping(ModelConfig, meta["model"], prefix="model")
    except ConfigError as exc:
        raise CheckpointError(f"{where}: invalid model config in metadata: {exc}") from exc
    except (TypeError, ValueError, AttributeError, RecursionError) as exc:
        raise CheckpointError(f"{where}: invalid model config in metadata ({type(exc).__name__})") from exc
    if cfg.kind != meta["kind"]:
        raise CheckpointError(f"{where}: metadata kind {meta['kind']!r} disagrees with model.kind {cfg.kind!r}")
    if robot_spec is not None and cfg.dof != robot_spec.dof:
        raise CheckpointError(f"{where}: the network takes {cfg.dof} joints, robot {robot_spec.name!r} has "
                              f"{robot_spec.dof}")
    cam = meta["camera"]
    if (cam["width"], cam["height"]) != (cfg.image_px, cfg.image_px):
        raise CheckpointError(f"{where}: metadata camera is {cam['width']}x{cam['height']} px but the network "
                              f"takes {cfg.image_px}x{cfg.image_px} px images")
    if cfg.kind == "trajectory":
        from tcot_hybrid.data.labels import windows_from_meta

        try:
            win = windows_from_meta(meta["windows"])
        except (ConfigError, TypeError) as exc:
            raise CheckpointError(f"{where}: invalid label windows in metadata: {exc}") from exc
        if win.L_g != cfg.n_global or win.L_l + 1 != cfg.n_local:
            raise CheckpointError(f"{where}: windows {short_repr(meta['windows'])} do not match the network "
                                  f"({cfg.n_global} global, {cfg.n_local} local waypoints)")
    vocab = meta["vocabulary"]
    if not isinstance(vocab, list) or len(vocab) != cfg.vocab_size:
        raise CheckpointError(f"{where}: vocabulary has {len(vocab) if isinstance(vocab, list) else '?'} words, "
                              f"model expects {cfg.vocab_size}")
    try:
        state = st_load(blob)
    except (SafetensorError, ValueError, RuntimeError) as exc:
        raise CheckpointError(f"{where}: cannot decode tensors ({exc})") from exc
    torch.manual_seed(0)
    model = PlannerNet(cfg)
    expected = {k: v for k, v in model.state_dict().items() if not k.endswith("num_batches_tracked")}
    missing = sorted(set(expected) - set(state))
    extra = sorted(set(state) - set(expected))
    if missing or extra:
        raise CheckpointError(f"{where}: tensor names do not match the model: missing {missing[:5]}"
                              f"{' …' if len(missing) > 5 else ''}, unexpected {extra[:5]}{' …' if len(extra) > 5 else ''}")
    for k, ref in expected.items():
        t = state[k]
        if tuple(t.shape) != tuple(ref.shape):
            raise CheckpointError(f"{where}: tensor {k!r} has shape {tuple(t.shape)}, the model needs {tuple(ref.shape)}")
        if t.dtype != ref.dtype:
            raise CheckpointError(f"{where}: tensor {k!r} has dtype {t.dtype}, the model needs {ref.dtype}")
        if t.is_floating_point() and not bool(torch.isfinite(t).all()):
            raise CheckpointError(f"{where}: tensor {k!r} contains NaN or inf values")
    model.load_state_dict(state, strict=False)
    model.eval()
    return Checkpoint(model=model, meta=meta, path=p)


# --- shipped defaults -------------------------------------------------------------------------------------

def checkpoints_dir() -> Path:
    return Path(__file__).resolve().parent.parent / "checkpoints"


TASK_MODELS_FILE = "task_models.json"


def task_models(robot: str) -> dict[str, str]:
    """Tasks whose shipped trajectory planner is not their suite's: {task: checkpoint stem}, from
    ``checkpoints/task_models.json`` (each choice made on development layouts by the rule docs/libero-planner.md
    states in "A model per task"). A route to a checkpoint that is not shipped is refused, naming the shipped ones."""
    path = checkpoints_dir() / TASK_MODELS_FILE
    if not path.is_file():
        return {}
    try:
        routes = json.loads(path.read_text())["routes"].get(robot, {})
    except (ValueError, KeyError, AttributeError) as exc:
        raise CheckpointError(f"{path}: not a task-model table ({type(exc).__name__}: {exc}); expected "
                              '{"routes": {robot: {task: checkpoint stem}}}') from exc
    if not isinstance(routes, dict) or not all(isinstance(v, str) for v in routes.values()):
        raise CheckpointError(f"{path}: routes of robot {robot!r} must map task names to checkpoint stems, got "
                              f"{short_repr(routes)}")
    for task, stem in routes.items():
        if not (checkpoints_dir() / f"{stem}{SUFFIX}").is_file():
            have = sorted(x.stem for x in checkpoints_dir().glob(f"*{SUFFIX}"))
            raise CheckpointError(f"{path.name}: task {task!r} of robot {robot!r} is routed to {stem!r}, which is "
                                  f"not shipped; shipped: {', '.join(have) or 'none'}")
    return routes


def default_checkpoint(robot: str, kind: str = "trajectory", *, suite: str | None = None, task: str | None = None,
                       robot_ref: str | None = None) -> Path:
    """The shipped checkpoint for ``robot`` on ``task`` of ``suite``: the model ``task_models.json`` routes the task
    to (trajectory planners only; :func:`task_models`), else the suite's own model if one is shipped
    (``<robot>_<suite>`` / ``<robot>_direct_<suite>``: the paper's TCoT row trains one model per LIBERO suite),
    else the robot's model for all suites (``<robot>_default`` / ``<robot>_direct_default``, its TCoT-Multi row)."""
    prefix = robot if kind == "trajectory" else f"{robot}_{kind}"
    if task and kind == "trajectory":
        stem = task_models(robot).get(task)
        if stem:
            return checkpoints_dir() / f"{stem}{SUFFIX}"
    if suite:
        own = checkpoints_dir() / f"{prefix}_{suite}{SUFFIX}"
        if own.is_file():
            return own
    p = checkpoints_dir() / f"{prefix}_default{SUFFIX}"
    if not p.is_file():
        have = sorted(x.stem for x in checkpoints_dir().glob(f"*{SUFFIX}")) if checkpoints_dir().is_dir() else []
        if robot == "libero_panda" and kind == "trajectory":  # LIBERO's own robot: its planner has its own pipeline
            raise CheckpointError(
                f"no shipped trajectory planner checkpoint for robot {robot!r} (looked for {p.name}); shipped: "
                f"{', '.join(have) or 'none'}. Build it with `make libero-planner` (LIBERO demonstrations on sampled "
                f"layouts, then training; docs/libero-planner.md), or pass --checkpoint")
        if robot == "libero_panda" and kind == "direct":
            raise CheckpointError(
                f"no shipped direct planner checkpoint for robot {robot!r} (looked for {p.name}); shipped: "
                f"{', '.join(have) or 'none'}. Train one with `tcot train --config examples/configs/"
                f"train_libero_direct.yaml` on LIBERO demonstrations (docs/libero-planner.md, \"Direct baseline on "
                f"LIBERO\"), or pass --checkpoint")
        raise CheckpointError(
            f"no shipped {kind} planner checkpoint for robot {robot!r} (looked for {p.name}); shipped: "
            f"{', '.join(have) or 'none'}. Train one with `tcot train --collect --robot {robot_ref or robot} --data "
            f"data/demos_{robot}.hdf5 --out runs/{robot}.safetensors{'' if kind == 'trajectory' else ' --kind ' + kind}` "
            f"and pass --checkpoint runs/{robot}.safetensors")
    return p
