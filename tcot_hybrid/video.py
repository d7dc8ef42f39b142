"""Episode visualisation: annotated video and a per-episode timeline plot.

Video (front camera, one frame per planner step): the global plan and the current local plan drawn
in different colours (projected pixels + their lifted 3D points as spheres in the scene), the GLSR
state and the latest success probability as text. Timeline (PNG): GLSR state, p(success) and replans,
joint positions against the Ruckig reference.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import imageio.v2 as imageio
import numpy as np

from tcot_hybrid.camera import CameraModel

PLAN_COLOURS = {"global": (0, 200, 255), "local": (255, 80, 200), "direct": (80, 255, 80)}  # RGB
SCENE_RGBA = {"global": (0.0, 0.8, 1.0, 0.9), "local": (1.0, 0.3, 0.8, 0.9), "direct": (0.3, 1.0, 0.3, 0.9)}
STATES = ("start", "global_follow", "detect", "local_follow", "reset", "direct")


def draw_plan(frame: np.ndarray, camera: CameraModel, points_world: np.ndarray, closed: np.ndarray,
              colour=(0, 200, 255), active: int | None = None) -> np.ndarray:
    """Draw a 3D waypoint path projected into ``camera`` (which must match the frame's size)."""
    uv, depth = camera.project(points_world)
    ok = (depth > 0) & camera.in_image(uv)
    pts = np.round(uv).astype(np.int32)
    img = np.ascontiguousarray(frame)
    for a, b, oka, okb in zip(pts[:-1], pts[1:], ok[:-1], ok[1:]):
        if oka and okb:
            cv2.line(img, tuple(map(int, a)), tuple(map(int, b)), colour, 1, cv2.LINE_AA)
    for i, (p, good) in enumerate(zip(pts, ok)):
        if good:
            r = 3 if i == active else 2
            cv2.circle(img, tuple(map(int, p)), r, (255, 40, 40) if closed[i] else colour, -1, cv2.LINE_AA)
    return img


def _last_p(runner) -> float | None:
    for e in reversed(runner.stack.executor.events):
        if "p_success" in e:
            return float(e["p_success"])
    return None


class EpisodeVideo:
    """Collects one annotated frame per planner step and writes an MP4 on close()."""

    def __init__(self, runner, path: str | Path, *, camera: str = "agentview"):
        cfg = runner.cfg.scene
        self.runner, self.path, self.camera_name = runner, Path(path), camera
        self.w, self.h = cfg.video_width, cfg.video_height
        sim = runner.stack.sim
        self.camera = CameraModel.from_mujoco(sim.model, sim.data, camera, width=self.w, height=self.h)
        self.fps = max(1, int(round(1.0 / runner.cfg.timing.plan_dt)))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.writer = imageio.get_writer(self.path, fps=self.fps, codec="libx264", quality=7,
                                         macro_block_size=8)

    def capture(self, runner, step: int) -> None:
        ex = runner.stack.executor
        plans = [(k, v) for k, v in ex.latest_points.items() if k in ("global", "local", "direct")]
        if ex.plan is not None and ex.plan.kind != "global":
            plans = [(k, v) for k, v in plans if k in ("global", ex.plan.kind)]
        markers = [(pts, SCENE_RGBA[kind]) for kind, (pts, _) in plans]
        frame = runner.stack.sim.render(self.camera_name, self.w, self.h, markers=markers)
        for kind, (pts, grip) in plans:
            active = ex.index if ex.plan is not None and ex.plan.kind == kind else None
            frame = draw_plan(frame, self.camera, pts, grip, PLAN_COLOURS[kind], active=active)
        p = _last_p(runner)
        text = [f"t={step} {runner.cfg.task}", f"{runner.supervisor.state}" + (f"  p(success)={p:.2f}" if p is not None else "")]
        for i, line in enumerate(text):
            cv2.putText(frame, line, (4, 12 + 12 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (255, 255, 255), 1, cv2.LINE_AA)
        self.writer.append_data(frame)

    def close(self) -> None:
        self.writer.close()


def check_timeline_path(path: str | Path, *, what: str = "--timeline") -> None:
    """Refuse a timeline path whose suffix matplotlib cannot draw to, before the episode runs: ``savefig`` would only
    fail once the episode is over. Raises OutputError naming the formats it can write."""
    from matplotlib.backend_bases import FigureCanvasBase

    from tcot_hybrid.errors import OutputError

    formats = sorted(FigureCanvasBase.get_supported_filetypes())
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in formats:
        got = f"'.{suffix}'" if suffix else "no suffix"
        raise OutputError(f"{what} {str(path)!r} has {got}; a timeline is an image: end it in one of "
                          f"{', '.join('.' + f for f in formats)} (e.g. timeline.png)")


class Timeline:
    """Records per planner step what the timeline plot shows; ``save(png)`` draws it."""

    def __init__(self):
        self.t, self.state, self.p, self.q, self.q_ref, self.replans = [], [], [], [], [], []

    def capture(self, runner, step: int) -> None:
        ex = runner.stack.executor
        self.t.append(float(runner.stack.sim.data.time))
        self.state.append(runner.supervisor.state)
        p = _last_p(runner)
        self.p.append(np.nan if p is None else p)
        self.q.append(runner.stack.sim.q)
        self.q_ref.append(np.array(ex.smoother.reference.q))
        self.replans.append(sum(1 for e in ex.events if e["kind"] == "plan_adopted"))

    def save(self, path: str | Path, title: str = "") -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        t = np.array(self.t)
        fig, ax = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
        ax[0].step(t, [STATES.index(s) if s in STATES else -1 for s in self.state], where="post")
        ax[0].set_yticks(range(len(STATES)), STATES)
        changes = np.flatnonzero(np.diff(self.replans)) + 1
        for i in changes:
            ax[0].axvline(t[i], color="tab:red", lw=0.8, alpha=0.6)
        ax[0].set_title(title or "episode timeline (red: new plan adopted)")
        ax[1].plot(t, self.p, ".-", color="tab:green")
        ax[1].set_ylim(-0.05, 1.05)
        ax[1].set_ylabel("p(success)")
        q, qr = np.array(self.q), np.array(self.q_ref)
        for j in range(q.shape[1]):
            line, = ax[2].plot(t, q[:, j], lw=1)
            ax[2].plot(t, qr[:, j], "--", lw=0.8, color=line.get_color())
        ax[2].set_ylabel("q [rad] (dashed: Ruckig reference)")
        ax[2].set_xlabel("time [s]")
        fig.tight_layout()
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=90)
        plt.close(fig)
