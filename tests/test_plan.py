import numpy as np
import pytest

from tcot_hybrid.errors import PlanningError
from tcot_hybrid.plan import WaypointPlan


def make(**kw):
    base = dict(uv_px=np.array([[10.0, 20.0], [30.0, 40.0]]), depth_m=np.array([1.0, 1.1]),
                gripper_closed=np.array([False, True]), camera="agentview", kind="global")
    base.update(kw)
    return WaypointPlan(**base)


def test_valid_plan_is_read_only():
    p = make()
    assert len(p) == 2
    with pytest.raises(ValueError):
        p.uv_px[0, 0] = 5.0


@pytest.mark.parametrize("kw, fragment", [
    (dict(uv_px=np.array([[np.nan, 1.0], [1.0, 1.0]])), "waypoint 0 is not finite"),
    (dict(depth_m=np.array([1.0, np.inf])), "waypoint 1 is not finite"),
    (dict(uv_px=np.zeros((2, 3))), "shape (N>=1, 2)"),
    (dict(depth_m=np.ones(3)), "depth_m must have shape (2,)"),
    (dict(gripper_closed=np.ones(1, bool)), "gripper_closed must have shape (2,)"),
    (dict(kind="sideways"), "global, local, direct"),
])
def test_bad_plans_are_rejected_with_the_value_named(kw, fragment):
    with pytest.raises(PlanningError) as exc:
        make(**kw)
    assert fragment in str(exc.value)
