"""Planner images at a fraction of the software-GL cost: what never moves (the backdrop) rendered once per layout,
everything else every frame, the two composited by depth.

A LIBERO scene has 0.7-1.1 M mesh vertices and llvmpipe's cost is in the vertices (DESIGN.md: ~50 ms a 128-px frame
on one core, 3.5 ms with the meshes hidden); the room and fixtures, welded to the world, hold about 60 % of them. With
shadows, reflections and multisampling off, an opaque pixel's colour is that of its nearest surface alone, so the
nearer of the two layers' pixels is exactly what one full render draws. Translucent things (the robot's grip sites,
a see-through geom) blend over whatever lies behind them: each frame they are drawn alone, and where one lies in front
of a pixel the backdrop wins, that frame is rendered whole and the backdrop geoms there move to the frame layer for
good (LIBERO's tables and the robot's base, under the grip sites' aiming line). So :class:`BackdropRenderer` changes only the cost, never
the image; it also checks its first frame against a full render and renders whole from then on if a pixel differs.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np

ALL = int(mujoco.mjtCatBit.mjCAT_ALL)


@dataclass(frozen=True)
class LayerGroups:
    """Geom groups of a layered scene (each used by no other geom, all shown by the scene's render option).

    backdrop:    opaque geoms welded to the world (:func:`split_layers`), drawn once per layout and camera pose
    translucent: geoms drawn with alpha < 1, drawn alone every frame to see where they cover the backdrop
    frame:       where a backdrop geom goes when something translucent turns up in front of it
    """

    backdrop: int = 4
    translucent: int = 3
    frame: int = 1


def _shown(model: mujoco.MjModel, option: mujoco.MjvOption) -> np.ndarray:
    return np.array([option.geomgroup[g] if 0 <= g < len(option.geomgroup) else 0 for g in model.geom_group], bool)


def translucent_geoms(model: mujoco.MjModel, data: mujoco.MjData, option: mujoco.MjvOption) -> np.ndarray:
    """Geoms a render draws with alpha < 1 (their own or their material's, as MuJoCo resolves it; geom ids)."""
    scene = mujoco.MjvScene(model, maxgeom=max(1000, 2 * model.ngeom))
    camera = mujoco.MjvCamera()
    mujoco.mjv_defaultFreeCamera(model, camera)
    mujoco.mjv_updateScene(model, data, option, None, camera, ALL, scene)
    return np.unique([g.objid for g in scene.geoms[:scene.ngeom]
                      if g.objtype == mujoco.mjtObj.mjOBJ_GEOM and 0 < g.rgba[3] < 1]).astype(int)


def split_layers(model: mujoco.MjModel, data: mujoco.MjData, option: mujoco.MjvOption,
                 groups: LayerGroups) -> None:
    """Move ``model``'s translucent geoms and its other shown geoms welded to the world (the backdrop) to their groups,
    once per compiled model; the scene's render option must show both groups from then on. Groups only decide what is
    drawn: physics and every full render are unchanged."""
    used = set(np.unique(model.geom_group).tolist())
    if used & {groups.backdrop, groups.translucent}:
        raise ValueError(f"geom groups {sorted(used & {groups.backdrop, groups.translucent})} are in use already "
                         f"(groups used: {sorted(used)}); pick free ones for the layers")
    see_through = translucent_geoms(model, data, option)
    static = _shown(model, option) & (model.body_weldid[model.geom_bodyid] == 0) & (model.geom_rgba[:, 3] > 0)
    static[see_through] = False
    model.geom_group[see_through] = groups.translucent
    model.geom_group[static] = groups.backdrop


def layering_blocker(model: mujoco.MjModel, data: mujoco.MjData, option: mujoco.MjvOption,
                     scene: mujoco.MjvScene, groups: LayerGroups) -> str | None:
    """Why two layers could differ from one render of this model (None: they cannot): anything that makes a pixel
    depend on more than its nearest surface, other than translucent things in their group (checked frame by frame)."""
    if model.vis.quality.offsamples:
        return f"multisampling is on (vis.quality.offsamples = {model.vis.quality.offsamples})"
    if scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] and model.vis.quality.shadowsize and model.light_castshadow.any():
        return "a light casts shadows"
    if scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] and (model.mat_reflectance > 0).any():
        return "a material reflects"
    stray = [g for g in translucent_geoms(model, data, option) if model.geom_group[g] != groups.translucent]
    if stray:
        return f"{len(stray)} translucent geoms are outside the translucent group {groups.translucent}"
    return None


