"""Low-level torque controllers, one file each, registered by name (installed as ``tcot_hybrid.controllers``).

Adding a controller = adding one module to this folder that defines a :class:`Controller` subclass
decorated with :func:`register`. Modules are discovered with ``pkgutil`` on first use, so nothing
here lists them.

    from tcot_hybrid.controllers import make_controller, list_controllers
    ctrl = make_controller("computed_torque", spec, ctrl_dt=0.01, params={"kp_scale": 2.0})
    ctrl.reset(dyn, last_tau=None)
    cmd = ctrl.compute(dyn, reference)          # -> Command(tau, status, detail, solve_time_s)
"""
from __future__ import annotations

import dataclasses
import importlib
import pkgutil
import types
import typing
from collections.abc import Mapping
from typing import Any

from tcot_hybrid.controllers.base import (
    STATUS_BLENDING,
    STATUS_FALLBACK,
    STATUS_OK,
    Command,
    Controller,
    ControllerConfig,
    JointGainsConfig,
)
from tcot_hybrid.errors import ConfigError, ControllerError, unknown_name

__all__ = [
    "Command", "Controller", "ControllerConfig", "JointGainsConfig", "STATUS_OK", "STATUS_BLENDING",
    "STATUS_FALLBACK", "register", "make_controller", "list_controllers", "controller_class",
]

_REGISTRY: dict[str, type[Controller]] = {}
_DISCOVERED = False
_NOT_CONTROLLERS = {"base"}


def register(cls: type[Controller]) -> type[Controller]:
    """Class decorator: make ``cls`` available under ``cls.name``. Duplicate names are an error."""
    if not (isinstance(cls, type) and issubclass(cls, Controller)):
        raise ControllerError(f"register expects a Controller subclass, got {cls!r}")
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name:
        raise ControllerError(f"controller class {cls.__name__} needs a non-empty class attribute `name`")
    other = _REGISTRY.get(name)
    where = lambda c: f"{c.__module__}.{c.__qualname__}"  # noqa: E731
    if other is not None and where(other) != where(cls):  # same class re-imported is fine
        raise ControllerError(f"controller name {name!r} is registered twice ({where(other)}, {where(cls)})")
    _REGISTRY[name] = cls
    return cls


def _discover() -> None:
    global _DISCOVERED
    if _DISCOVERED:
        return
    for mod in pkgutil.iter_modules(__path__):
        if not mod.name.startswith("_") and mod.name not in _NOT_CONTROLLERS:
            importlib.import_module(f"{__name__}.{mod.name}")
    _DISCOVERED = True


def list_controllers() -> list[str]:
    """Registered controller names, sorted."""
    _discover()
    return sorted(_REGISTRY)


def controller_class(name: str) -> type[Controller]:
    """The class registered as ``name``; ControllerError listing the valid names otherwise."""
    _discover()
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ControllerError(unknown_name("controller", name, _REGISTRY)) from None


def make_controller(name: str, spec: Any, *, ctrl_dt: float, config: ControllerConfig | Mapping | None = None,
                    params: Mapping | None = None) -> Controller:
    """Build controller ``name`` for robot ``spec`` running every ``ctrl_dt`` [s].

    config: the controller's own config dataclass (``controller_class(name).Config``), a mapping of its
            fields, or None for the defaults (derived from the robot spec where they are gains).
    params: field overrides applied on top of ``config`` (e.g. ``{"kp_scale": 2.0}`` from the CLI);
            an unknown field raises ConfigError listing the valid ones.
    """
    cls = controller_class(name)
    cfg_cls = cls.Config
    if config is None:
        base: dict[str, Any] = {}
    elif isinstance(config, cfg_cls):
        base = {f.name: getattr(config, f.name) for f in dataclasses.fields(cfg_cls)}
    elif isinstance(config, Mapping):
        base = dict(config)
    else:
        raise ConfigError(f"config for controller {name!r} must be a {cfg_cls.__name__} or a mapping, "
                          f"got {type(config).__name__}")
    merged = {**base, **_coerce(cfg_cls, dict(params or {}))}
    valid = [f.name for f in dataclasses.fields(cfg_cls)]
    unknown = sorted(set(merged) - set(valid))
    if unknown:
        raise ConfigError(f"unknown {name} controller parameter(s) {unknown}; valid: {', '.join(valid)}")
    try:
        cfg = cfg_cls(**merged)
    except TypeError as exc:
        raise ConfigError(f"bad {name} controller config {merged!r}: {exc}") from exc
    return cls(spec, ctrl_dt=ctrl_dt, config=cfg)


def _coerce(cfg_cls: type, params: dict) -> dict:
    """Lossless conversions for values typed as floats by a CLI (``horizon 12.0`` → 12, ``1.0`` → True).

    Anything else is passed through unchanged for the config's own validation to accept or refuse.
    """
    hints = typing.get_type_hints(cfg_cls)
    out = {}
    for key, value in params.items():
        hint = hints.get(key)
        allowed = set(typing.get_args(hint)) if isinstance(hint, types.UnionType) else {hint}
        if isinstance(value, float) and value.is_integer():
            if bool in allowed and value in (0.0, 1.0):
                value = bool(value)
            elif int in allowed:
                value = int(value)
        out[key] = value
    return out
