"""The planner network and the instruction vocabulary: shapes, ranges, conditioning, read-out, config checks."""
import dataclasses

import numpy as np
import pytest
import torch

from tcot_hybrid.errors import ConfigError, PlanningError
from tcot_hybrid.learning.model import ModelConfig, PlannerNet, count_parameters, widened_source
from tcot_hybrid.learning.vocab import Vocabulary


def _inputs(b=3, vocab=10):
    g = torch.Generator().manual_seed(0)
    return (torch.rand(b, 3, 128, 128, generator=g), torch.randint(1, vocab, (b, 24), generator=g),
            torch.tensor([0, 1, 2][:b]), torch.randn(b, 8, generator=g))


def test_trajectory_outputs_shapes_and_ranges():
    m = PlannerNet(ModelConfig(vocab_size=10, width=8)).eval()
    with torch.inference_mode():
        o = m(*_inputs())
    assert o["uv_px"].shape == (3, 60, 2) and o["z_m"].shape == (3, 60)
    assert o["grip_logit"].shape == (3, 60) and o["success_logit"].shape == (3,)
    uv = o["uv_px"]
    assert (uv >= -0.5).all() and (uv <= 127.5).all()  # soft-argmax never leaves the image
    assert torch.isfinite(o["z_m"]).all()
    with torch.inference_mode():  # the detector's fast path: same pooled outputs, no waypoint decoder
        d = m(*_inputs(), waypoints=False)
    assert set(d) == {"grip_logit", "success_logit"}
    assert torch.equal(d["success_logit"], o["success_logit"]) and torch.equal(d["grip_logit"], o["grip_logit"])


@pytest.mark.parametrize("rot_head,radius", [(False, 0), (True, 0), (True, 2)])
def test_a_waypoint_slice_computes_exactly_those_waypoints(rot_head, radius):
    m = PlannerNet(ModelConfig(vocab_size=10, width=8, rot_head=rot_head, readout_radius_cells=radius)).eval()
    with torch.no_grad():  # random maps: give the heads a non-trivial spread
        m.maps.bias.copy_(torch.randn(m.maps.bias.shape, generator=torch.Generator().manual_seed(1)))
    with torch.inference_mode():
        full = m(*_inputs())
        for sl in (slice(25, 51), slice(51, 60), slice(7, 8)):
            part = m(*_inputs(), waypoints=sl)
            n = len(range(60)[sl])
            assert part["uv_px"].shape == (3, n, 2) and part["grip_logit"].shape == (3, n)
            for k in ("uv_px", "z_m", "grip_logit", "heat_logits") + (("rot6",) if rot_head else ()):
                torch.testing.assert_close(part[k], full[k][:, sl], rtol=1e-5, atol=1e-5)
            assert torch.equal(part["success_logit"], full["success_logit"])


def test_widened_source_keeps_the_old_window_and_repeats_its_pieces():
    src = widened_source(97, 51, 9, 6)
    assert len(src) == 97 + 9 and list(src[97:]) == list(range(51, 60))  # local waypoints map to themselves
    assert list(src[48 - 25:48 + 26]) == list(range(51))  # the old window's offsets keep their waypoint
    # past the old window: the same place in an earlier whole piece (4 pieces of 6 in the old half)
    assert src[48 + 26] == 25 + 2 and src[48 + 31] == 25 + 7 and src[48 + 48] == 25 + 24
    assert src[48 - 26] == 25 - 2 and src[0] == 25 - 24
    with pytest.raises(ValueError, match="n_global .*> n_global_old"):
        widened_source(51, 51, 9, 6)
    with pytest.raises(ValueError, match="whole piece"):
        widened_source(21, 11, 9, 6)


