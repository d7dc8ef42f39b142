"""The generic LIBERO oracle: a task file's goal (a conjunction of On, In, Open, Close, TurnOn, TurnOff)
becomes a script of skills (:mod:`tcot_hybrid.libero.skills`), composed from the predicates and the
scene's privileged geometry — no per-task scripts.

Order of the steps: switches first (TurnOn/TurnOff: knobs are out of the way of everything else), then
opening what a placement needs open (a drawer or door whose region is a destination and is not open), then
the placements (objects going to one destination are spread over it), then Open goals, then Close goals
(closing after putting something inside).

Joint goals are read from LIBERO's own predicate functions (``is_open``/``is_close``/``turn_on``/``turn_off``
of the fixture) by scanning the joint's range, so a fixture with other thresholds needs no change here.
"""
from __future__ import annotations

import mujoco
import numpy as np
# The oracle planner slerps orientations with scipy; importing it costs ~0.4 s, which must not land inside the
# first plan's latency budget (SupervisorConfig.max_plan_latency_s): LiberoTask.build_scene imports this module.
import scipy.spatial.transform  # noqa: F401

from tcot_hybrid.errors import ConfigError, PlanningError
from tcot_hybrid.libero.joints import MoveJoint
from tcot_hybrid.libero.geometry import Boxes, subtree_bodies
from tcot_hybrid.libero.grasps import hand_points
from tcot_hybrid.libero.skills import RELEASE_GAP_M, Destination, Effect, LiberoSkill, OracleContext, PickPlace

SUPPORTED_PREDICATES = ("on", "in", "open", "close", "turnon", "turnoff")
JOINT_PREDICATES = {"open": "is_open", "close": "is_close", "turnon": "turn_on", "turnoff": "turn_off"}
SLIDE_DEPTH_M = 0.008  # [m] a slide goal this far inside the predicate's interval
SLIDE_PUSH_M = 0.03  # [m] the hand moves this much further (the joint limit stops the part; the pinch slips ~2 cm)
HINGE_DEPTH_RAD = 0.35  # [rad] a hinge goal this far inside the predicate's interval
HINGE_PUSH_RAD = 0.10  # [rad]
ASIDE_MIN_REACH_M = 0.55  # [m] set-aside spots nearer the robot's base than this cost extra (see _aside_spot)
TRAVEL_ABOVE_GROUND_M = 0.25  # [m] LiberoTask.travel_z above the lowest resting surface


def ground_z(task) -> float:
    """The lowest resting surface of the task's scene now (the oracle's floor for hand points)."""
    world = getattr(task, "world", None)
    if world is None:
        return float(task.scene.support_z()) if task.scene is not None else 0.0
    ctx = getattr(task, "_oracle", None) or OracleContext(task, world)
    return ctx.ground_z()


def goal_skills(task) -> list[LiberoSkill]:
    """The oracle script for the task's goal (cached per episode: ``task._oracle`` is reset by ``reset``)."""
    cached = getattr(task, "_oracle", None)
    # A script composed before the robot acts (e.g. read by a perturbation or a check while the objects settle)
    # saw unsettled objects (a bowl still above the table has no support to set it aside on): it is composed
    # again while the hand is still at its start pose; once the hand has moved the script stays fixed.
    if cached is not None and (float(cached.data.time) == cached.built_at
                               or np.linalg.norm(cached.world.tcp_pos() - cached.home_tcp) > 0.01):
        return cached.skills
    world = task.world if hasattr(task, "world") else None
    if world is None:
        raise PlanningError("LIBERO oracle: the task has no world yet (call reset first)")
    ctx = OracleContext(task, world)
    ctx.skills = compose(ctx, goal_predicates(task))
    task._oracle = ctx
    return ctx.skills


def goal_predicates(task) -> list[list[str]]:
    goal = [list(map(str, g)) for g in task.scene.env.parsed_problem["goal_state"]]
    for g in goal:
        if not g or g[0].lower() not in SUPPORTED_PREDICATES:
            # a property of the task file, not a transient planning failure: refused outright (exit != 0)
            raise ConfigError(f"LIBERO oracle: task {task.name!r} has goal predicate {g[0] if g else g!r} "
                                f"({' '.join(g)}) with no skill; supported predicates: "
                                f"{', '.join(SUPPORTED_PREDICATES)}")
    return goal


