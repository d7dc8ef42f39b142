"""One registration point for tasks."""
from __future__ import annotations

from tcot_hybrid.errors import ConfigError, unknown_name

_TASKS: dict[str, type] = {}
SUITES = ("spatial", "object", "goal", "long", "tool")


def register_task(cls):
    if cls.name in _TASKS:
        raise ValueError(f"task {cls.name!r} registered twice")
    if cls.suite not in SUITES:
        raise ValueError(f"task {cls.name!r} has unknown suite {cls.suite!r}; valid: {SUITES}")
    _TASKS[cls.name] = cls
    return cls


def list_tasks() -> list[type]:
    """Task classes ordered by suite, then name."""
    return sorted(_TASKS.values(), key=lambda c: (SUITES.index(c.suite), c.name))


def make_task(name: str):
    if name not in _TASKS:
        raise ConfigError(unknown_name("task", name, _TASKS))
    return _TASKS[name]()
