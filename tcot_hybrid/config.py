"""Config primitives shared by every component.

Configs are frozen, keyword-only dataclasses; ``__post_init__`` validates with the helpers below so
every error names the field and the bad value. YAML/TOML are only how configs are stored.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tcot_hybrid.errors import ConfigError


def require_finite(field: str, value: Any) -> None:
    """Raise ConfigError unless ``value`` (scalar or array) is all finite numbers."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ConfigError(f"{field} must be numeric, got {value!r}") from exc
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{field} must be finite, got {value!r}")


def require_positive(field: str, value: Any) -> None:
    """Raise ConfigError unless ``value`` is a finite number (or array) strictly greater than zero."""
    if isinstance(value, bool):
        raise ConfigError(f"{field} must be a positive number, got bool {value!r}")
    require_finite(field, value)
    if not np.all(np.asarray(value, dtype=float) > 0):
        raise ConfigError(f"{field} must be > 0, got {value!r}")


def require_nonnegative(field: str, value: Any) -> None:
    """Raise ConfigError unless ``value`` is finite and >= 0."""
    if isinstance(value, bool):
        raise ConfigError(f"{field} must be a number, got bool {value!r}")
    require_finite(field, value)
    if not np.all(np.asarray(value, dtype=float) >= 0):
        raise ConfigError(f"{field} must be >= 0, got {value!r}")


def require_int(field: str, value: Any, *, minimum: int | None = None) -> None:
    """Raise ConfigError unless ``value`` is an int (not bool) and >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{field} must be an integer, got {value!r} ({type(value).__name__})")
    if minimum is not None and value < minimum:
        raise ConfigError(f"{field} must be >= {minimum}, got {value!r}")


def require_choice(field: str, value: Any, choices: tuple[str, ...] | list[str]) -> None:
    """Raise ConfigError unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ConfigError(f"{field} = {value!r} is not valid; choose one of {', '.join(map(str, choices))}")


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
            require_positive(name, getattr(self, name))
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
