"""Grasp and gripper geometry for the LIBERO oracle: candidate grasps from an object's collision boxes, the
Panda hand as sample points for clearance tests, orientation helpers.

Orientation convention (the stack's TCP frame): columns x, y = the fingers' closing axis, z = the approach
axis (out of the palm, towards the fingertips). Top-down = z along world -z; ``R_DOWN`` = diag(1, -1, -1).

Two grasp families, chosen from the object's category name and checked against its geometry:

- **rim pinch** (bowls, ramekins, plates, mugs, moka pots, pans): one finger inside, one outside the wall at
  the object's top ring; the closing axis is radial. Candidates: every collision box of the top ring (a
  mug's handle, off the ring's radius, is not a candidate).
- **inset rim pinch**: a rim pinch with the TCP moved into the object (RIM_INSETS_M), for a rim with too little
  room outside it for the outer finger (a bowl against a drawer's wall): the outer finger lands that much nearer
  the wall and, closing, drags the object by the inset away from whatever was beside it (``Grasp.drag``).
- **top grasp** (boxes, cans, bottles, books, cartons, everything else): the fingers straddle the top slab
  of the object across its narrowest horizontal width; yaws every 15 degrees, those the open hand spans.

Every candidate is scored by the hand's clearance from everything else in the scene (the hand at the grasp
and on its vertical approach) and by how far its wrist turns from the home yaw.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tcot_hybrid.libero.geometry import Boxes

RIM_WORDS = ("bowl", "ramekin", "plate", "mug", "cup", "moka_pot", "pot", "pan", "frypan")
ALIGN_SLACK_M = 0.006  # [m] top grasps close on at most this much more than the object's narrowest width
MAX_SPAN_M = 0.072  # [m] widest slab the open hand closes on (8 cm between the pads, minus margin)
FINGER_BELOW_TCP_M = 0.012  # [m] the finger meshes reach this far past the TCP (fingertip centre)
APPROACH_DZ = 0.10  # [m] pre-grasp height above a grasp (vertical approach)
RIM_INSETS_M = (0.01, 0.02)  # [m] how far an inset rim pinch puts the TCP inside the rim (the object's drag)
# A dragged object may tip or catch: an inset pinch costs as much as one more colliding hand point per cm, so it
# wins only where the pinch at the rim hits something
DRAG_COST_PER_M = 100.0

E_Z = np.array([0.0, 0.0, 1.0])
R_DOWN = np.diag([1.0, -1.0, -1.0])


def frame(z_axis, y_axis) -> np.ndarray:
    """Rotation with approach axis z and closing axis y (y is made orthogonal to z)."""
    z = np.asarray(z_axis, float)
    z = z / np.linalg.norm(z)
    y = np.asarray(y_axis, float)
    y = y - z * (y @ z)
    y = y / np.linalg.norm(y)
    return np.column_stack([np.cross(y, z), y, z])


# The hand's yaw (about world z, from the home hand) is kept in (YAW_MIN - 180, YAW_MIN] degrees. Measured on
# the stove knob (libero_goal turn_on_the_stove, sampled seed 0): a +90 degree hand tripped joint 7's tracking
# reflex on the way there (its 12 N m motor lags), the -90 degree hand turned the knob.
YAW_MIN_RAD = np.deg2rad(60.0)


def top_down(closing_xy) -> np.ndarray:
    """Top-down hand whose fingers close along the horizontal direction ``closing_xy`` (either sign: the
    one whose yaw is in (-120, 60] degrees, see YAW_MIN_RAD)."""
    c = np.array([closing_xy[0], closing_xy[1], 0.0])
    yaw = np.arctan2(c[0], -c[1])
    if yaw > YAW_MIN_RAD or yaw <= YAW_MIN_RAD - np.pi:
        c = -c
    return frame(-E_Z, c)


def rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def yaw_from_home(rot: np.ndarray) -> float:
    """How far [rad] the hand's closing axis is turned about world z from the home hand's (-y)."""
    y = rot[:, 1]
    return float(np.arctan2(y[0], -y[1]))


def _grid(lo, hi, n) -> np.ndarray:
    axes = [np.linspace(a, b, k) for a, b, k in zip(lo, hi, n)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


# The Panda hand in the TCP frame (measured from robosuite's collision meshes, fingers fully open).
_HAND = _grid((-0.032, -0.104, -0.124), (0.032, 0.104, -0.028), (3, 9, 4))
_FINGERS = np.vstack([_grid((-0.011, s * 0.041, -0.05), (0.011, s * 0.062, FINGER_BELOW_TCP_M), (3, 2, 5))
                      for s in (-1.0, 1.0)])
_FINGERS_CLOSED = np.vstack([_grid((-0.011, s * 0.004, -0.05), (0.011, s * 0.025, FINGER_BELOW_TCP_M), (3, 2, 5))
                             for s in (-1.0, 1.0)])


def hand_points(pos, rot, *, closed: bool = False, fingers_only: bool = False) -> np.ndarray:
    """World sample points of the hand (palm + fingers) with the TCP at ``pos``, oriented ``rot``."""
    fingers = _FINGERS_CLOSED if closed else _FINGERS
    local = fingers if fingers_only else np.vstack([_HAND, fingers])
    return np.asarray(pos) + local @ np.asarray(rot).T


@dataclass(frozen=True)
class Grasp:
    """A TCP pose [world] that holds the object, the family it came from and its score (lower is better)."""

    pos: np.ndarray
    rot: np.ndarray
    kind: str
    score: float
    collisions: int
    drag: np.ndarray = field(default_factory=lambda: np.zeros(3))  # [m] the object's shift as the hand closes


def family(category: str) -> str:
    c = category.lower()
    return "rim" if any(w in c for w in RIM_WORDS) else "top"


RING_RADIUS_TOL_M = 0.012  # [m] a ring's boxes lie this close to its median radius; handles and spouts beyond


def _ring(obj: Boxes, *, recentre: bool = False):
    """The object's top ring: (indices of its boxes, the object's centre, each box's top, the ring's top).
    ``recentre``: centre on the ring's boxes rather than the bounding box (a handle shifts the box's centre by
    half its length; a tilted bowl's highest boxes, all on one side, would shift the ring's instead)."""
    lo, hi = obj.aabb()
    centre = (lo + hi) / 2
    ext = obj.world_extents()
    tops = obj.centre[:, 2] + ext[:, 2]
    top = tops.max()
    high = tops >= top - 0.02
    ring = np.zeros(len(obj), bool)
    for _ in range(2 if recentre else 1):
        radial = np.linalg.norm(obj.centre[:, :2] - centre[:2], axis=1)
        ring = high & (radial >= 0.35 * radial.max())
        if not ring.any():
            return np.zeros(0, int), centre, tops, top
        r_ring = float(np.median(radial[ring]))
        ring &= np.abs(radial - r_ring) <= RING_RADIUS_TOL_M
        if recentre and ring.sum() >= 3:
            centre = np.append(obj.centre[ring, :2].mean(axis=0), centre[2])
    return np.flatnonzero(ring), centre, tops, top


def rim_candidates(obj: Boxes) -> list[tuple[np.ndarray, np.ndarray]]:
    """(TCP position, rotation) per box of the object's top ring, closing radially across the wall."""
    ring, centre, tops, top = _ring(obj)
    lo, hi = obj.aabb()
    height = hi[2] - lo[2]
    out = []
    for i in ring:
        u = obj.centre[i, :2] - centre[:2]
        u = u / np.linalg.norm(u)
        depth = min(0.02, 0.5 * height)
        z = max(tops[i] - depth, lo[2] + FINGER_BELOW_TCP_M + 0.004)
        p = np.array([obj.centre[i, 0], obj.centre[i, 1], z])
        out.append((p, top_down(u)))
    return out


