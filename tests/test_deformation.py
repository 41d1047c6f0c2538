"""Landmark-guided mesh deformation (§3.3, §6): the networks, the data pairs, the splits, training,
the per-vertex error and ``deform``."""
import numpy as np
import pytest
import torch

from facelib import config, deformation, training
from facelib.face import template as tpl
from facelib.models import coma, deformer

V = tpl.get_template().num_vertices


@pytest.fixture(scope="module")
def test_pairs():
    _, test = deformation.split_datasets("identity")
    return deformation.make_pairs(test.subset(np.arange(0, len(test), 40)), frames_per_sequence=5)


@pytest.mark.parametrize("method", list(deformation.METHODS))
def test_every_method_maps_a_mesh_and_landmark_motion_to_displacements(method):
    torch.manual_seed(0)
    model = deformation.build_model(method)
    neutral = model.template[None] + torch.randn(2, V, 3)
    out = model(neutral, torch.randn(2, 3, 68, 3))
    assert out.shape == (2, 3, V, 3) and torch.isfinite(out).all()


def test_identity_enters_only_through_lambda_theta():
    # z = lambda_theta z_id + Delta L: with lambda_theta = 0 the network is S2D and ignores the mesh
    torch.manual_seed(0)
    model = deformation.build_model("ours").eval()
    delta = torch.randn(1, 2, 68, 3)
    a, b = (model.template[None] + 3 * torch.randn(1, V, 3) for _ in range(2))
    with torch.no_grad():
        assert (model(a, delta) - model(b, delta)).abs().max() > 1e-4
        model.identity_weight.fill_(0.0)
        torch.testing.assert_close(model(a, delta), model(b, delta))


def test_cross_attention_weights_are_a_distribution_over_coarse_vertices():
    torch.manual_seed(0)
    model = deformation.build_model("ours")
    features = model.encode(model.template[None].expand(2, -1, -1))
    attended, weights = model.attend(features, torch.randn(2, 5, 68, 3))
    assert weights.shape == (2, 5, 80) and attended.shape == (2, 5, features.shape[-1])
    torch.testing.assert_close(weights.sum(-1), torch.ones(2, 5))


def test_chebyshev_layer_is_the_polynomial_filter():
    torch.manual_seed(0)
    conv = coma.ChebConv(2, 3, level=3, order=4).double()
    lap = coma.scaled_laplacian(3).to_dense().double()
    x = torch.randn(1, len(lap), 2, dtype=torch.float64)
    t = [x[0], lap @ x[0]]
    for _ in range(2):
        t.append(2 * lap @ t[-1] - t[-2])
    theta = conv.layer.weight.reshape(3, 2, 4)  # (out, in, k): inputs are stacked as (channel, order)
    manual = sum(t[k] @ theta[:, :, k].T for k in range(4)) + conv.layer.bias
    torch.testing.assert_close(conv(x)[0], manual)
    eig = torch.linalg.eigvalsh(lap)
    assert eig.min() >= -1 - 1e-6 and eig.max() <= 1 + 1e-6  # the scaled Laplacian's spectrum lies in [-1, 1]


def test_loss_weights_keep_every_vertex_and_peak_at_the_landmarks():
    w = deformation.loss_weights().numpy()
    assert w.shape == (V,) and w.min() > 0 and w.max() == pytest.approx(1.0)
    np.testing.assert_allclose(w[tpl.get_template().landmark_index], 1.0)
    target = torch.randn(1, 2, V, 3)
    assert deformer.deformation_loss(target, target, torch.as_tensor(w)) == 0
    assert deformer.deformation_loss(target + 0.1, target, torch.as_tensor(w)) > 0


def test_pairs_are_consistent_with_the_landmarks(test_pairs):
    p = test_pairs
    assert p.delta_mesh.shape[1:] == (5, V, 3) and p.delta_landmarks.shape[1:] == (5, 68, 3)
    np.testing.assert_array_equal(p.frames[0], [0, 10, 20, 29, 39])  # evenly spaced for evaluation
    # the mesh displacement at the landmark vertices is Delta L up to the 0.2 mm capture noise
    at_landmarks = p.delta_mesh[:, :, tpl.get_template().landmark_index]
    residual = at_landmarks - p.delta_landmarks
    assert residual.std() == pytest.approx(0.2, abs=0.02) and abs(residual.mean()) < 0.01
    assert np.abs(p.delta_mesh).max() > 3  # something moves by millimetres


