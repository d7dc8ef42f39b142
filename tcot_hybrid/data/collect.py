"""``tcot collect``: run the oracle through the real motion stack and record demonstrations to HDF5.

Each worker process (multiprocessing "spawn") runs whole episodes and returns arrays; the parent is
the only writer. A demo is written under ``/data/_partial_<n>`` and renamed to ``/data/demo_<i>`` only
once every dataset and attribute is in place, and the file is flushed after every demo, so an
interrupted collection leaves complete demos plus at most one partial group, which the next run with
the same ``--out`` deletes before collecting the missing (task, seed) pairs.

Sample ``t`` is the state at the start of planner step ``t`` (``pre_step_hook``), plus the final state
after the last step. See docs/dataset.md for the layout.
"""
from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before anything imports mujoco (spawned workers too)

import argparse  # noqa: E402
import contextlib  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from tcot_hybrid.data.dataset import (  # noqa: E402
    DEMO_PREFIX, FORMAT, PARTIAL_PREFIX, PER_DEMO, VALID_EVERY, DemoFile, env_difference, image_key,
    is_valid_seed,
)
from tcot_hybrid.config import require_int  # noqa: E402
from tcot_hybrid.errors import ConfigError, DatasetError  # noqa: E402
from tcot_hybrid.workers import one_torch_thread, worker_pool  # noqa: E402

STEPS_AFTER_SUCCESS = 5  # planner steps recorded after the task predicate first holds
# ... and on LIBERO, before those, the plan is carried out (at most this many planner steps): LIBERO judges several
# tasks done while the object is still held (butter in the basket, the book in the caddy), and demos that stopped
# there taught plans with no release (docs/libero-planner.md, "Demonstrations through the release"). The workcell's
# goals hold only once the object is released, and its shipped data and tables were collected without it.
FINISH_PLAN_STEPS = {"libero": 60, "workcell": 0}
TRAIN_SEED_LIMIT = 1000  # workcell seeds >= this are evaluation seeds: never collect training data on them
# LIBERO: sampled layouts 0-49999 are for training and tuning, 90000+ report (docs/seeds.md); the shipped init
# states are the test set and are never collected.
LIBERO_TRAIN_SEED_LIMIT = 50000
SCENE_BLOCK = 5  # LIBERO: seeds of one task collected in a row (scene reuse), see collect()
GZIP_LEVEL = 4  # measured on 128x128 frames: 6.5 KB/frame vs 10.5 KB with lzf, same read speed


@dataclass(frozen=True)
class DemoRecord:
    """One recorded episode: demo attributes, arrays keyed by path inside the demo group, env args."""

    attrs: dict
    arrays: dict
    env_args: dict
    wall_s: float


def collection_hash(cfg) -> str:
    """Hash of the run config with the per-episode fields (task, seed, perturbation) blanked: one value per
    file. The perturbation is per episode (demo attributes ``perturb``, ``perturb_step``, ``recover_step``)."""
    from tcot_hybrid.perturbations import PerturbConfig

    return dataclasses.replace(cfg, task="*", seed=0, perturb=PerturbConfig()).digest()


def _quat_wxyz(xmat: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.asarray(xmat, dtype=float).reshape(9))
    return q


