"""Training frames: every sample of every demo of one split, with its labels, held in memory.

One row per demo sample t (the state at the start of planner step t). Labels per row:
  global window (paper eq. 4) and local window (eq. 5) from the data package's label helpers: pixel,
  TCP height z_m and gripper bit per point, plus the ground-truth 3D TCP point (for the 3D error);
  success (task predicate at t) for detect; direct action (TCP displacement over ``direct_horizon``
  steps and the gripper bit at the end of it) for the direct baseline.
Images stay uint8 (T, H, W, 3); batches are converted on the fly.

Online data (paper eq. 7, stage 2) comes from further files of the same format (``tcot collect
--planner learned`` rollouts, ``tcot collect --perturb ...`` oracle recoveries): every episode, failed or
not, gives failure-detection frames labelled by the simulator's success predicate; a successful oracle
episode also gives trajectory labels from its first plan after the perturbation on (``recover_step``: how
to recover from the perturbed state). ``FrameSet.traj`` marks the frames whose trajectory labels are imitated.
"""
from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from tcot_hybrid.data import open_demos
from tcot_hybrid.data.labels import (TrajectoryWindowConfig, commanded_track, global_labels, local_labels,
                                     track_from_arrays)
from tcot_hybrid.errors import DatasetError
from tcot_hybrid.learning.vocab import Vocabulary

RECOVERY_DENSE_STEPS = 10  # frames kept at stride 1 from a recovery's first plan on (the arm turns there)
_KEYS = ("obs/robot0_joint_pos", "obs/robot0_eef_pos", "obs/robot0_eef_quat", "obs/robot0_gripper_closed",
         "obs/eef_uv_px", "task_success")
HEIGHT_REFS = ("world", "camera")


def height_reference(camera, height_ref: str) -> float:
    """[m] world height the lift cue z_m is measured from: 0 (``world``: the workcell's table top is z = 0) or the
    planner camera's own height (``camera``: LIBERO's scenes put their table at 0, 0.42 or 0.9 m and their camera
    with it; the planner knows its camera's calibration, not the table's height)."""
    from tcot_hybrid.errors import ConfigError

    if height_ref == "world":
        return 0.0
    if height_ref == "camera":
        return float(np.asarray(camera.T_world_cam)[2, 3])
    raise ConfigError(f"height_ref = {height_ref!r} is not one of {', '.join(HEIGHT_REFS)}")


def quat_wxyz_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) → (..., 3, 3) rotation matrices."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def camera_rot6(camera, R_world: np.ndarray) -> np.ndarray:
    """(..., 3, 3) TCP orientations in the world → (..., 6) in ``camera``'s frame (x column, then y column)."""
    from tcot_hybrid.learning.model import matrix_to_rot6

    R_cw = np.asarray(camera.T_world_cam, dtype=float)[:3, :3].T
    return matrix_to_rot6(R_cw @ R_world).astype(np.float32)


@dataclass
class FrameSet:
    """All frames of one split. Arrays share the first dimension N (frames)."""

    images: torch.Tensor  # (N, H, W, 3) uint8
    tokens: torch.Tensor  # (N, max_tokens) int64
    proprio: torch.Tensor  # (N, dof + 1) float32: joints [rad] + gripper command
    g_uv: torch.Tensor  # (N, L_g, 2) [px]
    g_z: torch.Tensor  # (N, L_g) [m]
    g_grip: torch.Tensor  # (N, L_g) float 0/1
    g_xyz: torch.Tensor  # (N, L_g, 3) [m] ground-truth TCP points
    g_rot: torch.Tensor  # (N, L_g, 6) TCP orientation in the frame's planner camera (x, y columns)
    l_uv: torch.Tensor
    l_z: torch.Tensor
    l_grip: torch.Tensor
    l_xyz: torch.Tensor
    l_rot: torch.Tensor
    success: torch.Tensor  # (N,) float 0/1
    traj: np.ndarray  # (N,) bool: trajectory labels are imitated (else a failure-detection frame only)
    online: np.ndarray  # (N,) bool: from an online file (rollout or perturbed recovery), not a demonstration
    d_delta: torch.Tensor  # (N, 3) [m] TCP displacement over direct_horizon steps
    d_grip: torch.Tensor  # (N,) float 0/1 gripper command direct_horizon steps ahead
    demo: np.ndarray  # (N,) demo index into ``demos``
    t: np.ndarray  # (N,) sample index within the demo
    cam: np.ndarray  # (N,) index into ``cameras``: the frame's planner camera (one per demo on LIBERO)
    z_ref: np.ndarray  # (N,) [m] world height the frame's z labels are measured from (``height_reference``)
    demos: list[str]
    tasks: list[str]
    instructions: list[str]
    cameras: list  # CameraModel per camera index
    camera_support_z: list = dataclasses.field(default_factory=list)  # per camera index: the lowest support surface
    # its demos recorded [m, world] (the table top; None: not recorded, e.g. a workcell file)

    def __len__(self) -> int:
        return int(self.images.shape[0])


