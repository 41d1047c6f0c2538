import numpy as np
import pytest

from facelib.face import ALL_LABELS, AU_NAMES, RECIPES, check_label, expressions, sequences


def test_recipes_cover_18_labels_with_valid_aus():
    assert len(ALL_LABELS) == 18 and set(RECIPES) == set(ALL_LABELS)
    for label, recipe in RECIPES.items():
        for aus in [recipe.aus] + [v for _, v in recipe.variants]:
            for name, lo, hi in aus:
                assert name in AU_NAMES and lo <= hi, label


def test_unknown_label():
    with pytest.raises(ValueError, match="unknown expression label 'smirk'; allowed: bareteeth"):
        check_label("smirk")


def test_styles_and_apex_are_deterministic():
    a = expressions.sample_style("eyebrow", np.random.default_rng(1))
    b = expressions.sample_style("eyebrow", np.random.default_rng(1))
    np.testing.assert_array_equal(a.gains, b.gains)
    w1 = expressions.apex_intensities("eyebrow", a, np.random.default_rng(2))
    w2 = expressions.apex_intensities("eyebrow", b, np.random.default_rng(2))
    np.testing.assert_array_equal(w1, w2)
    assert np.abs(w1).max() <= expressions.MAX_INTENSITY


def test_recipe_aus_dominate_the_apex():
    rng = np.random.default_rng(3)
    for label in ALL_LABELS:
        style = expressions.sample_style(label, rng)
        w = expressions.apex_intensities(label, style, rng)
        main = [AU_NAMES.index(a) for a, lo, hi in RECIPES[label].variant_aus(style.variant) if hi >= 0.6]
        assert np.abs(w[main]).max() >= 0.25, label


def test_n2e_rises_and_e2n_relaxes():
    apex = np.zeros(len(AU_NAMES))
    apex[AU_NAMES.index("AU25")] = 1.0
    k = AU_NAMES.index("AU25")
    up = sequences.au_curves(apex, "N2E", 40, np.random.default_rng(0))
    down = sequences.au_curves(apex, "E2N", 40, np.random.default_rng(0))
    assert up.shape == (40, len(AU_NAMES))
    assert up[0, k] < 0.1 and up[-1, k] > 0.95 and np.all(np.diff(up[:, k]) >= -1e-12)
    np.testing.assert_allclose(down[:, k], 1.0 - up[:, k])


@pytest.mark.parametrize("n", [1, 0, -3, 401, 2.5, "40", True])
def test_bad_lengths(n):
    with pytest.raises(ValueError, match="num_frames"):
        sequences.au_curves(np.zeros(len(AU_NAMES)), "N2E", n, np.random.default_rng(0))


def test_bad_apex_and_kind():
    with pytest.raises(ValueError, match="apex"):
        sequences.au_curves(np.full(len(AU_NAMES), np.nan), "N2E", 40, np.random.default_rng(0))
    with pytest.raises(ValueError, match="kind must be 'N2E' or 'E2N'"):
        sequences.au_curves(np.zeros(len(AU_NAMES)), "up", 40, np.random.default_rng(0))
