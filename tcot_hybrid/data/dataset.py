"""Demonstration files (HDF5, robomimic conventions): the layout, and a validated reader.

Layout (``docs/dataset.md`` describes every field)::

    /                     attrs: format="tcot-demos-v1", tcot_version
    /data                 attrs: total, env_args (JSON)
    /data/demo_<i>        attrs: task, suite, instruction, seed, robot, planner, mode, perturb, perturb_step,
                                 recover_step, source,
                                 success, t_success, num_samples
                          optional attrs: K (3x3), T_world_cam (4x4), support_z: this demo's planner camera and
                                 support height (files with env_args camera_per_demo = true must have them; LIBERO's
                                 agentview takes four poses across its scenes)
        obs/<camera>_image, obs/robot0_*, obs/eef_uv_px, obs/eef_depth_m, task_success, actions
        obs/image_valid (optional, uint8 (T,)): which samples have a rendered image (``tcot collect
                         --image-every``); absent = all of them
        obs/tcp_target_pos (optional, float32 (T, 3)) [m, world]: the waypoint the executor was driving the
                         TCP to at each sample (the TCP itself before the first plan). In contact it runs ahead
                         of obs/robot0_eef_pos: a knob bar holds the hand back while the command goes past it
    /mask/train, /mask/valid   demo names (bytes), split by seed

Every error is a :class:`~tcot_hybrid.errors.DatasetError` naming the file and what is wrong; no raw
h5py traceback reaches the user.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tcot_hybrid.errors import DatasetError

FORMAT = "tcot-demos-v1"
DEMO_PREFIX = "demo_"
PARTIAL_PREFIX = "_partial_"  # a demo being written; renamed to demo_<i> only once complete
VALID_EVERY = 10  # seed % VALID_EVERY == 0 -> validation split

# Per-sample observation datasets: name -> (dtype, trailing shape). "{dof}" is the arm's joint count.
OBS_SPEC: dict[str, tuple[type, tuple]] = {
    "robot0_joint_pos": (np.float32, ("dof",)),
    "robot0_joint_vel": (np.float32, ("dof",)),
    "robot0_eef_pos": (np.float32, (3,)),
    "robot0_eef_quat": (np.float32, (4,)),
    "robot0_gripper_qpos": (np.float32, (2,)),
    "robot0_gripper_closed": (np.uint8, ()),
    "eef_uv_px": (np.float32, (2,)),
    "eef_depth_m": (np.float32, ()),
}
IMAGE_VALID = "obs/image_valid"  # optional per-sample mask of rendered images
TCP_TARGET = "obs/tcp_target_pos"  # optional per-sample commanded waypoint [m, world]
TOP_SPEC: dict[str, tuple[type, tuple]] = {
    "task_success": (np.uint8, ()),
    "actions": (np.float32, (4,)),
}
ENV_ARGS_KEYS = ("robot", "camera", "K", "T_world_cam", "width", "height", "sim_dt", "ctrl_dt", "plan_dt",
                 "config_hash")
DEMO_ATTRS: dict[str, type] = {
    "task": str, "suite": str, "instruction": str, "seed": int, "robot": str, "planner": str, "mode": str,
    "perturb": str, "perturb_step": int, "recover_step": int, "source": str, "success": bool, "t_success": int, "num_samples": int,
}
SOURCES = ("demo", "rollout")
DEMO_INITS = ("sampled", "spread")  # layouts a demo may hold (never the shipped init states: the test set)


CAMERA_KEYS = ("K", "T_world_cam")
PER_DEMO = "camera_per_demo"  # env_args flag: every demo carries its own camera (K, T_world_cam attributes)


def camera_per_demo(env_args: dict) -> bool:
    """Whether a file's demos carry their own planner camera (LIBERO) instead of one per file (workcell)."""
    return bool(env_args.get(PER_DEMO, False))