def test_splits_hold_out_subjects_or_expressions():
    train, test = deformation.split_datasets("identity")
    held_out_faces = sum(config.DATASETS[d].num_test_subjects for d in config.DEFORMATION_DATASET.split("+"))
    assert not set(train.subjects) & set(test.subjects) and len(set(test.subjects)) == held_out_faces
    train, test = deformation.split_datasets("expression")
    held = {train.label_names.index(y) for y in deformation.HELD_OUT_EXPRESSIONS}
    assert set(test.labels) == held and not held & set(train.labels)
    assert set(test.subjects) <= set(train.subjects)
    with pytest.raises(ValueError, match="unknown split 'subject'; allowed: identity, expression"):
        deformation.split_datasets("subject")


def test_short_training_learns_and_is_deterministic(test_pairs):
    recipe = training.recipe("deformer", fast=True, method="ours")
    model, history = training.fit(recipe, progress=False, log_every=5)
    _, again = training.fit(recipe, progress=False, log_every=5)
    assert history["loss"] == again["loss"]
    assert history["loss"][-1] < 0.8 * history["loss"][0]
    result = deformation.evaluate(model, test_pairs)
    assert result["per_vertex"].shape == (V,) and 0 < result["mean"] and result["std"] > 0
    with pytest.raises(ValueError, match=r"method must be one of \('ours', 'no_attention', 's2d', 'coma', 'linear'\), got 'flame'"):
        training.recipe("deformer", method="flame")


