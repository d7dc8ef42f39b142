"""Robot descriptions: a validated spec per robot and its MuJoCo model (its Pinocchio model: robot_pinocchio.py).

Each robot lives in ``robots/<name>/`` as an MJCF file plus a ``robot.toml`` spec (format in
docs/robot_spec.md). ``load_robot_spec`` reads the TOML, cross-checks it against the compiled MJCF and
returns a frozen :class:`RobotSpec`; every problem raises :class:`RobotModelError` naming the robot,
the field and the bad value, before anything moves.

World convention: robot base at the world origin, x forward toward the workspace, z up, table top at
z = 0. The TCP site (``ee_site``) has z = approach axis (out of the palm) and y = finger closing
axis; the top-down grasp orientation is ``R_down = diag(1, -1, -1)``.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import mujoco
import numpy as np

from tcot_hybrid.errors import RobotModelError, unknown_name

ROBOTS_DIR = Path(__file__).resolve().parent.parent / "robots"
"""Folder holding one sub-folder per bundled robot (installed as package ``tcot_hybrid.robots``)."""

SPEC_FILE = "robot.toml"

# TCP orientation for a top-down grasp: TCP z -> world -z, fingers close along world y.
R_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
R_DOWN.flags.writeable = False

_TOP_KEYS = {
    "name", "mjcf", "arm_joints", "arm_actuators", "ee_site", "gripper_joints", "gripper_actuator",
    "gripper_open", "gripper_closed", "home_q", "limits", "gains",
}
_OPTIONAL_TOP_KEYS = {"gripper_mirror_actuator"}
_LIMIT_KEYS = ("q_min", "q_max", "v_max", "a_max", "j_max", "tau_max")
_GAIN_KEYS = ("kp", "kd")
_ARRAY_FIELDS = ("home_q",) + _LIMIT_KEYS + _GAIN_KEYS


def _robots_dir() -> Path:
    try:  # the installed package is the source of truth; fall back to the repo layout
        import tcot_hybrid.robots as pkg

        return Path(pkg.__file__).resolve().parent
    except ImportError:  # pragma: no cover - only without an install
        return ROBOTS_DIR


def list_robots() -> list[str]:
    """Names of the bundled robots (folders of ``robots/`` holding a robot.toml), sorted."""
    root = _robots_dir()
    return sorted(p.parent.name for p in root.glob(f"*/{SPEC_FILE}"))


@dataclass(frozen=True, kw_only=True, eq=False)
class RobotSpec:
    """What the stack needs to know about one arm + parallel gripper. Validated on construction.

    name:             robot name (folder name for bundled robots).
    mjcf_path:        absolute path of the MJCF file.
    arm_joints:       hinge joints of the arm, base to tip; this order is the order of every array.
    arm_actuators:    torque (motor) actuators, same order; ctrl = joint torque [N m].
    ee_site:          TCP site: z = approach axis (out of the palm), y = finger closing axis.
    gripper_joints:   finger joints (for reading the opening; not controlled by arm controllers).
    gripper_actuator: position actuator driving the fingers.
    gripper_open:     gripper actuator ctrl for open (unit of the actuator, [m] for both bundled).
    gripper_closed:   gripper actuator ctrl for closed.
    gripper_mirror_actuator: optional second finger actuator driven with the negated command (grippers with
                      one position actuator per finger, mirrored, e.g. robosuite's PandaGripper); None if the
                      gripper has one actuator.
    home_q:           arm joint positions at home [rad]: TCP ~ (0.45, 0, 0.35) m pointing down.
    q_min, q_max:     joint position limits [rad]; within the MJCF joint range.
    v_max:            joint speed limits [rad/s]; lower = slower, safer trajectories.
    a_max:            joint acceleration limits [rad/s^2].
    j_max:            joint jerk limits [rad/s^3]; lower = smoother torque commands.
    tau_max:          joint torque limits [N m]; equal to the motors' ctrlrange.
    kp:               default joint stiffness as acceleration gain [1/s^2], used as
                      tau = M(q) (kp e + kd de) + h(q, v); higher = stiffer, but keep
                      sqrt(kp) * ctrl_dt well below 1 for a sampled controller.
    kd:               default joint damping as acceleration gain [1/s]; 2 sqrt(kp) is critical.
    """

    name: str
    mjcf_path: Path
    arm_joints: tuple[str, ...]
    arm_actuators: tuple[str, ...]
    ee_site: str
    gripper_joints: tuple[str, ...]
    gripper_actuator: str
    gripper_open: float
    gripper_closed: float
    home_q: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray
    j_max: np.ndarray
    tau_max: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    gripper_mirror_actuator: str | None = None

    def __post_init__(self) -> None:
        _validate_fields(self)
        check_physical_bounds(self)
        _validate_against_mjcf(self, _compile(self.name, self.mjcf_path))

    @property
    def dof(self) -> int:
        """Number of arm joints."""
        return len(self.arm_joints)


SPEC_BOUNDS: dict[str, tuple[float, float, str]] = {
    "q_min": (-4 * math.pi, 4 * math.pi, "rad"),
    "q_max": (-4 * math.pi, 4 * math.pi, "rad"),
    "v_max": (0.01, 10.0, "rad/s"),
    "a_max": (0.1, 1000.0, "rad/s^2"),
    "j_max": (1.0, 1e5, "rad/s^3"),
    "tau_max": (0.1, 2000.0, "N m"),
    "kp": (1e-3, 1e5, "1/s^2"),
    "kd": (1e-3, 1e3, "1/s"),
}
"""Per-joint ranges a spec value must lie in (docs/robot_spec.md, "Sanity bounds"). No real arm is
outside them; a value beyond (v_max 1e12, tau_max 1e9) would silently switch a safety check off."""


def _err(robot: str, fld: str, msg: str) -> RobotModelError:
    return RobotModelError(f"robot {robot!r}: {fld}: {msg}")


def _names(robot: str, fld: str, value: Any, *, allow_empty: bool = False) -> tuple[str, ...]:
    if isinstance(value, str) or not isinstance(value, (list, tuple)):
        raise _err(robot, fld, f"must be a list of names, got {value!r}")
    if not all(isinstance(v, str) and v for v in value):
        raise _err(robot, fld, f"every entry must be a non-empty string, got {value!r}")
    if not value and not allow_empty:
        raise _err(robot, fld, "must not be empty")
    if len(set(value)) != len(value):
        raise _err(robot, fld, f"has duplicates: {value!r}")
    return tuple(value)


def _number(robot: str, fld: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise _err(robot, fld, f"must be a number, got {value!r}")
    if not math.isfinite(float(value)):
        raise _err(robot, fld, f"must be finite, got {value!r}")
    return float(value)


def _array(robot: str, fld: str, value: Any, n: int) -> np.ndarray:
    if isinstance(value, np.ndarray):
        ok = value.dtype.kind in "iuf"
    elif isinstance(value, (list, tuple)):
        ok = all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in value)
    else:
        ok = False
    if not ok:
        raise _err(robot, fld, f"must be a list of {n} numbers, got {value!r}")
    arr = np.array(value, dtype=float)
    if arr.shape != (n,):
        raise _err(robot, fld, f"needs {n} values (one per arm joint), got shape {arr.shape}: {value!r}")
    if not np.all(np.isfinite(arr)):
        raise _err(robot, fld, f"must be finite, got {arr.tolist()}")
    arr.flags.writeable = False
    return arr


def _validate_fields(spec: RobotSpec) -> None:
    """Type, length and range checks that do not need the MJCF. Normalises arrays in place."""
    if not isinstance(spec.name, str) or not spec.name:
        raise RobotModelError(f"robot spec: name must be a non-empty string, got {spec.name!r}")
    r = spec.name
    set_ = object.__setattr__  # frozen dataclass: normalise once, here
    set_(spec, "mjcf_path", Path(spec.mjcf_path))
    set_(spec, "arm_joints", _names(r, "arm_joints", spec.arm_joints))
    set_(spec, "arm_actuators", _names(r, "arm_actuators", spec.arm_actuators))
    set_(spec, "gripper_joints", _names(r, "gripper_joints", spec.gripper_joints))
    for fld in ("ee_site", "gripper_actuator"):
        if not isinstance(getattr(spec, fld), str) or not getattr(spec, fld):
            raise _err(r, fld, f"must be a non-empty name, got {getattr(spec, fld)!r}")
    n = len(spec.arm_joints)
    if len(spec.arm_actuators) != n:
        raise _err(r, "arm_actuators", f"needs {n} actuators (one per arm joint), got {len(spec.arm_actuators)}")
    overlap = set(spec.arm_joints) & set(spec.gripper_joints)
    if overlap:
        raise _err(r, "gripper_joints", f"shares joints with arm_joints: {sorted(overlap)}")
    if spec.gripper_mirror_actuator is not None and (
            not isinstance(spec.gripper_mirror_actuator, str) or not spec.gripper_mirror_actuator
            or spec.gripper_mirror_actuator == spec.gripper_actuator):
        raise _err(r, "gripper_mirror_actuator", f"must be a second actuator's name (not gripper_actuator) or absent, "
                                                 f"got {spec.gripper_mirror_actuator!r}")
    for fld in ("gripper_open", "gripper_closed"):
        set_(spec, fld, _number(r, fld, getattr(spec, fld)))
    if spec.gripper_open == spec.gripper_closed:
        raise _err(r, "gripper_closed", f"must differ from gripper_open, both are {spec.gripper_open!r}")
    for fld in _ARRAY_FIELDS:
        set_(spec, fld, _array(r, fld, getattr(spec, fld), n))
    bad = np.flatnonzero(spec.q_min >= spec.q_max)
    if bad.size:
        i = int(bad[0])
        raise _err(r, "q_min", f"must be < q_max for every joint; joint {spec.arm_joints[i]!r} has "
                               f"q_min = {float(spec.q_min[i])} >= q_max = {float(spec.q_max[i])}")
    for fld in ("v_max", "a_max", "j_max", "tau_max", "kp", "kd"):
        arr = getattr(spec, fld)
        bad = np.flatnonzero(arr <= 0)
        if bad.size:
            i = int(bad[0])
            raise _err(r, fld, f"must be > 0 for every joint; joint {spec.arm_joints[i]!r} has {float(arr[i])}")
    bad = np.flatnonzero((spec.home_q < spec.q_min) | (spec.home_q > spec.q_max))
    if bad.size:
        i = int(bad[0])
        raise _err(r, "home_q", f"joint {spec.arm_joints[i]!r} home {float(spec.home_q[i])} rad is outside "
                                f"[q_min, q_max] = [{float(spec.q_min[i])}, {float(spec.q_max[i])}]")


def check_physical_bounds(spec: RobotSpec) -> None:
    """Refuse limits and gains outside SPEC_BOUNDS (values no real arm has), naming joint, value, bound."""
    for fld, (lo, hi, unit) in SPEC_BOUNDS.items():
        arr = getattr(spec, fld)
        bad = np.flatnonzero((arr < lo) | (arr > hi))
        if bad.size:
            i = int(bad[0])
            raise _err(spec.name, fld, f"joint {spec.arm_joints[i]!r} has {float(arr[i]):g} {unit}, outside the "
                                       f"sanity range [{lo:g}, {hi:g}] {unit} (no real arm has it; "
                                       f"docs/robot_spec.md, 'Sanity bounds')")


def _compile(robot: str, path: Path) -> mujoco.MjModel:
    if not path.is_file():
        raise _err(robot, "mjcf", f"file not found: {str(path)!r}")
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:
        raise _err(robot, "mjcf", f"MuJoCo cannot compile {str(path)!r}: {exc}") from exc


def _all_names(m: mujoco.MjModel, obj: mujoco.mjtObj, count: int) -> list[str]:
    return [mujoco.mj_id2name(m, obj, i) or f"<unnamed #{i}>" for i in range(count)]


def _lookup(robot: str, fld: str, m: mujoco.MjModel, obj: mujoco.mjtObj, count: int, name: str) -> int:
    idx = mujoco.mj_name2id(m, obj, name)
    if idx < 0:
        kind = {mujoco.mjtObj.mjOBJ_JOINT: "joint", mujoco.mjtObj.mjOBJ_ACTUATOR: "actuator",
                mujoco.mjtObj.mjOBJ_SITE: "site"}[obj]
        raise _err(robot, fld, unknown_name(kind, name, _all_names(m, obj, count)) + " (in the MJCF)")
    return idx


def _validate_against_mjcf(spec: RobotSpec, m: mujoco.MjModel) -> None:
    """Every name exists with the right type; limits agree with the MJCF."""
    r = spec.name
    J, A, S = mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_ACTUATOR, mujoco.mjtObj.mjOBJ_SITE
    jids = [_lookup(r, "arm_joints", m, J, m.njnt, j) for j in spec.arm_joints]
    for name, jid in zip(spec.arm_joints, jids):
        if m.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            kind = mujoco.mjtJoint(m.jnt_type[jid]).name
            raise _err(r, "arm_joints", f"joint {name!r} is {kind}, expected a hinge joint")
    for i, (name, jid) in enumerate(zip(spec.arm_joints, jids)):
        if m.jnt_limited[jid]:
            lo, hi = m.jnt_range[jid]
            if spec.q_min[i] < lo - 1e-9 or spec.q_max[i] > hi + 1e-9:
                raise _err(r, "q_min/q_max", f"joint {name!r} limits [{float(spec.q_min[i])}, {float(spec.q_max[i])}] rad "
                                             f"exceed the MJCF range [{float(lo)}, {float(hi)}]")
    for i, (name, jid) in enumerate(zip(spec.arm_actuators, jids)):
        aid = _lookup(r, "arm_actuators", m, A, m.nu, name)
        if m.actuator_trntype[aid] != mujoco.mjtTrn.mjTRN_JOINT or m.actuator_trnid[aid, 0] != jid:
            raise _err(r, "arm_actuators", f"actuator {name!r} does not drive joint {spec.arm_joints[i]!r}")
        is_motor = (m.actuator_gaintype[aid] == mujoco.mjtGain.mjGAIN_FIXED
                    and m.actuator_biastype[aid] == mujoco.mjtBias.mjBIAS_NONE
                    and m.actuator_gainprm[aid, 0] == 1.0 and m.actuator_gear[aid, 0] == 1.0
                    and m.actuator_dyntype[aid] == mujoco.mjtDyn.mjDYN_NONE)
        if not is_motor:
            raise _err(r, "arm_actuators", f"actuator {name!r} is not a plain torque <motor> (gear 1)")
        lo, hi = m.actuator_ctrlrange[aid]
        tau = spec.tau_max[i]
        if not m.actuator_ctrllimited[aid] or not (math.isclose(lo, -tau, abs_tol=1e-9)
                                                   and math.isclose(hi, tau, abs_tol=1e-9)):
            raise _err(r, "tau_max", f"joint {spec.arm_joints[i]!r} tau_max {float(tau)} N m must equal actuator "
                                     f"{name!r} ctrlrange, which is "
                                     f"{[float(lo), float(hi)] if m.actuator_ctrllimited[aid] else 'unlimited'}")
    _lookup(r, "ee_site", m, S, m.nsite, spec.ee_site)
    for name in spec.gripper_joints:
        _lookup(r, "gripper_joints", m, J, m.njnt, name)
    gripper = [(spec.gripper_actuator, 1.0, "gripper_actuator")]
    if spec.gripper_mirror_actuator is not None:
        gripper.append((spec.gripper_mirror_actuator, -1.0, "gripper_mirror_actuator"))
    for name, sign, fld_a in gripper:
        gid = _lookup(r, fld_a, m, A, m.nu, name)
        if gid in [mujoco.mj_name2id(m, A, a) for a in spec.arm_actuators]:
            raise _err(r, fld_a, f"{name!r} is also an arm actuator")
        if m.actuator_ctrllimited[gid]:
            lo, hi = m.actuator_ctrlrange[gid]
            for fld in ("gripper_open", "gripper_closed"):
                val = sign * getattr(spec, fld)
                if not lo - 1e-12 <= val <= hi + 1e-12:
                    raise _err(r, fld, f"{val!r} (sent to {name!r}) is outside that actuator's ctrlrange "
                                       f"[{float(lo)}, {float(hi)}]")


def _resolve_spec_path(name_or_path: str | Path) -> Path:
    if isinstance(name_or_path, Path) or "/" in str(name_or_path) or str(name_or_path).endswith(".toml"):
        path = Path(name_or_path).expanduser()
        if path.is_dir():
            path = path / SPEC_FILE
        if not path.is_file():
            raise RobotModelError(f"robot spec file not found: {str(path)!r}")
        return path.resolve()
    if not isinstance(name_or_path, str) or not name_or_path:
        raise RobotModelError(unknown_name("robot", name_or_path, list_robots()))
    path = _robots_dir() / name_or_path / SPEC_FILE
    if not path.is_file():
        raise RobotModelError(unknown_name("robot", name_or_path, list_robots()))
    return path


def load_robot_spec(name_or_path: str | Path) -> RobotSpec:
    """Load and validate a robot: a bundled name (``"panda"``, ``"ur5e"``) or a path to a robot.toml
    (or to the folder holding it). Raises RobotModelError naming the robot, field and bad value."""
    path = _resolve_spec_path(name_or_path)
    label = str(path)
    try:
        with path.open("rb") as f:
            raw = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise RobotModelError(f"robot spec {label!r} is not valid TOML: {exc}") from exc
    robot = raw.get("name", label)
    if not isinstance(robot, str) or not robot:
        raise RobotModelError(f"robot spec {label!r}: name must be a non-empty string, got {robot!r}")

    def check_keys(table: dict, expected: set[str] | tuple[str, ...], where: str, optional=frozenset()) -> None:
        missing = sorted(set(expected) - set(table))
        unknown = sorted(set(table) - set(expected) - set(optional))
        if missing:
            raise _err(robot, where, f"missing key(s) {missing} in {label!r}")
        if unknown:
            raise _err(robot, where, f"unknown key(s) {unknown} in {label!r}; valid keys: {sorted(set(expected) | set(optional))}")

    check_keys(raw, _TOP_KEYS, "spec", _OPTIONAL_TOP_KEYS)
    for table in ("limits", "gains"):
        if not isinstance(raw[table], dict):
            raise _err(robot, table, f"must be a [{table}] table, got {raw[table]!r}")
    check_keys(raw["limits"], _LIMIT_KEYS, "limits")
    check_keys(raw["gains"], _GAIN_KEYS, "gains")
    if not isinstance(raw["mjcf"], str) or not raw["mjcf"]:
        raise _err(robot, "mjcf", f"must be a file name, got {raw['mjcf']!r}")
    bundled = path.parent.parent.resolve() == _robots_dir().resolve()
    if bundled and robot != path.parent.name:
        raise _err(robot, "name", f"must equal its folder name {path.parent.name!r}")
    return RobotSpec(
        name=robot,
        mjcf_path=(path.parent / raw["mjcf"]).resolve(),
        arm_joints=raw["arm_joints"],
        arm_actuators=raw["arm_actuators"],
        ee_site=raw["ee_site"],
        gripper_joints=raw["gripper_joints"],
        gripper_actuator=raw["gripper_actuator"],
        gripper_open=raw["gripper_open"],
        gripper_closed=raw["gripper_closed"],
        home_q=raw["home_q"],
        gripper_mirror_actuator=raw.get("gripper_mirror_actuator"),
        **{k: raw["limits"][k] for k in _LIMIT_KEYS},
        **{k: raw["gains"][k] for k in _GAIN_KEYS},
    )


def robot_mjspec(spec: RobotSpec) -> mujoco.MjSpec:
    """A fresh, editable MjSpec of the robot alone (the scene adds floor, lights, cameras, objects)."""
    return mujoco.MjSpec.from_file(str(spec.mjcf_path))


class RobotIndices(NamedTuple):
    """Where the robot lives inside a (scene) MjModel. Arrays follow the spec's arm joint order."""

    arm_qpos: np.ndarray        # qpos addresses of the arm joints
    arm_dof: np.ndarray         # qvel / qfrc addresses of the arm joints
    arm_actuators: np.ndarray   # actuator ids (ctrl indices) of the arm motors
    gripper_qpos: np.ndarray    # qpos addresses of the gripper joints
    gripper_dof: np.ndarray     # dof addresses of the gripper joints
    gripper_actuator: int       # actuator id of the gripper
    ee_site: int                # site id of the TCP


def mj_robot_indices(spec: RobotSpec, model: mujoco.MjModel, *, prefix: str = "") -> RobotIndices:
    """Look the spec's names (with ``prefix``, for robots attached under a prefix) up in ``model``."""
    r = spec.name
    J, A, S = mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_ACTUATOR, mujoco.mjtObj.mjOBJ_SITE
    arm_j = [_lookup(r, "arm_joints", model, J, model.njnt, prefix + n) for n in spec.arm_joints]
    grip_j = [_lookup(r, "gripper_joints", model, J, model.njnt, prefix + n) for n in spec.gripper_joints]
    arm_a = [_lookup(r, "arm_actuators", model, A, model.nu, prefix + n) for n in spec.arm_actuators]
    return RobotIndices(
        arm_qpos=np.array([model.jnt_qposadr[j] for j in arm_j], dtype=int),
        arm_dof=np.array([model.jnt_dofadr[j] for j in arm_j], dtype=int),
        arm_actuators=np.array(arm_a, dtype=int),
        gripper_qpos=np.array([model.jnt_qposadr[j] for j in grip_j], dtype=int),
        gripper_dof=np.array([model.jnt_dofadr[j] for j in grip_j], dtype=int),
        gripper_actuator=_lookup(r, "gripper_actuator", model, A, model.nu, prefix + spec.gripper_actuator),
        ee_site=_lookup(r, "ee_site", model, S, model.nsite, prefix + spec.ee_site),
    )


# --- identity and sanity checks (bring-your-own arm) ---------------------------------------------------

def robot_ref(spec: RobotSpec) -> str:
    """How to name this robot on the command line: its name if bundled, else the folder of its robot.toml
    (a name would not find it)."""
    folder = spec.mjcf_path.parent
    bundled = folder.parent.resolve() == _robots_dir().resolve() and folder.name == spec.name
    return spec.name if bundled else str(folder)


def robot_model_digest(spec: RobotSpec) -> str:
    """Hash of what a planner checkpoint depends on: the compiled robot model's kinematics and dynamics
    (bodies, joints, sites, actuators; floats rounded to 1e-9) and the spec's arm joints and TCP site.
    Checkpoints are matched to a robot by this hash, never by name: a different arm renamed ``panda``
    has another digest; reformatting the MJCF or moving its folder keeps it."""
    import hashlib

    m = _compile(spec.name, spec.mjcf_path)
    h = hashlib.sha256()
    h.update(repr((spec.arm_joints, spec.ee_site, spec.gripper_joints)).encode())
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, i) or "" for i in range(m.njnt)]
    h.update(repr(names).encode())
    for arr in (m.body_parentid, m.body_pos, m.body_quat, m.body_ipos, m.body_iquat, m.body_mass, m.body_inertia,
                m.jnt_type, m.jnt_bodyid, m.jnt_axis, m.jnt_pos, m.jnt_range, m.dof_armature, m.dof_damping,
                m.site_bodyid, m.site_pos, m.site_quat, m.actuator_trnid, m.actuator_gear, m.actuator_ctrlrange):
        a = np.asarray(arr)
        h.update(str(a.shape).encode())
        h.update((np.round(a.astype(float), 9) + 0.0).tobytes() if a.dtype.kind == "f" else a.astype(np.int64).tobytes())
    return h.hexdigest()[:16]


# The Pinocchio model of a robot lives in tcot_hybrid/robot_pinocchio.py; its names stay importable from here.
_PINOCCHIO_NAMES = ("PinocchioRobot", "build_pinocchio_model", "mj_full_mass_matrix")


def __getattr__(name: str):
    if name in _PINOCCHIO_NAMES:
        from tcot_hybrid import robot_pinocchio

        return getattr(robot_pinocchio, name)
    raise AttributeError(f"module 'tcot_hybrid.robot' has no attribute {name!r}")