def env_difference(have: dict, want: dict, keys: tuple[str, ...]) -> str | None:
    """The first way two env_args differ in ``keys`` or the camera (``K``, ``T_world_cam``), as text
    (``"robot = 'panda', not 'ur5e'"``), or None when they agree. Files whose demos carry their own camera
    (``camera_per_demo``) agree on the camera's name and size only; one per-demo file and one per-file file
    never agree."""
    for key in keys:
        if have.get(key) != want.get(key):
            return f"{key} = {have.get(key)!r}, not {want.get(key)!r}"
    if camera_per_demo(have) != camera_per_demo(want):
        return f"{PER_DEMO} = {camera_per_demo(have)}, not {camera_per_demo(want)}"
    if camera_per_demo(have):
        return None
    for key in CAMERA_KEYS:
        if not np.allclose(have[key], want[key], atol=1e-9):
            return f"camera {key} differs"
    return None


def image_key(camera: str) -> str:
    """Name of the image dataset inside ``obs/`` for planner camera ``camera``."""
    return f"{camera}_image"


def is_valid_seed(seed: int, valid_every: int = VALID_EVERY) -> bool:
    """The split rule: a seed belongs to the validation split iff ``seed % valid_every == 0``.

    Split by seed (never by frame) so no layout seen in training is used for validation.
    """
    return int(seed) % int(valid_every) == 0


@dataclass(frozen=True, kw_only=True)
class DemoInfo:
    """One demo's attributes (see docs/dataset.md)."""

    name: str
    task: str
    suite: str
    instruction: str
    seed: int
    robot: str
    planner: str
    mode: str
    perturb: str
    perturb_step: int
    recover_step: int
    source: str
    success: bool
    t_success: int
    num_samples: int
    init: str = "sampled"  # layout mode (``--init``); files written before it existed hold only sampled layouts


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _coerce_attr(path: Path, where: str, key: str, value: Any, tp: type) -> Any:
    value = _attr(value)
    if tp is bool:
        if isinstance(value, (bool, int)) and value in (0, 1, True, False):
            return bool(value)
    elif tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif isinstance(value, tp):
        return value
    raise DatasetError(f"demo file {path}: {where} attribute {key!r} = {value!r} is not a {tp.__name__}")