def compose(ctx: OracleContext, goal: list[list[str]]) -> list[LiberoSkill]:
    env = ctx.env
    switches, opens_needed, places, opens, closes = [], [], [], [], []
    dest_count: dict[str, int] = {}
    for g in goal:
        if g[0].lower() in ("on", "in"):
            dest_count[g[2]] = dest_count.get(g[2], 0) + 1
    dest_seen: dict[str, int] = {}
    for g in goal:
        p = g[0].lower()
        if p in ("on", "in"):
            obj, target = g[1], g[2]
            if obj not in env.objects_dict:
                raise ConfigError(f"LIBERO oracle: {p}({obj}, {target}) moves {obj!r}, which is not a movable "
                                    f"object of this scene ({', '.join(env.objects_dict)})")
            is_site = target in env.object_sites_dict
            if not is_site and target not in env.objects_dict and target not in env.fixtures_dict:
                raise ConfigError(f"LIBERO oracle: {p}({obj}, {target}): unknown destination {target!r}")
            if not is_site and target in env.fixtures_dict:
                raise ConfigError(f"LIBERO oracle: {p}({obj}, {target}): a fixture as destination needs a region")
            k = dest_seen.get(target, 0)
            dest_seen[target] = k + 1
            dest = Destination(relation=p, target=target, is_site=is_site, slot=k, slots=dest_count[target])
            places.append(PickPlace(ctx, obj, dest, g))
            inside = _drawer_holding(ctx, obj)
            if inside is not None and all(s.joint != inside.joint for s in opens_needed):
                opens_needed.append(inside)
            if is_site and p == "in":
                need = _open_for(ctx, target, g)
                if need is not None and all(s.joint != need.joint for s in opens_needed):
                    opens_needed.append(need)
        elif p in ("turnon", "turnoff"):
            switches.append(joint_skill(ctx, g))
        elif p == "open":
            opens.append(joint_skill(ctx, g))
        else:
            closes.append(joint_skill(ctx, g))
    opens_needed = [s for s in opens_needed if all(o.joint != s.joint for o in opens)]
    # an Open goal whose region is also a destination must happen before the placement
    early_opens = [o for o in opens if any(d.dest.is_site and _joint_of(ctx, d.dest.target) == o.joint for d in places)]
    late_opens = [o for o in opens if o not in early_opens]
    # an object the opening drawer would shove (a bowl standing in front of it) is set aside first
    asides = []
    for step in opens_needed + early_opens:
        for place in places:
            spot = _aside_spot(ctx, place.obj, step) if _in_the_way(ctx, place.obj, step) else None
            if spot is not None and all(a.obj != place.obj for a in asides):
                asides.append(PickPlace(ctx, place.obj, Destination(relation="aside", target=None, is_site=False,
                                                                    point=spot), ["aside", place.obj]))
    # an object standing where the hand must go to grasp a goal object (a milk carton beside the cream cheese)
    # is set aside first too
    destinations = {_destination_object(ctx, p.dest.target) for p in places}
    for place in places:
        for blocker, keep_clear in _grasp_blockers(ctx, place):
            if (blocker in [p.obj for p in places] or blocker in destinations
                    or any(a.obj == blocker for a in asides)):
                continue  # goal objects are moved by their own steps; a destination stays where it is
            spot = _aside_spot(ctx, blocker, None, keep_clear=keep_clear)
            if spot is not None:
                asides.append(PickPlace(ctx, blocker, Destination(relation="aside", target=None, is_site=False,
                                                                  point=spot), ["aside", blocker]))
    return switches + asides + opens_needed + early_opens + places + late_opens + closes


def _destination_object(ctx: OracleContext, target: str | None) -> str | None:
    """The object a destination belongs to: the object itself, or the owner of a region site (the basket of
    ``basket_1_contain_region``)."""
    if target is None or target in ctx.env.objects_dict:
        return target
    return getattr(ctx.env.object_states_dict.get(target), "parent_name", None)


def _grasp_blockers(ctx: OracleContext, place: PickPlace) -> list[tuple[str, np.ndarray]]:
    """Movable objects the hand hits at ``place``'s best grasp (or on its way down to it), when no grasp is
    clean: (name, the hand's sample points, which the object's new spot must keep clear)."""
    g = place.first_grasp(ctx.world, [])
    if g.collisions == 0:
        return []
    pts = np.vstack([hand_points(g.pos - g.rot[:, 2] * dz, g.rot) for dz in (0.0, 0.03, 0.06, 0.10)])
    out = []
    for name in ctx.env.objects_dict:
        if name == place.obj or name not in ctx.bodies:
            continue
        if ctx.object_boxes(name, []).contains(pts, margin=0.004).any():
            out.append((name, pts))
    return out


def _in_the_way(ctx: OracleContext, obj: str, step: MoveJoint) -> bool:
    """Whether ``step``'s moving part, at its goal, overlaps ``obj`` or the 25 cm above it (an open drawer over a
    bowl leaves no room for the hand to pick it), 2 cm margin."""
    part = ctx.boxes(subtree_bodies(ctx.model, int(ctx.model.jnt_bodyid[step.joint])),
                     [Effect(joint=step.joint, q=step.q_push)])
    lo, hi = ctx.object_boxes(obj, []).aabb()
    column = Boxes(((lo + hi) / 2 + np.array([0, 0, 0.125]))[None], np.eye(3)[None],
                   ((hi - lo) / 2 + np.array([0, 0, 0.125]))[None], np.zeros(1, int))
    return PickPlace._boxes_hit(column, part, margin=0.02) or PickPlace._boxes_hit(part, column, margin=0.02)


