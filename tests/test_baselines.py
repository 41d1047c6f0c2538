"""The generative baselines of Table 1: SRVF geometry (Motion3DGAN) and the shipped generators."""
import numpy as np
import pytest
import torch

from facelib import baselines, srvf, training


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
    from facelib import evaluation
    ev = evaluation.load_evaluator("coma")
    labels = [y for y in ev.class_names for _ in range(10)]
    x = baselines.generate(baselines.load_baseline("actor", "coma"), labels, seed=1)
    accuracy = ev.score(x, [ev.class_index(y) for y in labels])["accuracy"]
    assert accuracy > 2 * 100 / len(ev.class_names)  # well above chance (the book reports the value)