class DemoFile:
    """A validated, read-only demonstration file. Use :func:`open_demos`; close it (or use ``with``).

    Opening checks the whole layout (format tag, env_args, every demo's attributes, datasets, dtypes
    and shapes, masks) from metadata only; array payloads are read lazily by :meth:`read`, which also
    turns h5py read errors (e.g. a cut-off file) into :class:`DatasetError`.
    """

    def __init__(self, path: str | Path, *, _allow_partial: bool = False, _h5=None):
        import h5py

        self.path = Path(path)
        if _h5 is None:
            if not self.path.is_file():
                raise DatasetError(f"demo file {self.path} does not exist")
            try:
                _h5 = h5py.File(self.path, "r")
            except (OSError, ValueError) as exc:
                raise DatasetError(f"demo file {self.path} cannot be opened as HDF5: it is truncated or corrupt "
                                   f"({exc}); delete it and collect again") from exc
            self._owns = True
        else:
            self._owns = False
        self._h5 = _h5
        try:
            self._validate(allow_partial=_allow_partial)
        except DatasetError:
            self.close()
            raise
        except (OSError, KeyError, ValueError, RuntimeError) as exc:  # h5py metadata read failures
            self.close()
            raise DatasetError(f"demo file {self.path} is corrupt: {type(exc).__name__}: {exc}") from exc

    # --- lifecycle -----------------------------------------------------------------------------------
    def close(self) -> None:
        if self._owns and self._h5 is not None:
            try:
                self._h5.close()
            except Exception:  # noqa: BLE001 - closing a broken file must not hide the real error
                pass
        self._h5 = None

    def __enter__(self) -> DemoFile:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- validation ----------------------------------------------------------------------------------
    def _fail(self, msg: str) -> DatasetError:
        return DatasetError(f"demo file {self.path}: {msg}")

    def _validate(self, *, allow_partial: bool) -> None:
        f = self._h5
        fmt = _attr(f.attrs.get("format"))
        if fmt != FORMAT:
            raise self._fail(f"format attribute is {fmt!r}, expected {FORMAT!r} (not a tcot demo file)")
        if "data" not in f:
            raise self._fail("missing group /data")
        data = f["data"]
        raw = _attr(data.attrs.get("env_args"))
        if raw is None:
            if allow_partial and not any(n.startswith(DEMO_PREFIX) for n in data):
                # a collection that stopped before its first demo: nothing to check yet
                self.env_args, self.camera, self.image_key, self.dof = {}, "", "", None
                self._infos, self.masks = {}, {}
                return
            raise self._fail("/data has no env_args attribute")
        try:
            env = json.loads(raw)
        except (TypeError, json.JSONDecodeError) as exc:
            raise self._fail(f"/data env_args is not valid JSON ({exc})") from exc
        missing = [k for k in ENV_ARGS_KEYS if k not in env]
        if missing:
            raise self._fail(f"/data env_args lacks {missing}; it has {sorted(env)}")
        K, T = np.asarray(env["K"], dtype=float), np.asarray(env["T_world_cam"], dtype=float)
        if K.shape != (3, 3) or T.shape != (4, 4) or not (np.isfinite(K).all() and np.isfinite(T).all()):
            raise self._fail(f"env_args K must be a finite 3x3 and T_world_cam a finite 4x4, got shapes "
                             f"{K.shape} and {T.shape}")
        self.env_args: dict = env
        self.camera: str = str(env["camera"])
        self.image_key: str = "obs/" + image_key(self.camera)
        h, w = int(env["height"]), int(env["width"])
        names = [n for n in data if n.startswith(DEMO_PREFIX)]
        others = [n for n in data if not n.startswith(DEMO_PREFIX)]
        if others and not allow_partial:
            raise self._fail(f"/data holds incomplete demo groups {others} (an interrupted collection); "
                             f"re-run tcot collect with the same --out to clean up and finish it")
        try:
            names.sort(key=lambda n: int(n[len(DEMO_PREFIX):]))
        except ValueError as exc:
            raise self._fail(f"demo group names must be demo_<int>, got {names}") from exc
        total = _attr(data.attrs.get("total"))
        if not isinstance(total, int) or total != len(names):
            raise self._fail(f"/data total attribute is {total!r} but the file holds {len(names)} demos")
        self._infos: dict[str, DemoInfo] = {}
        dof = None
        for name in names:
            info = self._validate_demo(name, h, w)
            d = data[name]["obs/robot0_joint_pos"].shape[1]
            if dof is None:
                dof = d
            elif d != dof:
                raise self._fail(f"{name}: robot0_joint_pos has {d} joints, other demos have {dof}")
            self._infos[name] = info
        self.dof: int | None = dof
        self.masks: dict[str, list[str]] = {}
        self.valid_every = VALID_EVERY
        if "mask" not in f:
            if not allow_partial:
                raise self._fail("missing group /mask (collection did not finish); re-run tcot collect "
                                 "with the same --out")
            return
        for split in ("train", "valid"):
            if split not in f["mask"]:
                raise self._fail(f"missing dataset /mask/{split}")
            members = [_attr(x) for x in f["mask"][split][()]]
            unknown = [m for m in members if m not in self._infos]
            if unknown:
                raise self._fail(f"/mask/{split} names demos that are not in the file: {unknown[:5]}")
            self.masks[split] = members
        self.valid_every = int(_attr(f["mask"].attrs.get("valid_every", VALID_EVERY)))

    def _validate_demo(self, name: str, h: int, w: int) -> DemoInfo:
        g = self._h5["data"][name]
        where = f"/data/{name}"
        values = {}
        for key, tp in DEMO_ATTRS.items():
            if key not in g.attrs:
                raise self._fail(f"{where} lacks attribute {key!r}")
            values[key] = _coerce_attr(self.path, where, key, g.attrs[key], tp)
        values["init"] = str(_attr(g.attrs.get("init", "sampled")))
        if values["init"] not in DEMO_INITS:
            raise self._fail(f"{where} init = {values['init']!r}, expected one of {', '.join(DEMO_INITS)}")
        info = DemoInfo(name=name, **values)
        if camera_per_demo(self.env_args):
            self._demo_camera_arrays(name, where)
        n = info.num_samples
        if n < 1:
            raise self._fail(f"{where} num_samples = {n}, expected >= 1")
        if info.source not in SOURCES:
            raise self._fail(f"{where} source = {info.source!r}, expected one of {', '.join(SOURCES)}")
        if not -1 <= info.t_success < n:
            raise self._fail(f"{where} t_success = {info.t_success} outside [-1, {n - 1}]")
        specs = {f"obs/{k}": v for k, v in OBS_SPEC.items()}
        specs[self.image_key] = (np.uint8, (h, w, 3))
        specs.update(TOP_SPEC)
        if IMAGE_VALID in g:
            specs[IMAGE_VALID] = (np.uint8, ())
        if TCP_TARGET in g:
            specs[TCP_TARGET] = (np.float32, (3,))
        for key, (dtype, trailing) in specs.items():
            if key not in g:
                raise self._fail(f"{where} lacks dataset {key!r}")
            ds = g[key]
            if ds.dtype != np.dtype(dtype):
                raise self._fail(f"{where}/{key} has dtype {ds.dtype}, expected {np.dtype(dtype)}")
            shape = ds.shape
            want = (n, *trailing)
            ok = len(shape) == len(want) and all(a == b or b == "dof" for a, b in zip(shape, want))
            if not ok:
                raise self._fail(f"{where}/{key} has shape {shape}, expected {tuple(want)} "
                                 f"(num_samples = {n})")
        return info

    def _demo_camera_arrays(self, name: str, where: str) -> tuple[np.ndarray, np.ndarray, float]:
        a = self._h5["data"][name].attrs
        missing = [k for k in (*CAMERA_KEYS, "support_z") if k not in a]
        if missing:
            raise self._fail(f"{where} lacks attribute(s) {missing} (the file's env_args say camera_per_demo)")
        K, T = np.asarray(a["K"], dtype=float), np.asarray(a["T_world_cam"], dtype=float)
        sz = float(np.asarray(a["support_z"], dtype=float))
        if K.shape != (3, 3) or T.shape != (4, 4) or not (np.isfinite(K).all() and np.isfinite(T).all()
                                                         and np.isfinite(sz)):
            raise self._fail(f"{where} K must be a finite 3x3, T_world_cam a finite 4x4 and support_z finite, got "
                             f"shapes {K.shape}, {T.shape} and {sz}")
        return K, T, sz

    # --- access --------------------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._h5 is None:
            raise DatasetError(f"demo file {self.path} is closed")

    @property
    def demos(self) -> list[str]:
        """Demo names in index order."""
        return list(self._infos)

    def info(self, name: str) -> DemoInfo:
        if name not in self._infos:
            raise DatasetError(f"demo file {self.path} has no demo {name!r} ({len(self._infos)} demos)")
        return self._infos[name]

    def infos(self) -> list[DemoInfo]:
        return list(self._infos.values())

    def mask(self, split: str) -> list[str]:
        """Demo names of split ``train`` or ``valid`` (successful demos only, split by seed)."""
        if split not in self.masks:
            raise DatasetError(f"demo file {self.path}: no mask {split!r}; masks: {', '.join(self.masks) or 'none'}")
        return list(self.masks[split])

    def read(self, name: str, keys: list[str] | tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
        """Arrays of one demo, keyed by path inside the demo group (``"obs/eef_uv_px"``, ``"actions"`` …).

        ``keys=None`` reads every dataset. A read failure (truncated payload) raises DatasetError.
        """
        self._check_open()
        self.info(name)
        g = self._h5["data"][name]
        if keys is None:
            keys = [f"obs/{k}" for k in g["obs"]] + [k for k in TOP_SPEC]
        out = {}
        for key in keys:
            if key not in g:
                raise DatasetError(f"demo file {self.path}: /data/{name} has no dataset {key!r}")
            try:
                out[key] = g[key][()]
            except (OSError, ValueError, RuntimeError) as exc:
                raise DatasetError(f"demo file {self.path}: reading /data/{name}/{key} failed ({exc}); "
                                   f"the file is truncated or corrupt") from exc
            arr = out[key]
            if arr.dtype.kind == "f" and not np.isfinite(arr).all():  # else training blames the learning rate
                bad = np.argwhere(~np.isfinite(arr))[0]
                raise DatasetError(f"demo file {self.path}: /data/{name}/{key} holds a non-finite value "
                                   f"({arr[tuple(bad)]} at sample {int(bad[0])}); the demo is corrupt: "
                                   f"re-collect it or drop it from the masks")
        return out

    def has(self, name: str, key: str) -> bool:
        """Whether demo ``name`` holds the dataset ``key`` (an optional one, e.g. ``obs/tcp_target_pos``)."""
        self._check_open()
        self.info(name)  # names the file and the demo when there is no such demo
        return key in self._h5["data"][name]

    def commanded_targets(self, name: str) -> np.ndarray:
        """(T, 3) commanded waypoints of demo ``name`` [m, world] (``obs/tcp_target_pos``): what commanded-path
        labels trace (``windows.global_path: commanded``, ``tcot replay --global-path commanded``)."""
        if not self.has(name, TCP_TARGET):
            raise DatasetError(f"{self.path}: {name} has no {TCP_TARGET} (collected before it was recorded), which "
                               "commanded-path labels trace (windows.global_path or windows.local_path "
                               "'commanded', --global-path commanded); recollect, or label the observed path")
        return self.read(name, [TCP_TARGET])[TCP_TARGET]

    def image_valid(self, name: str) -> np.ndarray:
        """(T,) bool: which samples of one demo have a rendered planner image (all, unless collected with
        ``--image-every``)."""
        self._check_open()
        info = self.info(name)
        if IMAGE_VALID not in self._h5["data"][name]:
            return np.ones(info.num_samples, bool)
        return self.read(name, [IMAGE_VALID])[IMAGE_VALID].astype(bool)

    def images(self, name: str) -> np.ndarray:
        """(T, H, W, 3) uint8 planner-camera frames of one demo."""
        return self.read(name, [self.image_key])[self.image_key]

    def verify(self) -> None:
        """Read every payload once (slow); raises DatasetError at the first unreadable dataset."""
        for name in self.demos:
            self.read(name)

    @property
    def camera_per_demo(self) -> bool:
        """Whether every demo carries its own planner camera (:meth:`camera_model` with a demo name)."""
        return camera_per_demo(self.env_args)

    def camera_model(self, name: str | None = None):
        """The planner camera as a :class:`~tcot_hybrid.camera.CameraModel`: demo ``name``'s own when the file
        stores one per demo (LIBERO), else the file's (the first demo's when ``name`` is None)."""
        from tcot_hybrid.camera import CameraModel

        env = self.env_args
        K, T = np.asarray(env["K"]), np.asarray(env["T_world_cam"])
        if name is not None and self.camera_per_demo:
            self.info(name)
            K, T, _ = self._demo_camera_arrays(name, f"/data/{name}")
        return CameraModel(name=self.camera, width=int(env["width"]), height=int(env["height"]),
                           K=K, T_world_cam=T,
                           near_m=float(env.get("near_m", 0.01)), far_m=float(env.get("far_m", 50.0)))

    def support_z(self, name: str) -> float | None:
        """World height of the surface demo ``name``'s objects rest on [m] (the table top), recorded per demo in a
        file with a camera per demo (LIBERO); None for a file with one camera (the workcell: table top z = 0)."""
        if not self.camera_per_demo:
            return None
        self.info(name)
        return self._demo_camera_arrays(name, f"/data/{name}")[2]


def open_demos(path: str | Path) -> DemoFile:
    """Open and validate a demonstration file (read-only). Raises DatasetError naming the file."""
    return DemoFile(path)
