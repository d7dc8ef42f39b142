"""The LIBERO oracle's scene knowledge and pick-and-place skill (joints: :mod:`tcot_hybrid.libero.joints`):
pick-and-place onto/into anything. Keyframes come from privileged geometry (collision boxes,
region sites, joint axes) read from MuJoCo, never from per-task tables.

A script is a list of skills in one :class:`OracleContext`. The planner asks each not-yet-done skill for
keyframes from the current world; a skill plans in the world as it *will be* once the earlier not-done
skills have run (their :meth:`effect`: a joint at its goal value, an object at its place), so one global
plan made at step 0 holds every step, and a local replan resumes wherever the episode is.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tcot_hybrid.errors import PlanningError
from tcot_hybrid.libero.geometry import Boxes, boxes_overlap, collision_boxes, subtree_bodies
from tcot_hybrid.libero.grasps import (
    APPROACH_DZ,
    E_Z,
    Grasp,
    family,
    handle_candidates,
    frame,
    hand_points,
    inset_rim_candidates,
    rim_candidates,
    rot_z,
    score_grasps,
    part_candidates,
    side_candidates,
    top_candidates,
)
from tcot_hybrid.tasks.base import Keyframe, Skill, World

ROBOT_PREFIXES = ("robot0_", "gripper0_", "mount0_")
ARM_LINK_PREFIX = "robot0_link"  # the arm's links (the hand, gripper0_*, is checked by its sample points)
TRAVEL_CLEARANCE_M = 0.05  # [m] carried object / hand above the highest obstacle under a transport move
# [m] a placed object's bottom this far above its support when released: a bowl held by its rim sags in the
# fingers, and released from higher it landed off the plate (a rim-pinch slips as it comes down)
RELEASE_GAP_M = 0.004
CAVITY_GAP_M = 0.012  # [m] the same for an object slid in level through a cavity's opening: clear of its floor
LIFT_M = 0.12  # [m] straight lift after a grasp or a release before moving sideways
# A release whose carried object has less than this side clearance to a wall (an obstacle rising
# WALL_RISE_M above the object's bottom) is tight: any swing in the fingers lands it on the wall. A clear
# release up to PLACE_MAX_DROP_M above the lowest one is preferred (a book into a caddy's narrow slot).
PLACE_CLEARANCE_M = 0.005
WALL_RISE_M = 0.02
PLACE_MAX_DROP_M = 0.08
PLACE_ALTERNATIVES = 3  # ranked releases tried per grasp for one the arm can reach
TRANSIT_RADIUS_M = 0.10  # [m] obstacles this close to the hand's straight way in count (the palm is 21 cm wide)
TRANSIT_CLEARANCE_M = 0.05  # [m] the TCP this far above them on the way in
GRASP_FALLBACKS = 8  # ranked grasps tried after the best when its plan leaves the planner camera's view
SLIDE_RAISE_M = 0.004  # [m] a grasped object is raised this much before it is dragged out from under something
SLIDE_MAX_M = 0.10  # [m] furthest such a drag
SLIDE_LIFT_CHECK_M = 0.08  # [m] a lift counts as clear when the first 8 cm of it are
SIDE_GRASP_COS = 0.7  # a hand whose approach points less than ~45 degrees below horizontal is a side grasp
# A side grasp (horizontal hand) costs this on top of its reach, where a top grasp pays its lean's distance from the
# one the reach wants. 0.4 was tried at stop 45 (the ketchup's side grasp wins by 0.005, and a planner taught it fell
# 3.3 cm short along the approach): the demonstrations then took the ketchup and 23 of 50 wine bottles bound for the
# cabinet from above, and the planner trained on them (v11) lost on development layouts (docs/libero-planner.md,
# "The control: the recollected demonstrations alone").
SIDE_GRASP_COST = 0.3
VIEW_MARGIN_PX = 0.5  # [px] every waypoint this far inside the planner camera's image (the executor's margin: 0)
LEVEL_APPROACH_MAX_Z = 0.35  # a grasp whose approach axis is this close to level carries into a cavity
CAVITY_CEILING_M = 0.25  # [m] a region with something this low above its floor is a cavity (a microwave)
CAVITY_ENTRY_M = 0.03  # [m] the carried object starts its way in this far outside the opening
CAVITY_PUSH_BACK_M = 0.035  # [m] the hand backs off this far to close its fingers in front of what it held


def kf(p, closed: bool, rot=None) -> Keyframe:
    return Keyframe(np.asarray(p, float).copy(), bool(closed), None if rot is None else np.asarray(rot, float))


# --- the scene as the oracle sees it ------------------------------------------------------------------------

@dataclass
class Effect:
    """What a skill changes: a joint's value or an object's origin (None: nothing predicted)."""

    joint: int | None = None
    q: float = 0.0
    obj: str | None = None
    pos: np.ndarray | None = None
    carried: tuple[str, ...] = ()  # objects inside the moving part (a bowl in a drawer) move with it


class OracleContext:
    """Per-episode privileged scene knowledge: object and fixture body trees, obstacles, home pose."""

    def __init__(self, task, world: World):
        self.task, self.world = task, world
        env = task.scene.env
        self.env, self.model, self.data = env, world.model, world.data
        m = self.model
        self.bodies: dict[str, np.ndarray] = {}
        self.category: dict[str, str] = {}
        for name, obj in list(env.objects_dict.items()) + list(env.fixtures_dict.items()):
            bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, obj.root_body)
            if bid >= 0:
                self.bodies[name] = subtree_bodies(m, bid)
                self.category[name] = str(getattr(obj, "category_name", name))
        robot = [b for b in range(m.nbody) if m.body(b).name.startswith(ROBOT_PREFIXES)]
        self._robot = set(robot)
        self.scene_bodies = np.array([b for b in range(1, m.nbody) if b not in self._robot], int)
        self.home_tcp = world.tcp_pos()
        base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "robot0_base")
        self.base_pos = self.data.xpos[base].copy() if base >= 0 else self.home_tcp.copy()
        self.home_rot = world.tcp_rot()
        self.skills: list["LiberoSkill"] = []
        self.built_at = float(self.data.time)  # [s] simulation time the script was composed at
        self.camera = getattr(task, "planner_camera", None) or "agentview"
        self.image_px = int(getattr(task, "planner_image_px", None) or 128)
        self._camera_model = None
        self._reach = None  # (IK solver, T_base_world, scratch arm state), built on first use

    # -- the planner camera: plans live in its pixels, so every waypoint must be in its view -----------
    def in_view(self, p, *, margin_px: float = VIEW_MARGIN_PX) -> bool:
        """Whether world point ``p`` projects inside the planner camera's image, ``margin_px`` from its border
        (the same camera model the planner projects plans with)."""
        if self._camera_model is None:
            from tcot_hybrid.camera import CameraModel

            m = self.model
            if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, self.camera) < 0:
                return True
            self._camera_model = CameraModel.from_mujoco(m, self.data, self.camera, width=self.image_px,
                                                         height=self.image_px)
        uv, depth = self._camera_model.project(np.asarray(p, float)[None])
        return bool(depth[0] > 0 and self._camera_model.in_image(uv, margin_px=margin_px)[0])

    # -- the arm: a plan whose poses it cannot reach is no plan ------------------------------------------
    def reachable(self, poses, *, moving: str | None = None, effects: list[Effect] = ()) -> bool:
        """Whether the arm follows the hand from where it is now through every (position, rotation) of
        ``poses`` [world] as the executor does, and fits: along the straight, slerped path between them in the
        planner's steps (4 cm, 0.3 rad), each IK solve seeded from the previous one; every pose of ``poses``
        must be reached (points on the way need not converge: the executor goes on from where it got), and
        no arm link may touch the scene (other than ``moving``, the object being moved; the hand itself is
        checked by the skills' hand points). Measured: a bottle held sideways and lifted over the wine rack
        walked the arm onto joint 5's limit and stalled 17 cm short; link 6 hit a mug standing behind the one
        whose handle the hand reached for. The scene is taken as it will be after ``effects``. True when the
        task carries no robot."""
        robot = getattr(self.task, "robot", None)
        if robot is None:
            return True
        from scipy.spatial.transform import Rotation, Slerp

        from tcot_hybrid.ik import IKTarget
        from tcot_hybrid.planners.oracle import OracleConfig
        from tcot_hybrid.robot_check import REACH_TOL_M, REACH_TOL_RAD

        ik, T, arm = self._arm(robot)
        self._arm_scene(arm, effects)
        step = OracleConfig()
        q = self.data.qpos[arm.qpos].copy()
        prev = (self.world.tcp_pos(), self.world.tcp_rot())
        for pos, rot in poses:
            pos, rot = np.asarray(pos, float), np.asarray(rot, float)
            turn = float(np.linalg.norm((Rotation.from_matrix(rot) * Rotation.from_matrix(prev[1]).inv()).as_rotvec()))
            n = max(1, int(np.ceil(max(np.linalg.norm(pos - prev[0]) / step.spacing_m, turn / step.rot_spacing_rad))))
            slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([prev[1], rot])))
            for f in np.arange(1, n + 1) / n:
                p = prev[0] + (pos - prev[0]) * f
                target = IKTarget(pos=T[:3, :3] @ p + T[:3, 3], rot=T[:3, :3] @ slerp(f).as_matrix())
                res = ik.solve(target, q)
                if f == 1.0:  # a key pose must be reached (the executor, too, waits there)
                    res = res if res.pos_err <= REACH_TOL_M else ik.solve(target, res.q)
                    if res.pos_err > REACH_TOL_M or res.rot_err > REACH_TOL_RAD:
                        return False
                q = res.q
                if self._arm_hits(arm, q, moving):
                    return False
            prev = (pos, rot)
        return True

    def _arm(self, robot):
        """(IK solver, T_base_world, the arm's scratch state) for :meth:`reachable`, built on first use."""
        if self._reach is None:
            from types import SimpleNamespace

            from tcot_hybrid.ik import IKConfig, make_ik
            from tcot_hybrid.sim import base_transform

            m = self.model
            links = {b for b in range(m.nbody) if m.body(b).name.startswith(ARM_LINK_PREFIX)}
            arm = SimpleNamespace(
                qpos=np.array([m.jnt_qposadr[m.joint(j).id] for j in robot.arm_joints]),
                data=mujoco.MjData(m), link_geoms=np.isin(m.geom_bodyid, list(links)))
            arm.data.qpos[:] = self.data.qpos
            # on the scratch state: kinematics run on the live state changed what the controller read before
            # the next step by 1e-14, and the episode drifted onto another outcome
            self._reach = (make_ik("pinocchio", robot, IKConfig()),
                           np.linalg.inv(base_transform(robot, m, arm.data)), arm)
        return self._reach

    def _arm_scene(self, arm, effects) -> None:
        """The scratch state as the scene will be after ``effects`` (joints at their goals, objects moved)."""
        m, d = self.model, arm.data
        d.qpos[:] = self.data.qpos
        for e in effects:
            if e.joint is not None:
                d.qpos[m.jnt_qposadr[e.joint]] = e.q
            elif e.obj is not None and e.pos is not None:
                jid = int(m.body_jntadr[int(self.bodies[e.obj][0])])
                if jid >= 0 and int(m.jnt_type[jid]) == int(mujoco.mjtJoint.mjJNT_FREE):
                    adr = m.jnt_qposadr[jid]
                    d.qpos[adr:adr + 3] += e.pos - self.world.pos(e.obj)

    def _arm_hits(self, arm, q, moving: str | None) -> bool:
        """Whether an arm link (not the hand) at joint values ``q`` penetrates a scene geom (not ``moving``)."""
        m, d = self.model, arm.data
        d.qpos[arm.qpos] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        skip = set(self.bodies.get(moving, [])) | self._robot
        for c in d.contact[: d.ncon]:
            g1, g2 = int(c.geom[0]), int(c.geom[1])
            if c.dist >= 0 or arm.link_geoms[g1] == arm.link_geoms[g2]:
                continue
            other = g2 if arm.link_geoms[g1] else g1
            if int(m.geom_bodyid[other]) not in skip:
                return True
        return False

    def into_view(self, p, z_floor: float) -> np.ndarray:
        """``p`` lowered (not below ``z_floor``) until the planner camera sees it; unchanged if it already
        does or if no height down to the floor helps."""
        p = np.asarray(p, float).copy()
        if self.in_view(p):
            return p
        for z in np.arange(p[2] - 0.01, z_floor - 1e-9, -0.01):
            q = np.array([p[0], p[1], z])
            if self.in_view(q):  # the same margin the plan is judged by (a lift 1 px inside hid the plan)
                return q
        return p

    # -- predictions -----------------------------------------------------------------------------------
    def effects_before(self, skill: "LiberoSkill", world: World) -> list[Effect]:
        out = []
        for s in self.skills:
            if s is skill:
                break
            if not s.done(world):
                e = s.effect(world)
                if e is not None:
                    out.append(e)
        return out

    def boxes(self, bodies, effects: list[Effect]) -> Boxes:
        """Collision boxes of ``bodies`` as they will be after ``effects``."""
        bx = collision_boxes(self.model, self.data, bodies)
        if not effects or len(bx) == 0:
            return bx
        centre, rot = bx.centre.copy(), bx.rot.copy()
        body_of = self.model.geom_bodyid[bx.geom]
        for e in effects:
            R, anchor, t, moved = self._delta(e)
            sel = np.isin(body_of, moved)
            centre[sel] = (centre[sel] - anchor) @ R.T + anchor + t
            rot[sel] = np.einsum("ij,njk->nik", R, rot[sel])
        return Boxes(centre, rot, bx.half, bx.geom)

    def point_after(self, point, body: int, effects: list[Effect]) -> np.ndarray:
        p = np.asarray(point, float).copy()
        for e in effects:
            R, anchor, t, moved = self._delta(e)
            if body in moved:
                p = R @ (p - anchor) + anchor + t
        return p

    def rot_after(self, rot, body: int, effects: list[Effect]) -> np.ndarray:
        r = np.asarray(rot, float).copy()
        for e in effects:
            R, _, _, moved = self._delta(e)
            if body in moved:
                r = R @ r
        return r

    def _delta(self, e: Effect):
        m, d = self.model, self.data
        if e.joint is not None:
            j = e.joint
            moved = subtree_bodies(m, int(m.jnt_bodyid[j]))
            if e.carried:
                moved = np.concatenate([moved] + [self.bodies[o] for o in e.carried])
            dq = e.q - float(d.qpos[m.jnt_qposadr[j]])
            axis = d.xaxis[j] / np.linalg.norm(d.xaxis[j])
            if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_SLIDE):
                return np.eye(3), np.zeros(3), axis * dq, moved
            return axis_angle(axis, dq), d.xanchor[j].copy(), np.zeros(3), moved
        moved = self.bodies[e.obj]
        return np.eye(3), np.zeros(3), e.pos - self.world.pos(e.obj), moved

    def obstacles(self, effects: list[Effect], *, exclude: tuple[str, ...] = ()) -> Boxes:
        """Every scene collision box (no robot, no world body such as the floor), after ``effects``."""
        skip = set()
        for name in exclude:
            skip.update(int(b) for b in self.bodies[name])
        bodies = [b for b in self.scene_bodies if b not in skip]
        return self.boxes(bodies, effects)

    def object_boxes(self, name: str, effects: list[Effect]) -> Boxes:
        return self.boxes(self.bodies[name], effects)

    def ground_z(self) -> float:
        """Lowest resting surface: no hand point may go below it (cached per simulation time)."""
        t = float(self.data.time)
        if getattr(self, "_ground", (None,))[0] != t:
            lows = [self.object_boxes(n, []).aabb()[0][2] for n in self.task.scene.env.objects_dict
                    if n in self.bodies and len(self.object_boxes(n, [])) > 0]
            self._ground = (t, min(lows) - 0.002 if lows else 0.0)
        return self._ground[1]

    def clear_z(self, a_xy, b_xy, obstacles: Boxes, radius: float) -> float:
        """Height of the highest obstacle top within ``radius`` of the segment a->b (xy)."""
        if len(obstacles) == 0:
            return -np.inf
        ext = obstacles.world_extents()
        lo, hi = obstacles.centre - ext, obstacles.centre + ext
        a, b = np.asarray(a_xy[:2], float), np.asarray(b_xy[:2], float)
        ts = np.linspace(0, 1, 25)
        pts = a + (b - a) * ts[:, None]
        near = np.zeros(len(lo), bool)
        for p in pts:
            dx = np.maximum(np.maximum(lo[:, 0] - p[0], p[0] - hi[:, 0]), 0)
            dy = np.maximum(np.maximum(lo[:, 1] - p[1], p[1] - hi[:, 1]), 0)
            near |= np.hypot(dx, dy) <= radius
        return float(hi[near, 2].max()) if near.any() else -np.inf


def axis_angle(axis, angle: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


# --- skills -------------------------------------------------------------------------------------------------

class LiberoSkill(Skill):
    ctx: OracleContext
    predicate: list

    def done(self, world: World) -> bool:
        return bool(self.ctx.env._eval_predicate(self.predicate))

    def keyframes(self, world: World) -> list[Keyframe]:
        """The skill's keyframes; when an earlier step is still ahead (planning the whole script at once),
        the hand first returns to its home pose so every step starts from the same posture."""
        kfs = self._keyframes(world)
        if self.ctx.effects_before(self, world):
            kfs.insert(0, kf(self.ctx.home_tcp, False, self.ctx.home_rot))
        return kfs

    def effect(self, world: World) -> Effect | None:
        return None


@dataclass
class Destination:
    """Where a pick-and-place puts its object: on another object, on a region site, or in a region site."""

    relation: str  # "on" | "in" | "aside"
    target: str | None  # object name or region site name (None: a free spot, ``point``)
    is_site: bool
    slot: int = 0  # several objects to one destination: slot k of n (spread apart)
    slots: int = 1
    point: np.ndarray | None = None  # "aside": a free spot on the object's own support [m, world]


class PickPlace(LiberoSkill):
    """Grasp ``obj`` (rim pinch or top grasp from its geometry), carry it above the obstacles, lower it onto
    or into the destination until the hand or the object would touch anything, release, lift."""

    def __init__(self, ctx: OracleContext, obj: str, dest: Destination, predicate: list):
        self.ctx, self.obj, self.dest, self.predicate = ctx, obj, dest, predicate
        self.target = dest.target
        self._place: np.ndarray | None = None

    def done(self, world: World) -> bool:
        if self.dest.point is not None:  # set aside: within 3 cm of the spot, released
            return bool(np.linalg.norm(world.pos(self.obj)[:2] - self.dest.point[:2]) < 0.03
                        and not world.is_held(self.obj))
        return super().done(world) and not world.is_held(self.obj)

    def effect(self, world: World) -> Effect | None:
        plan = self._plan(world)
        return Effect(obj=self.obj, pos=plan["obj_at_release"] - np.array([0, 0, RELEASE_GAP_M]))

    # ---------------------------------------------------------------------------------------------------
    def grasp(self, world: World, effects: list[Effect]) -> Grasp:
        ctx = self.ctx
        obj = ctx.object_boxes(self.obj, effects)
        kind = family(ctx.category.get(self.obj, self.obj))
        # rim-family objects (bowls, mugs, pots) get both kinds: a pot's "ring" may be its lid, and the
        # fingers' clash with the object itself (below) sorts out which rim is a real, open rim
        rims = rim_candidates(obj) if kind == "rim" else []
        tops = top_candidates(obj)
        parts = part_candidates(obj) if not tops else []
        cands = rims + tops + parts
        if not cands:
            raise PlanningError(f"oracle: no grasp for {self.obj!r} (category {ctx.category.get(self.obj)!r}): "
                                f"no rim and no top slab narrower than the open hand")
        obstacles = ctx.obstacles(effects, exclude=(self.obj,))
        parts = parts + tilted(parts, ctx.base_pos)
        cands = (rims + tops + tilted(rims + tops, ctx.base_pos) + parts + side_candidates(obj, ctx.base_pos)
                 + inset_rim_candidates(obj, rims))
        if kind == "rim" and self._cavity(effects, obstacles) is not None:
            cands += handle_candidates(obj)
        bottom = float(obj.aabb()[0][2])
        centre_xy = obj.centre[:, :2].mean(axis=0) if len(obj) else np.zeros(2)

        def prefer(pos, rot):
            # nearer the robot is easier; far and low grasps want the hand tilted away from the robot
            # (a vertical hand 0.6 m out at table height stretched the wrist into the tracking reflex)
            reach = float(np.linalg.norm(pos[:2] - ctx.base_pos[:2]))
            ideal = np.clip((reach - 0.45) / 0.25, 0.0, 1.0) * TILT_MAX_RAD
            tilt = float(np.arccos(np.clip(-rot[2, 2], -1.0, 1.0)))
            if tilt > 1.0:  # a side grasp (horizontal hand): no lean to compare
                return 0.5 * reach + SIDE_GRASP_COST
            return 0.5 * reach + 1.0 * abs(tilt - ideal)

        n_rim = len(rims)
        rim_ids = {id(c[1]) for c in rims}
        part_ids = {id(c[1]) for c in parts}

        def prefer_all(pos, rot):
            cost = prefer(pos, rot)
            if not (ctx.in_view(pos) and ctx.in_view(pos - rot[:, 2] * 0.02)):
                cost += 5.0  # plans live in the planner camera's pixels: a grasp it cannot see is refused
            # the open fingers must not land on the object itself (2 mm slack), except the boxes within 1.5 cm of
            # the TCP (the wall a rim pinch closes on; an inset pinch's wall lies between the open pads)
            near = np.linalg.norm(obj.centre[:, :2] - pos[:2], axis=1) > 0.015
            if id(rot) in part_ids:  # a part's strip lies between the open fingers: nothing may be under them
                near[:] = True
            own = obj.select(near).contains(hand_points(pos, rot, fingers_only=True), margin=-0.002)
            cost += float(own.sum())
            # a tall object held near its top hangs its whole height below the hand: the carry then goes
            # so high that the planner camera loses the hand (a wine bottle by the neck over the cabinet)
            cost += 5.0 * max(0.0, float(pos[2] - bottom) - 0.08)
            if kind == "rim" and not rim_ids.__contains__(id(rot)) and n_rim:
                cost += 0.5  # a top grasp on a rim-family object only when no rim pinch is clean
            if parts:  # a part far from the object's middle tilts it in the fingers
                cost += 5.0 * float(np.linalg.norm(pos[:2] - centre_xy))
            return cost

        graded = score_grasps(cands, obstacles, ground_z=ctx.ground_z(), kind=kind, prefer=prefer_all)
        self.last_grasps = graded  # for inspection, and for _plan_now's fallbacks
        return graded[0]

    def _plan(self, world: World) -> dict:
        """Grasp, release pose and carry height, from the world now (cached per simulation time: the planner
        and every later step's prediction ask for it at the same instant)."""
        t = float(self.ctx.data.time)
        cached = getattr(self, "_plan_cache", None)
        if cached is not None and cached[0] == t:
            return cached[1]
        out = self._plan_now(world)
        self._plan_cache = (t, out)
        return out

    def _plan_now(self, world: World) -> dict:
        ctx = self.ctx
        effects = ctx.effects_before(self, world)
        held = world.is_held(self.obj)
        obj_pos = world.pos(self.obj) if not effects else ctx.point_after(
            world.pos(self.obj), int(ctx.bodies[self.obj][0]), effects)
        if held:
            out = self._plan_with(world, effects, held, obj_pos, world.tcp_pos(), world.tcp_rot())
            if out.get("blocked"):  # as held now (e.g. grasped off-centre), it does not fit through the opening
                raise PlanningError(f"oracle: {self.obj!r} as held now does not fit into {self.dest.target!r} "
                                    "(the hand or the object hits the opening's edges)")
            return out
        best = self.grasp(world, effects)
        # plans live in the planner camera's pixels: a grasp whose lift or carry leaves the view (a wine bottle
        # held by its top, carried over the rack) gives way to the next one whose whole plan stays in view
        # and so does one the arm cannot reach (a bottle held sideways, lifted over the wine rack)
        pool = self._grasp_pool(best, effects)
        first = visible = None
        for g in pool:
            plans = self._plans_with(world, effects, held, obj_pos, g.pos, g.rot, drag=g.drag)
            for out in plans:
                if not out["hidden"] and ctx.reachable(self._key_poses(out), moving=self.obj, effects=effects):
                    return out
            out = plans[0]
            if not out.get("blocked"):
                first = first or out
                visible = visible or (None if out["hidden"] else out)
        # none both in view and judged within reach: the first one in view still runs (the reach check walks
        # one IK branch; the executor got to the bowl by the plate in layouts where that walk did not), and a
        # plan out of view only when there is no other (the executor refuses it)
        first = visible or first
        if first is None:
            raise PlanningError(f"oracle: no grasp of {self.obj!r} carries it into {self.dest.target!r} "
                                f"({len(pool)} grasps tried: the hand or the object hits the opening's edges)")
        return first

    def _grasp_pool(self, best: Grasp, effects) -> list[Grasp]:
        """The ranked grasps a plan is tried with (after :meth:`grasp`): the best and its fallbacks; into a
        cavity only a level hand fits through the opening, so there every level grasp, best first."""
        pool = [best] + [g for g in self.last_grasps[1:GRASP_FALLBACKS + 1] if g.collisions <= best.collisions]
        if self._cavity(effects, self.ctx.obstacles(effects, exclude=(self.obj,))) is not None:
            level = [g for g in self.last_grasps if abs(g.rot[2, 2]) < LEVEL_APPROACH_MAX_Z and all(g is not p for p in pool)]
            pool += [g for g in level if g.collisions <= min(h.collisions for h in level)] if level else []
        return pool

    def first_grasp(self, world: World, effects) -> Grasp:
        """The first grasp whose plan takes the object there and stays in view, before the arm's reach is
        checked (what a blocker standing in the hand's way is judged against: a mug behind the handle the
        hand must take to carry another mug into the microwave)."""
        pool = self._grasp_pool(self.grasp(world, effects), effects)
        obj_pos = self.ctx.point_after(world.pos(self.obj), int(self.ctx.bodies[self.obj][0]), effects)
        for g in pool:
            if not self._plan_with(world, effects, False, obj_pos, g.pos, g.rot, drag=g.drag)["hidden"]:
                return g
        return pool[0]

    def _plan_with(self, world, effects, held: bool, obj_pos, g_pos, g_rot, *, drag=None) -> dict:
        """The best-ranked plan for this grasp (:meth:`_plans_with`)."""
        return self._plans_with(world, effects, held, obj_pos, g_pos, g_rot, drag=drag)[0]

    def _plans_with(self, world, effects, held: bool, obj_pos, g_pos, g_rot, *, drag=None) -> list[dict]:
        """Plans that carry the object, held by the grasp (g_pos, g_rot), to its destination: the best-ranked
        releases first (up to PLACE_ALTERNATIVES, so that a release the arm cannot reach gives way to the next
        one before the grasp does). ``drag``: how far the closing hand moves the object (an inset rim pinch)."""
        ctx = self.ctx
        obj_boxes = ctx.object_boxes(self.obj, effects)
        if drag is not None and drag.any() and not held:  # the object as the closed hand holds it
            obj_boxes = Boxes(obj_boxes.centre + drag, obj_boxes.rot, obj_boxes.half, obj_boxes.geom)
            obj_pos = obj_pos + drag
        # the object in the hand's frame (rigid while held)
        rel_c = (obj_boxes.centre - g_pos) @ g_rot
        rel_R = np.einsum("ji,njk->nik", g_rot, obj_boxes.rot)
        rel_origin = g_rot.T @ (obj_pos - g_pos)
        obstacles = ctx.obstacles(effects, exclude=(self.obj,))
        start = world.tcp_pos() if held else g_pos
        centre_xy = self._centre_xy(world, effects)
        ranked = []
        for place_xy, yaw, spot in self._place_candidates(world, effects, obj_boxes, obj_pos):
            R_place = rot_z(yaw) @ g_rot
            tcp_xy = place_xy - (R_place @ rel_origin)[:2]

            def carried(tcp, R_place=R_place) -> Boxes:
                return Boxes(tcp + rel_c @ R_place.T, np.einsum("ij,njk->nik", R_place, rel_R), obj_boxes.half,
                             obj_boxes.geom)

            probe = carried(np.array([tcp_xy[0], tcp_xy[1], 0.0]))
            lo, hi = probe.aabb()
            near = _near(obstacles, lo - 0.12, hi + 0.12)
            support = self._support_z(near, lo, hi)
            z_min = support + RELEASE_GAP_M - lo[2]
            top = ctx.clear_z(start, tcp_xy, obstacles, radius=0.08)
            carry_z = max(top + TRAVEL_CLEARANCE_M - lo[2], start[2] + LIFT_M, z_min + 0.06)
            def blocked(z):
                tcp = np.array([tcp_xy[0], tcp_xy[1], z])
                return bool(near.contains(hand_points(tcp, R_place, closed=True), margin=0.003).any()
                            or self._boxes_hit(carried(tcp), near))

            z = carry_z
            for step in (0.03, 0.005):  # coarse, then fine
                while z - step >= z_min - 1e-9 and not blocked(z - step):
                    z -= step
            if z - 0.005 < z_min and z > z_min and not blocked(z_min):
                z = z_min
            release_pt = np.array([tcp_xy[0], tcp_xy[1], z])
            over = ctx.into_view([tcp_xy[0], tcp_xy[1], carry_z], max(top + 0.01 - lo[2], z + 0.03))
            hidden = not (ctx.in_view(release_pt) and ctx.in_view(release_pt + np.array([0, 0, 0.03]))
                          and ctx.in_view(over))
            key = (hidden, z - z_min > PLACE_MAX_DROP_M, self._tight(carried(release_pt), near),
                   round(z - z_min, 2), float(np.linalg.norm(spot - centre_xy)))
            ranked.append((key, dict(release=release_pt, release_rot=R_place, carry_z=carry_z,
                                     carry_floor=top + 0.01 - lo[2], obj_below_tcp=float(-lo[2]))))
        ranked.sort(key=lambda r: r[0])  # stable: equal keys keep the candidates' order
        cavity = self._cavity(effects, obstacles)
        if cavity is not None:
            # lowered from above, the object stops on the cavity's ceiling (a mug on top of the microwave):
            # then it goes in through the opening, level, or this grasp cannot take it there
            bottom = ranked[0][1]["release"][2] - ranked[0][1]["obj_below_tcp"]
            if bottom > cavity[0][2] + cavity[3][2]:
                inside = self._place_in_cavity(cavity, obj_boxes, rel_c, rel_R, rel_origin, g_rot, obstacles, start)
                ranked = [] if inside is None else [inside]
        if not ranked:  # no way into the cavity with this grasp: the next grasp is tried
            return [dict(held=held, grasp_pos=g_pos, grasp_rot=g_rot, hidden=True, blocked=True)]
        slide = None if held else self._slide_out(g_pos, g_rot, rel_c, rel_R, obj_boxes, obstacles)
        lift_from = slide if slide is not None else start
        held_boxes = Boxes(rel_c @ g_rot.T, np.einsum("ij,njk->nik", g_rot, rel_R), obj_boxes.half, obj_boxes.geom)
        below = float(-held_boxes.aabb()[0][2])  # how far the object hangs under the TCP, held as grasped
        lift_floor = max(ctx.clear_z(lift_from, lift_from, obstacles, radius=0.08) + 0.02 + below, lift_from[2] + 0.03)
        plans = []
        for key, out in ranked[:PLACE_ALTERNATIVES]:
            lift = ctx.into_view([lift_from[0], lift_from[1], out["carry_z"]], lift_floor)
            out.update(held=held, grasp_pos=g_pos, grasp_rot=g_rot, obstacles=obstacles, slide=slide,
                       obj_at_release=out["release"] + out["release_rot"] @ rel_origin, lift=lift,
                       hidden=bool(key[0]) or not ctx.in_view(lift))
            plans.append(out)
        return plans

    def _cavity(self, effects, obstacles: Boxes):
        """For an ``in`` destination region with something low above it (a microwave's ceiling): (region centre,
        inward opening direction n (horizontal, unit), region rotation, half sizes (3,)); None when the region is
        open from above (a basket, a drawer, a tray). The opening is the region's side whose rays, from the
        region's centre outward to 10 cm past its face, meet nothing."""
        d = self.dest
        if d.relation != "in" or not d.is_site or d.point is not None:
            return None
        ctx = self.ctx
        sid = ctx.model.site(d.target).id
        centre = ctx.point_after(ctx.data.site_xpos[sid], int(ctx.model.site_bodyid[sid]), effects)
        R = ctx.rot_after(ctx.data.site_xmat[sid].reshape(3, 3), int(ctx.model.site_bodyid[sid]), effects)
        half = ctx.model.site_size[sid].copy()
        floor = centre[2] - half[2]
        grid = [centre + R[:, 0] * fx * half[0] + R[:, 1] * fy * half[1]
                for fx in (-0.5, 0.0, 0.5) for fy in (-0.5, 0.0, 0.5)]
        zs = floor + np.arange(0.06, CAVITY_CEILING_M, 0.01)
        above = np.array([[g[0], g[1], z] for g in grid for z in zs])
        covered = obstacles.contains(above).reshape(len(grid), len(zs)).any(axis=1)
        if covered.mean() < 0.5:
            return None
        best = None
        for axis, sign in ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)):
            out = sign * R[:, axis]
            out = np.array([out[0], out[1], 0.0]) / max(np.linalg.norm(out[:2]), 1e-9)
            across = R[:, 1 - axis]
            rays = []
            for f in (-0.5, 0.0, 0.5):
                for z in (floor + 0.03, floor + 0.06):
                    o = np.array([centre[0], centre[1], z]) + across * f * half[1 - axis]
                    rays += [o + out * t for t in np.arange(0.0, half[axis] + 0.10, 0.01)]
            hits = obstacles.contains(np.array(rays)).reshape(6, -1).any(axis=1).mean()
            if best is None or hits < best[0]:
                best = (hits, -out)
        if best[0] > 0.2:
            return None  # enclosed on every side: nothing a hand can do
        return centre, best[1], R, half

    def _place_in_cavity(self, cavity, obj_boxes: Boxes, rel_c, rel_R, rel_origin, g_rot, obstacles: Boxes,
                         start) -> tuple | None:
        """Release pose for a level grasp carried straight in through the cavity's opening: the hand turned
        about the vertical so it points in, the object's origin inside the region as deep as the hand and the
        object stay clear of everything (checked along the whole way in), the object's bottom CAVITY_GAP_M
        above the cavity's floor. None when no such pose exists (the grasp's hand does not fit through)."""
        ctx = self.ctx
        centre, n, R, half = cavity
        a = g_rot[:, 2]
        if abs(a[2]) >= LEVEL_APPROACH_MAX_Z:
            return None
        yaw = float(np.arctan2(n[1], n[0]) - np.arctan2(a[1], a[0]))
        R_place = rot_z(yaw) @ g_rot
        across = np.cross(E_Z, n)

        def carried(tcp) -> Boxes:
            return Boxes(tcp + rel_c @ R_place.T, np.einsum("ij,njk->nik", R_place, rel_R), obj_boxes.half,
                         obj_boxes.geom)

        def clear(tcp) -> bool:
            return not (obstacles.contains(hand_points(tcp, R_place, closed=True), margin=0.004).any()
                        or self._boxes_hit(carried(tcp), obstacles, margin=0.004))

        origin_off = R_place @ rel_origin
        probe = carried(np.zeros(3))
        lo, hi = probe.aabb()
        ext_n = float(np.max(np.abs((probe.centre - probe.centre.mean(axis=0)) @ n)) + obj_boxes.half.max())
        # region bounds along n and across it (LIBERO's In: the object's origin inside the region's box)
        c_n, c_a = float(centre[:2] @ n[:2]), float(centre[:2] @ across[:2])
        h_n = float(np.abs(R.T @ n) @ half)
        h_a = float(np.abs(R.T @ across) @ half)
        floor_ref = centre[2] - half[2]
        for depth in np.arange(h_n - 0.02, -h_n + 0.015, -0.01):  # deepest first
            for off in (0.0, 0.25, -0.25, 0.5, -0.5):
                o_xy = (c_n + depth) * n[:2] + (c_a + off * h_a) * across[:2]
                tcp_xy = o_xy - origin_off[:2]
                foot_lo, foot_hi = lo[:2] + tcp_xy, hi[:2] + tcp_xy
                near = _near(obstacles, np.append(foot_lo, 0) - 0.01, np.append(foot_hi, 0) + 0.01)
                support = self._support_z(near, np.append(foot_lo, lo[2]), np.append(foot_hi, hi[2]))
                if support < floor_ref - 0.03:
                    continue  # nothing to stand on there
                release = np.array([tcp_xy[0], tcp_xy[1], support + CAVITY_GAP_M - lo[2]])
                way_in = release - n * (ext_n + CAVITY_ENTRY_M)
                path = [way_in + (release - way_in) * f for f in np.linspace(0.0, 1.0, 12)]
                if not all(clear(q) for q in path):
                    continue
                top = ctx.clear_z(start, way_in, obstacles, radius=0.08)
                carry_z = max(top + TRAVEL_CLEARANCE_M - lo[2], start[2] + LIFT_M, way_in[2] + 0.06)
                drop = [np.array([way_in[0], way_in[1], z]) for z in np.arange(way_in[2], carry_z, 0.02)]
                if not all(clear(q) for q in drop):
                    continue
                hidden = not all(ctx.in_view(q) for q in (release, way_in))
                return ((hidden,), dict(release=release, release_rot=R_place, carry_z=carry_z,
                                        carry_floor=way_in[2] + 0.03, obj_below_tcp=float(-lo[2]),
                                        way_in=way_in))
        return None

    @staticmethod
    def _key_poses(p: dict) -> list:
        """The plan's poses that decide whether the arm reaches it: pre-grasp, grasp, lift, above and at the
        release."""
        g, R, Rp, rel = p["grasp_pos"], p["grasp_rot"], p["release_rot"], p["release"]
        above = rel if p.get("way_in") is None else p["way_in"]
        poses = [(g - R[:, 2] * APPROACH_DZ, R), (g, R), (p["lift"], R),
                 (np.array([above[0], above[1], max(p["carry_floor"], above[2] + 0.03)]), Rp)]
        return poses + ([] if p.get("way_in") is None else [(p["way_in"], Rp)]) + [(rel, Rp)]

    def _slide_out(self, g_pos, g_rot, rel_c, rel_R, obj_boxes: Boxes, obstacles: Boxes) -> np.ndarray | None:
        """Where to drag the grasped object (TCP position, raised SLIDE_RAISE_M) before lifting it, when a
        straight lift would hit something above it (a bowl at the back of a drawer, half under the cabinet's
        top panel): the shortest horizontal move, within SLIDE_MAX_M, along which the object and the closed
        hand stay clear and from whose end the lift is clear. None when the straight lift is clear (or no
        move frees it: the lift is then tried as it is)."""
        def carried(tcp) -> Boxes:
            return Boxes(tcp + rel_c @ g_rot.T, np.einsum("ij,njk->nik", g_rot, rel_R), obj_boxes.half,
                         obj_boxes.geom)

        lo, hi = obj_boxes.aabb()
        near = _near(obstacles, lo - 0.25, hi + 0.25)

        def clear(tcp) -> bool:
            return not (self._boxes_hit(carried(tcp), near)
                        or near.contains(hand_points(tcp, g_rot, closed=True), margin=0.002).any())

        raised = g_pos + np.array([0.0, 0.0, SLIDE_RAISE_M])

        def lift_clear(base) -> bool:
            return all(clear(base + np.array([0.0, 0.0, dz])) for dz in np.arange(0.01, SLIDE_LIFT_CHECK_M + 1e-9,
                                                                                  0.01))

        if lift_clear(raised):
            return None
        for dist in np.arange(0.01, SLIDE_MAX_M + 1e-9, 0.01):
            for ang in np.deg2rad(np.arange(0.0, 360.0, 22.5)):
                d = np.array([np.cos(ang), np.sin(ang), 0.0])
                end = raised + d * dist
                path = [raised + d * s for s in np.arange(0.005, dist + 1e-9, 0.005)]
                if lift_clear(end) and all(clear(q) for q in path):
                    return end
        return None

    def _tight(self, body: Boxes, near: Boxes) -> bool:
        """Whether ``body`` moved sideways by PLACE_CLEARANCE_M (either way along x or y) meets a wall:
        a box of ``near`` whose top rises WALL_RISE_M above the body's bottom (low rims do not count)."""
        bottom = body.aabb()[0][2]
        ext = near.world_extents()
        walls = near.select(near.centre[:, 2] + ext[:, 2] > bottom + WALL_RISE_M)
        if not len(walls):
            return False
        lift = np.array([0.0, 0.0, 0.003])  # clear of the support it is released over
        for shift in np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]) * PLACE_CLEARANCE_M:
            moved = Boxes(body.centre + shift + lift, body.rot, body.half, body.geom)
            if self._boxes_hit(moved, walls):
                return True
        return False

    @staticmethod
    def _boxes_hit(body: Boxes, obstacles: Boxes, margin: float = 0.002) -> bool:
        """Whether any carried box overlaps an obstacle box grown by ``margin`` [m]."""
        return bool(boxes_overlap(body, obstacles, margin).any())

    def _support_z(self, obstacles: Boxes, lo, hi) -> float:
        """Top of the highest obstacle box under the footprint [lo, hi] (xy) whose top is below the
        destination's reference height (a region's top, an object's top)."""
        ext = obstacles.world_extents()
        blo, bhi = obstacles.centre - ext, obstacles.centre + ext
        over = (blo[:, 0] < hi[0]) & (bhi[:, 0] > lo[0]) & (blo[:, 1] < hi[1]) & (bhi[:, 1] > lo[1])
        ref = self._reference_top()
        cand = over & (bhi[:, 2] <= ref + 1e-6)
        if cand.any():
            return float(bhi[cand, 2].max())
        return self.ctx.ground_z()

    def _reference_top(self) -> float:
        ctx, d = self.ctx, self.dest
        if d.point is not None:
            return float(d.point[2] + 0.005)
        if d.is_site:
            sid = ctx.model.site(d.target).id
            effects = ctx.effects_before(self, ctx.world)
            pos = ctx.point_after(ctx.data.site_xpos[sid], int(ctx.model.site_bodyid[sid]), effects)
            size = ctx.model.site_size[sid]
            if d.relation == "in":
                return float(pos[2] - size[2] + 0.02)
            return float(pos[2] + size[2] + 0.10)
        effects = ctx.effects_before(self, ctx.world)
        return float(ctx.object_boxes(d.target, effects).aabb()[1][2] + 0.005)

    def _region(self, world, effects):
        """Destination frame: centre (3,), rotation, xy half size, and whether it is a region site."""
        ctx, d = self.ctx, self.dest
        if d.point is not None:
            return np.asarray(d.point, float), np.eye(3), np.array([0.005, 0.005])
        if d.is_site:
            sid = ctx.model.site(d.target).id
            bid = int(ctx.model.site_bodyid[sid])
            centre = ctx.point_after(ctx.data.site_xpos[sid], bid, effects)
            R = ctx.rot_after(ctx.data.site_xmat[sid].reshape(3, 3), bid, effects)
            return centre, R, ctx.model.site_size[sid][:2].copy()
        centre = ctx.point_after(world.pos(d.target), int(ctx.bodies[d.target][0]), effects)
        return centre, np.eye(3), np.array([0.012, 0.012])

    def _centre_xy(self, world, effects) -> np.ndarray:
        centre, R, half = self._region(world, effects)
        return centre[:2] + R[:2, :2] @ self._slot_offset(half)

    def _slot_offset(self, half, axis: int | None = None) -> np.ndarray:
        """This object's slot when several go to one destination: spread along ``axis`` of the region
        (default: its longer one)."""
        d = self.dest
        offset = np.zeros(2)
        if d.slots > 1:
            if axis is None:
                axis = 0 if half[0] >= half[1] else 1
            span = half[axis] * 0.9
            offset[axis] = -span + 2 * span * (d.slot + 0.5) / d.slots
        return offset

    def _place_candidates(self, world, effects, obj_boxes: Boxes, obj_pos):
        """(object origin xy, hand yaw change, spot xy) candidates: the object's footprint centred on a spot,
        the region's centre (or this object's slot in it) and, inside a region, a grid of offsets; the yaw is
        the one that best fits the footprint in the region (books into narrow slots)."""
        centre, R, half = self._region(world, effects)
        best, best_yaw, footprint = -np.inf, 0.0, np.zeros(2)
        for yaw in np.deg2rad([0, 15, -15, 30, -30, 45, -45, 60, -60, 75, -75, 90, -90]):
            Rz = rot_z(yaw)
            b = Boxes((obj_boxes.centre - obj_pos) @ Rz.T, np.einsum("ij,njk->nik", Rz, obj_boxes.rot),
                      obj_boxes.half, obj_boxes.geom)
            lo, hi = b.extents_in(R, np.zeros(3))
            # the footprint's centre, not the origin, goes to each spot (a book's origin sits off its middle)
            mid = (lo[:2] + hi[:2]) / 2 if self.dest.is_site else np.zeros(2)
            slack = float(np.min(half - (hi[:2] - lo[:2]) / 2)) if self.dest.is_site else 0.0
            fit = min(slack, 0.01) - 0.002 * abs(yaw)
            if fit > best + 1e-9:
                best, best_yaw, footprint = fit, yaw, R[:2, :2] @ mid
        offsets = []
        f = 0.6 if self.dest.slots == 1 else 0.5 / self.dest.slots
        bases = [self._slot_offset(half, axis) for axis in ((None,) if self.dest.slots == 1 else (0, 1))]
        if self.dest.slots == 2:  # two objects: also the region's diagonals, where they sit furthest apart
            sgn = -1.0 if self.dest.slot == 0 else 1.0
            bases += [sgn * 0.6 * half, sgn * 0.6 * half * np.array([1.0, -1.0])]
        for base in bases:
            offsets.append(base)
            for fx in (-f, 0.0, f):
                for fy in (-f, 0.0, f):
                    if fx or fy:
                        offsets.append(base + np.array([fx * half[0], fy * half[1]]))
        for off in offsets:
            spot = centre[:2] + R[:2, :2] @ off
            yield spot - footprint, best_yaw, spot

    def _retreat(self, release, R_place, carry_z: float) -> np.ndarray:
        """Where the open hand goes after the release: up for a hand from above; for a side grasp, back out
        along its approach axis first (rising with the fingers round a bottle's neck lifts it off the rack,
        and above the rack top the planner camera no longer sees the hand)."""
        ctx = self.ctx
        approach = R_place[:, 2]
        if approach[2] < -SIDE_GRASP_COS:
            return ctx.into_view([release[0], release[1], max(release[2] + LIFT_M, carry_z)], release[2] + 0.04)
        for dist in (LIFT_M, 0.09, 0.06):
            p = release - approach * dist
            if ctx.in_view(p):
                return p
        return release - approach * 0.06

    def _keyframes(self, world: World) -> list[Keyframe]:
        ctx = self.ctx
        p = self._plan(world)
        obstacles = p["obstacles"]
        kfs: list[Keyframe] = []
        g_pos, g_rot = p["grasp_pos"], p["grasp_rot"]
        release, R_place = p["release"], p["release_rot"]
        if not p["held"]:
            back = -g_rot[:, 2]  # out along the approach axis (up for a top-down hand)
            pre = g_pos + back * APPROACH_DZ
            kfs += [kf(pre, False, g_rot), kf(g_pos + back * 0.02, False, g_rot), kf(g_pos, False, g_rot),
                    kf(g_pos, True, g_rot)]
        start = world.tcp_pos() if p["held"] else g_pos
        if p["slide"] is not None:  # drag it out from under an overhang first
            kfs += [kf(g_pos + np.array([0.0, 0.0, SLIDE_RAISE_M]), True, g_rot), kf(p["slide"], True, g_rot)]
            start = p["slide"]
        carry_z = p["carry_z"]
        floor = p["carry_floor"]
        # the lift only has to clear what is near the start (the carry then climbs towards the destination); a
        # replan with the object already in the hand lifts no higher than that clearance or where the hand is
        # (a fixed rise above the hand ratcheted it up by that much at every local replan, out of the camera's view)
        lift = p["lift"] if not p["held"] else ctx.into_view(
            [start[0], start[1], carry_z],
            max(ctx.clear_z(start, start, obstacles, radius=0.08) + 0.02 + p["obj_below_tcp"], start[2]))
        way_in = p.get("way_in")  # into a cavity: down in front of its opening, then straight in
        above = release if way_in is None else way_in
        over = ctx.into_view([above[0], above[1], carry_z], max(floor, above[2] + 0.03))
        kfs += [kf(lift, True, g_rot if not p["held"] else world.tcp_rot()), kf(over, True, R_place)]
        kfs += ([kf(release + np.array([0, 0, 0.03]), True, R_place)] if way_in is None
                else [kf(way_in, True, R_place)])
        kfs += [kf(release, True, R_place), kf(release, False, R_place)]
        if way_in is None:
            kfs.append(kf(self._retreat(release, R_place, carry_z), False, R_place))
        else:
            # in a cavity the palm stops at the opening, so what the hand held (a mug's handle) ends up just
            # inside it, in the way of the door (a microwave's stopped 11 degrees short): back off, close, and
            # push it home with the fingertips, which reach 1.2 cm past where they held it (opening there makes
            # the push's end a stop: the executor blends through other waypoints and fell 2 cm short)
            back = release - R_place[:, 2] * CAVITY_PUSH_BACK_M
            kfs += [kf(back, False, R_place), kf(back, True, R_place), kf(release, True, R_place),
                    kf(release, False, R_place), kf(self._retreat(release, R_place, carry_z), False, R_place)]
        if not p["held"]:
            kfs[0] = kf(ctx.into_view(kfs[0].pos, g_pos[2] + 0.04), False, g_rot)
            # the way in: when the straight way from home (or from where the hand is) would hit something, the
            # hand comes in above it (a drawer the previous step pulled out stopped the hand on its way to a
            # bowl behind it)
            start = ctx.home_tcp if ctx.effects_before(self, world) else world.tcp_pos()
            pre = kfs[0].pos
            z_safe = ctx.clear_z(start, pre, obstacles, radius=TRANSIT_RADIUS_M) + TRANSIT_CLEARANCE_M
            n = max(2, int(np.linalg.norm(pre - start) / 0.02))
            path = np.vstack([hand_points(start + (pre - start) * f, g_rot) for f in np.linspace(0.2, 1.0, n)])
            if pre[2] < z_safe and obstacles.contains(path, margin=0.0).any():
                kfs.insert(0, kf(ctx.into_view([pre[0], pre[1], z_safe], pre[2]), False, g_rot))
        return kfs


