"""The executor's touch-down on a retried grasp (``touch_retry_depth_m``) on a real LIBERO scene: the LIBERO Panda has a
wrist force sensor, so a grasp planned in the air near where one closed on nothing goes on down until the fingertips
meet the table, and closes there; other grasps close where planned."""
import numpy as np
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.episode import EpisodeRunner  # noqa: E402
from tcot_hybrid.executor import ExecutorConfig  # noqa: E402
from tcot_hybrid.plan import WaypointPlan  # noqa: E402
from tcot_hybrid.run_config import RunConfig  # noqa: E402

SPATIAL_TASK = "libero_spatial:pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate"
ABOVE_TABLE_M = 0.06  # the planned grasp: the TCP this high over the table top, an empty hand in the air


def _grasp_in_the_air(*, touch: bool, retry: bool, lean_deg: float = 0.0, ticks: int = 600,
                      above_table_m: float = ABOVE_TABLE_M):
    """The arm at home over a free stretch of table; a plan down onto a grasp ``above_table_m`` over it. ``retry``: an
    empty grasp closed 2 cm beside that point before. Returns (executor, grasp point, the table's height, the TCP
    where the gripper closed or None)."""
    from scipy.spatial.transform import Rotation

    cfg = RunConfig(task=SPATIAL_TASK, seed=20000, init="sampled",
                    executor=ExecutorConfig(touch_retry_depth_m=0.08 if touch else None))
    runner = EpisodeRunner(cfg)
    runner.settle()
    ex, cam, sim = runner.stack.executor, runner.stack.camera, runner.stack.sim
    table = float(runner.stack.task.scene.support_z())
    xy = sim.tcp_pos()[:2] + np.array([0.05, 0.0])  # in front of the hand at home: no object stands there
    grasp = np.array([xy[0], xy[1], table + above_table_m])
    if retry:
        ex.empty_grasp_points.append(grasp + np.array([0.0, 0.02, 0.0]))
    _, R_home = ex.dyn.ee_pose()
    rot = Rotation.from_rotvec(np.radians(lean_deg) * np.array([0.0, 1.0, 0.0])).as_matrix() @ R_home
    points = np.array([grasp + np.array([0.0, 0.0, 0.08]), grasp])
    uv, depth = cam.project(points)
    plan = WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([False, True]), camera=cam.name,
                        kind="local", tcp_rot=np.stack([rot, rot]))
    assert ex.set_plan(plan)
    closed_at = None
    for _ in range(ticks):
        ex.tick()
        if sim.gripper_closed_cmd():
            closed_at = sim.tcp_pos()
            break
    return ex, grasp, table, closed_at


def _until_touching(ex) -> None:
    """Tick until the hand has begun touching down (at most 6 s)."""
    for _ in range(600):
        ex.tick()
        if ex.phase == "touch":
            break
    assert ex.phase == "touch"


def _touches(ex) -> list[dict]:
    return [e for e in ex.events if e["kind"] == "touch"]


def test_the_lab_panda_has_a_wrist_force_sensor(libero_runner):
    force = libero_runner.stack.sim.wrist_force()
    assert force is not None and force.shape == (3,) and np.all(np.isfinite(force))


def test_a_retried_grasp_in_the_air_touches_down_on_the_table_and_closes_there():
    ex, grasp, table, closed_at = _grasp_in_the_air(touch=True, retry=True)
    touch = _touches(ex)
    assert closed_at is not None and len(touch) == 1 and touch[0]["touched"] and touch[0]["ended"] == "touched"
    # it feels its way down and does not strike the table (at a move's full speed it met it at 43 N)
    assert ExecutorConfig().touch_force_n <= touch[0]["force_n"] < 3 * ExecutorConfig().touch_force_n
    # the open fingertips reach 1.2 cm past the TCP: it stops on the table, well below the planned point
    assert grasp[2] - closed_at[2] > 0.03 and table < closed_at[2] < table + 0.03
    assert touch[0]["below_grasp_m"] == pytest.approx(grasp[2] - closed_at[2], abs=0.005)
    assert ex.grasp_tcp_z == pytest.approx(closed_at[2], abs=0.002)


@pytest.mark.parametrize("touch, retry, lean_deg", [(False, True, 0.0), (True, False, 0.0), (True, True, 40.0)])
def test_other_grasps_close_where_planned(touch, retry, lean_deg):
    """Off, a grasp with no empty grasp near it, and a hand leaning past TOUCH_MAX_TILT_RAD: no touch."""
    ex, grasp, _, closed_at = _grasp_in_the_air(touch=touch, retry=retry, lean_deg=lean_deg)
    assert closed_at is not None and not _touches(ex)
    assert np.linalg.norm(closed_at - grasp) < 0.01


def test_a_touch_that_meets_nothing_closes_at_its_bottom():
    ex, grasp, _, closed_at = _grasp_in_the_air(touch=True, retry=True, above_table_m=0.20, ticks=1500)
    touch = _touches(ex)
    assert closed_at is not None and len(touch) == 1
    assert not touch[0]["touched"] and touch[0]["ended"] == "bottom"
    assert grasp[2] - closed_at[2] == pytest.approx(ex.config.touch_retry_depth_m, abs=0.01)


def test_a_plan_that_comes_while_the_hand_touches_down_is_refused_and_one_after_it_is_taken():
    ex, grasp, _, _ = _grasp_in_the_air(touch=True, retry=True, ticks=0)
    _until_touching(ex)
    cam = ex.camera
    uv, depth = cam.project(grasp[None] + np.array([[0.0, 0.0, 0.1]]))
    other = WaypointPlan(uv_px=uv, depth_m=depth, gripper_closed=np.array([False]), camera=cam.name, kind="local")
    assert not ex.set_plan(other)
    refused = [e for e in ex.events if e["kind"] == "plan_refused"]
    assert len(refused) == 1 and refused[0]["plan_kind"] == "local"
    assert ex.phase == "touch" and ex.plan is not other
    for _ in range(600):
        ex.tick()
        if ex.phase != "touch":
            break
    assert ex.sim.gripper_closed_cmd() and ex.set_plan(other) and ex.plan is other


def test_a_touch_cut_short_by_a_move_home_is_said():
    ex, _, _, _ = _grasp_in_the_air(touch=True, retry=True, ticks=0)
    _until_touching(ex)
    ex.go_home(0.05)
    touch = _touches(ex)
    assert len(touch) == 1 and touch[0]["ended"] == "interrupted: the plan was dropped" and not touch[0]["touched"]
    assert ex.phase == "home" and not ex.sim.gripper_closed_cmd()


def test_libero_cuts_a_holding_hands_descents_by_default():
    """``executor.max_segment_m`` "auto" is 4 cm on LIBERO, for the descents of a hand that holds something
    (``cut_segments`` "holding_descents"); an open hand's descent onto its grasp is left as planned."""
    ex, grasp, _, closed_at = _grasp_in_the_air(touch=False, retry=False)
    assert ex.max_segment_m == 0.04 and ex.config.cut_segments == "holding_descents"
    assert not [e for e in ex.events if e["kind"] == "segment_cut"] and len(ex.points) == 2
    assert closed_at is not None and np.linalg.norm(closed_at - grasp) < 0.01
