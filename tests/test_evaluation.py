"""The evaluation protocol of §5: FID, diversity, multimodality, classifier types, the shipped ICs."""
import numpy as np
import pytest
import torch

from facelib import data, evaluation, metrics
from facelib.face.aus import AU_NAMES


def test_frechet_distance_matches_the_closed_form_for_gaussians(rng):
    # FID(N(m1, C1), N(m2, C2)) = |m1 - m2|^2 + tr(C1 + C2 - 2 (C1 C2)^1/2); diagonal case by hand.
    d, n = 4, 200_000
    s1, s2 = np.array([1.0, 2.0, 0.5, 1.5]), np.array([0.5, 1.0, 1.0, 3.0])
    m2 = np.array([1.0, -1.0, 0.0, 2.0])
    a = rng.normal(size=(n, d)) * s1
    b = m2 + rng.normal(size=(n, d)) * s2
    closed = (m2 ** 2).sum() + ((s1 - s2) ** 2).sum()
    assert metrics.frechet_distance(a, b) == pytest.approx(closed, rel=0.02)


def test_frechet_distance_is_zero_for_identical_sets_and_symmetric(rng):
    a, b = rng.normal(size=(500, 6)), rng.normal(size=(400, 6)) @ rng.normal(size=(6, 6))
    assert abs(metrics.frechet_distance(a, a)) < 1e-8
    assert metrics.frechet_distance(a, b) == pytest.approx(metrics.frechet_distance(b, a), rel=1e-6)


def test_frechet_distance_rejects_bad_input(rng):
    with pytest.raises(ValueError, match="same d"):
        metrics.frechet_distance(rng.normal(size=(10, 3)), rng.normal(size=(10, 4)))
    bad = rng.normal(size=(10, 3))
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        metrics.frechet_distance(bad, bad)


def test_diversity_and_multimodality_scale_with_the_features(rng):
    f = rng.normal(size=(100, 5))
    y = rng.integers(0, 4, 100)
    assert metrics.diversity(2 * f) == pytest.approx(2 * metrics.diversity(f))
    assert metrics.multimodality(3 * f, y) == pytest.approx(3 * metrics.multimodality(f, y))
    # features grouped tightly by label: multimodality far below diversity
    grouped = 10 * np.eye(4)[y] + 0.01 * f[:, :4]
    assert metrics.multimodality(grouped, y) < 0.01 * metrics.diversity(grouped)


