"""Trajectory label windows (paper eq. 4/5): exact indices, clamping, validation, vectorised labels."""
import numpy as np
import pytest

from tcot_hybrid.data.labels import (
    TrajectoryWindowConfig, event_index_table, global_index_table, global_indices, global_labels, local_index_table,
    local_indices, local_labels, make_track, window_labels, windows_from_meta,
)
from tcot_hybrid.errors import ConfigError, DatasetError

SMALL = TrajectoryWindowConfig(L_g=5, n_g=3, L_l=3, n_l=2)


def test_global_window_hand_computed():
    # eq. 4: t + n_g*k, k = -2..2 (L_g = 5, n_g = 3), inside the episode: no clamping
    assert global_indices(30, 10, SMALL).tolist() == [4, 7, 10, 13, 16]
    assert global_indices(30, 6, SMALL).tolist() == [0, 3, 6, 9, 12]


def test_global_window_clamps_both_ends():
    assert global_indices(30, 2, SMALL).tolist() == [0, 0, 2, 5, 8]
    assert global_indices(30, 27, SMALL).tolist() == [21, 24, 27, 29, 29]
    assert global_indices(1, 0, SMALL).tolist() == [0, 0, 0, 0, 0]


def test_local_window_hand_computed_and_clamped():
    # eq. 5: t + n_l*k, k = 0..L_l (L_l + 1 = 4 points, n_l = 2)
    assert local_indices(30, 10, SMALL).tolist() == [10, 12, 14, 16]
    assert local_indices(30, 26, SMALL).tolist() == [26, 28, 29, 29]
    assert local_indices(30, 29, SMALL).tolist() == [29, 29, 29, 29]


def test_defaults_and_centre():
    cfg = TrajectoryWindowConfig()
    assert (cfg.L_g, cfg.n_g, cfg.L_l, cfg.n_l) == (51, 4, 8, 2)
    g = global_indices(500, 200, cfg)
    assert len(g) == 51 and g[cfg.global_center] == 200 and g[0] == 100 and g[-1] == 300
    assert np.all(np.diff(g) == 4)
    loc = local_indices(500, 200, cfg)
    assert loc.tolist() == list(range(200, 217, 2))


def test_tables_match_single_step_functions():
    for T in (1, 7, 60):
        gt, lt = global_index_table(T, SMALL), local_index_table(T, SMALL)
        assert gt.shape == (T, 5) and lt.shape == (T, 4)
        for t in range(T):
            assert gt[t].tolist() == global_indices(T, t, SMALL).tolist()
            assert lt[t].tolist() == local_indices(T, t, SMALL).tolist()
        assert gt.min() >= 0 and gt.max() <= T - 1


@pytest.mark.parametrize("kw", [dict(n_l=4, n_g=4), dict(n_l=5, n_g=4), dict(L_g=50), dict(n_g=0, n_l=0),
                                dict(L_l=0), dict(L_g=2.0)])
def test_config_validation(kw):
    with pytest.raises(ConfigError):
        TrajectoryWindowConfig(**kw)


def test_step_outside_demo_refused():
    with pytest.raises(ConfigError, match="outside"):
        global_indices(10, 10, SMALL)
    with pytest.raises(ConfigError):
        local_indices(0, 0, SMALL)


def test_labels_gather_track_rows():
    T = 40
    t = np.arange(T, dtype=float)
    track = make_track(np.stack([t, 2 * t], 1), 0.01 * t, t >= 20)
    g, loc = window_labels(track, SMALL)
    assert g.uv_px.shape == (T, 5, 2) and g.z_m.shape == (T, 5) and g.gripper_closed.shape == (T, 5)
    assert loc.uv_px.shape == (T, 4, 2)
    # row t, point k holds the track sample at the window index
    np.testing.assert_array_equal(g.uv_px[:, :, 0], g.indices)
    np.testing.assert_array_equal(loc.uv_px[:, :, 1], 2 * loc.indices)
    np.testing.assert_allclose(g.z_m, 0.01 * g.indices, rtol=1e-6)
    np.testing.assert_array_equal(loc.gripper_closed, loc.indices >= 20)
    assert global_labels(track, SMALL).indices.tolist() == g.indices.tolist()
    assert local_labels(track, SMALL).indices.tolist() == loc.indices.tolist()


