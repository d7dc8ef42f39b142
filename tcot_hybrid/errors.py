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


class DatasetError(TcotError):
    """A demonstration file is missing, truncated, corrupt or not in the expected layout."""


def unknown_name(kind: str, name: object, valid: Iterable[str]) -> str:
    """Message for an unknown registry name, listing the valid ones."""
    return f"unknown {kind} {name!r}; valid {kind}s: {', '.join(sorted(valid))}"