def inset_rim_candidates(obj: Boxes, rims) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(TCP position, rotation, drag) per rim pinch ``rims`` (from :func:`rim_candidates`) and inset in
    RIM_INSETS_M: the TCP moved that far towards the ring's centre. The fingers close about the TCP, so the outer
    one pushes the wall to it: the object moves by ``drag`` (the TCP's shift) as the hand closes. Each keeps its rim
    pinch's rotation object: PickPlace.grasp tells rim pinches from top grasps by that identity."""
    _, centre, _, _ = _ring(obj)
    out = []
    for p, R in rims:
        u = p[:2] - centre[:2]
        if np.linalg.norm(u) < 1e-6:
            continue
        u = u / np.linalg.norm(u)
        for inset in RIM_INSETS_M:
            shift = np.array([-u[0] * inset, -u[1] * inset, 0.0])
            out.append((p + shift, R, shift))
    return out


def handle_candidates(obj: Boxes) -> list[tuple[np.ndarray, np.ndarray]]:
    """Level grasps of a handle (the boxes standing off the top ring's radius, outward: a mug's handle): the
    hand level, pointing in at the object along the handle's radius, the fingers closing across the handle's
    outermost bar at its middle. A level hand is 6.4 cm tall and holds the mug ahead of it, so it carries a mug
    into a cavity a top-down hand cannot enter (the microwave: 14.4 cm tall, the mug 10.3 cm); a level pinch on
    the rim cannot, since the inner finger, straight and 5 cm long, would cross the curved wall."""
    ring, centre, _, _ = _ring(obj, recentre=True)
    if len(ring) == 0:
        return []
    radial = np.linalg.norm(obj.centre[:, :2] - centre[:2], axis=1)
    r_ring = float(np.median(radial[ring]))
    handle = np.flatnonzero(radial > r_ring + RING_RADIUS_TOL_M)
    if len(handle) == 0:
        return []
    bar = int(handle[np.argmax(radial[handle])])
    u = np.append(obj.centre[bar, :2] - centre[:2], 0.0)
    u = u / np.linalg.norm(u)
    tangent = np.cross(E_Z, u)
    b_lo, b_hi = obj.select(np.arange(len(obj)) == bar).extents_in(frame(-u, tangent), np.zeros(3))
    if b_hi[1] - b_lo[1] > MAX_SPAN_M:
        return []
    p = obj.centre[bar].copy()
    return [(p, frame(-u, t)) for t in (tangent, -tangent)]


def candidate_yaws(obj: Boxes) -> np.ndarray:
    """Hand yaws [rad, 0..pi) to try: every 15 degrees, plus the object's own face directions (the largest
    boxes' horizontal axes): fingers 7 degrees off a book's faces turned it as they closed, and the turned
    book no longer fitted the caddy's slot it had been aimed at."""
    yaws = list(np.deg2rad(np.arange(0, 180, 15)))
    if len(obj):
        for i in np.argsort(-np.prod(obj.half, axis=1))[:3]:
            for k in range(3):
                a = obj.rot[i][:, k]
                if abs(a[2]) < 0.3:
                    for extra in (0.0, np.pi / 2):
                        yaws.append((np.arctan2(a[1], a[0]) + extra) % np.pi)
    yaws = np.array(yaws)
    keep = [0]
    for i in range(1, len(yaws)):  # drop near-duplicates (within 2 degrees, modulo pi)
        d = np.abs((yaws[keep] - yaws[i] + np.pi / 2) % np.pi - np.pi / 2)
        if d.min() > np.deg2rad(2.0):
            keep.append(i)
    return yaws[keep]


def top_candidates(obj: Boxes) -> list[tuple[np.ndarray, np.ndarray]]:
    """(TCP position, rotation) per yaw (15-degree steps) whose top slab the open hand spans."""
    lo, hi = obj.aabb()
    height = hi[2] - lo[2]
    depth = min(0.03, 0.55 * height)
    ext = obj.world_extents()
    in_slab = (obj.centre[:, 2] + ext[:, 2] >= hi[2] - depth) & (obj.centre[:, 2] - ext[:, 2] <= hi[2])
    slab = obj.select(in_slab)
    z = max(hi[2] - depth + 0.008, lo[2] + FINGER_BELOW_TCP_M + 0.004)
    fits = []
    for yaw in candidate_yaws(slab):
        R = rot_z(yaw)
        s_lo, s_hi = slab.extents_in(R, np.zeros(3))
        span = s_hi[1] - s_lo[1]
        if span <= MAX_SPAN_M:
            fits.append((span, R, s_lo, s_hi))
    out = []
    narrowest = min((f[0] for f in fits), default=0.0)
    for span, R, s_lo, s_hi in fits:
        if span > narrowest + ALIGN_SLACK_M:
            continue  # fingers oblique to the faces turn the object as they close (a book, 16 degrees)
        mid = R @ ((s_lo + s_hi) / 2)
        out.append((np.array([mid[0], mid[1], z]), top_down(R[:, 1])))
    return out


PART_MAX_SPAN_M = 0.05  # [m] a part's strip leaves the open fingers room (a 7 cm strip across a moka pot's
#                         body had the tilted fingers land on its lid)
PART_PAD_M = 0.008  # [m] a pad's half width, less a margin
PART_BAND_M = 0.015  # [m] half width of the strip a finger pair sweeps (pads 2.2 cm wide, plus margin)


def part_candidates(obj: Boxes) -> list[tuple[np.ndarray, np.ndarray]]:
    """Top grasps of a narrow part of an object too wide to grasp whole (a moka pot's handle or spout):
    per yaw whose whole top slab the hand cannot span, strips across the object 1 cm apart, each taken by
    the boxes it crosses (down to the object's bottom: a handle reaches below the top slab); a strip the
    open hand spans is a candidate, the TCP 2.2 cm below the strip's top."""
    lo, hi = obj.aabb()
    height = hi[2] - lo[2]
    ext = obj.world_extents()
    in_slab = obj.centre[:, 2] + ext[:, 2] >= hi[2] - min(0.03, 0.55 * height)
    found = []
    for yaw in candidate_yaws(obj):
        R = rot_z(yaw)
        s_lo, s_hi = obj.select(in_slab).extents_in(R, np.zeros(3))
        if s_hi[1] - s_lo[1] <= MAX_SPAN_M:
            continue  # the whole slab fits: top_candidates has it
        local_c = obj.centre @ R
        local_ext = np.einsum("nij,nj->ni", np.abs(np.einsum("ji,njk->nik", R, obj.rot)), obj.half)
        b_lo, b_hi = local_c - local_ext, local_c + local_ext
        for x in np.arange(s_lo[0], s_hi[0] + 1e-9, 0.01):
            band = (b_hi[:, 0] >= x - PART_BAND_M) & (b_lo[:, 0] <= x + PART_BAND_M)
            top = b_hi[band, 2].max() if band.any() else -np.inf
            band &= b_hi[:, 2] >= top - 0.04  # what the fingers reach from the strip's top
            if not band.any() or b_hi[band, 1].max() - b_lo[band, 1].min() > PART_MAX_SPAN_M:
                continue
            spans = []  # the pads need parallel faces under their whole width: a strip off a rounded edge
            for xs in (x - PART_PAD_M, x, x + PART_PAD_M):  # narrows (or ends) under a pad and squeezes out
                cut = band & (b_lo[:, 0] <= xs) & (b_hi[:, 0] >= xs)
                spans.append(b_hi[cut, 1].max() - b_lo[cut, 1].min() if cut.any() else -1.0)
            if min(spans) < 0 or max(spans) - min(spans) > 0.006:
                continue
            z = max(top - 0.022, lo[2] + FINGER_BELOW_TCP_M + 0.004)
            mid = R @ np.array([x, (b_hi[band, 1].max() + b_lo[band, 1].min()) / 2, 0.0])
            found.append((np.array([mid[0], mid[1], z]), top_down(R[:, 1]), float(np.mean(spans))))
    # as for whole objects: fingers close on the part's faces, so of the strips over one spot (1.5 cm) only
    # the narrowest ones stay
    out = []
    for p, R, span in found:
        near = [f[2] for f in found if np.linalg.norm(f[0][:2] - p[:2]) < 0.015]
        if span <= min(near) + ALIGN_SLACK_M:
            out.append((p, R))
    return out


def side_candidates(obj: Boxes, base_pos) -> list[tuple[np.ndarray, np.ndarray]]:
    """Horizontal grasps of a tall object (bottles): the hand comes from the robot's side (straight and 30
    degrees either way), fingers closing horizontally on a 2.4 cm slab at 35-65 % of its height that the
    open hand spans. Carried this way the object hangs a few cm below the hand instead of its full height."""
    lo, hi = obj.aabb()
    height = hi[2] - lo[2]
    if height < 0.10 or height < 1.5 * min(hi[0] - lo[0], hi[1] - lo[1]):
        return []
    c = (lo + hi) / 2
    d0 = c[:2] - np.asarray(base_pos)[:2]
    d0 = d0 / np.linalg.norm(d0)
    ext = obj.world_extents()
    out = []
    for frac in (0.35, 0.5, 0.65):
        z = max(lo[2] + frac * height, lo[2] + 0.04)  # the palm (3.2 cm either side) stays off the support
        sel = (obj.centre[:, 2] - ext[:, 2] <= z + 0.012) & (obj.centre[:, 2] + ext[:, 2] >= z - 0.012)
        if not sel.any():
            continue
        slab = obj.select(sel)
        for turn in np.deg2rad([0.0, 30.0, -30.0]):
            d = rot_z(turn)[:2, :2] @ d0
            a = np.array([d[0], d[1], 0.0])
            y = np.cross(E_Z, a)
            R = np.column_stack([a, y, E_Z])
            s_lo, s_hi = slab.extents_in(R, np.zeros(3))
            if s_hi[1] - s_lo[1] > MAX_SPAN_M:
                continue
            mid = R @ ((s_lo + s_hi) / 2)
            for yy in (y, -y):
                out.append((np.array([mid[0], mid[1], z]), frame(a, yy)))
    return out


def score_grasps(candidates, obstacles: Boxes, *, ground_z: float, kind: str, prefer=None) -> list[Grasp]:
    """Score candidates, (pos, rot) or (pos, rot, drag): hand collisions at the grasp and on its vertical
    approach (margin 4 mm), points below the ground, wrist turn from the home yaw, the object's drag
    (DRAG_COST_PER_M) and an optional extra cost ``prefer(pos, rot)``."""
    out = []
    for pos, rot, *rest in candidates:
        drag = rest[0] if rest else np.zeros(3)
        pts = [hand_points(pos, rot)]
        for dz in (0.03, 0.06, APPROACH_DZ):  # back out along the approach axis
            pts.append(hand_points(pos - rot[:, 2] * dz, rot))
        pts = np.vstack(pts)
        hits = int(obstacles.contains(pts, margin=0.004).sum()) + int((pts[:, 2] < ground_z).sum())
        yaw = abs(yaw_from_home(rot)) if abs(rot[2, 2]) > 0.5 else 0.0
        extra = prefer(pos, rot) if prefer is not None else 0.0
        extra += DRAG_COST_PER_M * float(np.linalg.norm(drag))
        out.append(Grasp(pos=pos, rot=rot, kind=kind, score=hits * 1.0 + 0.3 * yaw + extra, collisions=hits,
                         drag=drag))
    return sorted(out, key=lambda g: g.score)