class BackdropRenderer:
    """RGB images of one fixed camera through ``renderer`` (a ``mujoco.Renderer`` of the image size, its scene flags
    set), as ``renderer`` would draw them with ``option``, for a model split by :func:`split_layers`. The backdrop
    layer is cached until the camera, a backdrop geom's pose or look, a material or a light changes. ``layered`` is
    False after a blocker or a failed first-frame check (``fallback_reason`` says which); ``whole_frames`` counts the
    frames rendered whole because something translucent lay in front of the backdrop."""

    def __init__(self, renderer: mujoco.Renderer, model: mujoco.MjModel, camera: str, option: mujoco.MjvOption,
                 groups: LayerGroups):
        self.renderer, self.model, self.option, self.groups = renderer, model, option, groups
        self.camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if self.camera_id < 0:
            raise ValueError(f"camera {camera!r} is not in the model; its cameras: "
                             f"{[model.camera(i).name for i in range(model.ncam)]}")
        hidden = [g for g in (groups.backdrop, groups.translucent, groups.frame) if not option.geomgroup[g]]
        if hidden:
            raise ValueError(f"the render option hides layer groups {hidden}: full renders would not draw them")
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = self.camera_id
        self.fallback_reason: str | None = None
        self._backdrop_only, self._frame_only, self._translucent_only = (copy.copy(option) for _ in range(3))
        self._backdrop_only.geomgroup[:] = 0
        self._backdrop_only.geomgroup[groups.backdrop] = 1
        self._backdrop_only.sitegroup[:] = 0
        self._frame_only.geomgroup[groups.backdrop] = 0
        self._translucent_only.geomgroup[:] = 0
        self._translucent_only.geomgroup[groups.translucent] = 1
        self._checked = False
        self._key: bytes | None = None
        self._backdrop_rgb = self._backdrop_depth = self._backdrop_ids = None
        self.backdrop_renders = 0  # how often the backdrop layer was drawn (once per layout and camera pose)
        self.whole_frames = 0

    @property
    def backdrop(self) -> np.ndarray:
        return np.flatnonzero(self.model.geom_group == self.groups.backdrop)

    @property
    def layered(self) -> bool:
        return self.fallback_reason is None

    def render(self, data: mujoco.MjData) -> np.ndarray:
        if not self._checked and self.fallback_reason is None:
            self.fallback_reason = layering_blocker(self.model, data, self.option, self.renderer.scene, self.groups)
            if self.fallback_reason is None and not len(self.backdrop):
                self.fallback_reason = f"no geom is in the backdrop group {self.groups.backdrop}"
        if not self.layered:
            return self._whole(data)
        key = self._backdrop_key(data)
        if key != self._key:
            self._backdrop_rgb, self._backdrop_depth = self._draw(data, self._backdrop_only)
            self._backdrop_ids = self._segments(data, self._backdrop_only)[0]
            self._key = key
            self.backdrop_renders += 1
        rgb, depth = self._draw(data, self._frame_only)
        backdrop_wins = self._backdrop_depth > depth  # reversed Z (MuJoCo's default): larger is nearer
        covered, front_depth = self._segments(data, self._translucent_only)
        blended = (covered > -2) & backdrop_wins & (front_depth > self._backdrop_depth)
        if blended.any():  # something translucent in front of the backdrop: it would blend over it in a full render
            self.model.geom_group[np.unique(self._backdrop_ids[blended & (self._backdrop_ids >= 0)])] = self.groups.frame
            self.whole_frames += 1
            return self._whole(data)
        out = np.where(backdrop_wins[..., None], self._backdrop_rgb, rgb)
        if self.renderer._gl_context:  # as mujoco.Renderer.render: OpenGL's rows run bottom-up
            out = out[::-1]
        out = np.ascontiguousarray(out)
        if not self._checked:
            self._checked = True
            whole = self._whole(data)
            if not np.array_equal(whole, out):
                self.fallback_reason = (f"the layers differed from a full render in "
                                        f"{int((whole != out).any(-1).sum())} pixels on the first frame")
                return whole
        return out

    def _backdrop_key(self, data: mujoco.MjData) -> bytes:
        """Everything the backdrop layer's pixels depend on that a run can change."""
        m, c = self.model, self.camera_id
        g = self.backdrop
        parts = (data.cam_xpos[c], data.cam_xmat[c], m.cam_fovy[c:c + 1], g, data.geom_xpos[g], data.geom_xmat[g],
                 m.geom_rgba[g], m.geom_matid[g], m.mat_rgba, m.mat_emission, m.mat_specular, m.mat_shininess,
                 m.mat_texid, data.light_xpos, data.light_xdir, m.light_active, m.light_diffuse, m.light_ambient,
                 m.light_specular, self.option.geomgroup, self.renderer.scene.flags)
        return b"".join(np.ascontiguousarray(p).tobytes() for p in parts)

    def _draw(self, data: mujoco.MjData, option: mujoco.MjvOption) -> tuple[np.ndarray, np.ndarray]:
        """RGB and raw depth of what ``option`` shows (bottom-up rows, as drawn)."""
        r = self.renderer
        mujoco.mjv_updateScene(self.model, data, option, None, self._camera, ALL, r.scene)
        h, w = r.height, r.width
        rgb, depth = np.empty((h, w, 3), np.uint8), np.empty((h, w), np.float32)
        if r._gl_context:
            r._gl_context.make_current()
        rect = mujoco.MjrRect(0, 0, w, h)
        mujoco.mjr_render(rect, r.scene, r._mjr_context)
        mujoco.mjr_readPixels(rgb, depth, rect, r._mjr_context)
        return rgb, depth

    def _segments(self, data: mujoco.MjData, option: mujoco.MjvOption) -> tuple[np.ndarray, np.ndarray]:
        """Per pixel, the geom id drawn there opaque (segmentation colours; -1 for none or a site, tendon, ...;
        -2 for nothing) and its depth, of what ``option`` shows."""
        scene = self.renderer.scene
        flags = scene.flags.copy()
        scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
        try:
            rgb, depth = self._draw(data, option)
        finally:
            np.copyto(scene.flags, flags)
        seg = rgb.astype(np.int64) @ np.array([1, 256, 65536])  # 0: nothing, else index + 1
        ids = np.full(scene.ngeom + 1, -1, np.int64)
        ids[0] = -2
        for i in range(scene.ngeom):
            g = scene.geoms[i]
            if g.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                ids[g.segid + 1] = g.objid
        return ids[np.minimum(seg, scene.ngeom)], depth

    def _whole(self, data: mujoco.MjData) -> np.ndarray:
        """One full render, as mujoco.Renderer makes it."""
        self.renderer.update_scene(data, camera=self.camera_id, scene_option=self.option)
        return self.renderer.render().copy()
