"""Episode video: front camera at planner rate with the current plan's waypoints drawn on it."""
from __future__ import annotations

from pathlib import Path

import cv2
import imageio.v2 as imageio
import numpy as np

from tcot_hybrid.camera import CameraModel

PLAN_COLOURS = {"global": (0, 200, 255), "local": (255, 80, 200), "direct": (80, 255, 80)}  # RGB


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
        frame = runner.stack.sim.render(self.camera_name, self.w, self.h)
        ex = runner.stack.executor
        if ex.plan is not None and len(ex.points):
            frame = draw_plan(frame, self.camera, ex.points, ex.grip,
                              PLAN_COLOURS.get(ex.plan.kind, (0, 200, 255)), active=ex.index)
        cv2.putText(frame, f"t={step} {runner.cfg.task}", (4, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                    (255, 255, 255), 1, cv2.LINE_AA)
        self.writer.append_data(frame)

    def close(self) -> None:
        self.writer.close()