def test_classifier_types(coma_train):
    names_i, names_s = coma_train.class_names("I"), coma_train.class_names("S")
    assert len(names_s) == 2 * len(names_i) == 24
    t_i, t_s = coma_train.targets("I"), coma_train.targets("S")
    assert np.array_equal(t_s // 2, t_i) and np.array_equal(t_s % 2, coma_train.kinds)
    assert names_s[t_s[0]].startswith(names_i[t_i[0]])
    with pytest.raises(ValueError, match="classifier type"):
        coma_train.targets("X")


def test_shipped_evaluators_give_the_ground_truth_row():
    ev = evaluation.load_evaluator("coma", "I")
    gt = ev.ground_truth()
    assert 70 < gt["accuracy"] <= 100 and gt["fid"] >= 0
    train = data.load_dataset("coma", "train")
    # the training set scored against itself: perfect FID, higher accuracy than the test set
    own = ev.score(train.landmarks, train.targets("I"))
    assert own["fid"] < 1e-6 and own["accuracy"] > gt["accuracy"]
    # a broken generator (frames shuffled in time) is recognised as worse on both columns
    shuffled = data.load_dataset("coma", "test")
    perm = np.random.default_rng(0).permutation(shuffled.landmarks.shape[1])
    bad = ev.score(shuffled.landmarks[:, perm], shuffled.targets("I"))
    assert bad["fid"] > gt["fid"] and bad["accuracy"] < gt["accuracy"]
    # any array layout is accepted: sequences played backwards are a negative-stride view
    backwards = shuffled.landmarks[:, ::-1]
    assert np.allclose(ev.features(backwards), ev.features(backwards.copy()))


def test_score_intervals_stay_in_range_and_hold_the_estimate():
    ev = evaluation.load_evaluator("coma", "I")
    train = data.load_dataset("coma", "train")
    # the training set against itself: FID 0 and accuracy near 100, where the bias-corrected
    # interval would cross the range of the statistic without clipping
    s = ev.score(train.landmarks, train.targets("I"), intervals=True, num_resamples=200)
    assert 0.0 <= s["accuracy_ci"][0] <= s["accuracy"] <= s["accuracy_ci"][1] <= 100.0
    assert s["fid_ci"][0] == 0.0 <= s["fid"] <= s["fid_ci"][1]
    assert s["diversity_ci"][0] <= s["diversity"] <= s["diversity_ci"][1]
    # Python floats: myst-nb's glue formats them ({glue:text}`key:.1f`), not numpy scalars
    assert all(type(v) is float for v in s.values() if not isinstance(v, tuple))
    assert all(type(u) is float for v in s.values() if isinstance(v, tuple) for u in v)
    # same seed, same interval; fewer resamples give a (slightly) different one
    assert ev.score(train.landmarks, train.targets("I"), intervals=True, num_resamples=200) == s
    assert ev.score(train.landmarks, train.targets("I"), intervals=True, num_resamples=50) != s


def test_evaluator_errors():
    ev = evaluation.load_evaluator("bu", "I")
    with pytest.raises(ValueError, match="allowed: anger"):
        ev.class_index("high_smile")
    with pytest.raises(ValueError, match="one target per sequence"):
        ev.score(np.zeros((3, 40, 68, 3)), [0, 1])
    with pytest.raises(ValueError, match=r"\(n, frames, 68, 3\)"):
        ev.features(np.zeros((3, 40, 60, 3)))
    with pytest.raises(ValueError, match="has classes"):
        evaluation.load_evaluator("coma", "I", name="ic_bu_I")


def test_compare_runs_and_scores_every_generator_with_its_time():
    ev = evaluation.load_evaluator("coma", "I")
    test = data.load_dataset("coma", "test")
    generators = {"GT": lambda: test.landmarks[:24], "reversed": lambda: test.landmarks[:24, ::-1]}
    rows, outputs = evaluation.compare(generators, ev, test.targets("I")[:24], num_resamples=50)
    assert list(rows) == ["GT", "reversed"] and np.array_equal(outputs["GT"], test.landmarks[:24])
    assert rows["GT"]["accuracy"] == ev.score(test.landmarks[:24], test.targets("I")[:24])["accuracy"]
    assert all(r["seconds"] >= 0 and "fid_ci" in r for r in rows.values())


def test_accuracy_per_class_averages_back_to_the_accuracy():
    ev = evaluation.load_evaluator("coma", "I")
    test = data.load_dataset("coma", "test")
    x, y = test.landmarks[:48], test.targets("I")[:48]
    per_class = ev.accuracy_per_class(x, y)
    assert set(per_class) == {ev.class_names[c] for c in np.unique(y)}
    counts = np.bincount(y)[np.unique(y)]
    assert np.isclose(np.average(list(per_class.values()), weights=counts), ev.score(x, y)["accuracy"])


def test_a_guide_reads_clean_sequences_well_and_pure_noise_at_chance():
    from facelib import tasks
    test = data.load_dataset("coma", "test")
    accuracy = evaluation.accuracy_by_noise(tasks.load_guide("coma").model, tasks.load_denoiser("denoiser_coma"),
                                            test, [0, 2000])
    assert accuracy[0] > 50 > 2 * 100 / 12 > accuracy[1]


def test_au_error_by_noise_is_zero_for_a_regressor_that_knows_the_answer(denoiser):
    test = data.load_dataset("coma", "test").subset(np.arange(4))
    truth = torch.as_tensor(test.au_weights, dtype=torch.float32)

    class Oracle(torch.nn.Module):
        def forward(self, xt, t):
            return truth + 0.25 * (t > 0).float()[:, None, None]  # exact on clean input, 0.25 off on noise

    assert evaluation.au_error_by_noise(Oracle(), denoiser, test, [0, 500]) == pytest.approx([0.0, 0.25])


def test_au_error_by_noise_counts_only_the_chosen_aus_where_they_act(denoiser):
    test = data.load_dataset("coma", "test").subset(np.arange(4))
    truth = torch.as_tensor(test.au_weights, dtype=torch.float32)

    class NoAU(torch.nn.Module):  # predicts no action unit at all
        def forward(self, xt, t):
            return torch.zeros_like(truth)

    k = AU_NAMES.index("AU26")
    on = truth[..., k] > 0.1
    expected = [truth[..., k][on].mean().item()] * 2  # its error: the intensity itself, where AU26 acts
    assert evaluation.au_error_by_noise(NoAU(), denoiser, test, [0, 500], active=0.1, aus=["AU26"]) == \
        pytest.approx(expected)
    assert evaluation.au_error_by_noise(NoAU(), denoiser, test, [0])[0] == pytest.approx(truth.abs().mean().item())
    with pytest.raises(ValueError, match="unknown AUs \\['AU99'\\]; allowed: AU1"):
        evaluation.au_error_by_noise(NoAU(), denoiser, test, [0], aus=["AU99"])


@pytest.mark.parametrize("kwargs, message", [
    (dict(aus=[]), "aus must be a non-empty list of AU names"),
    (dict(aus="AU26"), "aus must be a non-empty list of AU names .* got 'AU26'"),
    (dict(active=-0.1), "active must be None .* or an intensity >= 0, got -0.1"),
    (dict(active="0.1"), "active must be None"),
    (dict(active=float("nan")), "active must be None"),
    (dict(active=10.0, aus=["AU26"]), "no entry to count: none of aus=\\['AU26'\\] exceeds active=10.0"),
])
def test_au_error_by_noise_refuses_bad_or_empty_selections(denoiser, kwargs, message):
    test = data.load_dataset("coma", "test").subset(np.arange(4))

    class NoAU(torch.nn.Module):
        def forward(self, xt, t):
            return torch.zeros(xt.shape[:2] + (len(AU_NAMES),))

    with pytest.raises(ValueError, match=message):
        evaluation.au_error_by_noise(NoAU(), denoiser, test, [0], **kwargs)
