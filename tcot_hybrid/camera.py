"""Pinhole camera geometry matching what ``mujoco.Renderer`` draws.

Frames and conventions
----------------------
* ``T_world_cam`` maps OpenCV camera coordinates (x right, y down, z forward) to the world.
  MuJoCo cameras look along their -z axis with y up, so ``R_world_cv = R_world_mjcam @ diag(1, -1, -1)``.
* ``uv_px``: column ``u`` to the right, row ``v`` down, as indexed in the rendered array
  ``image[v, u]``. Integer coordinates are pixel centres, so pixel ``(i, j)`` covers
  ``[i - 0.5, i + 0.5) x [j - 0.5, j + 0.5)`` and the image spans ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``.
  With MuJoCo's symmetric frustum the principal point is therefore ``((W - 1) / 2, (H - 1) / 2)``.
* ``depth_m``: z coordinate in the OpenCV camera frame (distance along the optical axis), which is
  what the renderer's depth mode returns. It is not the ray length.

``mujoco.Renderer`` already converts its z-buffer to metric depth (reverse-Z aware), so no
z-buffer conversion is provided here.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import mujoco
import numpy as np

from tcot_hybrid.errors import ConfigError, LiftError, unknown_name

# OpenCV camera axes expressed in MuJoCo camera axes (y and z flipped).
_R_MJCAM_CV = np.diag([1.0, -1.0, -1.0])


def _frozen(arr: np.ndarray) -> np.ndarray:
    out = np.array(arr, dtype=float)
    out.setflags(write=False)
    return out


def as_points(name: str, value: object, cols: int, *, error: type[Exception] = LiftError) -> np.ndarray:
    """Return ``value`` as a finite float array of shape (N, cols), N >= 1, else raise ``error``.

    The message names the argument, the shape received and the first bad row.
    """
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise error(f"{name} must be a numeric array of shape (N, {cols}), got {value!r}") from exc
    if arr.ndim != 2 or arr.shape[1] != cols or arr.shape[0] == 0:
        raise error(f"{name} must have shape (N>=1, {cols}), got {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        i = int(bad[0])
        raise error(f"{name}[{i}] = {arr[i].tolist()} is not finite ({bad.size} of {arr.shape[0]} rows bad)")
    return arr


@dataclass(frozen=True, kw_only=True, eq=False)
class CameraModel:
    """A calibrated pinhole camera.

    name:        camera name (the MJCF camera it came from) [-]
    width:       image width [px]
    height:      image height [px]
    K:           3x3 intrinsics [px]; ``K[0,0]``/``K[1,1]`` focal lengths, ``K[:2,2]`` principal point
    T_world_cam: 4x4 pose of the OpenCV camera frame in the world [m]
    near_m:      nearest valid depth along the optical axis [m] (renderer's near clip plane)
    far_m:       farthest valid depth along the optical axis [m] (renderer's far clip plane)
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    T_world_cam: np.ndarray
    near_m: float
    far_m: float

    def __post_init__(self) -> None:
        for field in ("width", "height"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ConfigError(f"camera {self.name!r}: {field} must be an integer >= 1 [px], got {value!r}")
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise ConfigError(f"camera {self.name!r}: K must be a finite 3x3 matrix, got {self.K!r}")
        if not (K[0, 0] > 0 and K[1, 1] > 0) or not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0:
            raise ConfigError(
                f"camera {self.name!r}: K must be upper triangular with positive focal lengths and "
                f"last row [0, 0, 1], got {K.tolist()}"
            )
        T = np.asarray(self.T_world_cam, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ConfigError(f"camera {self.name!r}: T_world_cam must be a finite 4x4 matrix, got {self.T_world_cam!r}")
        R = T[:3, :3]
        if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]) or not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ConfigError(
                f"camera {self.name!r}: T_world_cam must be a rigid transform (orthonormal rotation, "
                f"det +1, last row [0, 0, 0, 1]), got {T.tolist()}"
            )
        for field in ("near_m", "far_m"):
            value = getattr(self, field)
            if isinstance(value, bool) or not np.isfinite(value) or value <= 0:
                raise ConfigError(f"camera {self.name!r}: {field} must be a finite number > 0 [m], got {value!r}")
        if not self.near_m < self.far_m:
            raise ConfigError(f"camera {self.name!r}: need near_m < far_m, got {self.near_m} >= {self.far_m}")
        object.__setattr__(self, "K", _frozen(K))
        object.__setattr__(self, "T_world_cam", _frozen(T))
        object.__setattr__(self, "near_m", float(self.near_m))
        object.__setattr__(self, "far_m", float(self.far_m))
        object.__setattr__(self, "_K_inv", _frozen(np.linalg.inv(K)))
        T_cam_world = np.eye(4)
        T_cam_world[:3, :3] = R.T
        T_cam_world[:3, 3] = -R.T @ T[:3, 3]
        object.__setattr__(self, "_T_cam_world", _frozen(T_cam_world))

    # -- construction ---------------------------------------------------------------------------------

    @classmethod
    def from_mujoco(cls, model: mujoco.MjModel, data: mujoco.MjData, camera: str, *, width: int, height: int) -> CameraModel:
        """Camera ``camera`` of a MuJoCo model as rendered at ``width`` x ``height`` [px].

        Reads the pose from ``data`` (call ``mj_forward``/``mj_kinematics`` first) and the frustum
        exactly as the renderer builds it (``mjv_updateCamera``), so fovy cameras and cameras with
        ``sensorsize``/``focal`` intrinsics are both handled. Orthographic cameras are refused.
        """
        cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cam_id < 0:
            names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, i) or f"#{i}" for i in range(model.ncam)]
            raise ConfigError(unknown_name("camera", camera, names))
        if model.cam_projection[cam_id] != mujoco.mjtProjection.mjPROJ_PERSPECTIVE:
            raise ConfigError(f"camera {camera!r} is orthographic; only perspective cameras are supported")
        for field, value in (("width", width), ("height", height)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ConfigError(f"camera {camera!r}: {field} must be an integer >= 1 [px], got {value!r}")
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            # The renderer itself refuses this; say so before anyone relies on the geometry.
            raise ConfigError(
                f"camera {camera!r}: {width}x{height} px exceeds the model's offscreen buffer "
                f"{model.vis.global_.offwidth}x{model.vis.global_.offheight} (visual/global offwidth/offheight)"
            )

        # Frustum as the renderer builds it (float32 inside MuJoCo; ~1e-7 relative, negligible).
        scene = mujoco.MjvScene(model, maxgeom=1)
        mjcam = mujoco.MjvCamera()
        mjcam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        mjcam.fixedcamid = cam_id
        mujoco.mjv_updateCamera(model, data, mjcam, scene)
        gl = mujoco.mjv_averageCamera(scene.camera[0], scene.camera[1])
        n = float(gl.frustum_near)
        b, t = float(gl.frustum_bottom), float(gl.frustum_top)
        # mjr_render: halfwidth from frustum_width if set, else from the viewport aspect ratio.
        half_w = float(gl.frustum_width) if gl.frustum_width else 0.5 * width / height * (t - b)
        left, right = float(gl.frustum_center) - half_w, float(gl.frustum_center) + half_w
        # glFrustum maps eye x/d in [left, right]/n to window [0, W]; the -0.5 moves the origin to the
        # first pixel's centre, and rows are flipped (renderer output has row 0 at the top).
        fx = width * n / (right - left)
        fy = height * n / (t - b)
        cx = -left * width / (right - left) - 0.5
        cy = t * height / (t - b) - 0.5
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

        R_world_mjcam = np.asarray(data.cam_xmat[cam_id], dtype=float).reshape(3, 3)
        T = np.eye(4)
        T[:3, :3] = R_world_mjcam @ _R_MJCAM_CV
        T[:3, 3] = data.cam_xpos[cam_id]
        # Stereo offset (ipd) is averaged out for mono rendering; check the pose agrees with the renderer.
        if np.linalg.norm(np.asarray(gl.pos, dtype=float) - T[:3, 3]) > 1e-4:
            raise ConfigError(f"camera {camera!r}: renderer camera position {list(gl.pos)} differs from cam_xpos {T[:3, 3].tolist()}")

        extent = float(model.stat.extent)
        return cls(
            name=camera,
            width=int(width),
            height=int(height),
            K=K,
            T_world_cam=T,
            near_m=float(model.vis.map.znear) * extent,
            far_m=float(model.vis.map.zfar) * extent,
        )

    # -- geometry -------------------------------------------------------------------------------------

    @property
    def T_cam_world(self) -> np.ndarray:
        """Inverse of ``T_world_cam`` (world → OpenCV camera)."""
        return self._T_cam_world  # type: ignore[attr-defined]

    @property
    def projection_matrix(self) -> np.ndarray:
        """3x4 ``K [R | t]`` mapping homogeneous world points to homogeneous pixels."""
        return self.K @ self._T_cam_world[:3]  # type: ignore[attr-defined]

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """(N, 3) world points [m] → (N, 3) OpenCV camera coordinates [m]."""
        p = as_points("points_world", points_world, 3)
        T = self._T_cam_world  # type: ignore[attr-defined]
        return p @ T[:3, :3].T + T[:3, 3]

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) world points [m] → ``uv_px`` (N, 2) [px], ``depth_m`` (N,) [m].

        ``uv_px`` is meaningless where ``depth_m <= 0`` (point behind the camera); callers must check
        ``depth_m`` (e.g. ``near_m < depth_m <= far_m``) before using the pixel. Nothing is clipped.
        """
        pc = self.to_camera(points_world)
        depth = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = pc[:, :2] / depth[:, None]
        uv = xy @ self.K[:2, :2].T + self.K[:2, 2]
        return uv, depth.copy()

    def unproject(self, uv_px: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
        """``uv_px`` (N, 2) [px] and ``depth_m`` (N,) [m, along the optical axis] → (N, 3) world [m].

        Pure geometry: only shapes and finiteness are checked here. Use
        :func:`tcot_hybrid.lift.lift_waypoints` to also refuse pixels outside the image and depths
        outside ``(near_m, far_m]``.
        """
        uv = as_points("uv_px", uv_px, 2)
        depth = _depths(depth_m, uv.shape[0])
        rays = np.c_[uv, np.ones(len(uv))] @ self._K_inv.T  # type: ignore[attr-defined]  # z = 1
        pc = rays * depth[:, None]
        return pc @ self.T_world_cam[:3, :3].T + self.T_world_cam[:3, 3]

    def in_image(self, uv_px: np.ndarray, *, margin_px: float = 0.0) -> np.ndarray:
        """Per-point bool: pixel lies inside the image, at least ``margin_px`` [px] from the border.

        The image spans ``[-0.5, W - 0.5] x [-0.5, H - 0.5]`` (integer coordinates = pixel centres).
        Non-finite pixels are outside.
        """
        uv = np.asarray(uv_px, dtype=float)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise LiftError(f"uv_px must have shape (N, 2), got {uv.shape}")
        lo, hi_u, hi_v = -0.5 + margin_px, self.width - 0.5 - margin_px, self.height - 0.5 - margin_px
        with np.errstate(invalid="ignore"):
            return (uv[:, 0] >= lo) & (uv[:, 0] <= hi_u) & (uv[:, 1] >= lo) & (uv[:, 1] <= hi_v)

    def rays_world(self, uv_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Viewing rays of pixels: origin (3,) [m] and unit directions (N, 3) in the world frame."""
        uv = as_points("uv_px", uv_px, 2)
        d = np.c_[uv, np.ones(len(uv))] @ self._K_inv.T @ self.T_world_cam[:3, :3].T  # type: ignore[attr-defined]
        return self.T_world_cam[:3, 3].copy(), d / np.linalg.norm(d, axis=1, keepdims=True)


