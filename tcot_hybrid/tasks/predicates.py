"""Success predicates on simulator state, shared by every task (and meant for other worlds' tasks too).

Strict by construction: an object counts as delivered only when it has been **released** — no finger
touches it and every gripper actuator is commanded open — and it is **settled** (still, upright) **in
place**: inside the target's footprint, with its bottom on the target's support surface and below a
container's rim top. Each helper returns a plain bool; :func:`check` gives the reasons a predicate fails
(for tests and diagnostics).

Tolerances [m, m/s, rad/s, rad] are module constants so tests and docs can name them:
"""
from __future__ import annotations

import numpy as np

from tcot_hybrid.tasks.base import World

STILL_SPEED_MPS = 0.05  # an object moving faster than this [m/s] has not come to rest
STILL_SPIN_RADPS = 0.5  # ... or turning faster than this [rad/s]
MAX_TILT_RAD = 0.35  # a cube may rest on any face, a cylinder on its base: that face's normal within ~20 deg of up
SUPPORT_TOL_M = 0.015  # the object's bottom within this of the support surface (plate top, container floor, block top)
FOOTPRINT_MARGIN_M = 0.01  # plate: the object's centre at least this far inside the rim
BOWL_MARGIN_M = 0.005  # bowl: ... inside the inner wall


def released(world: World, obj: str) -> bool:
    """No finger touches ``obj`` and every gripper actuator is commanded open."""
    return world.fingers_open() and not world.touching(obj, world.finger_geoms)


def settled(world: World, obj: str) -> bool:
    """``obj`` has come to rest (linear and angular speed under STILL_SPEED_MPS / STILL_SPIN_RADPS)."""
    return world.speed(obj) < STILL_SPEED_MPS and world.spin(obj) < STILL_SPIN_RADPS


def upright(world: World, obj: str, *, max_tilt_rad: float = MAX_TILT_RAD) -> bool:
    """A cube (or block) rests on a face: one of its axes within ``max_tilt_rad`` of world z; any other object
    (cylinder, ...) stands on its base: its body z axis within ``max_tilt_rad`` of world z."""
    R = world.rot(obj)
    cos = np.cos(max_tilt_rad)
    if world.objects[obj].kind == "cube":
        return bool(np.max(np.abs(R[2, :])) >= cos)
    return bool(R[2, 2] >= cos)


def _bottom_z(world: World, obj: str) -> float:
    return float(world.pos(obj)[2] - world.objects[obj].half_height)


def resting_on(world: World, obj: str, surface: str, *, tol_z: float = SUPPORT_TOL_M) -> bool:
    """``obj`` lies on a plate-like ``surface``: its centre inside the surface's radius (minus
    FOOTPRINT_MARGIN_M), its bottom within ``tol_z`` of the surface's top, upright, released and settled."""
    o, s = world.objects[obj], world.objects[surface]
    p, q = world.pos(obj), world.pos(surface)
    inside = np.linalg.norm(p[:2] - q[:2]) <= s.inner_half - FOOTPRINT_MARGIN_M
    height = abs((p[2] - o.half_height) - (q[2] + s.half_height)) <= tol_z
    return bool(inside and height and upright(world, obj) and released(world, obj) and settled(world, obj))


def inside_container(world: World, obj: str, container: str, *, tol_z: float = SUPPORT_TOL_M) -> bool:
    """``obj`` is in a bowl, basket or drawer: its centre within the inner extent, its bottom on the floor
    (within ``tol_z``) and below the rim top, upright, released and settled."""
    from tcot_hybrid.tasks.objects import DRAWER_INNER

    o, c = world.objects[obj], world.objects[container]
    local = world.rot(container).T @ (world.pos(obj) - world.pos(container))
    if c.kind == "bowl":
        inside_xy = np.linalg.norm(local[:2]) <= c.inner_half - BOWL_MARGIN_M
    elif c.kind == "drawer":
        inside_xy = abs(local[0] - (0.01 + DRAWER_INNER[0])) <= DRAWER_INNER[0] and abs(local[1]) <= DRAWER_INNER[1]
    else:
        inside_xy = bool(np.all(np.abs(local[:2]) <= c.inner_half))
    bottom = local[2] - o.half_height
    on_floor = bottom - c.bottom <= tol_z
    below_rim = bottom < c.rim_top
    return bool(inside_xy and on_floor and below_rim and upright(world, obj) and released(world, obj)
                and settled(world, obj))


def stacked_on(world: World, top: str, bottom: str, *, tol_z: float = 0.01) -> bool:
    """``top`` rests on ``bottom``: centres within the smaller half-size in xy, ``top``'s bottom face within
    ``tol_z`` of ``bottom``'s top face, upright, released and settled."""
    t, b = world.pos(top), world.pos(bottom)
    ht, hb = world.objects[top].half_height, world.objects[bottom].half_height
    return bool(np.linalg.norm(t[:2] - b[:2]) <= min(ht, hb) and abs(t[2] - b[2] - ht - hb) <= tol_z
                and upright(world, top) and released(world, top) and settled(world, top))
