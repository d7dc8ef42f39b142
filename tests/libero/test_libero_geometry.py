"""The oracle's box geometry: the exact box-box overlap test the placement and clearance checks rely on."""
import numpy as np
from scipy.spatial.transform import Rotation

from tcot_hybrid.libero.geometry import Boxes, boxes_overlap


def box(centre, half, rot=None) -> Boxes:
    rot = np.eye(3) if rot is None else rot
    return Boxes(np.array([centre], float), np.array([rot], float), np.array([half], float), np.array([0]))


def test_a_thin_wall_across_a_box_middle_overlaps():
    # a book (11 cm long) lowered over an 8 mm divider: no corner of either box lies in the other
    book = box([0, 0, 0.05], [0.014, 0.055, 0.067])
    wall = box([0, 0.01, 0.0], [0.06, 0.004, 0.06])
    assert not wall.contains(book.centre + np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                                                     for sz in (-1, 1)]) * book.half).any()
    assert boxes_overlap(book, wall)[0, 0]
    assert not boxes_overlap(book, box([0, 0.01, -0.1], [0.06, 0.004, 0.03]))[0, 0]  # the wall lower down


def test_margin_grows_the_second_boxes():
    a = box([0, 0, 0], [0.01, 0.01, 0.01])
    b = box([0.025, 0, 0], [0.01, 0.01, 0.01])  # 5 mm apart
    assert not boxes_overlap(a, b, margin=0.004)[0, 0]
    assert boxes_overlap(a, b, margin=0.006)[0, 0]


def test_rotated_boxes_agree_with_dense_point_samples(rng):
    grid = np.stack(np.meshgrid(*[np.linspace(-1, 1, 21)] * 3), axis=-1).reshape(-1, 3)
    for _ in range(200):
        c = rng.uniform(-0.08, 0.08, (2, 3))
        half = rng.uniform(0.005, 0.06, (2, 3))
        rot = Rotation.random(2, random_state=int(rng.integers(1 << 30))).as_matrix()
        a, b = box(c[0], half[0], rot[0]), box(c[1], half[1], rot[1])
        sampled = (b.contains(c[0] + (grid * half[0]) @ rot[0].T).any()
                   or a.contains(c[1] + (grid * half[1]) @ rot[1].T).any())
        if sampled:  # a sample of one inside the other: they overlap
            assert boxes_overlap(a, b)[0, 0]
        # and the test is symmetric
        assert boxes_overlap(a, b)[0, 0] == boxes_overlap(b, a)[0, 0]


def test_separated_along_a_rotated_face_normal_is_no_overlap():
    rot = Rotation.from_euler("xyz", [0.3, -0.5, 0.9]).as_matrix()
    a = box([0, 0, 0], [0.02, 0.03, 0.04], rot)
    normal = rot[:, 1]
    b = box(normal * (0.03 + 0.02 + 0.001), [0.02, 0.02, 0.02], rot)  # 1 mm beyond a's face, same axes
    assert not boxes_overlap(a, b)[0, 0]
    assert boxes_overlap(a, b, margin=0.002)[0, 0]


def test_pairs_shape_and_empty_sets():
    many = Boxes(np.zeros((3, 3)), np.tile(np.eye(3), (3, 1, 1)), np.full((3, 3), 0.01), np.arange(3))
    empty = Boxes(np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0, int))
    assert boxes_overlap(many, many).shape == (3, 3) and boxes_overlap(many, many).all()
    assert boxes_overlap(many, empty).shape == (3, 0)
    assert boxes_overlap(empty, many).shape == (0, 3)