def _depths(depth_m: object, n: int, *, error: type[Exception] = LiftError) -> np.ndarray:
    try:
        depth = np.asarray(depth_m, dtype=float)
    except (TypeError, ValueError) as exc:
        raise error(f"depth_m must be a numeric array of shape ({n},), got {depth_m!r}") from exc
    if depth.shape != (n,):
        raise error(f"depth_m must have shape ({n},) to match uv_px, got {depth.shape}")
    bad = np.flatnonzero(~np.isfinite(depth))
    if bad.size:
        i = int(bad[0])
        raise error(f"depth_m[{i}] = {depth[i]} is not finite ({bad.size} of {n} bad)")
    return depth


def _ray_plane(camera: CameraModel, uv: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The one ray-plane intersection: for pixels ``uv`` (N, 2) and plane heights ``z`` (N,), the world
    displacement per unit of optical-axis depth along each pixel's ray (N, 3) and the depth at which the ray
    meets its plane (N,) (inf/NaN for rays parallel to the plane; <= 0 for a plane behind the camera)."""
    rays_cv = np.c_[uv, np.ones(len(uv))] @ camera._K_inv.T  # type: ignore[attr-defined]  # OpenCV z = 1
    d_world = rays_cv @ camera.T_world_cam[:3, :3].T  # world displacement per unit of optical-axis depth
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = (z - camera.T_world_cam[2, 3]) / d_world[:, 2]
    return d_world, depth


def points_at_height(camera: CameraModel, uv_px: np.ndarray, z_m: np.ndarray) -> np.ndarray:
    """World points [m] where the viewing rays of pixels ``uv_px`` (..., 2) meet the planes z = ``z_m`` (...);
    NaN where the plane is not in front of the camera. The unchecked, batched form of
    :func:`depth_at_height` for offline metrics (training validation, held-out reports)."""
    shape = np.shape(uv_px)[:-1]
    uv = np.asarray(uv_px, dtype=float).reshape(-1, 2)
    d_world, depth = _ray_plane(camera, uv, np.asarray(z_m, dtype=float).reshape(-1))
    depth[~(depth > 0)] = np.nan
    return (camera.T_world_cam[:3, 3] + d_world * depth[:, None]).reshape(*shape, 3)


def depth_at_height(camera: CameraModel, uv_px: np.ndarray, z_m: np.ndarray, *, min_cos: float = 1e-3) -> np.ndarray:
    """Depth along the optical axis [m] at which each pixel's viewing ray meets the plane world z = ``z_m``.

    uv_px: (N, 2) pixels [px]; z_m: (N,) plane heights [m, world z]. This turns a height lift cue
    (the learned planner predicts the TCP's height above the table) into ``depth_m`` for
    :func:`tcot_hybrid.lift.lift_waypoints`. Raises LiftError for non-finite input, a ray (nearly)
    parallel to the plane (|direction z| < ``min_cos``) and a plane behind the camera along the ray.
    """
    uv = as_points("uv_px", uv_px, 2)
    z = _depths(z_m, uv.shape[0])  # same shape/finiteness checks as a depth array
    d_world, depth = _ray_plane(camera, uv, z)
    norm = np.linalg.norm(d_world, axis=1)
    bad = np.flatnonzero(np.abs(d_world[:, 2]) < min_cos * norm)
    if bad.size:
        i = int(bad[0])
        raise LiftError(f"waypoint {i}: the ray through uv_px={uv[i].tolist()} is parallel to the plane "
                        f"z = {z[i]} m; no depth for a height cue")
    bad = np.flatnonzero(~(depth > 0))
    if bad.size:
        i = int(bad[0])
        raise LiftError(f"waypoint {i}: the plane z = {z[i]} m lies behind camera {camera.name!r} along the ray "
                        f"through uv_px={uv[i].tolist()} (depth {depth[i]:.4g} m)")
    return depth


def triangulate(cam_a: CameraModel, uv_a: np.ndarray, cam_b: CameraModel, uv_b: np.ndarray) -> np.ndarray:
    """Linear (DLT) triangulation of matching pixels in two cameras → (N, 3) world points [m].

    Uses ``cv2.triangulatePoints``. Raises LiftError for bad shapes, non-finite pixels and
    degenerate rays (homogeneous scale ~ 0, i.e. point at infinity or parallel rays).
    Checking the result (in front of both cameras, reprojection error) is the caller's job;
    :func:`tcot_hybrid.lift.lift_two_view` does it.
    """
    a = as_points("uv_a", uv_a, 2)
    b = as_points("uv_b", uv_b, 2)
    if a.shape != b.shape:
        raise LiftError(f"uv_a and uv_b must have the same shape, got {a.shape} and {b.shape}")
    if cam_a.T_world_cam is cam_b.T_world_cam or np.linalg.norm(cam_a.T_world_cam[:3, 3] - cam_b.T_world_cam[:3, 3]) < 1e-9:
        raise LiftError(f"cameras {cam_a.name!r} and {cam_b.name!r} share a centre; triangulation needs a baseline")
    X = cv2.triangulatePoints(cam_a.projection_matrix, cam_b.projection_matrix, a.T.copy(), b.T.copy())
    X = np.asarray(X, dtype=float)
    w = X[3]
    scale = np.linalg.norm(X, axis=0)
    bad = np.flatnonzero(~(np.abs(w) > 1e-12 * scale))
    if bad.size:
        i = int(bad[0])
        raise LiftError(f"waypoint {i}: rays from uv_a={a[i].tolist()} and uv_b={b[i].tolist()} do not intersect (point at infinity)")
    return (X[:3] / w).T
