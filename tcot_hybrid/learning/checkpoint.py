"""Planner checkpoints: safetensors weights + a JSON metadata file next to them. Never pickle.

``<name>.safetensors`` holds only tensors; ``<name>.json`` holds everything else (model config, robot,
planner camera with K / T_world_cam / image size, vocabulary, label windows, training data hash,
metrics, versions and the weights' SHA-256). Loading is validation first: nothing in either file is
ever executed (the header and the metadata are parsed with ``json``; tensors are copied out of the
byte buffer by ``safetensors``), and every problem is a :class:`CheckpointError` saying what is wrong:

* not a safetensors file (``.pt``/``.pth``/``.ckpt``, pickle or zip payloads, even when renamed),
* truncated or corrupt bytes, header offsets outside the file, unknown dtypes,
* weights that do not match their metadata (hash), NaN/inf values, missing/unexpected keys, wrong shapes,
* a checkpoint made for another robot, planner camera (name, K, pose) or image size than the run,
  or for another planner kind (trajectory vs direct).
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

from tcot_hybrid.errors import CheckpointError, ConfigError
from tcot_hybrid.jsonio import json_default as _json_default

FORMAT = "tcot-planner-v1"
SUFFIX = ".safetensors"
MAX_HEADER_BYTES = 16 * 1024 * 1024
MAX_FILE_BYTES = 512 * 1024 * 1024
_ALLOWED_DTYPES = {"F32": 4, "F16": 2, "BF16": 2, "I64": 8}
REQUIRED_META = ("format", "kind", "model", "robot", "camera", "vocabulary", "windows", "weights_sha256",
                 "data_hash", "metrics", "versions")
# What pickle / torch.save / numpy archives start with: refused with a message saying so.
_PICKLE_MAGIC = (b"\x80\x02", b"\x80\x03", b"\x80\x04", b"\x80\x05")
_ZIP_MAGIC = b"PK\x03\x04"
CAMERA_ATOL = {"K": 1e-6, "T_world_cam": 1e-6}


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
    missing = [k for k in REQUIRED_META if k not in full]
    if missing:
        raise CheckpointError(f"checkpoint metadata lacks {missing}")
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_suffix(".tmp")
    tmp.write_bytes(blob)
    tmp.replace(p)
    meta_path(p).write_text(json.dumps(full, indent=1, default=_json_default) + "\n")
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
    if not mp.is_file():
        raise CheckpointError(f"checkpoint {str(path)!r} has no metadata file {str(mp)!r} next to it")
    try:
        meta = json.loads(mp.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"checkpoint metadata {str(mp)!r} is not valid JSON ({exc})") from exc
    if not isinstance(meta, dict):
        raise CheckpointError(f"checkpoint metadata {str(mp)!r} is not a JSON object")
    missing = [k for k in REQUIRED_META if k not in meta]
    if missing:
        raise CheckpointError(f"checkpoint metadata {str(mp)!r} lacks {missing}")
    if meta["format"] != FORMAT:
        raise CheckpointError(f"checkpoint metadata {str(mp)!r} has format {meta['format']!r}, expected {FORMAT!r}")
    return meta


def check_compatible(meta: dict, *, robot: str | None = None, camera=None, kind: str | None = None,
                     where: str = "checkpoint") -> None:
    """Refuse a checkpoint made for another robot, planner camera, image size or planner kind."""
    if kind is not None and meta.get("kind") != kind:
        raise CheckpointError(f"{where} is a {meta.get('kind')!r} planner checkpoint; this planner needs {kind!r}")
    if robot is not None and meta.get("robot") != robot:
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
        for key, tol in CAMERA_ATOL.items():
            try:
                ref = np.asarray(cm.get(key), dtype=float)
            except (TypeError, ValueError):
                ref = np.zeros(0)
            cur = np.asarray(getattr(camera, key), dtype=float)
            if ref.shape != cur.shape or not np.allclose(ref, cur, rtol=0, atol=tol * max(1.0, float(np.abs(cur).max()))):
                diff = float(np.max(np.abs(ref - cur))) if ref.shape == cur.shape else float("nan")
                raise CheckpointError(f"{where} was trained with a different planner camera {key} "
                                      f"(max difference {diff:.3g}); the camera must match the training data's")


def load_checkpoint(path: str | Path, *, robot: str | None = None, camera=None, kind: str | None = None) -> Checkpoint:
    """Validate and load a checkpoint; ``robot``/``camera``/``kind`` (when given) must match its metadata."""
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
    check_compatible(meta, robot=robot, camera=camera, kind=kind, where=where)
    try:
        cfg = from_mapping(ModelConfig, meta["model"], prefix="model")
    except ConfigError as exc:
        raise CheckpointError(f"{where}: invalid model config in metadata: {exc}") from exc
    if cfg.kind != meta["kind"]:
        raise CheckpointError(f"{where}: metadata kind {meta['kind']!r} disagrees with model.kind {cfg.kind!r}")
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


def default_checkpoint(robot: str, kind: str = "trajectory") -> Path:
    """The shipped checkpoint for ``robot`` (``<robot>_default`` / ``<robot>_direct_default``)."""
    stem = f"{robot}_default" if kind == "trajectory" else f"{robot}_{kind}_default"
    p = checkpoints_dir() / f"{stem}{SUFFIX}"
    if not p.is_file():
        have = sorted(x.stem for x in checkpoints_dir().glob(f"*{SUFFIX}")) if checkpoints_dir().is_dir() else []
        raise CheckpointError(
            f"no shipped {kind} planner checkpoint for robot {robot!r} (looked for {p.name}); shipped: "
            f"{', '.join(have) or 'none'}. Train one with `tcot train --collect --robot {robot} --data "
            f"data/demos_{robot}.hdf5 --out runs/{robot}.safetensors{'' if kind == 'trajectory' else ' --kind ' + kind}` "
            f"and pass --checkpoint runs/{robot}.safetensors")
    return p
