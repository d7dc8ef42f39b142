"""LIBERO demonstrations run the oracle's plan out past a success reached while the object is still held: the
labels then carry the release (collect.FINISH_PLAN_STEPS), unless releasing undoes the success or there is no release."""
import numpy as np
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.data.collect import record_demo  # noqa: E402
from tcot_hybrid.run_config import RunConfig  # noqa: E402

BUTTER = "libero_object:pick_up_the_butter_and_place_it_in_the_basket"
BOOK = "libero_10:STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_back_compartment_of_the_caddy"


def _record(task, **kw):
    rec = record_demo(RunConfig(task=task, robot="libero_panda", init="sampled", seed=0), image_every=50, **kw)
    return rec, rec.arrays["obs/robot0_gripper_closed"].astype(bool), rec.arrays["task_success"].astype(bool)


def test_held_success_is_recorded_through_the_release():
    rec, closed, success = _record(BUTTER)
    t = rec.attrs["t_success"]
    assert rec.attrs["success"] and closed[t], "LIBERO judges the butter in the basket while it is still held"
    assert not closed[-1] and closed[t:].any(), "the demo goes on to the oracle's release"
    assert success[-1], "and the butter is still in the basket after it"
    _, closed_short, _ = _record(BUTTER, finish_plan_steps=0)
    assert closed_short[-1] and len(closed_short) < len(closed)  # without it the demo stops with the butter held


def test_release_that_undoes_the_success_is_not_recorded():
    rec, closed, success = _record(BOOK)
    assert rec.attrs["success"] and success[-1], "the demo ends in a successful state"
    assert closed[-1], "the book tips out of the compartment when released: the demo keeps it held"
    assert np.count_nonzero(np.diff(closed.astype(int))) == 1  # one grasp, no release


def test_closed_hand_after_success_keeps_the_short_ending():
    rec, closed, success = _record("libero_goal:turn_on_the_stove")
    t = rec.attrs["t_success"]
    assert rec.attrs["success"] and closed[t] and closed[-1], "the knob is turned with closed fingers, never released"
    assert len(closed) - 1 - t == 5, "no retreat recorded past the success: it would thin the turn's labelled points"
