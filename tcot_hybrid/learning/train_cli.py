"""``tcot train`` on the command line: a TrainConfig from a file and flags, optionally collecting the
demonstrations first."""
from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import tyro

from tcot_hybrid.errors import ConfigError
from tcot_hybrid.learning.train import train
from tcot_hybrid.learning.train_config import TrainConfig, load_train_config


@dataclass(frozen=True, kw_only=True)
class TrainCommand:
    """Train the learned planner (or the direct baseline) and write a checkpoint.

    With --collect, first collects demonstrations with the oracle (``tcot collect``) into --cfg.data when
    the file does not exist yet: nothing → usable checkpoint in one command.
    """

    cfg: Annotated[TrainConfig, tyro.conf.arg(name="")] = field(default_factory=TrainConfig)
    config: Path | None = None
    """YAML/TOML/JSON file with TrainConfig fields; command-line flags override it."""
    collect: bool = False
    """Collect the demonstration file first if it is missing."""
    robot: str = "panda"
    """Robot to collect demonstrations with (only with --collect)."""
    episodes_per_task: int = 50
    """Demonstrations per task to collect (only with --collect); seeds 0 .. N-1."""
    workers: int = 2
    """Collection worker processes (only with --collect)."""
    overwrite: bool = False
    """Replace an existing checkpoint at --out (refused without this flag)."""
    resume: bool = False
    """Continue the run writing --out from its last finished epoch (``<out>.resume.pt``, written every epoch), e.g.
    after ``max_minutes`` cut it or it was killed; same config (``max_minutes`` and ``threads`` may change). Without a
    saved state the run starts afresh."""


def check_train_out(out: str | Path, *, overwrite: bool) -> None:
    """Before any training: refuse to replace an existing checkpoint unless asked, and make sure the
    checkpoint's folder can be written (read-only, a file where the folder belongs, disk full)."""
    from tcot_hybrid.errors import OutputError
    from tcot_hybrid.jsonio import check_output_file

    p = Path(out)
    existing = [x for x in (p, p.with_suffix(".json")) if x.exists() or x.is_symlink()]
    if existing and not overwrite:
        raise OutputError(f"--out {str(p)!r}: {', '.join(repr(str(x)) for x in existing)} already exist(s) (a trained "
                          f"checkpoint?); pass --overwrite to replace it, or choose another --out")
    check_output_file(p, what="--out")


def cmd_train(argv: list[str]) -> int:
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--config", type=Path)
    known, _ = pre.parse_known_args(argv)
    base = load_train_config(known.config) if known.config else TrainConfig()
    cmd = tyro.cli(TrainCommand, args=argv, default=TrainCommand(cfg=base, config=known.config), prog="tcot train")
    t0 = time.perf_counter()
    from tcot_hybrid.learning.train import resume_path

    resuming = cmd.resume and resume_path(cmd.cfg.out).is_file()
    check_train_out(cmd.cfg.out, overwrite=cmd.overwrite or resuming)
    data = Path(cmd.cfg.data)
    if cmd.collect and data.exists():
        from tcot_hybrid.learning.data import env_of

        have = env_of(data)[0].get("robot")
        if have != cmd.robot:
            raise ConfigError(f"--collect --robot {cmd.robot}: {str(data)!r} already holds {have!r} demonstrations; "
                              f"pass --data data/demos_{cmd.robot}.hdf5")
    if cmd.collect and not data.exists():
        from tcot_hybrid.data.collect import cmd_collect

        rc = cmd_collect(["--robot", cmd.robot, "--episodes-per-task", str(cmd.episodes_per_task),
                          "--seed-start", "0", "--workers", str(cmd.workers), "--out", str(data)])
        if rc != 0:
            return rc
        print(f"collection took {(time.perf_counter() - t0) / 60:.1f} min")
    elif not data.exists():
        raise ConfigError(f"demonstration file {str(data)!r} does not exist; run `tcot collect --out {data}` "
                          f"or add --collect")
    os.environ.setdefault("OMP_NUM_THREADS", str(cmd.cfg.threads))
    res = train(cmd.cfg, resume=cmd.resume)
    print(f"total time {(time.perf_counter() - t0) / 60:.1f} min -> {res.checkpoint}")
    return 0