def file_hash(path: str | Path, *, chunk: int = 1 << 22) -> str:
    """SHA-256 of a data file (first 16 hex digits); recorded in checkpoints."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while b := f.read(chunk):
            h.update(b)
    return h.hexdigest()[:16]


def load_frames(path: str | Path, split: str, vocab: Vocabulary, *, windows: TrajectoryWindowConfig,
                max_tokens: int, direct_horizon: int, max_demos: int | None = None,
                successful_only: bool = True, frame_stride: int = 1, height_ref: str = "world",
                suites: tuple[str, ...] = (), exclude_tasks: frozenset[str] = frozenset()) -> FrameSet:
    """Read split ``train``/``valid`` (or ``all``: both) of demo file ``path`` into memory with every label
    computed. Only successful demos carry trajectory labels worth imitating; ``successful_only`` drops the rest.
    ``frame_stride`` keeps every k-th frame of each demo (t = 0 always; labels still come from the whole track).
    ``suites`` keeps only the demos of those suites (empty: all); ``exclude_tasks`` leaves out the demos of those
    tasks (their demos collected again into another file).
    """
    with open_demos(path) as f:
        names = f.mask("train") + f.mask("valid") if split == "all" else f.mask(split)
        infos = [i for i in of_suites(f, [f.info(n) for n in names], suites, path) if i.task not in exclude_tasks]
        names = [i.name for i in infos]
        if successful_only:
            names = [i.name for i in infos if i.success]
        if max_demos is not None:
            names = names[:max_demos]
        if not names:
            raise DatasetError(f"demo file {path}: split {split!r} has no usable demos")
        return _read_frames(f, names, vocab, windows=windows, max_tokens=max_tokens, direct_horizon=direct_horizon,
                            keep=lambda info, T: (np.arange(T) % frame_stride == 0, np.ones(T, bool)), online=False,
                            height_ref=height_ref)


def of_suites(f, infos: list, suites: tuple[str, ...], path: str | Path) -> list:
    """The infos (of open file ``f``) of ``suites``: all of them when empty. A suite the file holds no demo of
    is refused, naming the file's suites: a misspelt suite would otherwise train on nothing of it."""
    if not suites:
        return infos
    present = sorted({i.suite for i in f.infos()})
    missing = [s for s in suites if s not in present]
    if missing:
        raise DatasetError(f"data file {path}: no demos of suite(s) {missing}; it holds {present}")
    return [i for i in infos if i.suite in suites]


def online_split_size(path: str | Path, split: str, suites: tuple[str, ...] = ()) -> int:
    """Episodes of online file ``path`` in ``split`` (by seed, as :func:`load_online_frames` splits them): a file of
    one seed per task (e.g. one rollout per task and perturbation) falls wholly into one split."""
    if split not in ("train", "valid"):
        raise DatasetError(f"split must be 'train' or 'valid', got {split!r}")
    with open_demos(path) as f:
        return len(of_suites(f, _split_infos(f, split), suites, path))


def _split_infos(f, split: str) -> list:
    """The episode infos of open online file ``f`` in ``split`` (by seed, like the demos)."""
    from tcot_hybrid.data.dataset import is_valid_seed

    every = int(f.valid_every)
    return [i for i in f.infos() if is_valid_seed(i.seed, every) == (split == "valid")]


