"""Task objects built from primitive geoms (fast software rendering, stable contacts).

Each builder adds bodies to a spec and returns an ``ObjectInfo`` with the geometry the oracle and the
success predicates need. Sizes are in metres; "half" sizes follow MuJoCo's convention.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tcot_hybrid.scene import GEOM, add_free_body, add_geom

RED = (0.85, 0.15, 0.12, 1)
GREEN = (0.15, 0.7, 0.2, 1)
BLUE = (0.15, 0.3, 0.85, 1)
YELLOW = (0.9, 0.8, 0.1, 1)
ORANGE = (0.95, 0.5, 0.1, 1)
WHITE = (0.92, 0.92, 0.9, 1)
BROWN = (0.45, 0.3, 0.18, 1)
GREY = (0.55, 0.55, 0.58, 1)


@dataclass(frozen=True, kw_only=True)
class ObjectInfo:
    """What the oracle and predicates know about an object.

    kind: cube | cylinder | plate | bowl | basket | drawer | stick
    body: MuJoCo body name (for a drawer, the sliding drawer body)
    half_height: half of the object's height [m] (a free body's origin is its centre)
    inner_half: for receptacles, inner half-extent [m] (radius for round ones)
    rim_height: for receptacles, wall height above the bottom [m]
    bottom:     for receptacles, height of the floor's top face in the body frame [m] (plate: its top face)
    rim_top:    for receptacles, height of the wall's top edge in the body frame [m]
    joint: name of the joint that moves it (free joint, or the drawer's slide)
    """

    name: str
    kind: str
    body: str
    joint: str
    half_height: float
    inner_half: float = 0.0
    rim_height: float = 0.0
    bottom: float = 0.0
    rim_top: float = 0.0
    rest_z: float = 0.0  # height of the body origin when resting on the table [m]


def cube(spec: mujoco.MjSpec, name: str, rgba, half: float = 0.02, mass: float = 0.05) -> ObjectInfo:
    body = add_free_body(spec, name)
    add_geom(body, type=GEOM.mjGEOM_BOX, size=(half, half, half), rgba=rgba, name=f"{name}_geom", mass=mass)
    return ObjectInfo(name=name, kind="cube", body=name, joint=f"{name}_free", half_height=half, rest_z=half)


def cylinder(spec, name: str, rgba, radius: float = 0.02, half_height: float = 0.03, mass=0.05) -> ObjectInfo:
    body = add_free_body(spec, name)
    add_geom(body, type=GEOM.mjGEOM_CYLINDER, size=(radius, half_height, 0), rgba=rgba, name=f"{name}_geom",
             mass=mass)
    return ObjectInfo(name=name, kind="cylinder", body=name, joint=f"{name}_free", half_height=half_height,
                      rest_z=half_height)


def plate(spec, name: str = "plate", radius: float = 0.08, half_thick: float = 0.006, mass=0.4) -> ObjectInfo:
    body = add_free_body(spec, name)
    add_geom(body, type=GEOM.mjGEOM_CYLINDER, size=(radius, half_thick, 0), rgba=WHITE, name=f"{name}_geom",
             mass=mass)
    return ObjectInfo(name=name, kind="plate", body=name, joint=f"{name}_free", half_height=half_thick,
                      inner_half=radius, rim_height=0.0, bottom=half_thick, rest_z=half_thick)


def bowl(spec, name: str = "bowl", inner_radius: float = 0.07, wall_h: float = 0.045, wall_t: float = 0.008,
         n_walls: int = 12, mass: float = 0.5) -> ObjectInfo:
    """Round open container: a flat bottom disk and a ring of wall boxes."""
    body = add_free_body(spec, name)
    bottom_half = 0.005
    add_geom(body, type=GEOM.mjGEOM_CYLINDER, size=(inner_radius + wall_t, bottom_half, 0),
             pos=(0, 0, -wall_h / 2), rgba=ORANGE, name=f"{name}_bottom", mass=mass * 0.4)
    seg_half = (inner_radius + wall_t) * np.tan(np.pi / n_walls) + 0.002
    for i in range(n_walls):
        a = 2 * np.pi * i / n_walls
        r = inner_radius + wall_t / 2
        add_geom(body, type=GEOM.mjGEOM_BOX, size=(wall_t / 2, seg_half, wall_h / 2),
                 pos=(r * np.cos(a), r * np.sin(a), 0), quat=(np.cos(a / 2), 0, 0, np.sin(a / 2)),
                 rgba=ORANGE, name=f"{name}_wall{i}", mass=mass * 0.6 / n_walls)
    return ObjectInfo(name=name, kind="bowl", body=name, joint=f"{name}_free", half_height=wall_h / 2,
                      inner_half=inner_radius, rim_height=wall_h, bottom=-wall_h / 2 + bottom_half,
                      rim_top=wall_h / 2, rest_z=wall_h / 2 + bottom_half)


def basket(spec, name: str = "basket", inner_half: float = 0.08, wall_h: float = 0.06, wall_t: float = 0.008,
           mass: float = 0.8) -> ObjectInfo:
    """Square open box."""
    body = add_free_body(spec, name)
    out = inner_half + wall_t
    add_geom(body, type=GEOM.mjGEOM_BOX, size=(out, out, 0.005), pos=(0, 0, -wall_h / 2), rgba=BROWN,
             name=f"{name}_bottom", mass=mass * 0.4)
    for i, (dx, dy) in enumerate(((1, 0), (-1, 0), (0, 1), (0, -1))):
        size = (wall_t / 2, out, wall_h / 2) if dx else (out, wall_t / 2, wall_h / 2)
        add_geom(body, type=GEOM.mjGEOM_BOX, size=size,
                 pos=(dx * (inner_half + wall_t / 2), dy * (inner_half + wall_t / 2), 0), rgba=BROWN,
                 name=f"{name}_wall{i}", mass=mass * 0.15)
    return ObjectInfo(name=name, kind="basket", body=name, joint=f"{name}_free", half_height=wall_h / 2,
                      inner_half=inner_half, rim_height=wall_h, bottom=-wall_h / 2 + 0.005,
                      rim_top=wall_h / 2, rest_z=wall_h / 2 + 0.005)


# Drawer geometry [m]: cabinet outer half extents and the drawer's interior.
DRAWER_INNER = (0.075, 0.085)  # interior half extents (x, y)
DRAWER_WALL_H = 0.05
CABINET_TOP_Z = 0.12
DRAWER_TRAVEL = 0.2


def drawer(spec, name: str = "drawer") -> ObjectInfo:
    """A cabinet fixed to the table with a drawer sliding out toward the robot (-x).

    The cabinet body's origin is the centre of its front face at table height; the scene moves it per
    episode through ``model.body_pos``. The drawer handle is an upright block on the front panel, grasped
    top-down with the fingers closing across its width.
    """
    ix, iy = DRAWER_INNER
    t = 0.01
    cab = spec.worldbody.add_body()
    cab.name = f"{name}_cabinet"
    cab.pos = (0.68, 0.0, 0.0)
    depth = 2 * ix + 2 * t + 0.01
    half_w = iy + 2 * t + 0.005
    top_z = CABINET_TOP_Z
    # top, back, sides, bottom shelf (open front)
    add_geom(cab, type=GEOM.mjGEOM_BOX, size=(depth / 2, half_w, t / 2), pos=(depth / 2, 0, top_z - t / 2),
             rgba=GREY, name=f"{name}_cab_top")
    add_geom(cab, type=GEOM.mjGEOM_BOX, size=(t / 2, half_w, top_z / 2), pos=(depth - t / 2, 0, top_z / 2),
             rgba=GREY, name=f"{name}_cab_back")
    for s in (1, -1):
        add_geom(cab, type=GEOM.mjGEOM_BOX, size=(depth / 2, t / 2, top_z / 2),
                 pos=(depth / 2, s * (half_w - t / 2), top_z / 2), rgba=GREY, name=f"{name}_cab_side{s:+d}")
    slide_z = 0.012
    drw = cab.add_body()
    drw.name = name
    drw.pos = (0.0, 0.0, slide_z)
    j = drw.add_joint()
    j.name = f"{name}_slide"
    j.type = mujoco.mjtJoint.mjJNT_SLIDE
    j.axis = (-1, 0, 0)
    j.range = (0.0, DRAWER_TRAVEL)
    j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
    j.damping = [8.0, 0.0, 0.0]  # linear damping [N s/m] (mujoco 4 stores a polynomial)
    j.frictionloss = 0.5
    j.armature = 0.05
    cx = t + ix  # interior centre, measured from the front panel's inner face
    add_geom(drw, type=GEOM.mjGEOM_BOX, size=(ix + t, iy + t, t / 2), pos=(cx, 0, t / 2), rgba=BROWN,
             name=f"{name}_bottom", mass=0.3)
    for s in (1, -1):
        add_geom(drw, type=GEOM.mjGEOM_BOX, size=(ix + t, t / 2, DRAWER_WALL_H / 2),
                 pos=(cx, s * (iy + t / 2), DRAWER_WALL_H / 2), rgba=BROWN, name=f"{name}_side{s:+d}",
                 mass=0.1)
    add_geom(drw, type=GEOM.mjGEOM_BOX, size=(t / 2, iy + t, DRAWER_WALL_H / 2),
             pos=(2 * ix + 1.5 * t, 0, DRAWER_WALL_H / 2), rgba=BROWN, name=f"{name}_back", mass=0.1)
    front_h = top_z - slide_z - 0.004
    add_geom(drw, type=GEOM.mjGEOM_BOX, size=(t / 2, half_w, front_h / 2), pos=(-t / 2, 0, front_h / 2),
             rgba=GREY, name=f"{name}_front", mass=0.2)
    add_geom(drw, type=GEOM.mjGEOM_BOX, size=(0.015, 0.0125, 0.02), pos=(-t - 0.015, 0, front_h - 0.02),
             rgba=BLUE, name=f"{name}_handle", mass=0.05)
    return ObjectInfo(name=name, kind="drawer", body=name, joint=f"{name}_slide", half_height=DRAWER_WALL_H / 2,
                      inner_half=min(ix, iy), rim_height=DRAWER_WALL_H, bottom=t, rim_top=DRAWER_WALL_H)


STICK_LENGTH = 0.40
STICK_GRIP_FROM_END = 0.045
HOOK_HALF_WIDTH = 0.08


def stick(spec, name: str = "stick") -> ObjectInfo:
    """A stick along its body x axis with a hook crossbar at the far (+x) end; origin at the near end."""
    body = add_free_body(spec, name)
    half_t = 0.01
    add_geom(body, type=GEOM.mjGEOM_BOX, size=(STICK_LENGTH / 2, 0.0125, half_t), pos=(STICK_LENGTH / 2, 0, 0),
             rgba=YELLOW, name=f"{name}_shaft", mass=0.1)
    add_geom(body, type=GEOM.mjGEOM_BOX, size=(0.0125, HOOK_HALF_WIDTH, half_t),
             pos=(STICK_LENGTH - 0.0125, 0, 0), rgba=YELLOW, name=f"{name}_hook", mass=0.03)
    return ObjectInfo(name=name, kind="stick", body=name, joint=f"{name}_free", half_height=half_t, rest_z=half_t)
