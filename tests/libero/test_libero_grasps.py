"""The LIBERO oracle's grasp geometry on synthetic collision boxes (no LIBERO scene needed)."""
import numpy as np

from tcot_hybrid.libero.geometry import Boxes
from tcot_hybrid.libero.grasps import (
    MAX_SPAN_M,
    RIM_INSETS_M,
    handle_candidates,
    hand_points,
    inset_rim_candidates,
    part_candidates,
    rim_candidates,
    rot_z,
    score_grasps,
    top_candidates,
)


def boxes(*specs) -> Boxes:
    """Boxes from (centre, half size, yaw [rad]) triples."""
    centre = np.array([s[0] for s in specs], float)
    half = np.array([s[1] for s in specs], float)
    rot = np.stack([rot_z(s[2]) for s in specs])
    return Boxes(centre, rot, half, np.arange(len(specs)))


def test_top_grasps_close_on_a_books_faces_not_across_them():
    yaw = np.deg2rad(58.8)  # a standing book turned off the 15-degree grid of candidate yaws
    book = boxes(([0.0, 0.0, 0.067], [0.014, 0.055, 0.067], yaw))
    thin_axis = rot_z(yaw)[:, 0]
    cands = top_candidates(book)
    assert cands
    for _, rot in cands:
        assert abs(rot[:, 1] @ thin_axis) > np.cos(np.deg2rad(3.0)), rot[:, 1]


def test_part_grasps_take_a_handle_of_an_object_too_wide_to_grasp_whole():
    body = ([0.0, 0.0, 0.065], [0.041, 0.041, 0.065], 0.0)  # 8.2 cm across: wider than the open hand
    handle = ([0.0, 0.062, 0.08], [0.0065, 0.02, 0.035], 0.0)  # 1.3 cm thick, off the +y side
    pot = boxes(body, handle)
    assert top_candidates(pot) == []
    cands = part_candidates(pot)
    on_handle = [(p, R) for p, R in cands if abs(p[0]) < 0.01 and 0.045 < p[1] < 0.08]
    assert on_handle, [p.round(3) for p, _ in cands]
    for p, R in on_handle:
        assert abs(R[:, 1] @ np.array([1.0, 0.0, 0.0])) > 0.99  # the fingers close across its thin side
        assert p[2] < 0.115  # below the handle's top, where the pads hold it


def test_a_plain_box_too_wide_for_the_hand_has_no_part_to_grasp():
    wide = boxes(([0.0, 0.0, 0.05], [0.05, 0.05, 0.05], 0.0))
    assert 2 * 0.05 > MAX_SPAN_M
    assert top_candidates(wide) == []
    assert part_candidates(wide) == []


def mug(n_wall: int = 16, radius: float = 0.042, handle_dir=(0.0, -1.0)) -> Boxes:
    """A mug as LIBERO models it: a ring of thin wall boxes, a bottom, and a handle bar 8 cm out."""
    specs = []
    for k in range(n_wall):
        a = 2 * np.pi * k / n_wall
        specs.append(([radius * np.cos(a), radius * np.sin(a), 0.05], [0.004, 0.009, 0.045], a))
    specs.append(([0.0, 0.0, 0.005], [0.03, 0.03, 0.005], 0.0))
    u = np.array(handle_dir, float) / np.linalg.norm(handle_dir)
    specs.append(([0.08 * u[0], 0.08 * u[1], 0.055], [0.009, 0.004, 0.029], np.arctan2(u[1], u[0])))
    return boxes(*specs)


def test_handle_grasps_hold_a_mugs_handle_level_pointing_in_at_the_mug():
    for handle_dir in ((0.0, -1.0), (1.0, 1.0)):
        u = np.append(np.array(handle_dir) / np.linalg.norm(handle_dir), 0.0)
        cands = handle_candidates(mug(handle_dir=handle_dir))
        assert len(cands) == 2  # the two rolls of the hand
        for p, R in cands:
            assert np.allclose(p[:2], 0.08 * u[:2], atol=1e-9)  # on the handle's bar
            assert np.allclose(R[:, 2], -u, atol=1e-9)  # level, pointing in along the handle's radius
            assert abs(R[:, 1] @ u) < 1e-9 and abs(R[2, 1]) < 1e-9  # closing across the bar, horizontally
            assert np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0


