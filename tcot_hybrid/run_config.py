"""The config tree of one run: component configs composed, loadable from YAML/TOML, overridable on the CLI.

Stored files are only a way to write this tree down: loading validates every key (unknown keys and
wrong types name the field), refuses YAML tags, and then each component's ``__post_init__`` checks
ranges. Nothing moves before the whole tree is valid.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from tcot_hybrid.config import TimingConfig, from_mapping, require_choice, require_int
from tcot_hybrid.errors import ConfigError, short_repr
from tcot_hybrid.executor import ExecutorConfig
from tcot_hybrid.ik import IKConfig
from tcot_hybrid.lift import LiftConfig
from tcot_hybrid.perturbations import PerturbConfig
from tcot_hybrid.planners.learned import LearnedPlannerConfig
from tcot_hybrid.planners.oracle import OracleConfig
from tcot_hybrid.scene import SceneConfig
from tcot_hybrid.smoothing import SmoothingConfig
from tcot_hybrid.supervision import SupervisorConfig

STOP_ON = ("auto", "simulator", "detector", "either")
INIT_MODES = ("shipped", "sampled", "spread")


@dataclass(frozen=True, kw_only=True)
class RunConfig:
    """One episode: what to run (names) and how (component configs).

    task/robot/controller/ik/planner: registry names (``tcot list`` shows them). robot "auto" = the task's
        own robot: panda in the workcell, libero_panda on a LIBERO task (its scenes mount that Panda).
    seed: episode seed; the same seed and config give a bit-identical run.
    init: how the episode's scene is laid out: "shipped" (a LIBERO task's shipped init state number
        seed, 0 <= seed < N: the paper's protocol), "sampled" (a fresh layout drawn from the seed) or "spread" (LIBERO:
        a sampled layout whose objects range wider than LIBERO's own regions, for training data); None = the
        task's default (LIBERO: shipped for a seed that names a shipped state, sampled past them, which the
        record's ``init_note`` says; the workcell knows only sampled).
    controller_params: overrides of the chosen controller's config fields, e.g. {"kp_scale": 2.0}.
    stop_on: what ends the episode before its time limit. "simulator": the task's success predicate
        (privileged; what a benchmark uses). "detector": the planner's failure detector, once it has judged the
        task successful (p >= supervisor.success_threshold) on ``stop_hold_steps`` consecutive planner steps,
        asked every step from ``supervisor.t_f`` on; success is judged afterwards by the predicate on the final
        state, and a stop the predicate does not confirm is a premature stop. Needs a planner with a detector.
        "either": whichever comes first: the predicate (a success, as with "simulator") or the detector's stop
        (the robot has declared the task done; success is the predicate then, so a false verdict is a failure
        and a premature stop instead of an arm idling to the time limit). "auto" (default): "either" for a GLSR
        mode with a detector on LIBERO (its demonstration-trained detector calls unfinished tasks done:
        docs/libero-planner.md), "simulator" everywhere else (the workcell's tables were measured so).
    stop_hold_steps: consecutive "successful" detector calls that end a detector-stopped episode. Up: fewer
        premature stops, longer episodes; down: stops sooner. Default 15 (1.5 s) by measurement on tuning seeds
        500-504 (learned GLSR, 60 episodes): premature stops 11 at 3, 5 at 10, 2 at 15 and at 20; the detector
        calls a drawer open while the fingers still hold the handle, ~14 steps before the strict predicate.
    """

    task: str = "goal_cube_on_plate"
    """Task name (`tcot list`)."""
    seed: int = 0
    """Episode seed; the same seed and config replay bit-identically."""
    robot: str = "auto"
    """A bundled robot name (`tcot list`; "auto" = the task's own robot), or the path of your own robot's
    robot.toml (or its folder). Check your own with `tcot robot check PATH` (docs/robot_spec.md)."""
    controller: str = "computed_torque"
    ik: str = "mink"
    planner: str = "oracle"
    checkpoint: str | None = None
    init: str | None = None
    stop_on: str = "auto"
    stop_hold_steps: int = 15
    controller_params: dict[str, float] = field(default_factory=dict)
    timing: TimingConfig = field(default_factory=TimingConfig)
    scene: SceneConfig = field(default_factory=SceneConfig)
    ik_params: IKConfig = field(default_factory=IKConfig)
    smoothing: SmoothingConfig = field(default_factory=SmoothingConfig)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)
    lift: LiftConfig = field(default_factory=LiftConfig)
    oracle: OracleConfig = field(default_factory=OracleConfig)
    learned: LearnedPlannerConfig = field(default_factory=LearnedPlannerConfig)
    supervisor: SupervisorConfig = field(default_factory=SupervisorConfig)
    perturb: PerturbConfig = field(default_factory=PerturbConfig)

    def __post_init__(self) -> None:
        require_int("seed", self.seed, minimum=0)
        require_choice("stop_on", self.stop_on, STOP_ON)
        require_int("stop_hold_steps", self.stop_hold_steps, minimum=1)
        for name in ("task", "robot", "controller", "ik", "planner"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ConfigError(f"{name} must be a non-empty name, got {getattr(self, name)!r}")
        if self.init is not None and self.init not in INIT_MODES:
            raise ConfigError(f"init = {self.init!r} is not one of {', '.join(INIT_MODES)} (or null: the task's default)")
        if self.robot == "auto":  # resolved once, so records and checkpoints name the robot that ran
            from tcot_hybrid.tasks.registry import default_robot

            object.__setattr__(self, "robot", default_robot(self.task))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def digest(self) -> str:
        """Stable hash of the whole config (recorded with every episode)."""
        blob = json.dumps(self.to_dict(), sort_keys=True, default=str).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


# --- loading stored configs ---------------------------------------------------------------------------

MAX_CONFIG_BYTES = 256 * 1024
"""Largest config file read [bytes]; real configs are a few kB (a 50 MB file is refused before parsing)."""
MAX_CONFIG_NODES = 100_000
"""Most values a config may hold once YAML aliases are expanded (an alias bomb expands to billions)."""


def _no_duplicate_keys(node: yaml.MappingNode, where: str) -> None:
    seen: dict = {}
    for key, _ in node.value:
        if isinstance(key, yaml.ScalarNode):
            k = (key.tag, key.value)
            if k in seen:
                raise ConfigError(f"{where}: key {short_repr(key.value)} appears twice (line {seen[k] + 1} and line "
                                  f"{key.start_mark.line + 1}); a repeated key would silently win, so it is refused")
            seen[k] = key.start_mark.line


def _check_yaml_nodes(root, where: str) -> None:
    """Refuse alias bombs and duplicate keys on the composed node graph, before any value is built:
    the expanded size is counted with shared (aliased) nodes counted once per use, memoised."""
    sizes: dict[int, int] = {}
    stack = [(root, False)]
    while stack:
        node, done = stack.pop()
        if id(node) in sizes:
            continue
        children = ([c for kv in node.value for c in kv] if isinstance(node, yaml.MappingNode) else
                    list(node.value) if isinstance(node, yaml.SequenceNode) else [])
        if not done:
            if isinstance(node, yaml.MappingNode):
                _no_duplicate_keys(node, where)
            stack.append((node, True))
            stack.extend((c, False) for c in children if id(c) not in sizes)
            if len(stack) > MAX_CONFIG_NODES:
                raise ConfigError(f"{where}: more than {MAX_CONFIG_NODES} values (or nested too deep); "
                                  f"a config holds a few hundred")
            continue
        total = 1
        for c in children:
            total += sizes.get(id(c), 1)
            if total > MAX_CONFIG_NODES:
                raise ConfigError(f"{where}: expands to more than {MAX_CONFIG_NODES} values (YAML aliases/anchors "
                                  f"repeating each other?); a config holds a few hundred, refused")
        sizes[id(node)] = total


def _safe_yaml(text: str, where: str):
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)(text)  # safe: python object tags are refused
    try:
        root = loader.get_single_node()
        if root is None:
            return None
        _check_yaml_nodes(root, where)
        return loader.construct_document(root)
    finally:
        loader.dispose()


def read_config_file(path: str | Path, *, what: str = "config file") -> Any:
    """Parse a .yaml/.yml/.toml/.json file into plain data, bounded: the file must be a regular file of at
    most MAX_CONFIG_BYTES; YAML may not repeat a key or expand (aliases) past MAX_CONFIG_NODES values;
    nesting too deep is refused. Every problem is a ConfigError naming the file."""
    p = Path(path)
    where = f"{what} {str(p)!r}"
    if not p.exists():
        raise ConfigError(f"{where} does not exist")
    if p.is_dir():
        raise ConfigError(f"{where} is a directory; give the path of a .yaml, .toml or .json file")
    if not p.is_file():
        raise ConfigError(f"{where} is not a regular file (a device or pipe?); give a .yaml, .toml or .json file")
    if p.suffix not in (".yaml", ".yml", ".toml", ".json"):
        raise ConfigError(f"{where}: unknown format {p.suffix!r}; use .yaml, .toml or .json")
    try:
        with p.open("rb") as f:
            raw = f.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{where} cannot be read: {exc.strerror or exc}") from exc
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(f"{where} is larger than {MAX_CONFIG_BYTES // 1024} KiB; a config is a few kB, refused "
                          f"before parsing")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{where} is not UTF-8 text ({exc.reason} at byte {exc.start})") from exc
    try:
        if p.suffix in (".yaml", ".yml"):
            return _safe_yaml(text, where)
        if p.suffix == ".toml":
            return tomllib.loads(text)
        return json.loads(text)
    except ConfigError:
        raise
    except RecursionError as exc:
        raise ConfigError(f"{where} is nested too deep to be a config") from exc
    except (yaml.YAMLError, tomllib.TOMLDecodeError, ValueError) as exc:  # ValueError: e.g. a 5000-digit integer
        msg = str(exc)
        mark = getattr(exc, "problem_mark", None)
        lines = text.splitlines()
        line = lines[mark.line] if mark is not None and mark.line < len(lines) else ""
        if line.strip():  # the C parser's message has no snippet: quote the offending line (bounded)
            msg += f"\n  line {mark.line + 1}: {line.strip()[:200]}"
        raise ConfigError(f"{where} is malformed: {msg[:800]}{'...' if len(msg) > 800 else ''}") from exc


def load_config_file(path: str | Path) -> RunConfig:
    """Load a RunConfig from .yaml/.yml/.toml/.json; errors name the file and the field."""
    p = Path(path)
    data = read_config_file(p)
    if data is None:
        data = {}
    try:
        return from_mapping(RunConfig, data)
    except ConfigError as exc:
        raise ConfigError(f"config file {str(p)!r}: {exc}") from exc
    except RecursionError as exc:
        raise ConfigError(f"config file {str(p)!r} is nested too deep to be a config") from exc
