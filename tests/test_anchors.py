"""Switch tracking (tcot_hybrid.anchors): finding a moved object or receptacle between two planner images, and moving
a plan with it."""
from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tcot_hybrid.anchors import TrackConfig, look, look_receptacle, shift_on_plane, shifted_plan  # noqa: E402
from tcot_hybrid.errors import ConfigError  # noqa: E402
from tcot_hybrid.plan import WaypointPlan  # noqa: E402

from test_lift import FRONT  # noqa: E402  (a camera looking down at the table)

CFG = TrackConfig()
rng = np.random.default_rng(0)
# a table with faint texture; objects are 9 x 9 px patterns of their own
TABLE = np.clip(120 + rng.normal(0, 4, (128, 128, 3)), 0, 255).astype(np.uint8)
OBJ = np.clip(rng.integers(0, 255, (9, 9, 3)), 0, 255).astype(np.uint8)


def plate(img: np.ndarray, centre) -> np.ndarray:
    """``img`` with a featureless plate (a light disc, 15 px across, with a darker rim) at pixel ``centre``."""
    import cv2

    out = img.copy()
    cv2.circle(out, (int(centre[0]), int(centre[1])), 15, (150, 110, 110), -1)
    cv2.circle(out, (int(centre[0]), int(centre[1])), 12, (235, 235, 230), -1)
    return out


def scene(*centres) -> np.ndarray:
    img = TABLE.copy()
    for u, v in centres:
        img[v - 4:v + 5, u - 4:u + 5] = OBJ
    return img


def test_an_object_moved_is_found_where_it_went():
    seen = look(scene((40, 60)), scene((52, 66)), np.array([40.0, 60.0]), CFG)
    assert seen.moved and seen.here < CFG.gone_ncc and seen.best > 0.9
    assert np.allclose(seen.uv_px, (52, 66))


def test_an_object_that_stayed_is_not_moved():
    seen = look(scene((40, 60)), scene((40, 60)), np.array([40.0, 60.0]), CFG)
    assert not seen.moved and seen.here > 0.99


def test_a_look_alike_that_stayed_put_is_not_taken_for_the_moved_object():
    # two identical objects; the one at the grasp pixel moves, its twin 12 px away stays
    before, after = scene((40, 60), (52, 60)), scene((52, 60), (40, 76))
    seen = look(before, after, np.array([40.0, 60.0]), CFG)
    assert seen.moved and np.allclose(seen.uv_px, (40, 76))


def test_a_camera_that_moved_is_not_an_object_that_moved():
    before = scene((40, 60), (80, 30), (90, 100))
    after = np.roll(before, (6, 6), axis=(0, 1))  # the whole view shifted
    after[:6], after[:, :6] = TABLE[:6], TABLE[:, :6]
    textured = np.clip(before.astype(int) + rng.integers(-60, 60, before.shape), 0, 255).astype(np.uint8)
    shifted = np.roll(textured, (6, 6), axis=(0, 1))
    seen = look(textured, shifted, np.array([40.0, 60.0]), CFG)
    assert seen.image_changed > CFG.max_image_changed and not seen.moved
    assert look(before, after, np.array([40.0, 60.0]), CFG) is not None


def test_nothing_to_track_off_the_image_or_on_a_blank_patch():
    blank = np.full((128, 128, 3), 120, np.uint8)
    assert look(scene((40, 60)), scene((40, 60)), np.array([2.0, 60.0]), CFG) is None
    assert look(blank, blank, np.array([40.0, 60.0]), CFG) is None
    with pytest.raises(ValueError, match="one shape"):
        look(scene((40, 60)), scene((40, 60))[:64], np.array([40.0, 60.0]), CFG)


def test_a_pixel_shift_is_lifted_to_the_objects_own_slide_on_the_table():
    point = np.array([0.55, 0.05, 0.03])
    slide = np.array([0.06, -0.08, 0.0])
    uv_to, _ = FRONT.project((point + slide)[None])
    assert np.allclose(shift_on_plane(FRONT, point, uv_to[0]), slide, atol=1e-9)


def _plan(points, grip):
    uv, depth = FRONT.project(np.asarray(points, float))
    return WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.asarray(grip), camera=FRONT.name, kind="global")


def test_the_approach_grasp_and_lift_move_with_the_object_and_the_rest_stays():
    pts = np.array([[0.45, 0.0, 0.30], [0.55, 0.05, 0.15], [0.55, 0.05, 0.03], [0.55, 0.05, 0.03],
                    [0.555, 0.05, 0.20], [0.40, -0.15, 0.20], [0.40, -0.15, 0.05]])
    grip = [False, False, False, True, True, True, False]
    slide = np.array([0.05, 0.02, 0.0])
    moved = shifted_plan(_plan(pts, grip), FRONT, 1, 3, slide, step=9, approach=True)
    got = FRONT.unproject(moved.uv_px, moved.depth_m)
    want = pts[1:].copy()
    want[:4] += slide  # approach 1-2, grasp 3, lift 4; the carry (5) and the release (6) stay
    assert np.allclose(got, want, atol=1e-9)
    assert moved.gripper_closed.tolist() == grip[1:] and moved.kind == "global" and moved.step == 9
    assert moved.meta["tracked_shift_m"] == [0.05, 0.02, 0.0]
    with pytest.raises(ValueError, match="start <= switch"):
        shifted_plan(_plan(pts, grip), FRONT, 4, 3, slide, step=9, approach=True)