def record_demo(cfg, *, steps_after_success: int = STEPS_AFTER_SUCCESS, progress=None,
                image_every: int = 1, finish_plan_steps: int | None = None) -> DemoRecord:
    """Run one episode of ``cfg`` and return its samples (see module doc). Raises on a crash.

    ``image_every`` > 1 renders the planner image only at every k-th sample and the last one (rendering a
    LIBERO scene costs 28-80 ms a frame, the rest of a sample microseconds): the other samples keep their
    robot state and track (labels need the whole track) with a black frame, and ``obs/image_valid`` marks
    the rendered ones. Loaders never train on a frame without an image.

    After a success reached with the gripper closed the plan is carried out (``finish_plan_steps``, None: the world's
    ``FINISH_PLAN_STEPS``). Only a release that keeps the success is kept: when the gripper stays closed (a knob
    turned, a door pushed shut: the rest of the plan is a retreat, which would thin the labelled points of the motion
    that mattered) or the release undoes the success (the book tips out of the caddy's compartment), the episode is
    recorded again, ending a few steps after success as before."""
    require_int("image_every", image_every, minimum=1)
    from tcot_hybrid.episode import EpisodeRunner

    t0 = time.perf_counter()
    runner = EpisodeRunner(cfg)
    s = runner.stack
    sim, cam, task = s.sim, s.camera, s.task
    px = cfg.scene.planner_image_px
    camera = cfg.scene.planner_camera
    rows: list[dict] = []
    steps_seen: list[int] = []

    def sample(r, step: int) -> None:
        if steps_seen and steps_seen[-1] == step:  # never record one state twice
            return
        tcp = sim.tcp_pos()
        uv, depth = cam.project(tcp[None])
        ex = s.executor
        rendered = len(rows) % image_every == 0
        rows.append({
            "image": sim.render(camera, px, px) if rendered else None, "rendered": rendered,
            "q": sim.q, "qd": sim.qd, "eef_pos": tcp,
            "eef_quat": _quat_wxyz(sim.data.site_xmat[sim.ee_site]),
            "gripper_qpos": sim.data.qpos[sim.gripper_qpos].copy(),
            "gripper_closed": sim.gripper_closed_cmd(),
            "target": ex.points[ex.index].copy() if 0 <= ex.index < len(ex.points) else tcp,
            "uv": uv[0], "depth": depth[0],
            "success": bool(task.success(sim.world)),
        })
        steps_seen.append(step)

    runner.pre_step_hook = sample
    if finish_plan_steps is None:
        finish_plan_steps = FINISH_PLAN_STEPS[task.world_kind]
    rec = runner.run(progress, steps_after_success=steps_after_success, finish_plan_steps=finish_plan_steps)
    first = next((r for r in rows if r["success"]), None)
    finished = finish_plan_steps and rec["success"] and first is not None and first["gripper_closed"]
    if finished and (sim.gripper_closed_cmd() or not task.success(sim.world)):
        sim.close()  # this scene is done with: the episode is recorded again in a fresh one
        return record_demo(cfg, steps_after_success=steps_after_success, progress=progress, image_every=image_every,
                           finish_plan_steps=0)
    if not steps_seen or steps_seen[-1] < runner.steps:  # the final state was not sampled (abort path)
        sample(runner, runner.steps)
    if not rows[-1]["rendered"]:  # the last sample is the state the episode ended in: always render it
        rows[-1]["image"], rows[-1]["rendered"] = sim.render(camera, px, px), True
    blank = np.zeros((px, px, 3), np.uint8)
    n = len(rows)
    eef = np.array([r["eef_pos"] for r in rows], dtype=np.float32)
    grip = np.array([r["gripper_closed"] for r in rows], dtype=np.uint8)
    succ = np.array([r["success"] for r in rows], dtype=np.uint8)
    actions = np.zeros((n, 4), dtype=np.float32)
    actions[:-1, :3] = eef[1:] - eef[:-1]
    actions[:-1, 3] = grip[1:]
    actions[-1, 3] = grip[-1]  # the last sample holds: no motion, same gripper
    arrays = {
        "obs/" + image_key(camera): np.stack([blank if r["image"] is None else r["image"] for r in rows]).astype(np.uint8),
        "obs/robot0_joint_pos": np.array([r["q"] for r in rows], dtype=np.float32),
        "obs/robot0_joint_vel": np.array([r["qd"] for r in rows], dtype=np.float32),
        "obs/robot0_eef_pos": eef,
        "obs/robot0_eef_quat": np.array([r["eef_quat"] for r in rows], dtype=np.float32),
        "obs/robot0_gripper_qpos": np.array([r["gripper_qpos"] for r in rows], dtype=np.float32),
        "obs/robot0_gripper_closed": grip,
        "obs/eef_uv_px": np.array([r["uv"] for r in rows], dtype=np.float32),
        "obs/eef_depth_m": np.array([r["depth"] for r in rows], dtype=np.float32),
        "obs/tcp_target_pos": np.array([r["target"] for r in rows], dtype=np.float32),
        "task_success": succ,
        "actions": actions,
    }
    if image_every > 1:
        arrays["obs/image_valid"] = np.array([r["rendered"] for r in rows], dtype=np.uint8)
    hits = np.flatnonzero(succ)
    fired = [e["step"] for e in s.executor.events if e["kind"] == "perturbation"]
    # first plan made at or after the perturbation: from there on the track shows the recovery
    replans = [e["step"] for e in s.executor.events if e["kind"] == "plan_adopted" and fired and e["step"] >= fired[0]]
    attrs = {
        "task": cfg.task, "suite": task.suite, "instruction": task.instruction, "seed": int(cfg.seed),
        "init": task.init,
        "robot": cfg.robot, "planner": cfg.planner, "mode": cfg.supervisor.mode,
        "perturb": str(getattr(getattr(cfg, "perturb", None), "name", "none")),
        "source": "demo" if cfg.planner == "oracle" else "rollout",
        "perturb_step": int(fired[0]) if fired else -1,
        "recover_step": int(replans[0]) if replans else -1,
        "success": bool(rec["success"]), "t_success": int(hits[0]) if hits.size else -1, "num_samples": n,
        "fault": rec.get("fault") or "",
        # this demo's planner camera and support height: LIBERO's agentview takes four poses across its scenes
        "K": np.asarray(cam.K, dtype=float), "T_world_cam": np.asarray(cam.T_world_cam, dtype=float),
        "support_z": float(sim.support_z),
    }
    env_args = {
        "robot": cfg.robot, "camera": camera, "K": cam.K.tolist(), "T_world_cam": cam.T_world_cam.tolist(),
        "width": cam.width, "height": cam.height, "near_m": cam.near_m, "far_m": cam.far_m,
        "sim_dt": cfg.timing.sim_dt, "ctrl_dt": cfg.timing.ctrl_dt, "plan_dt": cfg.timing.plan_dt,
        "config_hash": collection_hash(cfg), "controller": cfg.controller, "ik": cfg.ik,
        "world": task.world_kind,
        # K / T_world_cam above are the first demo's; on LIBERO every demo's own are its attributes
        PER_DEMO: task.world_kind == "libero",
    }
    sim.close()
    return DemoRecord(attrs=attrs, arrays=arrays, env_args=env_args, wall_s=time.perf_counter() - t0)


