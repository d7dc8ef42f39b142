"""Tasks: objects, seeded layouts, success predicates, oracle scripts. See suites.py."""
from tcot_hybrid.tasks import suites as _suites  # noqa: F401  (registers the tasks)
from tcot_hybrid.tasks.base import Task, World
from tcot_hybrid.tasks.registry import SUITES, list_tasks, make_task

__all__ = ["SUITES", "Task", "World", "list_tasks", "make_task"]
