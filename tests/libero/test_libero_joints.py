"""The LIBERO oracle's joint skill: a replan with the fingers already closed on the part carries on along the move
(tcot_hybrid.libero.joints.carry_on_closed), and GLSR's local replans finish a knob turn."""
import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("libero.libero")  # tests/libero is itself a namespace "libero"

from tcot_hybrid.episode import EpisodeRunner  # noqa: E402
from tcot_hybrid.libero.joints import RESUME_CLOSED_M, carry_on_closed, segment_distance  # noqa: E402
from tcot_hybrid.run_config import RunConfig  # noqa: E402
from tcot_hybrid.tasks.base import Keyframe  # noqa: E402

# a push: open above the part, close there, down onto it, then along it, and open at the end
PUSH = [Keyframe(np.array([0.0, 0.0, 0.10]), False), Keyframe(np.array([0.0, 0.0, 0.10]), True),
        Keyframe(np.array([0.0, 0.0, 0.02]), True), Keyframe(np.array([0.05, 0.0, 0.02]), True),
        Keyframe(np.array([0.10, 0.0, 0.02]), True), Keyframe(np.array([0.10, 0.0, 0.10]), False)]


def world(tcp, *, fingers_open: bool):
    return SimpleNamespace(tcp_pos=lambda: np.asarray(tcp, float), fingers_open=lambda: fingers_open)


def test_a_closed_hand_on_the_way_down_carries_on_from_that_piece():
    out = carry_on_closed(PUSH, world([0.005, 0.0, 0.06], fingers_open=False))
    assert out == PUSH[1:]  # the piece from above (closed) down to the part: no re-opening


def test_a_closed_hand_mid_push_carries_on_from_the_piece_it_is_on():
    out = carry_on_closed(PUSH, world([0.07, 0.01, 0.02], fingers_open=False))
    assert out == PUSH[3:]


@pytest.mark.parametrize("tcp,fingers_open", [([0.07, 0.0, 0.02], True),  # open fingers: the approach as planned
                                              ([0.3, 0.0, 0.3], False)])  # closed but far from the move
def test_open_fingers_or_a_far_hand_keep_the_whole_move(tcp, fingers_open):
    assert carry_on_closed(PUSH, world(tcp, fingers_open=fingers_open)) == PUSH


def test_the_bound_is_the_distance_to_the_closed_stretch():
    just_in = world([0.05, RESUME_CLOSED_M - 1e-4, 0.02], fingers_open=False)
    just_out = world([0.05, RESUME_CLOSED_M + 1e-4, 0.02], fingers_open=False)
    assert carry_on_closed(PUSH, just_in) != PUSH and carry_on_closed(PUSH, just_out) == PUSH


def test_segment_distance():
    a, b = np.zeros(3), np.array([1.0, 0.0, 0.0])
    assert segment_distance(np.array([0.5, 0.2, 0.0]), a, b) == pytest.approx(0.2)
    assert segment_distance(np.array([-0.3, 0.4, 0.0]), a, b) == pytest.approx(0.5)  # beyond an end: to the end
    assert segment_distance(np.array([0.0, 0.3, 0.0]), a, a) == pytest.approx(0.3)  # a point


def test_glsr_local_replans_finish_a_knob_turn_and_the_next_step():
    # each local replan used to open the fingers above the knob and come back: the stove never came on
    cfg = RunConfig(task="libero_10:KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it", seed=2102,
                    init="sampled", planner="oracle")
    result = EpisodeRunner(dataclasses.replace(cfg, supervisor=dataclasses.replace(cfg.supervisor, mode="glsr"))).run()
    switches = [e for e in result["events"] if e["kind"] == "gripper"]
    assert result["fault"] is None and result["success"], result["fault"]
    assert len(switches) <= 6, switches  # knob: close, open; moka pot: close, open (not one cycle per replan)
