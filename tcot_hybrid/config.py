"""Config primitives shared by every component.

Configs are frozen, keyword-only dataclasses; ``__post_init__`` validates with the helpers below so
every error names the field and the bad value. YAML/TOML are only how configs are stored.
"""
from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass
from typing import Any

import numpy as np

from tcot_hybrid.errors import ConfigError, short_repr


def require_finite(field: str, value: Any) -> None:
    """Raise ConfigError unless ``value`` (scalar or array) is all finite numbers."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ConfigError(f"{field} must be numeric, got {short_repr(value)}") from exc
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{field} must be finite, got {short_repr(value)}")


def require_positive(field: str, value: Any) -> None:
    """Raise ConfigError unless ``value`` is a finite number (or array) strictly greater than zero."""
    if isinstance(value, bool):
        raise ConfigError(f"{field} must be a positive number, got bool {short_repr(value)}")
    require_finite(field, value)
    if not np.all(np.asarray(value, dtype=float) > 0):
        raise ConfigError(f"{field} must be > 0, got {short_repr(value)}")


def require_nonnegative(field: str, value: Any) -> None:
    """Raise ConfigError unless ``value`` is finite and >= 0."""
    if isinstance(value, bool):
        raise ConfigError(f"{field} must be a number, got bool {short_repr(value)}")
    require_finite(field, value)
    if not np.all(np.asarray(value, dtype=float) >= 0):
        raise ConfigError(f"{field} must be >= 0, got {short_repr(value)}")


def require_in_range(field: str, value: Any, low: float, high: float, *, low_closed: bool = True,
                     high_closed: bool = True, meaning: str = "") -> None:
    """Raise ConfigError unless ``value`` is a number (not bool, not NaN) in the interval from ``low`` to ``high``,
    each end included or not; the message names the interval and, when given, what the number is (``meaning``)."""
    number = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    above = number and (low <= value if low_closed else low < value)
    below = number and (value <= high if high_closed else value < high)
    if not (above and below):
        interval = f"{'[' if low_closed else '('}{low:g}, {high:g}{']' if high_closed else ')'}"
        what = f" ({meaning})" if meaning else ""
        raise ConfigError(f"{field} must be a number in {interval}{what}, got {short_repr(value)}")


def require_int(field: str, value: Any, *, minimum: int | None = None) -> None:
    """Raise ConfigError unless ``value`` is an int (not bool) and >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{field} must be an integer, got {short_repr(value)} ({type(value).__name__})")
    if minimum is not None and value < minimum:
        raise ConfigError(f"{field} must be >= {minimum}, got {short_repr(value)}")


def require_bool(field: str, value: Any) -> None:
    """Raise ConfigError unless ``value`` is True or False (not 1, not "yes")."""
    if not isinstance(value, bool):
        raise ConfigError(f"{field} must be true or false, got {short_repr(value)}")