def _worker(job):
    """Pool entry point: never raises (a crash is reported back and that pair is retried next run)."""
    cfg, image_every = job
    try:
        return "ok", record_demo(cfg, image_every=image_every)
    except Exception as exc:  # noqa: BLE001 - reported by the parent
        return "crash", (cfg.task, cfg.seed, f"{type(exc).__name__}: {exc}")


# --- the writer ----------------------------------------------------------------------------------------

def _image_chunks(shape: tuple) -> tuple:
    return (1, *shape[1:])  # one frame per chunk: random frame access decompresses one image


def write_demo(h5, rec: DemoRecord, *, compression: str = "gzip") -> str:
    """Append ``rec`` to the open file ``h5`` as the next ``demo_<i>`` (written as partial, then renamed)."""
    data = h5["data"]
    names = [n for n in data if n.startswith(DEMO_PREFIX)]
    index = 1 + max((int(n[len(DEMO_PREFIX):]) for n in names), default=-1)
    tmp = f"{PARTIAL_PREFIX}{index}"
    if tmp in data:
        del data[tmp]
    g = data.create_group(tmp)
    for key, arr in rec.arrays.items():
        if arr.ndim == 4:  # images
            g.create_dataset(key, data=arr, chunks=_image_chunks(arr.shape), compression=compression,
                             compression_opts=GZIP_LEVEL if compression == "gzip" else None)
        else:
            g.create_dataset(key, data=arr)
    for key, value in rec.attrs.items():
        g.attrs[key] = value
    name = f"{DEMO_PREFIX}{index}"
    data.move(tmp, name)  # the demo becomes visible only now
    data.attrs["total"] = len(names) + 1
    h5.flush()
    return name