def test_default_stride_lands_in_every_gripper_pause():
    """n_g = 4 puts at least one global point inside any 5-step pause wherever the window starts."""
    cfg = TrajectoryWindowConfig()
    T = 100
    table = global_index_table(T, cfg)
    for start in range(0, T - 5):
        pause = set(range(start, start + 5))
        for t in range(T):
            idx = set(table[t].tolist())
            if min(idx) <= start and max(idx) >= start + 4:
                assert idx & pause, (start, t)


def test_bad_track_refused():
    with pytest.raises(DatasetError):
        make_track(np.zeros((5, 3)), np.zeros(5), np.zeros(5))
    with pytest.raises(DatasetError):
        make_track(np.zeros((5, 2)), np.zeros(4), np.zeros(5))
    with pytest.raises(DatasetError):
        make_track(np.full((5, 2), np.nan), np.zeros(5), np.zeros(5))


EVENTS = TrajectoryWindowConfig(L_g=9, L_l=3, n_l=2, global_spacing="events", points_per_segment=2)


def _line_track(T: int, closed):
    """Constant-speed straight track (1 cm per sample): path length == sample index."""
    x = 0.01 * np.arange(T, dtype=float)
    return np.c_[x, np.zeros(T), np.zeros(T)], np.asarray(closed, bool)


def test_event_window_hand_computed():
    # 21 samples, gripper closes at sample 8 and opens at 14: pieces 0..8, 8..14, 14..20
    xyz, g = _line_track(21, [False] * 8 + [True] * 6 + [False] * 7)
    table = event_index_table(xyz, g, EVENTS)
    # t = 0: the middle point is t; 2 points per piece at path fractions 1/2 and 1, each piece ending on the
    # switch sample (the first one with the new bit); past points clamp to sample 0
    assert table[0].tolist() == [0, 0, 0, 0, 0, 4, 8, 11, 14]
    # t = 10, inside the grasp: the rest of piece 10..14, then 14..20, then clamped at the last sample; the past
    # half runs backwards (10 -> 7 -> 0) and its pieces end on the last sample with the old bit (7, before 8)
    assert table[10].tolist() == [0, 3, 7, 8, 10, 12, 14, 17, 20]
    # t = 20: nothing ahead; backwards 20 -> 13 (the sample before the opening at 14) -> 7
    assert table[20].tolist() == [7, 10, 13, 16, 20, 20, 20, 20, 20]


def test_event_window_ends_each_piece_on_its_switch_whatever_the_speed():
    rng = np.random.default_rng(0)
    T = 80
    xyz = np.cumsum(rng.uniform(0.0, 0.02, (T, 3)), axis=0)  # uneven speed
    g = np.zeros(T, bool)
    g[20:45] = True
    g[60:] = True
    cfg = TrajectoryWindowConfig(L_g=51, global_spacing="events", points_per_segment=6)
    table = event_index_table(xyz, g, cfg)
    assert table.shape == (T, 51) and table.min() >= 0 and table.max() == T - 1
    h = cfg.global_center
    assert (table[:, h] == np.arange(T)).all()
    assert table[0, h + 1:].tolist()[5::6][:3] == [20, 45, 60]  # every 6th future point is a switch sample
    assert (np.diff(table, axis=1) >= 0).all()  # time runs forward through every window
    track = make_track(np.zeros((T, 2)), xyz[:, 2], g, xyz)
    labels = global_labels(track, cfg)
    np.testing.assert_array_equal(labels.gripper_closed, g[table])


def test_event_windows_need_the_track():
    xyz, g = _line_track(10, [False] * 10)
    with pytest.raises(ConfigError, match="global_spacing = 'time'.*global_labels"):
        global_index_table(10, EVENTS)
    with pytest.raises(DatasetError, match="xyz_m"):
        global_labels(make_track(np.zeros((10, 2)), np.zeros(10), g), EVENTS)
    with pytest.raises(ConfigError, match="global_spacing = 'distance' is not valid; choose one of time, events"):
        TrajectoryWindowConfig(global_spacing="distance")
    with pytest.raises(DatasetError, match="xyz_m"):
        make_track(np.zeros((10, 2)), np.zeros(10), g, np.zeros((9, 3)))
    with pytest.raises(ConfigError, match="points_per_segment = 6 must be <= L_g // 2 = 4"):
        TrajectoryWindowConfig(L_g=9, global_spacing="events", points_per_segment=6)