def test_deform_checks_its_inputs_and_returns_meshes():
    torch.manual_seed(0)
    model = deformation.build_model("s2d").eval()
    neutral = tpl.get_template().vertices
    landmarks = np.repeat(neutral[tpl.get_template().landmark_index][None], 4, 0)
    meshes = deformation.deform(neutral, landmarks, model=model)
    assert meshes.shape == (4, V, 3) and meshes.dtype == np.float32
    again = meshes.copy()  # the mouth-interior rows sit between the inner lips, as the world places them
    np.testing.assert_allclose(tpl.place_mouth_band(again, tpl.get_template()), meshes, atol=1e-5)
    with pytest.raises(ValueError, match=f"has 100 vertices; the template topology has {V}"):
        deformation.deform(neutral[:100], landmarks, model=model)
    bad = neutral.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="1 non-finite vertices"):
        deformation.deform(bad, landmarks, model=model)
    with pytest.raises(ValueError, match=r"must be \(F, 68, 3\)"):
        deformation.deform(neutral, landmarks[:, :60], model=model)
    nan_landmarks = landmarks.copy()
    nan_landmarks[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        deformation.deform(neutral, nan_landmarks, model=model)


@pytest.mark.parametrize("split", deformation.SPLITS)
def test_shipped_deformers_load_and_predict_far_better_than_no_motion(split):
    _, test = deformation.split_datasets(split)
    pairs = deformation.make_pairs(test.subset(np.arange(0, len(test), 25)), frames_per_sequence=4)
    no_motion = np.linalg.norm(pairs.delta_mesh, axis=-1).mean()
    for method in deformation.METHODS:
        model = deformation.load_deformer(method, split)
        assert model.meta["split"] == split and model.meta["method"] == method
        assert deformation.evaluate(model, pairs)["mean"] < 0.6 * no_motion, method


def test_a_checkpoint_of_another_method_is_refused():
    for other in ("s2d", "linear"):  # the same network class, and another one
        with pytest.raises(ValueError, match=f"holds method 'ours', not '{other}'"):
            deformation.load_deformer(other, checkpoint="deform_ours_identity")


def test_noise_free_pairs_are_the_worlds_exact_landmarks_and_captured_ones_differ_by_the_capture_noise(test_pairs):
    _, test = deformation.split_datasets("identity")
    exact = deformation.make_pairs(test.subset(np.arange(0, len(test), 40)), frames_per_sequence=5, noise_free=True)
    np.testing.assert_array_equal(exact.delta_mesh, test_pairs.delta_mesh)
    noise = (test_pairs.delta_landmarks - exact.delta_landmarks).std()
    assert 0.15 < noise < 0.25  # Timing.noise_mm = 0.2
    np.testing.assert_array_equal(exact.subjects, test_pairs.subjects)
    np.testing.assert_array_equal(test_pairs.noise_free().delta_landmarks, exact.delta_landmarks)
    # the exact Delta L_f is the world's own landmark function, evaluated independently here
    first = test.subset([0])
    face, w = first.face(int(first.subjects[0])), first.au_weights[0, exact.frames[0]].astype(np.float64)
    truth = face.landmarks(w) - face.landmarks(np.zeros_like(w[0]))
    np.testing.assert_allclose(exact.delta_landmarks[0], truth, atol=1e-4)


def test_the_closed_form_regression_recovers_an_exactly_linear_world(test_pairs):
    rng = np.random.default_rng(0)
    truth = rng.standard_normal((205, V * 3)).astype(np.float32) * 0.01
    fake = deformation.Pairs(test_pairs.neutral, test_pairs.delta_landmarks, None, test_pairs.frames,
                             test_pairs.labels, test_pairs.subjects)
    fake.delta_mesh = (deformation.motion_features(fake) @ truth).reshape(*fake.delta_landmarks.shape[:2], V, 3)
    coef = deformation.fit_linear_regression(fake, penalty=1e-6)
    assert deformation.linear_regression_errors(coef, fake).max() < 1e-3


def test_a_regression_on_identity_interactions_recovers_a_map_that_changes_with_the_face(test_pairs):
    """Delta M = [Delta L, 1] (A + sum_k c_k B_k), with c the face's standardised identity coefficients: built
    here per sequence, independently of identity_features, which must make it linear again."""
    rng = np.random.default_rng(1)
    n, k = len(test_pairs), 2
    coeffs = rng.standard_normal((n, k)) * 3.0 + 1.0
    c = (coeffs - coeffs.mean(0)) / coeffs.std(0)
    a, b = (rng.standard_normal((m, 205, V * 3)).astype(np.float32) * 0.01 for m in (1, k))
    fake = deformation.Pairs(test_pairs.neutral, test_pairs.delta_landmarks, None, test_pairs.frames,
                             test_pairs.labels, test_pairs.subjects)
    base = deformation.motion_features(fake).reshape(n, -1, 205)
    fake.delta_mesh = np.stack([base[i] @ (a[0] + np.tensordot(c[i], b, 1)) for i in range(n)]).reshape(
        *fake.delta_landmarks.shape[:2], V, 3)
    x = deformation.identity_features(fake, coeffs, coeffs)
    assert x.shape == (base.shape[0] * base.shape[1], 205 * (1 + k))
    np.testing.assert_allclose(x[:, :205], base.reshape(-1, 205))
    np.testing.assert_allclose(x[0, 205 + 3 * k + 1], base[0, 0, 3] * c[0, 1], rtol=1e-5)  # feature 3 x c_1
    coef = deformation.fit_linear_regression(fake, penalty=1e-6, features=x)
    assert deformation.linear_regression_errors(coef, fake, features=x).max() < 1e-2


def test_attention_entropy_is_between_zero_and_uniform_and_refused_without_attention(test_pairs):
    torch.manual_seed(0)
    model = deformation.build_model("ours").eval()
    h = deformation.attention_entropy(model, test_pairs)
    w = deformation.attention_weights(model, test_pairs)
    assert w.shape == (*test_pairs.delta_landmarks.shape[:2], model.num_coarse)
    assert np.allclose(w.sum(-1), 1, atol=1e-5) and h.shape == test_pairs.delta_landmarks.shape[:2]
    assert np.all(h >= 0) and np.all(h <= np.log(model.num_coarse) + 1e-5)
    for other in ("no_attention", "s2d"):
        with pytest.raises(ValueError, match="does not attend to the face"):
            deformation.attention_entropy(deformation.build_model(other), test_pairs)


def test_paired_differences_are_taken_per_face_and_seed_summaries_use_the_sample_std():
    subjects = np.array([0, 0, 1, 1, 2, 2])
    a = np.ones((6, 2, 3)) * np.array([1, 1, 2, 2, 3, 3])[:, None, None]
    faces, means = deformation.per_face(a, subjects)
    assert faces.tolist() == [0, 1, 2] and means.tolist() == [1, 2, 3]
    diff, (low, high) = deformation.paired_difference(a + 0.5, a, subjects)
    assert diff == pytest.approx(0.5) and low == pytest.approx(0.5) and high == pytest.approx(0.5)
    assert deformation.over_seeds([1.0, 2.0, 3.0]) == (2.0, 1.0) and deformation.over_seeds([4.0]) == (4.0, 0.0)
