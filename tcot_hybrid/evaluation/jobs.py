"""Evaluation jobs: one episode's config per job, keyed for resuming, and the cross product (with sweeps)."""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import itertools
import typing
from pathlib import Path

from tcot_hybrid.config import coerce_field
from tcot_hybrid.errors import ConfigError, TcotError
from tcot_hybrid.run_config import RunConfig

CELL_KEYS = ("task", "suite", "planner", "mode", "perturb", "robot", "controller", "ik", "sweep")


@dataclasses.dataclass(frozen=True)
class Job:
    cfg: RunConfig
    sweep: str = "-"  # "field=value" when this job belongs to a sweep
    fixed_key: str | None = None  # the key as the parent process computed it (workers never recompute it)

    @property
    def perturb(self) -> str:
        return self.cfg.perturb.name

    @property
    def key(self) -> str:
        if self.fixed_key is not None:
            return self.fixed_key
        c = self.cfg
        ck = checkpoint_digest(c)
        return "|".join(map(str, (c.task, c.planner, c.supervisor.mode, self.perturb, c.robot, c.controller,
                                  c.ik, self.sweep, c.seed, c.digest(), task_code_digest(), *([ck] if ck else []))))


@functools.lru_cache(maxsize=1)
def task_code_digest() -> str:
    """Hash of the task package's source (layouts, success predicates, oracle scripts): an episode run with
    other task code is not credited on resume (e.g. the oracle's hook clearance changed)."""
    import hashlib

    from tcot_hybrid import libero, tasks

    h = hashlib.sha256()
    for pkg in (tasks, libero):  # LIBERO's goal-driven oracle lives in tcot_hybrid/libero
        for f in sorted(Path(pkg.__file__).parent.glob("*.py")):
            h.update(f.name.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]


def checkpoint_digest(cfg: RunConfig) -> str | None:
    """Hash of the checkpoint the job's planner will load (the shipped default or ``--checkpoint``): its weights
    and its JSON metadata, which holds inference settings too (e.g. ``model.readout_radius_cells``). None for
    planners without one, or when it cannot be resolved (the episode then records why)."""
    from tcot_hybrid.learning.checkpoint import meta_path
    from tcot_hybrid.planners import run_checkpoint

    try:
        path = run_checkpoint(cfg)
    except TcotError:
        return None
    if path is None or not path.is_file():
        return None
    parts = []
    for f in (path, meta_path(path)):
        if f.is_file():
            st = f.stat()
            parts.append(_digest_of(str(f.resolve()), st.st_mtime_ns, st.st_size))
    return hashlib.sha256("".join(parts).encode()).hexdigest()[:16]


@functools.lru_cache(maxsize=64)
def _digest_of(path: str, mtime_ns: int, size: int) -> str:  # keyed by mtime/size: a rewritten file is re-hashed
    from tcot_hybrid.episode import file_digest

    return file_digest(path)


# --- sweeps --------------------------------------------------------------------------------------------

def parse_sweep(spec: str) -> tuple[str, list[str]]:
    """"ik_params.damping=1e-3,1e-2" -> ("ik_params.damping", ["1e-3", "1e-2"])."""
    if "=" not in spec:
        raise ConfigError(f"--sweep {spec!r} must look like FIELD=V1,V2 (e.g. ik_params.damping=1e-3,1e-2)")
    field, values = spec.split("=", 1)
    vals = [v.strip() for v in values.split(",") if v.strip()]
    if not vals:
        raise ConfigError(f"--sweep {spec!r} lists no values")
    return field.strip().replace("-", "_"), vals


def with_field(cfg, path: str, raw: str):
    """A copy of the config tree with the dotted field ``path`` set from the string ``raw`` (typed and
    validated like a config file value)."""
    head, _, rest = path.partition(".")
    names = {f.name: f for f in dataclasses.fields(cfg)}
    if head not in names:
        raise ConfigError(f"--sweep: unknown field {head!r} in {type(cfg).__name__}; valid: {', '.join(sorted(names))}")
    hint = typing.get_type_hints(type(cfg))[head]
    if rest:
        sub = getattr(cfg, head)
        if not dataclasses.is_dataclass(sub):
            raise ConfigError(f"--sweep: {head!r} has no sub-fields")
        return dataclasses.replace(cfg, **{head: with_field(sub, rest, raw)})
    import yaml

    value = yaml.safe_load(raw)  # numbers, booleans and strings as in a config file
    return dataclasses.replace(cfg, **{head: coerce_field(path, hint, value)})


def make_jobs(base: RunConfig, *, tasks, planners, modes, robots, controllers, iks, episodes: int,
              seed_start: int, perturbs=("none",), sweep: str | None = None) -> list[Job]:
    """The cross product, every field validated by the config dataclasses before anything runs."""
    variants = [(base, "-")]
    if sweep:
        field, values = parse_sweep(sweep)
        variants = [(with_field(base, field, v), f"{field}={v}") for v in values]
    jobs = []
    for (cfg0, label), task, planner, mode, perturb, robot, ctrl, ik in itertools.product(
            variants, tasks, planners, modes, perturbs, robots, controllers, iks):
        for seed in range(seed_start, seed_start + episodes):
            cfg = dataclasses.replace(
                cfg0, task=task, planner=planner, robot=robot, controller=ctrl, ik=ik, seed=seed,
                supervisor=dataclasses.replace(cfg0.supervisor, mode=mode),
                perturb=dataclasses.replace(cfg0.perturb, name=perturb))
            jobs.append(Job(cfg, label))
    return jobs