def write_masks(h5, *, valid_every: int = VALID_EVERY) -> tuple[int, int]:
    """Recompute /mask/train and /mask/valid: successful demos split by seed. Returns (n_train, n_valid)."""
    data = h5["data"]
    train, valid = [], []
    names = sorted((n for n in data if n.startswith(DEMO_PREFIX)), key=lambda n: int(n[len(DEMO_PREFIX):]))
    for name in names:
        a = data[name].attrs
        if not bool(a["success"]):
            continue  # failed episodes stay in the file (useful later) but are not training demos
        (valid if is_valid_seed(int(a["seed"]), valid_every) else train).append(name)
    if "mask" in h5:
        del h5["mask"]
    m = h5.create_group("mask")
    m.create_dataset("train", data=np.array(train, dtype="S"))
    m.create_dataset("valid", data=np.array(valid, dtype="S"))
    m.attrs["valid_every"] = int(valid_every)
    h5.flush()
    return len(train), len(valid)


def _open_for_append(path: Path):
    """Open (or create) ``path`` for writing; validate what is there and drop partial demo groups."""
    import h5py

    from tcot_hybrid import __version__

    if path.exists():
        DemoFile(path, _allow_partial=True).close()  # layout check with a clear error before writing
        try:
            h5 = h5py.File(path, "a")
        except (OSError, ValueError) as exc:
            raise DatasetError(f"demo file {path} cannot be opened for writing ({exc})") from exc
        data = h5["data"]
        for name in [n for n in data if not n.startswith(DEMO_PREFIX)]:
            del data[name]  # an interrupted write: that demo is collected again
        data.attrs["total"] = sum(1 for n in data if n.startswith(DEMO_PREFIX))
        return h5
    path.parent.mkdir(parents=True, exist_ok=True)
    h5 = h5py.File(path, "w")
    h5.attrs["format"] = FORMAT
    h5.attrs["tcot_version"] = __version__
    data = h5.create_group("data")
    data.attrs["total"] = 0
    return h5


def _existing_episodes(h5) -> set[tuple[str, int, str]]:
    """(task, seed, perturbation) of every complete demo in the file."""
    data = h5["data"]
    return {(str(data[n].attrs["task"]), int(data[n].attrs["seed"]), str(data[n].attrs["perturb"]))
            for n in data if n.startswith(DEMO_PREFIX)}


def _check_env(path: Path, h5, env_args: dict) -> None:
    """First demo sets the file's env_args; later demos must match (one robot/camera/config per file)."""
    data = h5["data"]
    if "env_args" not in data.attrs:
        data.attrs["env_args"] = json.dumps(env_args)
        return
    have = json.loads(data.attrs["env_args"])
    diff = env_difference(have, env_args, ("robot", "camera", "width", "height", "sim_dt", "ctrl_dt", "plan_dt",
                                           "config_hash"))
    if diff:
        raise DatasetError(f"demo file {path} was collected with {diff} (this run); use another --out or the "
                           f"same settings")


def _precheck_env(path: Path, h5, cfg) -> None:
    """Refuse, before running any episode, to append to a file collected with other settings."""
    if "env_args" not in h5["data"].attrs:
        return
    have = json.loads(h5["data"].attrs["env_args"])
    want = {"robot": cfg.robot, "camera": cfg.scene.planner_camera, "width": cfg.scene.planner_image_px,
            "height": cfg.scene.planner_image_px, "sim_dt": cfg.timing.sim_dt, "ctrl_dt": cfg.timing.ctrl_dt,
            "plan_dt": cfg.timing.plan_dt, "config_hash": collection_hash(cfg)}
    for key, value in want.items():
        if have.get(key) != value:
            raise DatasetError(f"demo file {path} was collected with {key} = {have.get(key)!r}, this run has "
                               f"{value!r}; use another --out or the same settings")


