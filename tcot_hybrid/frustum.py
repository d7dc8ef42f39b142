"""Which mesh geoms a camera cannot see: their bounding sphere lies wholly outside its view frustum.

Software rendering (llvmpipe) pays per vertex whether or not a triangle lands in the image, and MuJoCo draws every
geom of the scene for every camera. A LIBERO scene holds 0.9-1.1 M mesh vertices, 10-13 % of them outside
agentview's frustum (robot links swung out of view, the room's far side); ``Simulation.render`` leaves those out.
The test is conservative (a sphere around the whole mesh against the four side planes and the camera's back), so
the image is the same pixel for pixel (tests/test_frustum.py, tests/test_sim.py) and only the cost changes.
"""
from __future__ import annotations

import mujoco
import numpy as np


def outside_frustum(cam_pos: np.ndarray, cam_mat: np.ndarray, fovy_deg: float, aspect: float,
                    centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(N,) bool: spheres (``centers`` (N, 3) [m, world], ``radii`` (N,) [m]) wholly outside the view frustum of
    a perspective camera at ``cam_pos`` with orientation ``cam_mat`` (3x3, columns = camera axes in the world;
    MuJoCo's convention: looking along -z, y up), vertical field of view ``fovy_deg`` and image ``aspect``
    (width / height). Behind the camera counts as outside; the near and far planes are not tested (a sphere in
    front of the near plane or past the far one may be called visible: never the other way round)."""
    if not 0.0 < fovy_deg < 180.0:
        raise ValueError(f"fovy_deg must be in (0, 180) degrees, got {fovy_deg!r}")
    if not aspect > 0.0:
        raise ValueError(f"aspect must be > 0 (width / height), got {aspect!r}")
    ty = np.tan(np.deg2rad(fovy_deg) / 2.0)
    tx = ty * aspect
    c = (np.asarray(centers, dtype=float) - np.asarray(cam_pos, dtype=float)) @ np.asarray(cam_mat, dtype=float)
    x, y, z = c[:, 0], c[:, 1], -c[:, 2]  # z: distance along the viewing direction
    r = np.asarray(radii, dtype=float)
    # signed distances to the side planes through the eye (inside > 0): |x| <= tx z, |y| <= ty z
    nx, ny = np.sqrt(1.0 + tx * tx), np.sqrt(1.0 + ty * ty)
    out = z < -r
    out |= (tx * z - x) / nx < -r
    out |= (tx * z + x) / nx < -r
    out |= (ty * z - y) / ny < -r
    out |= (ty * z + y) / ny < -r
    return out


class OffscreenMeshCulling:
    """Leaves out of a camera's render the mesh geoms it cannot see, by giving them alpha 0 (MuJoCo's scene
    update skips a geom with alpha 0) for that one scene update; :meth:`restore` puts their colours back.

    It stays off where a geom outside the frustum can still change the image: shadows or reflections on, a
    camera with a sensor size or principal point (an off-centre frustum) or an orthographic one."""

    def __init__(self, model: mujoco.MjModel):
        self.model = model
        self.meshes = np.flatnonzero(model.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
        self._saved: tuple[np.ndarray, np.ndarray] | None = None

    def applies(self, camera_id: int, scene: mujoco.MjvScene) -> bool:
        m = self.model
        if camera_id < 0 or not self.meshes.size:
            return False
        if scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] and m.light_castshadow.any():
            return False
        if scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] and (m.mat_reflectance > 0).any():
            return False
        perspective = m.cam_projection[camera_id] == mujoco.mjtProjection.mjPROJ_PERSPECTIVE
        return bool(perspective and not m.cam_sensorsize[camera_id].any())

    def hide(self, data: mujoco.MjData, camera_id: int, width: int, height: int) -> int:
        """Give alpha 0 to the meshes outside camera ``camera_id``'s frustum (positions from ``data``, kinematics
        current); returns how many. Call :meth:`restore` after the scene update."""
        m, ids = self.model, self.meshes
        ids = ids[m.geom_rgba[ids, 3] > 0]
        hidden = ids[outside_frustum(data.cam_xpos[camera_id], data.cam_xmat[camera_id].reshape(3, 3),
                                     float(m.cam_fovy[camera_id]), width / height,
                                     data.geom_xpos[ids], m.geom_rbound[ids])]
        self._saved = (hidden, m.geom_rgba[hidden, 3].copy())
        m.geom_rgba[hidden, 3] = 0.0
        return int(hidden.size)

    def restore(self) -> None:
        if self._saved is not None:
            hidden, alpha = self._saved
            self.model.geom_rgba[hidden, 3] = alpha
            self._saved = None