def load_online_frames(path: str | Path, split: str, vocab: Vocabulary, *, windows: TrajectoryWindowConfig,
                       max_tokens: int, direct_horizon: int, frame_stride: int = 1, height_ref: str = "world",
                       suites: tuple[str, ...] = ()) -> FrameSet:
    """Online episodes of ``path`` (split by seed like the demos, failed episodes included), every
    ``frame_stride``-th frame plus every success frame (and every frame of the first
    ``RECOVERY_DENSE_STEPS`` of a recovery): all for failure detection; those of successful
    oracle episodes from their first plan after the perturbation on (``recover_step``) also carry trajectory
    labels (recovery demonstrations). ``suites`` keeps only the episodes of those suites (empty: all)."""
    if split not in ("train", "valid"):
        raise DatasetError(f"split must be 'train' or 'valid', got {split!r}")
    with open_demos(path) as f:
        names = [i.name for i in of_suites(f, _split_infos(f, split), suites, path)]
        if not names:
            raise DatasetError(f"online data file {path}: split {split!r} has no episodes")

        def keep(info, T: int) -> tuple[np.ndarray, np.ndarray]:
            t = np.arange(T)
            traj = np.zeros(T, bool)
            if info.source == "demo" and info.success and info.perturb_step < 0:
                traj[:] = True
            elif info.source == "demo" and info.success and info.recover_step >= 0:
                traj = t >= info.recover_step  # before it the track still follows the stale plan
            rows = (t % frame_stride == 0) | ((t >= info.t_success) & (info.t_success >= 0))
            if traj.any():  # every frame where the recovery starts: the decision the local prompt must learn
                rows |= traj & (t < info.recover_step + RECOVERY_DENSE_STEPS)
            return rows, traj

        return _read_frames(f, names, vocab, windows=windows, max_tokens=max_tokens, direct_horizon=direct_horizon,
                            keep=keep, online=True, height_ref=height_ref)


def _read_frames(f, names: list[str], vocab: Vocabulary, *, windows: TrajectoryWindowConfig, max_tokens: int,
                 direct_horizon: int, keep, online: bool, height_ref: str = "world") -> FrameSet:
    """Frames of demos ``names`` of open file ``f``; ``keep(info, T) -> (rows kept, rows with trajectory
    labels)`` as boolean masks over the demo's samples (labels always come from the whole track). Heights are
    measured from ``height_reference(camera, height_ref)`` of each demo's own camera."""
    cols: dict[str, list] = {k: [] for k in ("img", "tok", "prop", "g", "l", "gx", "lx", "gr", "lr", "succ", "dd",
                                             "dg", "demo", "t", "traj", "cam", "zref")}
    tasks, instrs = [], []
    cameras: list = []
    supports: list = []
    cam_keys: dict[bytes, int] = {}
    for di, name in enumerate(names):
        camera = f.camera_model(name)
        key = np.r_[np.ravel(camera.K), np.ravel(camera.T_world_cam)].tobytes()
        support = f.support_z(name)
        if key not in cam_keys:
            cam_keys[key] = len(cameras)
            cameras.append(camera)
            supports.append(support)
        elif support is not None and supports[cam_keys[key]] is not None:  # one camera over several tables: lowest
            supports[cam_keys[key]] = min(supports[cam_keys[key]], support)
        zref = height_reference(camera, height_ref)
        info = f.info(name)
        arr = f.read(name, _KEYS)
        T = info.num_samples
        rows, traj = keep(info, T)
        rows = rows & f.image_valid(name)  # a sample collected without an image is never a training frame
        track = track_from_arrays(arr)
        ctrack = None
        if "commanded" in (windows.global_path, windows.local_path):
            ctrack = commanded_track(track, f.commanded_targets(name), camera)
        gtrack = ctrack if windows.global_path == "commanded" else track
        ltrack = ctrack if windows.local_path == "commanded" else track
        gl, ll = global_labels(gtrack, windows), local_labels(ltrack, windows)
        pos = arr["obs/robot0_eef_pos"].astype(np.float32)
        gpos = gtrack.xyz_m.astype(np.float32)
        lpos = ltrack.xyz_m.astype(np.float32)
        grip = arr["obs/robot0_gripper_closed"].astype(np.float32)
        ids, _, _ = vocab.encode(info.instruction, max_tokens)
        ahead = np.minimum(np.arange(T) + direct_horizon, T - 1)
        r = np.flatnonzero(rows)
        cols["img"].append(f.images(name)[r])
        cols["tok"].append(np.repeat(ids[None], len(r), axis=0))
        cols["prop"].append(np.c_[arr["obs/robot0_joint_pos"], grip].astype(np.float32)[r])
        cols["g"].append((gl.uv_px[r], gl.z_m[r] - zref, gl.gripper_closed[r].astype(np.float32)))
        cols["l"].append((ll.uv_px[r], ll.z_m[r] - zref, ll.gripper_closed[r].astype(np.float32)))
        cols["gx"].append(gpos[gl.indices[r]])
        cols["lx"].append(lpos[ll.indices[r]])
        rot6 = camera_rot6(camera, quat_wxyz_to_matrix(arr["obs/robot0_eef_quat"]))  # (T, 6)
        cols["gr"].append(rot6[gl.indices[r]])
        cols["lr"].append(rot6[ll.indices[r]])
        cols["cam"].append(np.full(len(r), cam_keys[key]))
        cols["zref"].append(np.full(len(r), zref, np.float32))
        cols["succ"].append(arr["task_success"].astype(np.float32)[r])
        cols["dd"].append((pos[ahead] - pos)[r])
        cols["dg"].append(grip[ahead][r])
        cols["demo"].append(np.full(len(r), di))
        cols["t"].append(r)
        cols["traj"].append(traj[r])
        tasks.append(info.task)
        instrs.append(info.instruction)

    def cat(key, j=None):
        xs = cols[key] if j is None else [c[j] for c in cols[key]]
        return torch.from_numpy(np.ascontiguousarray(np.concatenate(xs, axis=0)))

    return FrameSet(
        images=cat("img"), tokens=cat("tok"), proprio=cat("prop"),
        g_uv=cat("g", 0).float(), g_z=cat("g", 1).float(), g_grip=cat("g", 2), g_xyz=cat("gx"), g_rot=cat("gr"),
        l_uv=cat("l", 0).float(), l_z=cat("l", 1).float(), l_grip=cat("l", 2), l_xyz=cat("lx"), l_rot=cat("lr"),
        success=cat("succ"), traj=np.concatenate(cols["traj"]), online=np.full(sum(map(len, cols["t"])), online),
        d_delta=cat("dd"), d_grip=cat("dg"),
        demo=np.concatenate(cols["demo"]), t=np.concatenate(cols["t"]), cam=np.concatenate(cols["cam"]),
        z_ref=np.concatenate(cols["zref"]), demos=names, tasks=tasks, instructions=instrs, cameras=cameras,
        camera_support_z=supports)


