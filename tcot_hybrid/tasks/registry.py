"""One registration point for tasks: this project's workcell tasks, and LIBERO's when it is installed."""
from __future__ import annotations

from tcot_hybrid.errors import ConfigError, unknown_name

_TASKS: dict[str, type] = {}
SUITES = ("spatial", "object", "goal", "long", "tool")  # the workcell's suites
LIBERO_SEP = ":"  # LIBERO task names are "<suite>:<task file name>"
WORKCELL_ROBOT, LIBERO_ROBOT = "panda", "libero_panda"


def register_task(cls):
    if cls.name in _TASKS:
        raise ValueError(f"task {cls.name!r} registered twice")
    if cls.suite not in SUITES:
        raise ValueError(f"task {cls.name!r} has unknown suite {cls.suite!r}; valid: {SUITES}")
    _TASKS[cls.name] = cls
    return cls


def list_tasks() -> list[type]:
    """The workcell's task classes ordered by suite, then name (LIBERO's: :func:`list_all_tasks`)."""
    return sorted(_TASKS.values(), key=lambda c: (SUITES.index(c.suite), c.name))


def is_libero_task(name: object) -> bool:
    """True for a name in LIBERO's namespace (``<suite>:<task>`` or a ``libero...`` suite name)."""
    return isinstance(name, str) and name not in _TASKS and (LIBERO_SEP in name or name.startswith("libero"))


def default_robot(task: str) -> str:
    """The robot a task runs when the run says ``robot: auto``: LIBERO's scenes mount their own Panda."""
    return LIBERO_ROBOT if is_libero_task(task) else WORKCELL_ROBOT


def make_task(name: str):
    if name in _TASKS:
        return _TASKS[name]()
    if is_libero_task(name):
        from tcot_hybrid.libero import require_libero

        require_libero()
        from tcot_hybrid.libero.tasks import make_libero_task

        return make_libero_task(name)
    raise ConfigError(unknown_name("task", name, _TASKS) + "; LIBERO tasks are named <suite>:<task> (`tcot list`)")


def list_all_tasks() -> list[dict]:
    """Every task this install can run, as {name, suite, instruction, world}: the workcell's, then LIBERO's
    (every suite the installed package registers; none without LIBERO)."""
    out = [{"name": c.name, "suite": c.suite, "instruction": c.instruction, "world": "workcell"} for c in list_tasks()]
    from tcot_hybrid.libero import libero_available

    if libero_available():
        from tcot_hybrid.libero.tasks import libero_catalog

        out += [{"name": i.name, "suite": i.suite, "instruction": i.instruction, "world": "libero"}
                for i in libero_catalog().values()]
    return out


def all_suites() -> list[str]:
    """The workcell's suites, then LIBERO's registered suites (four standard ones first)."""
    from tcot_hybrid.libero import libero_available

    if not libero_available():
        return list(SUITES)
    from tcot_hybrid.libero.tasks import libero_suites

    return list(SUITES) + libero_suites()


def check_suite(suite: str) -> None:
    """An unknown suite names the valid ones; a LIBERO suite without LIBERO says how to install it."""
    if suite in SUITES:
        return
    if isinstance(suite, str) and suite.startswith("libero"):
        from tcot_hybrid.libero import require_libero

        require_libero()
    if suite not in all_suites():
        raise ConfigError(unknown_name("suite", suite, all_suites()))


def suite_task_names(suite: str) -> list[str]:
    check_suite(suite)
    return [t["name"] for t in list_all_tasks() if t["suite"] == suite]
