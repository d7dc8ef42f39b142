"""The LIBERO oracle's joint skill: move an articulated joint (drawer slide, door hinge, knob) until a goal
predicate holds. Drawers are opened by pinching the handle bar and pulling, and closed by a tilted push on the
front panel; knobs by pushing the end of their bar round; doors by pushing the leaf along its arc. Goal values
come from LIBERO's own predicate functions (:func:`tcot_hybrid.libero.oracle.joint_goal`)."""
from __future__ import annotations

import mujoco
import numpy as np

from tcot_hybrid.errors import ConfigError
from tcot_hybrid.libero.geometry import Boxes
from tcot_hybrid.libero.grasps import APPROACH_DZ, E_Z, R_DOWN, frame, rot_z, top_down
from tcot_hybrid.libero.skills import Effect, LiberoSkill, OracleContext, axis_angle, kf
from tcot_hybrid.tasks.base import Keyframe, World

PAD_CENTRE_M = 0.004  # [m] the finger pads' centre is this far behind the TCP along the approach axis
KNOB_EXTRA_RAD = 0.5  # [rad] a knob push goes this much past its goal (contact slips as the bar turns)
KNOB_YAW_BACK_RAD = np.deg2rad(30.0)  # [rad] see MoveJoint._knob
DOOR_EXTRA_RAD = 0.25  # [rad] a door push goes this much past its goal (see MoveJoint._door)
RESUME_CLOSED_M = 0.03  # [m] a closed hand this near a joint move's closed stretch carries on from it (a replan)