def concat_frames(sets: list[FrameSet]) -> FrameSet:
    """One FrameSet of several (demo indices renumbered so each still names its own demo)."""
    if len(sets) == 1:
        return sets[0]
    offsets = np.cumsum([0] + [len(s.demos) for s in sets[:-1]])
    cam_offsets = np.cumsum([0] + [len(s.cameras) for s in sets[:-1]])
    out = {}
    for fld in dataclasses.fields(FrameSet):
        vals = [getattr(s, fld.name) for s in sets]
        if fld.name == "demo":
            out["demo"] = np.concatenate([v + o for v, o in zip(vals, offsets)])
        elif fld.name == "cam":
            out["cam"] = np.concatenate([v + o for v, o in zip(vals, cam_offsets)])
        elif isinstance(vals[0], torch.Tensor):
            out[fld.name] = torch.cat(vals)
        elif isinstance(vals[0], np.ndarray):
            out[fld.name] = np.concatenate(vals)
        else:
            out[fld.name] = [x for v in vals for x in v]
    return FrameSet(**out)


def tasks_of(path: str | Path) -> frozenset[str]:
    """The tasks demo file ``path`` holds demos of (either split)."""
    with open_demos(path) as f:
        return frozenset(i.task for i in f.infos())


def instructions_of(path: str | Path, split: str = "train") -> list[str]:
    with open_demos(path) as f:
        return sorted({f.info(n).instruction for n in f.mask(split)})


def env_of(path: str | Path) -> tuple[dict, object, int]:
    """(env_args, planner CameraModel, dof) of a demo file (the camera: the file's, or its first demo's when every
    demo carries its own)."""
    with open_demos(path) as f:
        return dict(f.env_args), f.camera_model(), int(f.dof or 0)
