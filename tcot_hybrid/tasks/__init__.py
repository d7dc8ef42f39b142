"""Tasks: objects, seeded layouts, success predicates, oracle scripts. See suites.py."""
from tcot_hybrid.tasks import suites as _suites  # noqa: F401  (registers the tasks)
from tcot_hybrid.tasks.base import Task, World
from tcot_hybrid.tasks.registry import (
    SUITES,
    all_suites,
    check_suite,
    default_robot,
    is_libero_task,
    list_all_tasks,
    list_tasks,
    make_task,
    suite_task_names,
)

__all__ = ["SUITES", "Task", "World", "all_suites", "check_suite", "default_robot", "is_libero_task", "list_all_tasks",
           "list_tasks", "make_task", "suite_task_names"]
