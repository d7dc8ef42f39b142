"""``tcot train``'s configuration: batch mixing, augmentation and the training run (stored as YAML/TOML/JSON;
every field is also a ``tcot train`` flag)."""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tcot_hybrid.config import require_choice, require_in_range, require_int, require_nonnegative, require_positive
from tcot_hybrid.data.labels import TrajectoryWindowConfig
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.learning.model import ModelConfig


TRAINABLE = ("all", "detect")


@dataclass(frozen=True, kw_only=True)
class MixConfig:
    """Fraction of each sample kind per batch (sums to 1). More of one kind = more of that objective."""

    global_frac: float = 0.6
    local_frac: float = 0.4
    detect_frac: float = 0.0

    def __post_init__(self) -> None:
        for name in ("global_frac", "local_frac", "detect_frac"):
            require_nonnegative(f"mix.{name}", getattr(self, name))
        total = self.global_frac + self.local_frac + self.detect_frac
        if not math.isclose(total, 1.0, abs_tol=1e-6):
            raise ConfigError(f"mix fractions must sum to 1, got {total} ({self})")

    def as_array(self) -> np.ndarray:
        return np.array([self.global_frac, self.local_frac, self.detect_frac])


@dataclass(frozen=True, kw_only=True)
class AugmentConfig:
    """Training-time augmentation (never at inference).

    shift_px:     random image translation in [-shift_px, shift_px] per axis, labels shifted with it [px].
                  Up: more translation invariance; too much teaches the wrong camera.
    brightness:   random brightness scale in [1 - b, 1 + b]. colour: per-channel gain in [1 - c, 1 + c].
    word_dropout: probability that an instruction word is replaced by <unk> (robustness to unseen words).
    """

    shift_px: int = 2
    brightness: float = 0.1
    colour: float = 0.05
    word_dropout: float = 0.1

    def __post_init__(self) -> None:
        require_int("augment.shift_px", self.shift_px, minimum=0)
        for name in ("brightness", "colour", "word_dropout"):
            require_nonnegative(f"augment.{name}", getattr(self, name))
        if self.word_dropout >= 1:
            raise ConfigError(f"augment.word_dropout must be < 1, got {self.word_dropout}")


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """One training run. Stored as YAML/TOML; every field is also a ``tcot train`` flag.

    data:            demonstration file (``tcot collect`` output) [path]
    extra_data:      further demonstration files (``tcot collect`` output, same robot and camera), e.g. more seeds
                     of the tasks a first-plan-at-t = 0 global plan gets wrong most (long, tool); split by seed
                     like ``data`` [paths]
    extra_data_replaces_tasks: a task with demos in an ``extra_data`` file is left out of ``data`` (both splits): its
                     demos there were collected again, e.g. after an oracle change (``tcot collect --tasks ...``
                     into a new file), and ``data`` keeps every other task's.
    extra_frame_stride: keep every k-th frame of an ``extra_data`` demo (every t = 0 frame is kept: k divides 0).
                     Up: less memory; the t = 0 scenes, where frozen global plans are made, stay complete.
    online_data:     further files of online episodes (``tcot collect --planner learned`` rollouts, oracle
                     recoveries under ``--perturb``): failure-detection frames from every episode, labelled by
                     the success predicate (paper eq. 7), and recovery trajectories from successful oracle
                     episodes after their perturbation [paths]
    online_frame_stride: keep every k-th frame of an online episode (neighbouring frames are nearly
                     identical; success frames are always kept). Up: less memory and load time, less data.
    suites:          train and validate on the demos (and online episodes) of these suites only, e.g.
                     ``[libero_10]`` for one model per LIBERO suite (the paper's TCoT row; its TCoT-Multi row is one
                     model for all four); empty = every demo. The vocabulary still comes from every training
                     instruction of ``data``, so a suite model can start from (``init``) a model of all suites.
    init:            start from this checkpoint's weights (same data vocabulary and model shape), e.g. stage 2
                     on online rollouts after a stage-1 run [path]; None = random init.
    out:             checkpoint to write (``.safetensors``; ``.json`` metadata and ``.metrics.jsonl`` next to it)
    kind:            "trajectory" (TCoT planner) or "direct" (next-action baseline)
    seed:            seeds weights, sampling and augmentation; same seed + data + config = same weights
                     (unless ``max_minutes`` cuts the run short)
    threads:         torch CPU threads; 0 = auto: each epoch times a few steps with 2 and with 1 thread
                     and keeps the faster (on a shared, busy machine 1 thread can be several times faster
                     than 2; set a fixed number for bit-reproducible runs)
    global_t0_frac:  fraction of global-mode samples drawn from t = 0 frames, where closed-loop global
                     plans are made. Up: better first plans, less practice on later steps.
    batch_size:      samples per step. Up: smoother gradients, slower steps.
    lr:              peak AdamW learning rate (one-cycle schedule). weight_decay: AdamW decay.
    max_epochs:      epochs (one epoch = ``epoch_samples`` samples). Up: better fit, longer.
    epoch_samples:   samples per epoch; None = as many as training frames. Set it when online data makes the
                     frame count large (fine-tuning needs fewer steps than a pass over every frame).
    max_minutes:     wall-clock cap [min]; stops after the current epoch's validation.
    patience:        stop after this many epochs without a better validation score.
    stage1_epochs:   epochs of stage 1 (trajectory only) before detection joins (trajectory kind only).
    mix_stage1/2:    batch composition per stage.
    recovery_frac:   fraction of local-prompt samples drawn from the recovery frames of ``online_data`` (when
                     there are any). Recovery states (e.g. the arm above an empty bowl after a drop) are a
                     small share of all frames and look like the end of a demonstration, where the local
                     label is "stay": up makes the local prompt recover, down keeps it closer to the demos.
    detect_ignore_before_success: detection negatives exclude the last k frames before an episode's first
                     success frame. The predicate needs the released object to be still, so those frames show
                     the same scene as the first success frames (object in place, gripper open) with the
                     opposite label; the detector learned to wait for the arm to move away and called the first
                     1-4 success steps failures. 0 = use every frame (rounds 1-2). Validation AUROC still
                     counts every frame.
    trainable:       "all" (every weight) or "detect": fine-tune the failure detector alone, i.e. only the weights
                     nothing but the detect prompt reads (``model.detect_head`` and the detect mode's embedding
                     row; needs ``model.detect_head: true``, ``stage1_epochs: 0`` and a detect-only
                     ``mix_stage2``). Every global and local output stays bit-identical to ``init``'s, so new
                     success labels (e.g. stricter predicates) reach the detector without touching the plans.
    direct_horizon:  direct kind: predict the TCP displacement over this many planner steps.
    max_train_demos: use only the first N training demos (quick experiments, tests); None = all.
    val_max_frames:  validation frames per epoch (every k-th frame; all t = 0 frames kept). Down: faster epochs.
    bf16:            bf16 autocast + channels_last where the CPU computes bf16 natively (AVX512-BF16/AMX: measured
                     ~2-3x faster than fp32); on other CPUs the run says so and trains in fp32 (emulated bf16 is
                     slower: 3.4x on an AVX2 EPYC).
    heatmap_ce:      weight of a cross-entropy term pulling each heatmap toward a 1-cell Gaussian at its
                     label (a shape prior for soft-argmax; 0 = coordinate loss only).
    max_unknown_fraction: stored in the checkpoint; the planner refuses instructions with more unknown words.
    height_ref:      what the lift cue z_m is measured from: "world" (world z; the workcell's table top is z = 0) or
                     "camera" (the planner camera's height: LIBERO's tables stand at 0, 0.42 or 0.9 m, each scene
                     with its own camera pose). Stored in the checkpoint; the planner lifts with it.
    model:           architecture knobs (vocab_size, dof, n_global, n_local, image_px are filled from the data).
    windows:         label windows (paper eq. 4/5).
    """

    data: str = "data/demos_panda.hdf5"
    extra_data: tuple[str, ...] = ()
    extra_data_replaces_tasks: bool = False
    extra_frame_stride: int = 1
    online_data: tuple[str, ...] = ()
    online_frame_stride: int = 2
    suites: tuple[str, ...] = ()
    init: str | None = None
    out: str = "runs/train/planner.safetensors"
    kind: str = "trajectory"
    seed: int = 0
    threads: int = 0
    batch_size: int = 64
    lr: float = 3e-3
    weight_decay: float = 1e-4
    max_epochs: int = 7
    epoch_samples: int | None = None
    max_minutes: float = 11.0
    patience: int = 4
    stage1_epochs: int = 3
    global_t0_frac: float = 0.25
    mix_stage1: MixConfig = field(default_factory=MixConfig)
    mix_stage2: MixConfig = field(default_factory=lambda: MixConfig(global_frac=0.5, local_frac=0.3, detect_frac=0.2))
    recovery_frac: float = 0.6
    detect_ignore_before_success: int = 0
    trainable: str = "all"
    direct_horizon: int = 3
    max_train_demos: int | None = None
    val_max_frames: int = 2000
    bf16: bool = True
    heatmap_ce: float = 0.5
    max_unknown_fraction: float = 0.5
    height_ref: str = "world"
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    windows: TrajectoryWindowConfig = field(default_factory=TrajectoryWindowConfig)

    def __post_init__(self) -> None:
        require_choice("kind", self.kind, ("trajectory", "direct"))
        require_choice("height_ref", self.height_ref, ("world", "camera"))
        for name in ("seed",):
            require_int(name, getattr(self, name), minimum=0)
        for name in ("batch_size", "max_epochs", "patience", "direct_horizon", "val_max_frames", "online_frame_stride",
                     "extra_frame_stride"):
            require_int(name, getattr(self, name), minimum=1)
        require_int("threads", self.threads, minimum=0)
        require_int("detect_ignore_before_success", self.detect_ignore_before_success, minimum=0)
        for name, what in (("extra_data", "files"), ("online_data", "files"), ("suites", "suite names")):
            value = getattr(self, name)
            if isinstance(value, str):  # would otherwise be split into its letters
                raise ConfigError(f"{name} must be a list of {what}, got the string {value!r} (write [{value}])")
        for name in ("extra_data", "online_data", "suites"):  # YAML gives a list
            object.__setattr__(self, name, tuple(str(p) for p in getattr(self, name)))
        if self.extra_data_replaces_tasks and not self.extra_data:
            raise ConfigError("extra_data_replaces_tasks needs extra_data (the files whose tasks replace data's)")
        if self.epoch_samples is not None:
            require_int("epoch_samples", self.epoch_samples, minimum=self.batch_size)
        for name in ("global_t0_frac", "recovery_frac"):
            require_in_range(name, getattr(self, name), 0.0, 1.0)
        require_int("stage1_epochs", self.stage1_epochs, minimum=0)
        for name in ("lr", "max_minutes"):
            require_positive(name, getattr(self, name))
        for name in ("weight_decay", "heatmap_ce"):
            require_nonnegative(name, getattr(self, name))
        require_in_range("max_unknown_fraction", self.max_unknown_fraction, 0.0, 1.0, high_closed=False)
        if not str(self.out).endswith(".safetensors"):
            raise ConfigError(f"out must end in .safetensors, got {self.out!r}")
        if self.kind == "direct" and self.model.kind != "direct":
            object.__setattr__(self, "model", dataclasses.replace(self.model, kind="direct"))
        if self.kind == "trajectory" and self.model.kind != "trajectory":
            raise ConfigError("model.kind must be 'trajectory' when kind is 'trajectory'")
        require_choice("trainable", self.trainable, TRAINABLE)
        if self.trainable == "detect":
            need = {"kind": (self.kind, "trajectory"), "model.detect_head": (self.model.detect_head, True),
                    "stage1_epochs": (self.stage1_epochs, 0), "mix_stage2.detect_frac": (self.mix_stage2.detect_frac, 1.0)}
            bad = [f"{k} = {v!r} (needs {want!r})" for k, (v, want) in need.items() if v != want]
            if bad:
                raise ConfigError(f"trainable 'detect' (fine-tune the detector alone) needs: {'; '.join(bad)}")
            if self.init is None:
                raise ConfigError("trainable 'detect' fine-tunes a trained planner's detector: set init to its checkpoint")


def load_train_config(path: str | Path) -> TrainConfig:
    """TrainConfig from YAML/TOML/JSON (unknown keys and wrong types name the field; size, alias expansion,
    nesting and duplicate keys bounded as for run configs)."""
    from tcot_hybrid.config import from_mapping
    from tcot_hybrid.run_config import read_config_file

    p = Path(path)
    data = read_config_file(p, what="train config")
    try:
        return from_mapping(TrainConfig, data or {})
    except ConfigError as exc:
        raise ConfigError(f"train config {str(p)!r}: {exc}") from exc