def _aside_spot(ctx: OracleContext, obj: str, step: MoveJoint | None, *,
                keep_clear: np.ndarray | None = None) -> np.ndarray | None:
    """A free spot for ``obj`` on its own support, clear of ``step``'s part at its goal (if any), of the points
    ``keep_clear`` (a blocked grasp's hand, 2 cm margin) and of everything else,
    in the planner camera's view: on rings 10-25 cm around it, the nearest, with a spot closer than
    ASIDE_MIN_REACH_M to the robot's base counted as further away (the arm folds to put a bowl down there, and
    joint 6's 12 N m motor lagged into the tracking reflex: libero_goal open_the_top_drawer_and_put_the_bowl_inside,
    sampled seed 2000)."""
    boxes = ctx.object_boxes(obj, [])
    origin = ctx.world.pos(obj)
    lo, hi = boxes.aabb()
    obstacles = ctx.obstacles([] if step is None else [Effect(joint=step.joint, q=step.q_push)], exclude=(obj,))
    ext = obstacles.world_extents()
    tops = obstacles.centre[:, 2] + ext[:, 2]
    # the hand puts it down the way it picks it up: its closed hand, shifted with the object, must fit there too
    # (next to the cabinet the hand stopped 19 cm up and the bowl fell)
    try:
        grasp = PickPlace(ctx, obj, Destination(relation="aside", target=None, is_site=False, point=origin),
                          []).grasp(ctx.world, [])
    except PlanningError:  # nothing the hand can hold it by: it is not set aside
        return None
    # (an inset pinch holds the object dragged by grasp.drag: the hand sits that much further the other way)
    hand = hand_points(grasp.pos - grasp.drag + np.array([0.0, 0.0, RELEASE_GAP_M]), grasp.rot, closed=True)
    best = None
    for radius in (0.10, 0.15, 0.20, 0.25):
        for ang in np.deg2rad(np.arange(0, 360, 30)):
            d = radius * np.array([np.cos(ang), np.sin(ang), 0.0])
            moved = Boxes(boxes.centre + d + np.array([0, 0, 0.015]), boxes.rot, boxes.half, boxes.geom)
            if PickPlace._boxes_hit(moved, obstacles, margin=0.012):  # (lifted off its support for the test)
                continue
            if obstacles.contains(hand + d, margin=0.004).any():
                continue
            if keep_clear is not None and moved.contains(keep_clear, margin=0.02).any():
                continue
            # the same support: whatever is under the new footprint tops out where the old support did
            under = obstacles.select((np.abs(obstacles.centre[:, 0] - (origin[0] + d[0])) <= ext[:, 0])
                                     & (np.abs(obstacles.centre[:, 1] - (origin[1] + d[1])) <= ext[:, 1])
                                     & (tops <= lo[2] + 0.01))
            if len(under) == 0 or abs(under.aabb()[1][2] - lo[2]) > 0.01:
                continue
            spot = origin + d
            if ctx.in_view(spot) and ctx.in_view(spot + np.array([0, 0, hi[2] - lo[2] + 0.05])):
                reach = float(np.linalg.norm(spot[:2] - ctx.base_pos[:2]))
                cost = radius + 2.0 * max(0.0, ASIDE_MIN_REACH_M - reach)
                if best is None or cost < best[0] - 1e-9:
                    best = (cost, spot)
    return None if best is None else best[1]


def _articulated_joints(ctx: OracleContext, name: str) -> list[int]:
    env, m = ctx.env, ctx.model
    if name in env.object_sites_dict:
        names = list(getattr(env.object_sites_dict[name], "joints", []) or [])
    else:
        names = list(getattr(env.get_object(name), "joints", []) or [])
    out = []
    for n in names:
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)
        if j >= 0 and int(m.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE)):
            out.append(j)
    return out


def _owner(ctx: OracleContext, name: str):
    env = ctx.env
    if name in env.object_sites_dict:
        return env.get_object(env.object_states_dict[name].parent_name)
    return env.get_object(name)


def _joint_of(ctx: OracleContext, name: str) -> int | None:
    joints = _articulated_joints(ctx, name) if name in ctx.env.object_sites_dict else []
    return joints[0] if joints else None