TILT_MAX_RAD = np.deg2rad(30.0)  # [rad] most a grasp's approach leans away from the robot


def tilted(cands, base_pos) -> list:
    """Tilted copies of top-down candidates: the approach axis leans away from the robot's base by 15 and 30
    degrees about the closing axis (only where the closing axis runs across the lean, so the fingers still
    close on the same two faces)."""
    out = []
    for p, R in cands:
        r = np.asarray(p[:2], float) - base_pos[:2]
        if np.linalg.norm(r) < 1e-6 or R[2, 2] > -0.99:
            continue
        r = np.append(r / np.linalg.norm(r), 0.0)
        if abs(R[:, 1] @ r) > 0.5:
            continue
        for th in (0.5 * TILT_MAX_RAD, TILT_MAX_RAD):
            out.append((p, frame(-E_Z * np.cos(th) + r * np.sin(th), R[:, 1])))
    return out


def _near(boxes: Boxes, lo, hi) -> Boxes:
    """The boxes whose xy bounds overlap [lo, hi] (xy)."""
    ext = boxes.world_extents()
    blo, bhi = boxes.centre - ext, boxes.centre + ext
    keep = (blo[:, 0] < hi[0]) & (bhi[:, 0] > lo[0]) & (blo[:, 1] < hi[1]) & (bhi[:, 1] > lo[1])
    return boxes.select(keep)