@dataclass(frozen=True)
class CollectSummary:
    """What a collection run did. Times in [s]; throughput figures per wall-clock second."""

    path: Path
    requested: int
    already_present: int
    written: int
    failed_episodes: int
    crashes: list
    n_train: int
    n_valid: int
    wall_s: float
    samples: int
    bytes_written: int

    def line(self) -> str:
        rate = self.written / self.wall_s if self.wall_s > 0 else 0.0
        srate = self.samples / self.wall_s if self.wall_s > 0 else 0.0
        return (f"{self.path}: {self.written} demos written ({self.already_present} already present, "
                f"{self.failed_episodes} unsuccessful kept, {len(self.crashes)} crashed) in {self.wall_s:.1f} s = "
                f"{rate:.2f} demos/s, {srate:.0f} samples/s, {self.bytes_written / 2**20:.1f} MiB; "
                f"masks: {self.n_train} train / {self.n_valid} valid")


MIN_FREE_BYTES = 16 * 2**20
"""[bytes] free space kept on the output's disk beyond one demo's uncompressed size: HDF5 crashes the
process when a write hits a full disk, so collection stops before that with a clear error."""


def _check_room(path: Path, rec, written: int) -> None:
    need = MIN_FREE_BYTES + (sum(a.nbytes for a in rec.arrays.values()) if rec is not None else 0)
    free = shutil.disk_usage(path.parent).free
    if free < need:
        raise DatasetError(f"the disk holding {path} is (nearly) full: {free / 2**20:.1f} MiB free, a demo needs up "
                           f"to {need / 2**20:.1f} MiB; stopped before writing. The {written} demos written in this "
                           f"run and all earlier ones are kept; free space and re-run the same command to resume")


def collect(base_cfg, *, tasks: list[str], seeds: list[int], out: str | Path, workers: int = 2,
            valid_every: int = VALID_EVERY, compression: str = "gzip", progress: bool = True,
            perturbs: list[str] | None = None, image_every: int = 1) -> CollectSummary:
    """Collect one episode per (task, seed, perturbation) not yet in ``out`` (resumable). ``perturbs``
    defaults to the base config's perturbation. Returns a summary."""
    from tqdm import tqdm

    from tcot_hybrid.tasks import is_libero_task

    path = Path(out)
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    if valid_every < 2:
        raise ConfigError(f"valid_every must be >= 2 (every seed would be validation), got {valid_every}")
    if compression not in ("lzf", "gzip"):
        raise ConfigError(f"compression = {compression!r} is not valid; choose one of lzf, gzip")
    require_int("image_every", image_every, minimum=1)
    t0 = time.perf_counter()
    h5 = _open_for_append(path)
    size0 = path.stat().st_size
    written = failed = samples = 0
    write_failed = False
    crashes: list = []
    n_train = n_valid = 0
    try:
        _precheck_env(path, h5, base_cfg)
        done = _existing_episodes(h5)
        perturbs = perturbs or [base_cfg.perturb.name]
        # seed-major: an interruption leaves tasks and perturbations balanced. A LIBERO scene takes 2-4 s to
        # build and a worker reuses its last ones: there, blocks of SCENE_BLOCK seeds run task by task, and a
        # worker takes a block of one task at a time (chunksize)
        block = SCENE_BLOCK if any(is_libero_task(t) for t in tasks) else 1
        pairs = [(t, s, p) for b in range(0, len(seeds), block) for t in tasks for s in seeds[b:b + block]
                 for p in perturbs] if block > 1 else [(t, s, p) for s in seeds for p in perturbs for t in tasks]
        todo = [key for key in pairs if key not in done]
        cfgs = [dataclasses.replace(base_cfg, task=t, seed=s, perturb=dataclasses.replace(base_cfg.perturb, name=p))
                for (t, s, p) in todo]
        with contextlib.ExitStack() as stack:
            if workers == 1 or len(cfgs) <= 1:
                stack.enter_context(one_torch_thread())
                results = map(_worker, [(c, image_every) for c in cfgs])
            else:
                pool = stack.enter_context(worker_pool(min(workers, len(cfgs)), maxtasksperchild=40))
                results = pool.imap_unordered(_worker, [(c, image_every) for c in cfgs],
                                              chunksize=block * len(perturbs) if block > 1 else 1)
            with tqdm(total=len(pairs), initial=len(pairs) - len(todo), desc=f"collect {path.name}", unit="demo",
                      disable=not progress) as bar:
                for status, payload in results:
                    if status == "crash":
                        crashes.append(payload)
                        bar.write(f"crash: task={payload[0]} seed={payload[1]}: {payload[2]}")
                    else:
                        _check_env(path, h5, payload.env_args)
                        _check_room(path, payload, written)
                        try:
                            write_demo(h5, payload, compression=compression)
                        except OSError as exc:  # HDF5 write failed (e.g. the disk filled up under us)
                            write_failed = True
                            raise DatasetError(f"writing a demo to {path} failed ({exc}); the {written} demos "
                                               f"written before are kept, re-run the same command to resume") from exc
                        written += 1
                        failed += not payload.attrs["success"]
                        samples += payload.attrs["num_samples"]
                    bar.update(1)
        present = len(done)
    finally:
        if write_failed:  # don't write more into a file whose last write failed; just close it
            with contextlib.suppress(Exception):
                h5.close()
        else:
            try:
                stale = (written or "mask" not in h5
                         or int(h5["mask"].attrs.get("valid_every", -1)) != valid_every)
                if "env_args" in h5["data"].attrs and stale:
                    _check_room(path, None, written)
                    n_train, n_valid = write_masks(h5, valid_every=valid_every)
                elif "mask" in h5:
                    n_train, n_valid = len(h5["mask/train"]), len(h5["mask/valid"])
            finally:
                h5.close()
    wall = time.perf_counter() - t0
    return CollectSummary(path=path, requested=len(pairs), already_present=present, written=written,
                          failed_episodes=failed, crashes=crashes, n_train=n_train, n_valid=n_valid, wall_s=wall,
                          samples=samples, bytes_written=path.stat().st_size - size0)