class MoveJoint(LiberoSkill):
    """Move an articulated joint (drawer slide, door hinge, knob) until a goal predicate holds: grasp the
    part's handle and carry it along the joint's path (slides: straight; hinges: an arc about the axis)."""

    def __init__(self, ctx: OracleContext, name: str, joint: int, q_goal: float, q_push: float, predicate: list,
                 carried: tuple[str, ...] = ()):
        self.ctx, self.obj, self.joint, self.predicate = ctx, name, joint, predicate
        self.q_goal, self.q_push, self.carried = q_goal, q_push, tuple(carried)
        self.target = None

    def effect(self, world: World) -> Effect | None:
        return Effect(joint=self.joint, q=self.q_goal, carried=self.carried)

    def _keyframes(self, world: World) -> list[Keyframe]:
        ctx = self.ctx
        m, d = ctx.model, ctx.data
        effects = ctx.effects_before(self, world)
        j = self.joint
        body = int(m.jnt_bodyid[j])
        q_now = float(d.qpos[m.jnt_qposadr[j]])
        for e in effects:
            if e.joint == j:
                q_now = e.q
        moving = ctx.boxes([body], effects)
        axis = d.xaxis[j] / np.linalg.norm(d.xaxis[j])
        anchor = d.xanchor[j].copy()
        if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_SLIDE):
            kfs = self._slide(world, moving, axis, q_now, effects)
        else:
            kfs = self._hinge(world, moving, axis, anchor, q_now, effects)
        return kfs if effects else carry_on_closed(kfs, world)

    # -- drawers ----------------------------------------------------------------------------------------
    def _slide(self, world, moving: Boxes, axis, q_now, effects) -> list[Keyframe]:
        """Pinch the handle bar horizontally (fingers above and below it), then move along the axis."""
        # the handle: the box that sticks out furthest towards the pull direction (-axis when opening is -q)
        pull = -axis  # direction the part moves as q decreases
        ext = moving.world_extents()
        front = (moving.centre @ pull) + np.abs(ext @ np.abs(pull))
        i = int(np.argmax(front))
        handle_c = moving.centre[i].copy()
        approach = -pull  # the hand approaches against the pull direction (into the cabinet)
        approach_h = approach - E_Z * (approach @ E_Z)
        approach_h /= np.linalg.norm(approach_h)
        # fingers close vertically on the horizontal bar; of the two rolls (closing axis up or down) the one
        # nearer the home hand pitched onto this approach (the other one ran joint 7 into its limit)
        rot = min((frame(approach_h, E_Z), frame(approach_h, -E_Z)),
                  key=lambda R: -np.trace(pitched_home(approach_h).T @ R))
        # the pads' centre sits 4 mm behind the TCP (fingertip centre): put it on the bar's centre
        grip = handle_c + approach_h * PAD_CENTRE_M
        dq = self.q_push - q_now  # along +axis per unit q
        if (axis * dq) @ approach_h > 0:  # moving into the fixture: close it with a push
            return self._push_in(moving, handle_c, approach_h, axis * dq)
        end = grip + axis * dq
        back = grip - approach_h * 0.10
        kfs = [kf(back + np.array([0, 0, 0.0]), False, rot), kf(grip - approach_h * 0.02, False, rot),
               kf(grip, False, rot), kf(grip, True, rot)]
        n = max(2, int(np.ceil(abs(dq) / 0.03)))
        for k in range(1, n + 1):
            kfs.append(kf(grip + axis * dq * k / n, True, rot))
        kfs += [kf(end, False, rot), kf(end - approach_h * 0.10, False, rot)]
        return kfs

    def _push_in(self, moving: Boxes, handle_c, into, travel) -> list[Keyframe]:
        """Close a drawer: the closed fingertips, on a hand leaning 45 degrees back from the fixture (the palm
        stays clear of the drawers above), push the drawer's front panel just below its handle along the
        slide (on the handle bar itself the fingers rode up over it)."""
        into = into / np.linalg.norm(into)
        along = np.cross(E_Z, into)  # the handle bar's length direction (horizontal)
        frame_d = np.column_stack([into, along, E_Z])
        # the front panel: the outermost box (against ``into``) that spans most of the drawer's width
        lo, hi = moving.extents_in(frame_d, handle_c)
        width = hi[1] - lo[1]
        face = None
        for i in range(len(moving)):
            b_lo, b_hi = moving.select(np.arange(len(moving)) == i).extents_in(frame_d, handle_c)
            if b_hi[1] - b_lo[1] >= 0.6 * width and (face is None or b_lo[0] < face[0]):
                face = (b_lo[0], b_lo[2], b_hi[2])
        approach = into * np.sin(np.pi / 4) - E_Z * np.cos(np.pi / 4)
        rot = min((frame(approach, along), frame(approach, -along)),
                  key=lambda R: -np.trace(pitched_home(approach).T @ R))
        if face is None:
            contact = handle_c - into * 0.02
        else:
            z = max(face[1] + 0.012, -0.016)  # right under the handle bar (it keeps the fingers from riding up)
            contact = handle_c + into * face[0] + E_Z * z
        start = contact - into * 0.018  # fingertips just outside the face
        end = start + travel + into * 0.01
        above = start - approach * 0.08
        kfs = [kf(above, False, rot), kf(above, True, rot), kf(start, True, rot)]
        n = max(2, int(np.ceil(np.linalg.norm(end - start) / 0.03)))
        for k in range(1, n + 1):
            kfs.append(kf(start + (end - start) * k / n, True, rot))
        kfs.append(kf(end - approach * 0.08, True, rot))
        return kfs

    # -- hinges: knobs (vertical axis, grasp the bar) and doors (push the leaf along its arc) ---------
    def _hinge(self, world, moving: Boxes, axis, anchor, q_now, effects) -> list[Keyframe]:
        ctx = self.ctx
        lo, hi = moving.aabb()
        if abs(axis @ E_Z) < 0.9:
            raise ConfigError(f"oracle: hinge {ctx.model.joint(self.joint).name!r} has a non-vertical axis "
                              f"{np.round(axis, 3).tolist()}; only vertical hinges (knobs, doors) are supported")
        sign = 1.0 if axis @ E_Z > 0 else -1.0
        dq = self.q_push - q_now
        extent = float(np.max(np.linalg.norm(np.stack([lo[:2], hi[:2]]) - anchor[:2], axis=1)))
        if extent < 0.08:  # a knob (small): push its top bar round; else a door
            return self._knob(moving, anchor, sign * dq)
        return self._door(moving, anchor, sign * dq)

    def _knob(self, moving: Boxes, anchor, turn) -> list[Keyframe]:
        """Turn a knob by pushing the end of its top bar along its arc with the closed fingers (no wrist
        turn: a knob sits close to the robot's base, where turning the hand about it runs joint 7 into
        its torque limit)."""
        ext = moving.world_extents()
        tops = moving.centre[:, 2] + ext[:, 2]
        bar = tops >= tops.max() - 0.02
        r = np.linalg.norm(moving.centre[:, :2] - anchor[:2], axis=1)
        r[~bar] = -1.0
        end = moving.centre[int(np.argmax(r))]
        u = end[:2] - anchor[:2]
        reach = float(np.linalg.norm(u))
        u = u / reach
        tangent = np.sign(turn) * np.array([-u[1], u[0]])  # where the bar's end moves
        t3 = np.append(tangent, 0.0)
        frame_ut = np.column_stack([np.append(u, 0.0), t3, E_Z])
        b_lo, b_hi = moving.select(bar).extents_in(frame_ut, anchor)
        bar_half = float(max(-b_lo[1], b_hi[1]))  # the bar's half width across the push
        radius = max(0.75 * reach, 0.02)
        turn = turn + np.sign(turn) * KNOB_EXTRA_RAD  # the bar slides along the fingers as it turns
        z = float(tops.max()) - 0.018
        start_xy = anchor[:2] + u * radius - tangent * (bar_half + 0.011 + 0.012)
        # closing axis about radial (the closed fingers' flat side pushes along the tangent), turned 30 degrees
        # towards the home yaw: at -90 degrees joint 7 ended the push at 2.85 of its 2.9 rad and stalled
        rot = top_down(u)
        yaw = np.arctan2(rot[0, 1], -rot[1, 1])
        rot = rot_z(-np.sign(yaw) * KNOB_YAW_BACK_RAD) @ rot
        p0 = np.array([start_xy[0], start_xy[1], z])
        # open above, close there: the planner resumes a plan from the point nearest the hand before its first
        # gripper switch, and a plan that starts closed has its first switch far down the script
        above = p0 + np.array([0, 0, APPROACH_DZ])
        kfs = [kf(above, False, rot), kf(above, True, rot), kf(p0, True, rot)]
        kfs += arc_keyframes(anchor, p0, turn, rot, turn_hand=False)
        kfs.append(kf(kfs[-1].pos + np.array([0, 0, APPROACH_DZ]), True, rot))
        return kfs

    def _door(self, moving: Boxes, anchor, turn) -> list[Keyframe]:
        """Push the leaf with the closed fingertips along its arc, on the side it moves towards."""
        _, hi = moving.aabb()
        # the leaf's far edge (from the hinge) at 80 % of its length, 2.5 cm below its top
        far = moving.centre[np.argmax(np.linalg.norm(moving.centre[:, :2] - anchor[:2], axis=1))]
        r_vec = far[:2] - anchor[:2]
        length = np.linalg.norm(r_vec)
        u = r_vec / length
        normal = np.array([-u[1], u[0]]) * np.sign(turn)  # direction the leaf moves at that point
        thickness = 0.02
        p0 = np.array([*(anchor[:2] + u * 0.8 * length - normal * (thickness + 0.012)), hi[2] - 0.025])
        rot0 = top_down(u)
        above = p0 + np.array([0, 0, APPROACH_DZ])
        kfs = [kf(above, False, rot0), kf(above, True, rot0), kf(p0, True, rot0)]
        # the executor blends into the next waypoint 0.15 s before it reaches one that is not a stop (a
        # microwave door left 1.8 cm short stayed 11 degrees open): the push goes on past the goal (the closed
        # leaf stops the hand)
        turn = turn + np.sign(turn) * DOOR_EXTRA_RAD
        kfs += arc_keyframes(anchor, p0, turn, rot0, turn_hand=True)
        last = kfs[-1]
        kfs.append(kf(last.pos - np.append(rot_z(turn)[:2, :2] @ normal, 0.0) * 0.05, True, last.rot))
        kfs.append(kf(kfs[-1].pos + np.array([0, 0, 0.08]), True, last.rot))
        return kfs


