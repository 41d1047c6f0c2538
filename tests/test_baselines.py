"""The related papers' baselines: SRVF geometry (Motion3DGAN) and the generators of Table 1, the BiLSTM filler of
Table 3 (Berson et al.) and the MotionCLIP-style decoder of Table 2."""

import numpy as np
import pytest
import torch

from facelib import baselines, evaluation, inpainting, metrics, srvf, training
from facelib.models.lstm_filler import masked_l1
from facelib.training.recipes import random_masks


def test_srvf_round_trip_and_unit_norm(coma_train):
    motion = torch.as_tensor(coma_train.landmarks[:4]).flatten(2).double()
    q, length = srvf.to_srvf(motion)
    assert torch.allclose(srvf.norm(q), torch.ones(4, dtype=torch.float64))
    back = srvf.from_srvf(q, motion[:, 0], length)
    assert torch.allclose(back, motion, atol=1e-9)
    # ||q||^2 before normalisation is the arc length of the motion
    arc = torch.diff(motion, dim=1).norm(dim=-1).sum(1)
    assert torch.allclose(length, arc, rtol=1e-9)


def test_log_and_exp_maps_are_inverse_and_the_reference_must_be_renormalised(coma_train):
    q, _ = srvf.to_srvf(torch.as_tensor(coma_train.landmarks[:50]).flatten(2).double())
    plain_mean = q.mean(0)
    assert srvf.norm(plain_mean) < 0.95  # the plain mean is not on the sphere
    p = srvf.reference_point(q)
    assert srvf.norm(p) == pytest.approx(1.0)
    s = srvf.log_map(q, p)
    assert torch.allclose(srvf.inner(s, p), torch.zeros(50, dtype=torch.float64), atol=1e-9)  # tangent at p
    assert torch.allclose(srvf.exp_map(s, p), q, atol=1e-7)
    assert torch.allclose(srvf.norm(s), torch.arccos(srvf.inner(q, p)), atol=1e-7)  # geodesic distance


@pytest.mark.parametrize("name", ["motion3dgan", "actor"])
def test_shipped_baselines_generate_deterministically(name):
    model = baselines.load_baseline(name, "coma")
    a = baselines.generate(model, ["high_smile", "mouth_open", "eyebrow"], seed=1)
    b = baselines.generate(model, ["high_smile", "mouth_open", "eyebrow"], seed=1)
    assert a.shape == (3, 40, 68, 3) and a.dtype == np.float32 and np.array_equal(a, b)
    assert np.isfinite(a).all()
    with pytest.raises(ValueError, match="allowed: bareteeth"):
        baselines.generate(model, ["happy"])


@pytest.mark.parametrize("name", ["motion3dgan", "actor"])
def test_baseline_training_writes_a_loadable_checkpoint(tmp_path, name):
    out = tmp_path / f"{name}_tiny"
    training.train_and_save(training.recipe(name, dataset="bu", steps=3), name=str(out), progress=False)
    model = baselines.load_baseline(name, "bu", checkpoint=str(out))
    assert baselines.generate(model, ["happy", "sad"]).shape == (2, 40, 68, 3)
    with pytest.raises(ValueError, match="generates"):
        baselines.load_baseline(name, "coma", checkpoint=str(out))  # trained on bu: other labels
    with pytest.raises(ValueError, match="unknown baseline"):
        baselines.load_baseline("gan", "coma")


def test_temporal_smoothing_keeps_straight_motions_and_removes_jitter():
    from facelib.models.motion3dgan import smooth_in_time
    frames = torch.arange(40, dtype=torch.float64)
    line = (frames[None, :, None] * torch.tensor([0.5, -1.0, 2.0], dtype=torch.float64)).expand(2, -1, -1)
    assert torch.allclose(smooth_in_time(line, 1.0)[:, 3:-3], line[:, 3:-3])  # linear in time: unchanged
    assert torch.equal(smooth_in_time(line, 0.0), line)
    jitter = torch.randn(4, 40, 6, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    smoothed = smooth_in_time(jitter, 1.0)
    assert smoothed.shape == jitter.shape and smoothed.std() < 0.6 * jitter.std()


def test_shipped_actor_follows_the_requested_label():
    ev = evaluation.load_evaluator("coma")
    labels = [y for y in ev.class_names for _ in range(10)]
    x = baselines.generate(baselines.load_baseline("actor", "coma"), labels, seed=1)
    accuracy = ev.score(x, [ev.class_index(y) for y in labels])["accuracy"]
    assert accuracy > 2 * 100 / len(ev.class_names)  # well above chance (the book reports the value)


def test_masked_l1_is_berson_eq_1_and_training_masks_mix_layouts():
    pred, target = torch.zeros(1, 4, 68, 3), torch.ones(1, 4, 68, 3)
    target[:, 2:] = 3.0
    known = torch.tensor([[True, True, False, False]])
    assert masked_l1(pred, target, known, alpha_gt=10.0).item() == pytest.approx(10 * 1.0 + 3.0)
    masks = random_masks(400, 40, torch.Generator().manual_seed(0))
    assert masks.shape == (400, 40) and masks.any(1).all() and (~masks).any(1).all()
    assert len({tuple(m.tolist()) for m in masks}) > 100


def test_lstm_filler_keeps_known_frames(coma_test):
    known = inpainting.fill_masks("FFE", 4, 40, seed=0)
    out = baselines.lstm_fill(coma_test.landmarks[:4], known)
    assert out.shape == (4, 40, 68, 3) and np.isfinite(out).all()
    assert np.array_equal(out[known], coma_test.landmarks[:4][known])
    # it does better than holding the last known frame on the missing ones
    hold = inpainting.linear_interpolation(coma_test.landmarks[:4], known)
    assert metrics.missing_frame_error(out, coma_test.landmarks[:4], known) < 2 * metrics.missing_frame_error(
        hold, coma_test.landmarks[:4], known)


def test_motionclip_baseline_is_deterministic():
    model = baselines.load_baseline("motionclip", "coma+bu")
    a = baselines.generate_from_text(model, ["disgust high smile", "sad"])
    b = baselines.generate_from_text(model, ["disgust high smile", "sad"])
    assert a.shape == (2, 40, 68, 3) and a.dtype == np.float32 and np.array_equal(a, b)
    assert not np.allclose(a[0], a[1])  # the text changes the motion
    with pytest.raises(ValueError, match="empty"):
        baselines.generate_from_text(model, [""])


def test_the_baselines_have_the_denoisers_parameter_budget_within_30_percent():
    g = torch.Generator().manual_seed(0)
    count = lambda m: sum(p.numel() for p in m.parameters())  # noqa: E731
    build = lambda name: training.recipe(name, fast=True).build(g)  # noqa: E731
    actor = build("actor")
    denoiser, actor_decoder, gan_generator = (count(build("denoiser")), count(actor.decoder) + count(actor.out),
                                              count(build("motion3dgan").generator))
    assert 0.7 < actor_decoder / denoiser < 1.3 and 0.7 < gan_generator / denoiser < 1.3