@pytest.mark.parametrize("rot_head", [False, True])
def test_a_widened_network_repeats_the_old_waypoints_outputs(rot_head):
    old = PlannerNet(ModelConfig(vocab_size=10, width=8, n_global=25, n_local=5, rot_head=rot_head)).eval()
    with torch.no_grad():  # random maps and grip logits: every waypoint's outputs differ
        old.maps.bias.copy_(torch.randn(old.maps.bias.shape, generator=torch.Generator().manual_seed(1)))
        old.pooled_head[2].bias.copy_(torch.randn(old.pooled_head[2].bias.shape,
                                                  generator=torch.Generator().manual_seed(2)))
    new = PlannerNet(dataclasses.replace(old.cfg, n_global=41)).eval()
    new.load_widened(old, points_per_segment=4)
    src = torch.as_tensor(widened_source(41, 25, 5, 4))
    with torch.inference_mode():
        a, b = old(*_inputs()), new(*_inputs())
    for k in ("uv_px", "z_m", "grip_logit", "heat_logits") + (("rot6",) if rot_head else ()):
        torch.testing.assert_close(b[k], a[k][:, src], rtol=1e-5, atol=1e-5)
    assert torch.equal(a["success_logit"], b["success_logit"])
    with pytest.raises(ValueError, match="does not widen"):
        PlannerNet(dataclasses.replace(old.cfg, n_global=41, width=16)).load_widened(old, points_per_segment=4)


def test_a_waypoint_slice_needs_the_heatmap_head():
    f = PlannerNet(ModelConfig(head="fc", vocab_size=10, width=8)).eval()
    with torch.inference_mode(), pytest.raises(ValueError, match="heatmap"):
        f(*_inputs(), waypoints=slice(0, 5))


def test_direct_and_fc_variants():
    d = PlannerNet(ModelConfig(kind="direct", vocab_size=10, width=8)).eval()
    with torch.inference_mode():
        o = d(*_inputs())
    assert o["delta_m"].shape == (3, 3) and o["grip_logit"].shape == (3, 1)
    f = PlannerNet(ModelConfig(head="fc", vocab_size=10, width=8)).eval()
    with torch.inference_mode():
        assert f(*_inputs())["uv_px"].shape == (3, 60, 2)
    assert count_parameters(f) > count_parameters(PlannerNet(ModelConfig(vocab_size=10, width=8)))


def test_conditioning_changes_the_heatmaps():
    torch.manual_seed(0)
    m = PlannerNet(ModelConfig(vocab_size=10, width=8)).eval()
    for mod in m.modules():  # FiLM starts as identity; give it weight so conditioning shows
        if mod.__class__.__name__ == "FiLM":
            torch.nn.init.normal_(mod.lin.weight, std=0.5)
    img, tok, _, prop = _inputs(2)
    img = img[:1].expand(2, -1, -1, -1)
    prop = prop[:1].expand(2, -1)
    with torch.inference_mode():
        a = m(img, tok[:1].expand(2, -1), torch.tensor([0, 1]), prop)  # same everything, other prompt
        b = m(img, torch.stack([tok[0], tok[1]]), torch.tensor([0, 0]), prop)  # other instruction
    assert not torch.allclose(a["uv_px"][0], a["uv_px"][1])
    assert not torch.allclose(b["uv_px"][0], b["uv_px"][1])


def test_local_readout_picks_one_mode():
    cfg = ModelConfig(vocab_size=10, width=8)
    m = PlannerNet(cfg).eval()
    n = cfg.n_waypoints
    with torch.no_grad():  # two equal peaks far apart in every heatmap: (row 8, col 4) and (row 8, col 27)
        m.maps.weight.zero_()
        bias = torch.zeros(2 * n)
        m.maps.bias.copy_(bias)
    logits = torch.full((1, n, 32, 32), -30.0)
    logits[:, :, 8, 4] = 5.0
    logits[:, :, 8, 27] = 4.0
    orig = m.maps.forward
    m.maps.forward = lambda x: torch.cat([logits.expand(x.shape[0], -1, -1, -1),
                                          torch.zeros(x.shape[0], n, 32, 32)], 1)
    with torch.inference_mode():
        soft = m(*_inputs(1))["uv_px"][0, 0]
        m.cfg = dataclasses.replace(cfg, readout_radius_cells=2)
        local = m(*_inputs(1))["uv_px"][0, 0]
    m.maps.forward = orig
    assert 40 < soft[0] < 100  # the mean of two modes lies between them: a corner cut
    assert abs(local[0] - (4 * 4 + 1.5)) < 0.01 and abs(local[1] - (8 * 4 + 1.5)) < 0.01