def joint_goal(ctx: OracleContext, name: str, predicate: str, joint: int) -> tuple[float, float]:
    """(goal, push) joint values that make LIBERO's ``predicate`` of ``name`` true, from the fixture's own
    predicate function scanned over the joint's range (goal: inside the satisfying interval nearest the
    current value; push: where the hand drives to, a little further)."""
    m, d = ctx.model, ctx.data
    owner = _owner(ctx, name)
    fn = getattr(owner, JOINT_PREDICATES[predicate], None)
    if fn is None:
        raise ConfigError(f"LIBERO oracle: {predicate}({name}): {type(owner).__name__} has no "
                            f"{JOINT_PREDICATES[predicate]}() to read the goal from")
    lo, hi = m.jnt_range[joint]
    qs = np.linspace(lo, hi, 400)
    ok = np.array([bool(fn(float(q))) for q in qs])
    if predicate in ("close", "turnoff"):  # close/off: the predicate itself is the target
        pass
    if not ok.any():
        raise ConfigError(f"LIBERO oracle: no value of joint {m.joint(joint).name!r} in [{lo}, {hi}] makes "
                            f"{predicate}({name}) true")
    q_now = float(d.qpos[m.jnt_qposadr[joint]])
    idx = np.flatnonzero(ok)
    nearest = int(idx[np.argmin(np.abs(qs[idx] - q_now))])
    q_edge = float(qs[nearest])
    direction = np.sign(q_edge - q_now) or 1.0
    slide = int(m.jnt_type[joint]) == int(mujoco.mjtJoint.mjJNT_SLIDE)
    depth, push = (SLIDE_DEPTH_M, SLIDE_PUSH_M) if slide else (HINGE_DEPTH_RAD, HINGE_PUSH_RAD)
    # the satisfying run that contains the edge: stay inside it
    run_end = nearest
    while 0 <= run_end + int(direction) < len(qs) and ok[run_end + int(direction)]:
        run_end += int(direction)
    q_far = float(qs[run_end])
    goal = q_edge + direction * min(depth, abs(q_far - q_edge) / 2 if abs(q_far - q_edge) > 0 else 0.0)
    at_limit = run_end in (0, len(qs) - 1)
    q_push = (q_far + direction * push) if at_limit and abs(q_far - q_edge) < 2 * depth else goal + direction * push
    return float(goal), float(q_push)


def joint_skill(ctx: OracleContext, g: list[str]) -> MoveJoint:
    p, name = g[0].lower(), g[1]
    joints = _articulated_joints(ctx, name)
    if not joints:
        raise ConfigError(f"LIBERO oracle: {p}({name}): {name!r} has no slide or hinge joint to move")
    j = joints[0]
    goal, push = joint_goal(ctx, name, p, j)
    return MoveJoint(ctx, name, j, goal, push, g)


def _drawer_holding(ctx: OracleContext, obj: str) -> MoveJoint | None:
    """An Open step (carrying ``obj`` along) when ``obj`` lies inside a drawer that can open further: the hand
    reaches a bowl in a half-open drawer only once the drawer is out (LIBERO's In test on the region)."""
    env, m, d = ctx.env, ctx.model, ctx.data
    p = ctx.world.pos(obj)
    for name in env.object_sites_dict:
        joints = _articulated_joints(ctx, name)
        if not joints or int(m.jnt_type[joints[0]]) != int(mujoco.mjtJoint.mjJNT_SLIDE):
            continue
        sid = m.site(name).id
        local = d.site_xmat[sid].reshape(3, 3).T @ (p - d.site_xpos[sid])
        half = m.site_size[sid]
        if np.all(np.abs(local[:2]) <= half[:2]) and -half[2] - 0.01 <= local[2] <= half[2]:
            owner = _owner(ctx, name)
            if not hasattr(owner, "is_open"):
                return None
            goal, push = joint_goal(ctx, name, "open", joints[0])
            q = float(d.qpos[m.jnt_qposadr[joints[0]]])
            if abs(goal - q) < 0.02:
                return None
            return MoveJoint(ctx, name, joints[0], goal, push, ["open", name], carried=(obj,))
    return None


def _open_for(ctx: OracleContext, region: str, g: list[str]) -> MoveJoint | None:
    """An Open step for a destination region inside an articulated fixture that is not open now."""
    joints = _articulated_joints(ctx, region)
    if not joints:
        owner_name = getattr(ctx.env.object_states_dict.get(region), "parent_name", None)
        if owner_name is None or owner_name not in ctx.env.fixtures_dict:
            return None
        joints = _articulated_joints(ctx, owner_name)
        if not joints:
            return None
        region = owner_name
    owner = _owner(ctx, region)
    if not hasattr(owner, "is_open"):
        return None
    j = joints[0]
    q = float(ctx.data.qpos[ctx.model.jnt_qposadr[j]])
    if owner.is_open(q):
        return None
    goal, push = joint_goal(ctx, region, "open", j)
    return MoveJoint(ctx, region, j, goal, push, ["open", region])