# --- the command ---------------------------------------------------------------------------------------

def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="tcot collect", description=(
        "Record oracle demonstrations (planner image + robot state per planner step) to an HDF5 file. "
        "Re-running with the same --out keeps the demos already there and collects only missing "
        "(task, seed) pairs."))
    p.add_argument("--tasks", help="comma-separated task names (default: all tasks)")
    p.add_argument("--suite", help="every task of these comma-separated suites (instead of --tasks); LIBERO "
                                   "suites collect sampled layouts, never the shipped init states (the test set)")
    p.add_argument("--robot", help="robot name (default: the tasks' own: panda, libero_panda on LIBERO)")
    p.add_argument("--controller", help="low-level controller (default: the config's)")
    p.add_argument("--ik", help="IK backend (default: the config's)")
    p.add_argument("--planner", default=None,
                   help="planner that drives the episodes (default oracle = demonstrations; "
                        "anything else is recorded as source=rollout)")
    p.add_argument("--checkpoint", help="checkpoint for a learned planner")
    p.add_argument("--mode", help="supervisor mode (default: the config's, global)")
    p.add_argument("--init", choices=("sampled", "spread"),
                   help="layouts (default sampled): spread = LIBERO layouts whose objects range wider than LIBERO's "
                        "own regions (tcot_hybrid.libero.tasks.LAYOUT_SPREAD)")
    p.add_argument("--perturb", help="comma-separated perturbations, one episode per (task, seed, perturbation) "
                                     "(default: the config's, none); `tcot list` shows them")
    p.add_argument("--episodes-per-task", type=int, default=50, help="seeds per task (default 50)")
    p.add_argument("--seed-start", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--valid-every", type=int, default=VALID_EVERY,
                   help=f"seed %% N == 0 goes to the validation mask (default {VALID_EVERY})")
    p.add_argument("--compression", default="gzip", choices=("lzf", "gzip"),
                   help="image compression (default gzip level 4: ~40%% smaller than lzf, same read speed)")
    p.add_argument("--image-every", type=int, default=1,
                   help="render the planner image only every N-th sample and the last (default 1: every sample); "
                        "the others keep state and track, marked in obs/image_valid (LIBERO frames cost 28-80 ms)")
    p.add_argument("--config", type=Path, help="YAML/TOML/JSON RunConfig shared by every episode")
    p.add_argument("--out", type=Path, help="output file (default data/demos_<robot>.hdf5)")
    p.add_argument("--allow-eval-seeds", action="store_true",
                   help=f"allow seeds >= {TRAIN_SEED_LIMIT} ({LIBERO_TRAIN_SEED_LIMIT} on LIBERO) (evaluation seeds; "
                        "never train on them)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def cmd_collect(argv: list[str]) -> int:
    from tcot_hybrid.episode import validate_names
    from tcot_hybrid.perturbations import PerturbConfig
    from tcot_hybrid.run_config import RunConfig, load_config_file
    from tcot_hybrid.tasks import default_robot, is_libero_task, list_tasks, suite_task_names

    args = _parser().parse_args(argv)
    base = load_config_file(args.config) if args.config else RunConfig()
    if args.suite and args.tasks:
        raise ConfigError("give --suite or --tasks, not both")
    all_tasks = list_tasks()
    if args.suite:
        tasks = [name for suite in args.suite.split(",") if suite.strip() for name in suite_task_names(suite.strip())]
    elif args.tasks:
        tasks = [t.strip() for t in args.tasks.split(",") if t.strip()]
    else:
        tasks = [t.name for t in all_tasks]
    worlds = {is_libero_task(t) for t in tasks}
    if len(worlds) > 1:
        raise ConfigError("one demo file holds one robot and world: collect the workcell's and LIBERO's tasks into "
                          "separate files (two runs)")
    libero = worlds == {True}
    over = {k: getattr(args, k) for k in ("robot", "controller", "ik", "planner", "checkpoint")
            if getattr(args, k) is not None}
    if "robot" not in over and base.robot == default_robot(base.task):  # robot auto: the tasks' own
        over["robot"] = default_robot(tasks[0])
    if args.mode is not None:
        over["supervisor"] = dataclasses.replace(base.supervisor, mode=args.mode)
    init = args.init or base.init
    if libero:
        if init == "shipped":
            raise ConfigError("LIBERO's shipped init states are the test set (docs/seeds.md): training data uses "
                              "sampled layouts (--init sampled or spread)")
        over["init"] = init or "sampled"
    elif args.init is not None:
        over["init"] = args.init  # the task refuses a mode it does not know, naming its own
    base = dataclasses.replace(base, **over)
    if args.episodes_per_task < 1 or args.seed_start < 0:
        raise ConfigError(f"--episodes-per-task must be >= 1 and --seed-start >= 0; got "
                          f"{args.episodes_per_task}, {args.seed_start}")
    seeds = list(range(args.seed_start, args.seed_start + args.episodes_per_task))
    limit = LIBERO_TRAIN_SEED_LIMIT if libero else TRAIN_SEED_LIMIT
    if seeds[-1] >= limit and not args.allow_eval_seeds:
        raise ConfigError(f"seeds {seeds[0]}..{seeds[-1]} reach the evaluation range (>= {limit}); "
                          f"training data must use seeds < {limit} (--allow-eval-seeds to override)")
    for t in tasks:
        validate_names(dataclasses.replace(base, task=t))
    out = args.out or Path("data") / f"demos_{base.robot}.hdf5"
    from tcot_hybrid.jsonio import check_output_file

    check_output_file(out, what="--out")  # read-only, a directory, a full disk: found before any episode
    perturbs = [p.strip() for p in args.perturb.split(",") if p.strip()] if args.perturb else None
    for name in perturbs or []:
        PerturbConfig(name=name)  # unknown names fail here, listing the valid ones
    summary = collect(base, tasks=tasks, seeds=seeds, out=out, workers=args.workers, valid_every=args.valid_every,
                      image_every=args.image_every,
                      compression=args.compression, progress=not args.quiet, perturbs=perturbs)
    print(summary.line())
    for task, seed, msg in summary.crashes:
        print(f"  crashed: {task} seed {seed}: {msg} (re-run to retry)")
    return 0 if not summary.crashes else 1


__all__ = ["CollectSummary", "DemoRecord", "cmd_collect", "collect", "record_demo", "write_demo", "write_masks"]