def test_event_window_through_a_pause_and_back_to_back_switches():
    # the arm holds still at samples 4-7 (the gripper closes at 6) and the gripper opens again at once at 7
    x = 0.01 * np.array([0, 1, 2, 3, 4, 4, 4, 4, 5, 6, 7, 8], dtype=float)
    xyz = np.c_[x, np.zeros(12), np.zeros(12)]
    g = np.array([0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0], bool)
    table = event_index_table(xyz, g, EVENTS)
    # piece 0..6 has length 4 cm: its middle is the first sample at 2 cm; the zero-length piece 6..7 gives 6, 7
    assert table[0, 5:].tolist() == [2, 6, 6, 7]
    assert table[6, 5:].tolist() == [6, 7, 9, 11]  # at the grasp sample itself: the hold piece, then the rest


def test_corner_points_keep_a_short_stroke_that_length_fractions_cut_across():
    # one closed piece: down 4 cm, a 3 cm sideways push at the bottom, then a 30 cm climb away (1 cm a sample)
    down = [(0.0, 0.0, 0.04 - 0.01 * i) for i in range(5)]
    push = [(0.0, 0.01 * i, 0.0) for i in range(1, 4)]
    climb = [(0.0, 0.03, 0.01 * i) for i in range(1, 31)]
    xyz = np.array(down + push + climb)
    T = len(xyz)
    g = np.array([True] * (T - 1) + [False])  # the piece ends on the release at the last sample
    g[0] = False  # closed from sample 1 on: piece 1..T-1
    length = TrajectoryWindowConfig(L_g=9, global_spacing="events", points_per_segment=3)
    corners = TrajectoryWindowConfig(L_g=9, global_spacing="events", points_per_segment=3, segment_points="corners")
    t = 1
    by_length = event_index_table(xyz, g, length)[t, 5:8].tolist()
    by_corner = event_index_table(xyz, g, corners)[t, 5:8].tolist()
    assert by_corner == [4, 7, T - 1]  # the bottom and the push's end, then the switch sample
    assert by_length[-1] == T - 1 and 4 not in by_length and 7 not in by_length  # equal fractions miss both
    # every window still ends each piece on its switch and runs forward in time
    table = event_index_table(xyz, g, corners)
    assert (np.diff(table, axis=1) >= 0).all() and (table[:, 4] == np.arange(T)).all()
    # a straight piece: no corner, the points halve the longest stretch instead (as length fractions would)
    line, gl = _line_track(13, [False] * 13)
    straight = TrajectoryWindowConfig(L_g=9, global_spacing="events", points_per_segment=4, segment_points="corners")
    assert event_index_table(line, gl, straight)[0, 5:].tolist() == [3, 6, 9, 12]
    with pytest.raises(ConfigError, match="segment_points = 'corner' is not valid; choose one of length, corners"):
        TrajectoryWindowConfig(segment_points="corner")


def test_windows_from_checkpoint_metadata():
    old = {"L_g": 51, "n_g": 4, "L_l": 8, "n_l": 2}  # written before event spacing existed: eq. 4 windows
    assert windows_from_meta(old) == TrajectoryWindowConfig()
    new = {**old, "global_spacing": "events", "points_per_segment": 5}  # before segment_points: length fractions
    assert windows_from_meta(new) == TrajectoryWindowConfig(global_spacing="events", points_per_segment=5)
    assert windows_from_meta({**new, "segment_points": "corners"}).segment_points == "corners"
    with pytest.raises(ConfigError, match="lack n_g, L_l, n_l"):
        windows_from_meta({"L_g": 51})
    with pytest.raises(ConfigError, match="lack points_per_segment"):  # never a silent 6 for an event checkpoint
        windows_from_meta({**old, "global_spacing": "events"})
    with pytest.raises(ConfigError, match="L_g"):  # a float is refused, not truncated
        windows_from_meta({**old, "L_g": 51.9})
    with pytest.raises(ConfigError, match="global_spacing = 'event' is not valid; choose one of time, events"):
        windows_from_meta({**old, "global_spacing": "event", "points_per_segment": 6})
    assert windows_from_meta(old).local_path == "observed"  # written before local_path existed
    assert windows_from_meta({**old, "local_path": "commanded"}).local_path == "commanded"
    with pytest.raises(ConfigError, match="local_path = 'command' is not valid; choose one of observed, commanded"):
        windows_from_meta({**old, "local_path": "command"})