def test_window_readout_matches_a_masked_soft_argmax_also_at_the_border():
    from tcot_hybrid.learning.model import window_readout

    g = torch.Generator().manual_seed(0)
    h, w, r = 8, 12, 2
    logits = torch.randn(2, 5, h * w, generator=g) * 3
    logits[0, 0, 0] = 50.0  # peak in a corner: the window is cut to 3 x 3 cells
    logits[1, 1, h * w - 2] = 50.0  # near the opposite corner
    values = torch.randn(2, 5, h * w, generator=g)
    prob = torch.softmax(logits, -1)
    u, v, z = window_readout(prob, values, h, w, r)
    cv, cu = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    cv, cu = cv.flatten(), cu.flatten()
    peak = prob.argmax(-1)
    near = ((cv - (peak // w)[..., None]).abs() <= r) & ((cu - (peak % w)[..., None]).abs() <= r)
    pm = prob * near
    pm = pm / pm.sum(-1, keepdim=True)
    assert torch.allclose(u, (pm * cu).sum(-1), atol=1e-5) and torch.allclose(v, (pm * cv).sum(-1), atol=1e-5)
    assert torch.allclose(z, (pm * values).sum(-1), atol=1e-5)
    assert u[0, 0] < 0.01 and v[0, 0] < 0.01 and abs(u[1, 1] - (w - 2)) < 0.01 and abs(v[1, 1] - (h - 1)) < 0.01


def test_model_config_validation():
    with pytest.raises(ConfigError, match="model.kind"):
        ModelConfig(kind="vla")
    with pytest.raises(ConfigError, match="multiple of 16"):
        ModelConfig(image_px=100)
    with pytest.raises(ConfigError, match="vocab_size"):
        ModelConfig(vocab_size=1)
    with pytest.raises(ConfigError, match="readout_radius_cells"):
        ModelConfig(readout_radius_cells=-1)


def test_vocabulary():
    v = Vocabulary.build(["Put the cube on the plate.", "open the drawer"])
    assert v.tokens[:2] == ("<pad>", "<unk>") and "cube" in v.tokens and "Put" not in v.tokens
    ids, n, unk = v.encode("put the BANANA on the plate", 8)
    assert n == 6 and unk == 1 and ids[2] == 1 and ids[6:].tolist() == [0, 0]
    assert np.array_equal(v.encode_checked("open the drawer!", 8, max_unknown_fraction=0.5),
                          v.encode("open the drawer", 8)[0])
    with pytest.raises(PlanningError, match="3 of 4 words"):
        v.encode_checked("please grab that drawer", 8, max_unknown_fraction=0.5)
    with pytest.raises(PlanningError, match="at most 2"):
        v.encode_checked("open the drawer", 2, max_unknown_fraction=0.5)
    with pytest.raises(ValueError):
        Vocabulary(("a", "b"))


def test_rotation_head_outputs_and_readouts_agree():
    """rot_head adds a 6D orientation per waypoint, read out with the heatmap's softmax like the height; the
    windowed read-out equals the full one when the window covers the map; the workcell's model has no such
    output and keeps its tensor names (old checkpoints load)."""
    m = PlannerNet(ModelConfig(vocab_size=10, width=8, rot_head=True)).eval()
    with torch.inference_mode():
        o = m(*_inputs())
    assert o["rot6"].shape == (3, 60, 6) and torch.isfinite(o["rot6"]).all()
    assert m.maps.out_channels == 8 * 60
    wide = PlannerNet(ModelConfig(vocab_size=10, width=8, rot_head=True, readout_radius_cells=40)).eval()
    wide.load_state_dict(m.state_dict())
    with torch.inference_mode():
        w = wide(*_inputs())
    torch.testing.assert_close(w["rot6"], o["rot6"], atol=1e-4, rtol=1e-4)
    torch.testing.assert_close(w["z_m"], o["z_m"], atol=1e-4, rtol=1e-4)
    plain = PlannerNet(ModelConfig(vocab_size=10, width=8)).eval()
    with torch.inference_mode():
        assert "rot6" not in plain(*_inputs())
    assert plain.maps.out_channels == 2 * 60
    with pytest.raises(ConfigError, match="rot_head needs kind 'trajectory' and head 'heatmap'"):
        ModelConfig(rot_head=True, head="fc")
    with pytest.raises(ConfigError, match="rot_head"):
        ModelConfig(rot_head=True, kind="direct")


def test_rot6_round_trip_and_gram_schmidt():
    from scipy.spatial.transform import Rotation

    from tcot_hybrid.learning.model import matrix_to_rot6, rot6_to_matrix

    R = Rotation.random(20, random_state=3).as_matrix()
    np.testing.assert_allclose(rot6_to_matrix(matrix_to_rot6(R)), R, atol=1e-12)
    noisy = matrix_to_rot6(R) * 1.7 + np.random.default_rng(0).normal(0, 0.05, (20, 6))
    Rn = rot6_to_matrix(noisy)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", Rn, Rn), np.broadcast_to(np.eye(3), (20, 3, 3)), atol=1e-12)
    assert (np.linalg.det(Rn) > 0.999).all()
    with pytest.raises(ValueError, match="parallel"):
        rot6_to_matrix(np.array([1.0, 0, 0, 2.0, 0, 0]))
    with pytest.raises(ValueError, match="not finite"):
        rot6_to_matrix(np.array([np.nan, 0, 0, 0, 1, 0]))


def test_orientation_loss_and_error_respect_the_parallel_jaw_symmetry():
    """A hand turned 180 degrees about its approach axis is the same grasp: the loss and the validation error of a
    prediction are the same against either label, and the loss stays a real distance otherwise."""
    from scipy.spatial.transform import Rotation

    from tcot_hybrid.learning.losses import trajectory_loss
    from tcot_hybrid.learning.model import matrix_to_rot6
    from tcot_hybrid.learning.validation import rotation_error_deg

    R = Rotation.random(8, random_state=0).as_matrix()
    turn = Rotation.from_rotvec([0.0, 0.0, 0.3]).as_matrix()  # 17 degrees about the approach axis
    pred, lab = matrix_to_rot6(R @ turn), matrix_to_rot6(R)
    flipped = matrix_to_rot6(R @ np.diag([-1.0, -1.0, 1.0]))
    np.testing.assert_allclose(rotation_error_deg(pred, lab), np.degrees(0.3), atol=1e-6)
    np.testing.assert_allclose(rotation_error_deg(pred, flipped), np.degrees(0.3), atol=1e-6)
    np.testing.assert_allclose(rotation_error_deg(matrix_to_rot6(R @ Rotation.from_rotvec([0, 0, 2.5]).as_matrix()), lab),
                               np.degrees(np.pi - 2.5), atol=1e-6)  # at most 90 degrees about the approach axis

    def loss(label):
        n = 8
        out = {"uv_px": torch.zeros(1, n, 2), "z_m": torch.zeros(1, n), "grip_logit": torch.zeros(1, n),
               "success_logit": torch.zeros(1), "rot6": torch.from_numpy(pred).float()[None]}
        b = {"mode": torch.zeros(1, dtype=torch.long), "uv": torch.zeros(1, n, 2), "z": torch.zeros(1, n),
             "grip": torch.zeros(1, n), "success": torch.zeros(1), "rot": torch.from_numpy(label).float()[None]}
        return trajectory_loss(out, b, n // 2)[1]["rot"].item()  # global prompt: the first half

    assert loss(flipped) == pytest.approx(loss(lab)) and loss(lab) > 0.5
    assert loss(matrix_to_rot6(R @ Rotation.from_rotvec([1.0, 0, 0]).as_matrix())) > loss(lab)  # a tilt is an error