def require_choice(field: str, value: Any, choices: tuple[str, ...] | list[str]) -> None:
    """Raise ConfigError unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ConfigError(f"{field} = {short_repr(value)} is not valid; choose one of {', '.join(map(str, choices))}")


def whole_multiple(field: str, value: float, base_field: str, base: float) -> int:
    """Return value/base when it is a whole number >= 1, else raise ConfigError naming both fields."""
    ratio = value / base
    if not math.isfinite(ratio):  # e.g. 1e308 / 0.002 overflows; round(inf) would raise OverflowError
        raise ConfigError(f"{field} = {value} s must be a whole multiple (>= 1) of {base_field} = {base} s")
    n = round(ratio)
    if n < 1 or not math.isclose(ratio, n, rel_tol=0, abs_tol=1e-9):
        raise ConfigError(
            f"{field} = {value} s must be a whole multiple (>= 1) of {base_field} = {base} s; "
            f"got ratio {ratio:.6g}"
        )
    return n


TIMING_BOUNDS_S = {"sim_dt": (1e-5, 0.01), "ctrl_dt": (1e-4, 0.05), "plan_dt": (1e-3, 1.0)}
"""Allowed range of each loop period [s]. Below: MuJoCo needs ~1e5 steps per simulated second and the
settle loop alone runs for hours (1e-300 would need ~1e299 ticks); above: the physics of a stiff arm
diverges (sim_dt), a sampled controller with the default gains goes unstable (ctrl_dt: sqrt(kp)
ctrl_dt must stay well below 1), and the planner reacts slower than a second (plan_dt)."""


@dataclass(frozen=True, kw_only=True)
class TimingConfig:
    """The three loop periods, in seconds. Each must be a whole multiple of the one below.

    sim_dt:  physics step [s]. Smaller is more accurate and slower; 0.002 is MuJoCo's default.
    ctrl_dt: low-level controller period [s]; a whole multiple of sim_dt. Smaller tracks better and
             costs more Python per simulated second (the bench reports the tick/mj_step ratio).
    plan_dt: planner step [s] (the paper's time step t); a whole multiple of ctrl_dt. Images are
             rendered only at this rate.
    """

    sim_dt: float = 0.002
    ctrl_dt: float = 0.01
    plan_dt: float = 0.1

    def __post_init__(self) -> None:
        for name in ("sim_dt", "ctrl_dt", "plan_dt"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise ConfigError(f"{name} must be a number of seconds, got {short_repr(value)}")
            require_positive(name, value)
            lo, hi = TIMING_BOUNDS_S[name]
            if not lo <= getattr(self, name) <= hi:
                raise ConfigError(f"{name} = {getattr(self, name)!r} s is outside [{lo:g}, {hi:g}] s, the range "
                                  f"MuJoCo and the controllers can use")
        whole_multiple("ctrl_dt", self.ctrl_dt, "sim_dt", self.sim_dt)
        whole_multiple("plan_dt", self.plan_dt, "ctrl_dt", self.ctrl_dt)

    @property
    def substeps(self) -> int:
        """Physics steps per control tick."""
        return whole_multiple("ctrl_dt", self.ctrl_dt, "sim_dt", self.sim_dt)

    @property
    def ticks_per_plan(self) -> int:
        """Control ticks per planner step."""
        return whole_multiple("plan_dt", self.plan_dt, "ctrl_dt", self.ctrl_dt)


# --- stored configs (YAML/TOML/JSON mappings) -> typed dataclasses ---------------------------------------

def coerce_field(path: str, tp: Any, value: Any) -> Any:
    """``value`` (from YAML/TOML/JSON) as type ``tp`` of the config field at dotted ``path``; ConfigError
    naming the field otherwise. Dataclass types are built with :func:`from_mapping`."""
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return from_mapping(tp, value, prefix=path)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        errors = []
        for a in inner:  # e.g. int | Literal["auto", "plan"]: the first type the value is
            try:
                return coerce_field(path, a, value)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError("; or ".join(errors))
    if origin is typing.Literal:
        choices = typing.get_args(tp)
        if isinstance(value, bool) or value not in choices:
            raise ConfigError(f"{path} = {short_repr(value)} is not valid; choose one of {', '.join(map(str, choices))}")
        return value
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{path} must be a mapping, got {short_repr(value)}")
        _, vt = typing.get_args(tp)
        return {str(k): coerce_field(f"{path}.{k}", vt, v) for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{path} must be a number, got {short_repr(value)} ({type(value).__name__})")
        try:
            return float(value)
        except OverflowError as exc:  # an integer beyond float range, e.g. 10**400 in YAML
            raise ConfigError(f"{path} must be a finite number, got a {value.bit_length()}-bit integer") from exc
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path} must be an integer, got {short_repr(value)} ({type(value).__name__})")
        return value
    if tp is bool:
        require_bool(path, value)
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path} must be a string, got {short_repr(value)} ({type(value).__name__})")
        return value
    return value


def from_mapping(cls, data: Any, *, prefix: str = ""):
    """Build dataclass ``cls`` from a plain mapping, naming any unknown key or wrongly typed value."""
    if not isinstance(data, dict):
        raise ConfigError(f"{prefix or cls.__name__} must be a mapping, got {short_repr(data)}")
    hints = typing.get_type_hints(cls)
    fields = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - fields)
    if unknown:
        where = prefix or "config"
        raise ConfigError(f"unknown key(s) {short_repr(unknown)} in {where}; valid keys: {', '.join(sorted(fields))}")
    kwargs = {k: coerce_field(f"{prefix}.{k}" if prefix else k, hints[k], v) for k, v in data.items()}
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ConfigError(f"{prefix or cls.__name__}: {exc}") from exc