def carry_on_closed(kfs: list[Keyframe], world: World) -> list[Keyframe]:
    """A replan while the fingers are closed on the part (a GLSR local plan mid-pull or mid-push) carries on along
    the move's closed stretch (the first close up to the next open) from the piece of it nearest the hand, instead
    of opening the fingers to approach the part again; unchanged when the fingers are open or the hand is more than
    RESUME_CLOSED_M from that stretch. Each local replan used to open the fingers, back off and come back, so a
    knob, a drawer pushed shut or a drawer pulled with a replan every 0.8 s never finished."""
    if world.fingers_open():
        return kfs
    first = next((i for i, k in enumerate(kfs) if k.closed), None)
    if first is None:
        return kfs
    end = next((i for i in range(first, len(kfs)) if not kfs[i].closed), len(kfs))
    tcp = world.tcp_pos()
    # distance to each piece (keyframe i to i + 1) of the stretch; a one-keyframe stretch is its point
    dist = [segment_distance(tcp, kfs[i].pos, kfs[min(i + 1, end - 1)].pos)
            for i in range(first, max(first + 1, end - 1))]
    nearest = int(np.argmin(dist))
    return kfs[first + nearest:] if dist[nearest] <= RESUME_CLOSED_M else kfs


def segment_distance(p, a, b) -> float:
    """Distance from point ``p`` to the segment a-b [m]."""
    ab = b - a
    t = 0.0 if ab @ ab < 1e-12 else float(np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


ARC_STEP_RAD = 0.15  # [rad] keyframe spacing along a knob's or a door's arc


def arc_keyframes(anchor, p0, turn: float, rot, *, turn_hand: bool) -> list[Keyframe]:
    """Closed-gripper keyframes from ``p0`` along the arc of ``turn`` [rad] about the vertical through ``anchor``,
    at ``p0``'s height (at least 3, every ARC_STEP_RAD); the hand keeps ``rot`` or turns with the arc."""
    n = max(3, int(np.ceil(abs(turn) / ARC_STEP_RAD)))
    out = []
    for k in range(1, n + 1):
        Rk = rot_z(turn * k / n)
        p = anchor + Rk @ (p0 - anchor)
        p[2] = p0[2]
        out.append(kf(p, True, Rk @ rot if turn_hand else rot))
    return out


def pitched_home(approach) -> np.ndarray:
    """The home (top-down) hand turned by the smallest rotation that points its approach axis along
    ``approach``: the reference for choosing among equivalent hands."""
    a = np.asarray(approach, float) / np.linalg.norm(approach)
    k = np.cross(-E_Z, a)
    s = np.linalg.norm(k)
    if s < 1e-9:
        return R_DOWN.copy()
    angle = np.arctan2(s, float(-E_Z @ a))
    return axis_angle(k / s, angle) @ R_DOWN