def ring_bowl(radius: float = 0.047, n_wall: int = 16) -> Boxes:
    """A bowl as LIBERO models it: a ring of thin wall boxes 5 cm tall on a bottom."""
    walls = [([radius * np.cos(a), radius * np.sin(a), 0.03], [0.004, 0.012, 0.025], a)
             for a in np.linspace(0, 2 * np.pi, n_wall, endpoint=False)]
    return boxes(*walls, ([0.0, 0.0, 0.004], [0.03, 0.03, 0.004], 0.0))


def test_an_object_without_a_handle_has_no_handle_grasp():
    assert handle_candidates(ring_bowl(radius=0.06)) == []


def test_inset_rim_pinches_sit_inside_the_rim_and_drag_the_bowl_by_the_inset():
    bowl = ring_bowl()
    rims = rim_candidates(bowl)
    insets = inset_rim_candidates(bowl, rims)
    assert len(insets) == len(rims) * len(RIM_INSETS_M)
    for (p, R, drag), (p0, R0), inset in zip(insets, [r for r in rims for _ in RIM_INSETS_M],
                                             list(RIM_INSETS_M) * len(rims)):
        assert R is R0  # PickPlace.grasp knows a rim pinch by its rotation object
        assert np.allclose(p - p0, drag) and drag[2] == 0.0
        assert np.isclose(np.linalg.norm(drag), inset)
        assert np.linalg.norm(p[:2]) < np.linalg.norm(p0[:2])  # towards the ring's centre
        assert abs(R[:, 1] @ np.append(drag[:2] / np.linalg.norm(drag), 0.0)) > 0.99  # along the closing axis


def test_a_bowl_against_a_wall_is_pinched_inset_and_dragged_off_it_a_free_bowl_at_its_rim():
    bowl = ring_bowl()
    rims = rim_candidates(bowl)
    insets_only = inset_rim_candidates(bowl, rims)
    free = score_grasps(rims + insets_only,
                        boxes(([1.0, 1.0, 0.5], [0.01, 0.01, 0.01], 0.0)), ground_z=-0.01, kind="rim")
    assert free[0].collisions == 0 and not free[0].drag.any()
    # a round pen 4.5 cm outside the rim, as tall as the bowl: at the rim the outer finger (4.1-6.2 cm out) lands
    # on its wall wherever it pinches
    out = 0.047 + 0.004 + 0.045 + 0.005
    walls = boxes(*[([out * np.cos(a), out * np.sin(a), 0.0275], [0.005, 0.025, 0.0275], a)
                    for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)])
    at_rim = score_grasps(rims, walls, ground_z=-0.01, kind="rim")
    assert min(g.collisions for g in at_rim) > 0
    insets = score_grasps(insets_only, walls, ground_z=-0.01, kind="rim")
    # the 1 cm inset's outer finger still reaches the pen (9.9 cm out against its wall at 9.6): only 2 cm clears it
    assert min(g.collisions for g in insets if np.isclose(np.linalg.norm(g.drag), 0.01)) > 0
    best = score_grasps(rims + insets_only, walls, ground_z=-0.01, kind="rim")[0]
    assert best.collisions == 0 and np.isclose(np.linalg.norm(best.drag), 0.02)
    dragged = Boxes(bowl.centre + best.drag, bowl.rot, bowl.half, bowl.geom)
    assert not walls.contains(np.vstack([dragged.centre + s * dragged.world_extents()
                                         for s in ((1, 1, 1), (-1, -1, 1), (1, -1, 1), (-1, 1, 1))])).any()