def test_a_release_moves_with_its_descent_and_retreat_and_the_carry_stays():
    pts = np.array([[0.55, 0.05, 0.03], [0.55, 0.05, 0.20], [0.40, -0.15, 0.20], [0.40, -0.15, 0.12],
                    [0.40, -0.15, 0.05], [0.40, -0.15, 0.15]])
    grip = [True, True, True, True, False, False]
    slide = np.array([-0.04, 0.09, 0.0])
    moved = shifted_plan(_plan(pts, grip), FRONT, 1, 4, slide, step=3, approach=False)
    got = FRONT.unproject(moved.uv_px, moved.depth_m)
    want = pts[1:].copy()
    want[1:] += slide  # the carry's end above the plate, the descent, the release and the retreat; the lift stays
    assert np.allclose(got, want, atol=1e-9)


def test_a_release_beside_its_grasp_moves_without_the_grasp():
    # put down 1.5 cm from where it was picked up: the plate moved, the object did not
    pts = np.array([[0.45, 0.0, 0.30], [0.55, 0.05, 0.12], [0.55, 0.05, 0.03], [0.55, 0.05, 0.03],
                    [0.55, 0.05, 0.12], [0.565, 0.05, 0.05], [0.565, 0.05, 0.15]])
    grip = [False, False, False, True, True, False, False]
    slide = np.array([-0.04, 0.09, 0.0])
    got = FRONT.unproject(*(lambda m: (m.uv_px, m.depth_m))(
        shifted_plan(_plan(pts, grip), FRONT, 1, 5, slide, step=3, approach=False)))
    want = pts[1:].copy()
    want[3:] += slide  # the lift's top, the release and the retreat; the grasp (3) and its descent stay
    assert np.allclose(got, want, atol=1e-9)


def test_a_featureless_plate_that_moved_is_found_where_it_went():
    before = plate(TABLE, (60, 70))
    after = plate(TABLE, (52, 84))
    rim = np.array([70.0, 64.0])  # the plan lets go near the rim, where a small patch sees only plate
    seen = look_receptacle(before, after, rim, CFG)
    assert seen.moved and np.allclose(seen.uv_px - rim, (-8, 14))
    assert seen.best < CFG.release_residual_ratio * seen.here


def test_a_plate_that_stayed_is_not_looked_at_and_a_move_onto_nothing_is_no_move():
    assert look_receptacle(plate(TABLE, (60, 70)), plate(TABLE, (60, 70)), np.array([70.0, 64.0]), CFG) is None
    # the plate went out of reach (or out of sight): its old place changed, no new place shows it
    gone = look_receptacle(plate(TABLE, (60, 70)), TABLE, np.array([70.0, 64.0]), CFG)
    assert gone is not None and not gone.moved
    # a release pixel off the image is refused as such, not for want of change
    assert look_receptacle(plate(TABLE, (20, 70)), plate(TABLE, (12, 84)), np.array([-1.0, 64.0]), CFG) is None
    assert look_receptacle(plate(TABLE, (20, 70)), plate(TABLE, (12, 84)), np.array([0.0, 64.0]), CFG) is not None


@pytest.mark.parametrize("kw", [dict(mode="always"), dict(every_steps=0), dict(found_ncc=1.5),
                                dict(changed_frac=0.0), dict(max_moves=-1), dict(hand_clear_m=0.0),
                                dict(releases="yes"), dict(placement_lift_m=0.0), dict(release_window_px=0),
                                dict(release_residual_ratio=1.5), dict(release_landed_frac=0.0),
                                dict(found_ncc=-1.0), dict(changed_frac=True), dict(release_landed_frac=True),
                                dict(gone_ncc="0.5")])
def test_bad_tracking_settings_are_refused_by_name(kw):
    with pytest.raises(ConfigError, match=next(iter(kw))):
        TrackConfig(**kw)


def test_tracking_is_a_libero_default_only():
    assert TrackConfig().enabled("libero") and not TrackConfig().enabled("workcell")
    assert TrackConfig(mode="on").enabled("workcell")
    assert not TrackConfig(mode="off").enabled("libero")


def test_a_plate_is_not_judged_while_the_object_to_grasp_has_moved_too():
    # a bowl beside the plate taken away changes the plate's window as a moved plate does: one change at a time
    before = plate(TABLE, (60, 70))
    before[66:75, 78:87] = OBJ
    after = plate(TABLE, (52, 84))
    after[40:49, 100:109] = OBJ
    rim = np.array([70.0, 64.0])
    assert look_receptacle(before, after, rim, CFG, grasp_uv_px=np.array([82.0, 70.0])) is None
    still = plate(TABLE, (52, 84))
    still[66:75, 78:87] = OBJ
    seen = look_receptacle(before, still, rim, CFG, grasp_uv_px=np.array([82.0, 70.0]))
    assert seen is not None and seen.moved
    # an object to grasp out of view cannot be judged unchanged: no plate is judged beside it
    assert look_receptacle(before, still, rim, CFG, grasp_uv_px=np.array([-40.0, 70.0])) is None
