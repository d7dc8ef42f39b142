"""Privileged geometry of a LIBERO scene for the oracle: collision boxes of a body subtree, their world AABBs,
point-in-box clearance tests, joint axes and region sites.

Every LIBERO object and fixture is a set of collision geoms (boxes almost everywhere); MuJoCo's per-geom
local AABB (``geom_aabb``) covers the other types, so nothing here depends on the geom type.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np


def subtree_bodies(model: mujoco.MjModel, body: int) -> np.ndarray:
    """Ids of ``body`` and every body below it."""
    out = [body]
    for b in range(body + 1, model.nbody):
        p = b
        while p > 0 and p != body:
            p = model.body_parentid[p]
        if p == body:
            out.append(b)
    return np.array(out, int)


def is_collision_geom(model: mujoco.MjModel, g: int) -> bool:
    return bool(model.geom_contype[g] or model.geom_conaffinity[g])


@dataclass(frozen=True)
class Boxes:
    """Oriented boxes in the world: centres (N, 3), rotations (N, 3, 3), half sizes (N, 3), geom ids (N,)."""

    centre: np.ndarray
    rot: np.ndarray
    half: np.ndarray
    geom: np.ndarray

    def __len__(self) -> int:
        return len(self.geom)

    def world_extents(self) -> np.ndarray:
        """(N, 3) half extents of each box along the world axes [m] (its own world AABB is centre -/+ these)."""
        return np.einsum("nij,nj->ni", np.abs(self.rot), self.half)

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounds (lo, hi) of all boxes."""
        ext = self.world_extents()
        return (self.centre - ext).min(axis=0), (self.centre + ext).max(axis=0)

    def extents_in(self, R: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds (lo, hi) of all boxes in the frame (R, origin) (R's columns = the frame's axes in world)."""
        local_c = (self.centre - origin) @ R
        local_R = np.einsum("ji,njk->nik", R, self.rot)
        ext = np.einsum("nij,nj->ni", np.abs(local_R), self.half)
        return (local_c - ext).min(axis=0), (local_c + ext).max(axis=0)

    def select(self, mask: np.ndarray) -> "Boxes":
        return Boxes(self.centre[mask], self.rot[mask], self.half[mask], self.geom[mask])

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """(P,) bool: which points lie inside any box grown by ``margin`` [m]."""
        if len(self) == 0 or len(points) == 0:
            return np.zeros(len(points), bool)
        ext = self.world_extents() + margin
        lo, hi = points.min(axis=0), points.max(axis=0)
        keep = np.all((self.centre + ext >= lo) & (self.centre - ext <= hi), axis=1)
        if not keep.any():
            return np.zeros(len(points), bool)
        centre, rot, half = self.centre[keep], self.rot[keep], self.half[keep]
        d = points[:, None, :] - centre[None, :, :]  # (P, N, 3)
        local = np.einsum("pni,nij->pnj", d, rot)
        inside = np.all(np.abs(local) <= half[None] + margin, axis=2)
        return inside.any(axis=1)


def boxes_overlap(a: Boxes, b: Boxes, margin: float = 0.0) -> np.ndarray:
    """(len(a), len(b)) bool: which pairs of oriented boxes overlap, ``b``'s grown by ``margin`` [m]
    (separating-axis test: the 3 + 3 face normals and the 9 edge-edge cross products)."""
    out = np.zeros((len(a), len(b)), bool)
    if len(a) == 0 or len(b) == 0:
        return out
    # world AABBs first: most pairs are far apart
    ext_a = a.world_extents()
    ext_b = np.einsum("nij,nj->ni", np.abs(b.rot), b.half + margin)
    near = np.all(np.abs(b.centre[None] - a.centre[:, None]) <= ext_a[:, None] + ext_b[None] + 1e-9, axis=2)
    ia, ib = np.nonzero(near)
    if ia.size:
        out[ia, ib] = _sat_overlap(a.centre[ia], a.rot[ia], a.half[ia], b.centre[ib], b.rot[ib], b.half[ib] + margin)
    return out


def _sat_overlap(ca, ra, ha, cb, rb, hb) -> np.ndarray:
    """(P,) bool for P box pairs given as centres (P, 3), rotations (P, 3, 3) and half sizes (P, 3)."""
    ax_a, ax_b = np.swapaxes(ra, -1, -2), np.swapaxes(rb, -1, -2)  # rows = each box's axes
    cross = np.cross(ax_a[:, :, None, :], ax_b[:, None, :, :]).reshape(-1, 9, 3)
    axes = np.concatenate([ax_a, ax_b, cross], axis=1)  # (P, 15, 3)
    dist = np.abs(np.einsum("pkj,pj->pk", axes, cb - ca))
    reach_a = np.einsum("pki,pi->pk", np.abs(axes @ ra), ha)
    reach_b = np.einsum("pki,pi->pk", np.abs(axes @ rb), hb)
    return ~(dist > reach_a + reach_b + 1e-9).any(axis=1)


def collision_boxes(model: mujoco.MjModel, data: mujoco.MjData, bodies) -> Boxes:
    """The collision geoms of ``bodies`` (ids) as world boxes (each geom's local AABB, posed)."""
    bodies = np.asarray(list(bodies), int)
    geoms = np.flatnonzero(np.isin(model.geom_bodyid, bodies))
    geoms = np.array([g for g in geoms if is_collision_geom(model, g)], int)
    if geoms.size == 0:
        z = np.zeros((0, 3))
        return Boxes(z, np.zeros((0, 3, 3)), z, np.zeros(0, int))
    R = data.geom_xmat[geoms].reshape(-1, 3, 3)
    c_local = model.geom_aabb[geoms, :3]
    half = model.geom_aabb[geoms, 3:]
    centre = data.geom_xpos[geoms] + np.einsum("nij,nj->ni", R, c_local)
    return Boxes(centre, R, half.copy(), geoms)


def joint_world_axis(model: mujoco.MjModel, data: mujoco.MjData, joint: int) -> tuple[np.ndarray, np.ndarray]:
    """World anchor and unit axis of a 1-dof joint."""
    return data.xanchor[joint].copy(), data.xaxis[joint].copy() / np.linalg.norm(data.xaxis[joint])


def site_box(model: mujoco.MjModel, data: mujoco.MjData, site: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A site's world centre, rotation and half size."""
    return data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy(), model.site_size[site].copy()
