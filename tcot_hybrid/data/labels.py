"""Trajectory labels (paper eq. 4 and 5) from a gripper track. Pure numpy, vectorised over steps.

A *track* is, per demo sample ``t = 0 .. T-1``: the gripper pixel ``p_t`` in the planner camera, the
lift cue ``z_m`` (TCP height above the table top, world z) and the commanded gripper bit.

* Global trajectory at step t (eq. 4): samples ``t + n_g * k`` for ``k = -(L_g // 2) .. L_g // 2``
  (``L_g`` points, the middle one is ``t``), indices clamped to ``[0, T-1]``. Past points are the task's
  progress context; only points from the middle on (``k >= 0``) are sent to the executor.
* Local trajectory at step t (eq. 5): samples ``t + n_l * k`` for ``k = 0 .. L_l`` (``L_l + 1`` points),
  clamped, with ``n_l < n_g``: short and dense.

``global_spacing = "events"`` replaces eq. 4's fixed time stride by the demo's gripper events: from step t
on, the path is cut at every gripper switch and each piece gets ``points_per_segment`` points at equal
path-length fractions, its last point being the switch sample itself (the past half mirrors this). Point k
then means the same thing in every scene of a task (with 6 points per piece, the 2nd grasp is always point
18), where with a time
stride it is wherever the demo happened to be 4k steps later: from one image the network cannot know a
1-2 s long-horizon timing, and regression averaged far-future descents away (grasps closing in the air).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from tcot_hybrid.config import require_choice, require_int
from tcot_hybrid.errors import ConfigError, DatasetError


GLOBAL_SPACINGS = ("time", "events")
SEGMENT_POINTS = ("length", "corners")
GLOBAL_PATHS = ("observed", "commanded")
# TrajectoryWindowConfig's fields that take one of a set of names, and those names (the config and a checkpoint's
# metadata check against the same sets)
WINDOW_CHOICES = {"global_spacing": GLOBAL_SPACINGS, "segment_points": SEGMENT_POINTS, "global_path": GLOBAL_PATHS,
                  "local_path": GLOBAL_PATHS}


@dataclass(frozen=True, kw_only=True)
class TrajectoryWindowConfig:
    """Which demo samples make up a global / local trajectory label. Units: planner steps (plan_dt each).

    L_g: points in a global trajectory, odd (the middle point is the current step). Up: longer horizon
         both ways; 51 with n_g = 4 spans ±100 steps = ±10 s. Most long-suite demos end before step 100;
         the slowest run to ~113 steps, and in 3 of 150 the last release comes after step 100, so their
         t = 0 label stops short of it (`tcot replay` measures what the labels achieve).
    n_g: stride between global points [steps]. Down: denser global plans. Keep n_g <= 4 so at least one
         point falls inside every 0.5 s (5-step) gripper pause, where the gripper bit flips.
    L_l: local trajectory length: L_l + 1 points from the current step on. Up: longer local horizon.
    n_l: stride between local points [steps], must be < n_g (local plans are denser). Down: denser.
    global_spacing: "time" (eq. 4: every n_g steps) or "events" (points_per_segment points between
         consecutive gripper switches, spaced by path length; see the module doc). n_g is used by "time" only.
    segment_points: "events" only: where a piece's points go. "length": at equal path-length fractions;
         "corners": where the path turns (greedy Douglas-Peucker: each next point is the sample farthest from
         the polyline through the points so far), so a short contact stroke inside a long piece (a knob pushed
         sideways at the bottom of a descent) keeps its corners where equal fractions cut across it.
    global_path: what global labels trace. "observed": the TCP where it was; "commanded": the waypoint the
         executor was driving it to (``obs/tcp_target_pos``). They differ in contact: a knob bar or a door leaf
         holds the hand back while the command goes on past it, and a plan of the observed path stops at the
         bar (a replayed knob push turned it 0.03 rad of the 0.6 it needs; docs/libero-planner.md).
    local_path: what local labels trace, as ``global_path``. "commanded" gives GLSR's local plans the same
         push past a contact that the global ones have, where an observed local plan stops at the knob bar.
    points_per_segment: "events" only: points per path piece between gripper switches, at most L_g // 2.
         (L_g // 2) / points_per_segment pieces fit in the future half; the long suite has 4 switches (5
         pieces, the last a short retreat), so with 6 the first four pieces take 24 of the 25 future points
         and every switch is in the window. Up: denser plans, fewer pieces fit.
    """

    L_g: int = 51
    n_g: int = 4
    L_l: int = 8
    n_l: int = 2
    global_spacing: str = "time"
    segment_points: str = "length"
    global_path: str = "observed"
    local_path: str = "observed"
    points_per_segment: int = 6

    def __post_init__(self) -> None:
        for name in ("L_g", "n_g", "L_l", "n_l", "points_per_segment"):
            require_int(name, getattr(self, name), minimum=1)
        for name, choices in WINDOW_CHOICES.items():
            require_choice(name, getattr(self, name), choices)
        if self.global_spacing == "events" and self.points_per_segment > self.L_g // 2:
            raise ConfigError(f"points_per_segment = {self.points_per_segment} must be <= L_g // 2 = {self.L_g // 2} "
                              "with global_spacing = 'events' (else the first switch falls outside the window)")
        if self.L_g % 2 != 1:
            raise ConfigError(f"L_g must be odd (k = -(L_g//2) .. L_g//2 has L_g points only then), got {self.L_g}")
        if not self.n_l < self.n_g:
            raise ConfigError(f"n_l must be < n_g (local trajectories are denser than global ones), got "
                              f"n_l = {self.n_l}, n_g = {self.n_g}")

    @property
    def global_offsets(self) -> np.ndarray:
        """(L_g,) step offsets ``n_g * k``, k = -(L_g//2) .. L_g//2."""
        h = self.L_g // 2
        return self.n_g * np.arange(-h, h + 1)

    @property
    def global_center(self) -> int:
        """Index of the current step inside a global window (points from here on are executed)."""
        return self.L_g // 2

    @property
    def local_offsets(self) -> np.ndarray:
        """(L_l + 1,) step offsets ``n_l * k``, k = 0 .. L_l."""
        return self.n_l * np.arange(self.L_l + 1)


def windows_from_meta(w: dict) -> TrajectoryWindowConfig:
    """The windows a checkpoint's metadata records. Checkpoints written before ``global_spacing`` existed
    have no such key and were all trained on eq.-4 (time-spaced) windows; an event-spaced one must name its
    ``points_per_segment``."""
    required = ["L_g", "n_g", "L_l", "n_l"]
    spacing = w.get("global_spacing", "time")
    if spacing == "events":
        required.append("points_per_segment")
    missing = [k for k in required if k not in w]
    if missing:
        raise ConfigError(f"checkpoint windows {w!r} lack {', '.join(missing)}")
    kw = {k: w[k] for k in required}  # ints are checked (not truncated) by TrajectoryWindowConfig
    # checkpoints written before segment_points existed placed a piece's points by path length
    return TrajectoryWindowConfig(**kw, global_spacing=spacing, segment_points=w.get("segment_points", "length"),
                                  global_path=w.get("global_path", "observed"),
                                  local_path=w.get("local_path", "observed"))


def _check_T(T: int) -> None:
    require_int("T (number of samples)", T, minimum=1)


def _require_time_spacing(cfg: TrajectoryWindowConfig) -> None:
    if cfg.global_spacing != "time":
        raise ConfigError(f"eq.-4 indices need global_spacing = 'time', got {cfg.global_spacing!r}; event-spaced "
                          "windows depend on the track: use global_labels(track, cfg)")


def global_indices(T: int, t: int, cfg: TrajectoryWindowConfig = TrajectoryWindowConfig()) -> np.ndarray:
    """(L_g,) sample indices of the global trajectory at step ``t`` of a T-sample demo (eq. 4), clamped."""
    _require_time_spacing(cfg)
    _check_T(T)
    _check_t(T, t)
    return np.clip(t + cfg.global_offsets, 0, T - 1)


def local_indices(T: int, t: int, cfg: TrajectoryWindowConfig = TrajectoryWindowConfig()) -> np.ndarray:
    """(L_l + 1,) sample indices of the local trajectory at step ``t`` (eq. 5), clamped."""
    _check_T(T)
    _check_t(T, t)
    return np.clip(t + cfg.local_offsets, 0, T - 1)


def _check_t(T: int, t: int) -> None:
    require_int("t (step)", t, minimum=0)
    if t >= T:
        raise ConfigError(f"step t = {t} is outside the demo (T = {T} samples)")


def global_index_table(T: int, cfg: TrajectoryWindowConfig = TrajectoryWindowConfig()) -> np.ndarray:
    """(T, L_g) global indices for every step (row t = :func:`global_indices` (T, t))."""
    _require_time_spacing(cfg)
    _check_T(T)
    return np.clip(np.arange(T)[:, None] + cfg.global_offsets[None, :], 0, T - 1)


def _piece_by_length(cum_len: np.ndarray, start: int, end: int, per: int, xyz: np.ndarray) -> np.ndarray:
    """``per`` sample indices in (start, end] at path-length fractions 1/per .. 1 of the piece."""
    piece = cum_len[start:end + 1] - cum_len[start]
    frac = np.arange(1, per + 1) / per
    idx = start + np.searchsorted(piece, frac * piece[-1] - 1e-9, side="left")  # 1 nm: float sums of steps
    idx[-1] = end  # the switch sample itself, whatever the rounding
    return np.minimum(idx, end)


def _piece_by_corners(cum_len: np.ndarray, start: int, end: int, per: int, xyz: np.ndarray) -> np.ndarray:
    """``per`` sample indices in (start, end], the last ``end``: greedy Douglas-Peucker from the chord
    start-end, each next point the sample farthest from the polyline through the points so far. Once no sample
    lies more than 1 mm off it, the rest split the longest stretch (by path length) in half; a piece of fewer
    samples than points repeats its end."""
    chosen = [start, end]
    while len(chosen) < per + 1:
        best, best_d = None, 1e-3
        for a, b in zip(chosen[:-1], chosen[1:]):
            if b - a < 2:
                continue
            pts, pa, pb = xyz[a + 1:b], xyz[a], xyz[b]
            ab = pb - pa
            n2 = float(ab @ ab)
            u = np.clip((pts - pa) @ ab / n2, 0.0, 1.0) if n2 > 1e-12 else np.zeros(len(pts))
            d = np.linalg.norm(pts - (pa + u[:, None] * ab), axis=1)
            i = int(d.argmax())
            if d[i] > best_d:
                best, best_d = a + 1 + i, float(d[i])
        if best is None:  # straight: halve the longest stretch that still has an inner sample
            gaps = [(cum_len[b] - cum_len[a], a, b) for a, b in zip(chosen[:-1], chosen[1:]) if b - a >= 2]
            if not gaps:
                break
            _, a, b = max(gaps)
            best = a + 1 + int(np.searchsorted(cum_len[a + 1:b], 0.5 * (cum_len[a] + cum_len[b])))
            best = min(best, b - 1)
        chosen = sorted(chosen + [best])
    idx = chosen[1:]
    return np.array(idx + [end] * (per - len(idx)), dtype=np.int64)


_PIECE_POINTS = {"length": _piece_by_length, "corners": _piece_by_corners}


def _future_event_indices(cum_len: np.ndarray, switches: np.ndarray, t: int, n: int, per: int,
                          xyz: np.ndarray | None = None, segment_points: str = "length",
                          cache: dict | None = None) -> np.ndarray:
    """(n,) sample indices after ``t``: ``per`` points per piece between the switches after t (and the last
    sample), the last of each on its switch, placed by ``segment_points`` (path-length fractions 1/per .. 1, or
    corners of the path ``xyz``); clamped to the last sample when they run out. ``cache`` keeps the pieces
    placed so far (all but the first piece are the same for every t)."""
    T = len(cum_len)
    ends = np.r_[switches[switches > t], T - 1]
    place = _PIECE_POINTS[segment_points]
    cache = {} if cache is None else cache
    out, start = [], t
    for end in ends:
        if end <= start:
            continue
        key = (start, int(end))
        if key not in cache:
            cache[key] = place(cum_len, start, int(end), per, xyz).tolist()
        out.extend(cache[key])
        start = end
        if len(out) >= n:
            break
    out = out[:n]
    return np.array(out + [T - 1] * (n - len(out)), dtype=np.int64)


def event_index_table(xyz_m: np.ndarray, gripper_closed: np.ndarray,
                      cfg: TrajectoryWindowConfig) -> np.ndarray:
    """(T, L_g) event-spaced global indices for every step (``global_spacing = "events"``, module doc): the
    middle point is t, the future half has ``points_per_segment`` points per piece between gripper switches
    (placed by ``cfg.segment_points``, ending on the switch sample: the first sample with the new gripper bit),
    and the past half is the same built backwards in time."""
    p = np.asarray(xyz_m, float)
    g = np.asarray(gripper_closed, bool)
    T = len(p)
    h, per = cfg.L_g // 2, cfg.points_per_segment
    step_len = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.r_[0.0, np.cumsum(step_len)]
    cum_rev = np.r_[0.0, np.cumsum(step_len[::-1])]
    switches = np.flatnonzero(g[1:] != g[:-1]) + 1  # first sample with the new bit
    # backwards in time, a piece ends on the last sample with the old bit: reversed index T - 1 - (s - 1) = T - s
    switches_rev = np.sort(T - switches)
    table = np.empty((T, cfg.L_g), dtype=np.int64)
    fwd, bwd = {}, {}
    for t in range(T):
        table[t, h] = t
        table[t, h + 1:] = _future_event_indices(cum, switches, t, h, per, p, cfg.segment_points, fwd)
        past = _future_event_indices(cum_rev, switches_rev, T - 1 - t, h, per, p[::-1], cfg.segment_points,
                                     bwd)
        table[t, :h] = (T - 1 - past)[::-1]
    return table


def local_index_table(T: int, cfg: TrajectoryWindowConfig = TrajectoryWindowConfig()) -> np.ndarray:
    """(T, L_l + 1) local indices for every step."""
    _check_T(T)
    return np.clip(np.arange(T)[:, None] + cfg.local_offsets[None, :], 0, T - 1)


class Track(NamedTuple):
    """A demo's gripper track, one row per sample.

    uv_px:          (T, 2) gripper pixel in the planner camera [px]
    z_m:            (T,) lift cue: TCP height above the table top (world z) [m]
    gripper_closed: (T,) commanded gripper state (True = closed)
    xyz_m:          (T, 3) TCP position [m, world], or None; event-spaced global windows need it (path length)
    """

    uv_px: np.ndarray
    z_m: np.ndarray
    gripper_closed: np.ndarray
    xyz_m: np.ndarray | None = None


class WindowLabels(NamedTuple):
    """Labels of one window kind for every step of a demo (K = points per window).

    indices:        (T, K) sample index of each point
    uv_px:          (T, K, 2) [px]
    z_m:            (T, K) [m]
    gripper_closed: (T, K) bool
    """

    indices: np.ndarray
    uv_px: np.ndarray
    z_m: np.ndarray
    gripper_closed: np.ndarray


def make_track(uv_px, z_m, gripper_closed, xyz_m=None) -> Track:
    """Validated :class:`Track` (shapes agree, values finite)."""
    uv = np.asarray(uv_px, dtype=np.float32)
    z = np.asarray(z_m, dtype=np.float32)
    g = np.asarray(gripper_closed).astype(bool)
    if uv.ndim != 2 or uv.shape[1] != 2 or uv.shape[0] < 1:
        raise DatasetError(f"track uv_px must have shape (T>=1, 2), got {uv.shape}")
    T = uv.shape[0]
    if z.shape != (T,) or g.shape != (T,):
        raise DatasetError(f"track z_m and gripper_closed must have shape ({T},), got {z.shape} and {g.shape}")
    if not (np.isfinite(uv).all() and np.isfinite(z).all()):
        raise DatasetError("track uv_px / z_m contain non-finite values")
    if xyz_m is not None:
        xyz_m = np.asarray(xyz_m, dtype=np.float32)
        if xyz_m.shape != (T, 3) or not np.isfinite(xyz_m).all():
            raise DatasetError(f"track xyz_m must be finite with shape ({T}, 3), got {xyz_m.shape}")
    return Track(uv, z, g, xyz_m)


TRACK_KEYS = ("obs/eef_uv_px", "obs/robot0_eef_pos", "obs/robot0_gripper_closed")  # what a track is read from


def track_from_arrays(arrays: dict, *, uv_key: str = TRACK_KEYS[0]) -> Track:
    """Track of a demo read with :meth:`DemoFile.read`: exact TCP pixel (or ``uv_key``), TCP height, gripper."""
    pos = arrays[TRACK_KEYS[1]]
    return make_track(arrays[uv_key], pos[:, 2], arrays[TRACK_KEYS[2]], pos)


def commanded_track(track: Track, target_xyz: np.ndarray, camera) -> Track:
    """``track`` with its path replaced by the commanded waypoints ``target_xyz`` (T, 3) [m, world]: pixels
    through the demo's planner ``camera``, heights from their z; the gripper bits stay (global_path
    'commanded')."""
    target = np.asarray(target_xyz, dtype=np.float64)
    if target.shape != (len(track.uv_px), 3):
        raise DatasetError(f"commanded waypoints must have shape ({len(track.uv_px)}, 3), got {target.shape}")
    uv, _ = camera.project(target)
    return make_track(uv, target[:, 2], track.gripper_closed, target)


def _gather(track: Track, idx: np.ndarray) -> WindowLabels:
    return WindowLabels(idx, track.uv_px[idx], track.z_m[idx], track.gripper_closed[idx])


def global_labels(track: Track, cfg: TrajectoryWindowConfig = TrajectoryWindowConfig()) -> WindowLabels:
    """Global trajectory labels (eq. 4, or event-spaced: ``cfg.global_spacing``) for every step of ``track``."""
    if cfg.global_spacing == "events":
        if track.xyz_m is None:
            raise DatasetError("event-spaced global windows need the track's TCP positions (xyz_m); got a track "
                               "without them")
        return _gather(track, event_index_table(track.xyz_m, track.gripper_closed, cfg))
    return _gather(track, global_index_table(len(track.uv_px), cfg))


def local_labels(track: Track, cfg: TrajectoryWindowConfig = TrajectoryWindowConfig()) -> WindowLabels:
    """Local trajectory labels (eq. 5) for every step of ``track``."""
    return _gather(track, local_index_table(len(track.uv_px), cfg))


def window_labels(track: Track, cfg: TrajectoryWindowConfig = TrajectoryWindowConfig()) -> tuple[WindowLabels, WindowLabels]:
    """(global, local) labels for every step of ``track``."""
    return global_labels(track, cfg), local_labels(track, cfg)


__all__ = ["GLOBAL_PATHS", "GLOBAL_SPACINGS", "SEGMENT_POINTS", "WINDOW_CHOICES", "commanded_track", "Track", "TrajectoryWindowConfig", "WindowLabels", "event_index_table", "global_index_table", "global_indices",
           "global_labels", "local_index_table", "local_indices", "local_labels", "make_track",
           "track_from_arrays", "window_labels", "windows_from_meta"]
