"""Domain exception tree.

Every message names the bad value, what was expected and, where there is a finite set, the valid
choices. Solvers return a status instead of raising for ordinary non-convergence; these exceptions
are for input that must not be acted on.
"""
from __future__ import annotations

from collections.abc import Iterable


class TcotError(Exception):
    """Base of every error raised on purpose by tcot-hybrid."""


class ConfigError(TcotError, ValueError):
    """A configuration value is missing, malformed or out of range."""


class RobotModelError(TcotError):
    """A robot description or spec is inconsistent (joint names, frames, limits)."""


class PlanningError(TcotError):
    """A planner produced an unusable plan (NaN, wrong shape, probability outside [0, 1])."""


class LiftError(TcotError):
    """A 2D waypoint cannot be lifted to 3D (outside the image, behind the camera, bad depth)."""


class IKError(TcotError):
    """IK input is unusable (non-finite target, wrong shape). Non-convergence is a status, not this."""


class TrajectoryError(TcotError):
    """Trajectory generation input is invalid (NaN, wrong DoF, non-positive limits)."""


class ControllerError(TcotError):
    """A controller cannot produce a command (bad reference, unknown name, bad gains)."""


class CheckpointError(TcotError):
    """A checkpoint is corrupt, unsafe (pickle) or made for another robot/camera/image size."""


class SimulationError(TcotError):
    """The simulator diverged or warned (MuJoCo auto-reset, bad accelerations)."""


class OutputError(TcotError):
    """An output location cannot take a record (read-only, an existing file where a folder belongs, a
    directory where a file belongs, disk full). Checked before an episode; records are written atomically."""


class DatasetError(TcotError):
    """A demonstration file is missing, truncated, corrupt or not in the expected layout."""


MAX_ECHO_CHARS = 200
"""Longest rendering of a bad value that an error message echoes (a huge value is cut, its size said)."""


def short_repr(value: object, limit: int = MAX_ECHO_CHARS) -> str:
    """``repr(value)`` cut to about ``limit`` characters. Containers are rendered item by item and the
    rendering stops once the budget is spent, so a value built by YAML aliases (millions of shared
    items) or nested thousands deep is never expanded into a string."""
    out: list[str] = []
    budget = [limit]

    def emit(text: str) -> bool:
        out.append(text[:max(budget[0], 0)])
        budget[0] -= len(text)
        return budget[0] > 0

    def walk(v: object, depth: int) -> bool:
        if depth > 50:
            return emit("...")
        if isinstance(v, (list, tuple, set, frozenset, dict)):
            open_, close = ("{", "}") if isinstance(v, (dict, set, frozenset)) else \
                ("(", ")") if isinstance(v, tuple) else ("[", "]")
            if not emit(open_):
                return False
            items = v.items() if isinstance(v, dict) else v
            for i, item in enumerate(items):
                if i and not emit(", "):
                    return False
                if isinstance(v, dict):
                    if not (walk(item[0], depth + 1) and emit(": ") and walk(item[1], depth + 1)):
                        return False
                elif not walk(item, depth + 1):
                    return False
            return emit(close)
        text = repr(v)
        return emit(text if len(text) <= limit else text[:limit])

    complete = walk(value, 0)
    text = "".join(out)
    if complete:
        return text
    size = f" ({len(value)} items)" if isinstance(value, (list, tuple, set, frozenset, dict)) else ""
    return text + f"...{size}"


def unknown_name(kind: str, name: object, valid: Iterable[str]) -> str:
    """Message for an unknown registry name, listing the valid ones."""
    return f"unknown {kind} {name!r}; valid {kind}s: {', '.join(sorted(valid))}"
