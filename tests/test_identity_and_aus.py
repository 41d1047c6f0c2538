import numpy as np
import pytest

from facelib.face import AU_NAMES, NUM_AUS, Face, au_vector, get_template, sample_identity
from facelib.face import identity, measures


def test_zero_identity_is_the_template():
    np.testing.assert_allclose(identity.neutral_vertices(np.zeros(identity.NUM_MODES)), get_template().vertices)


def test_identity_is_deterministic_and_smooth():
    s = sample_identity(3)
    np.testing.assert_array_equal(s, sample_identity(3))
    a = identity.neutral_vertices(s)
    np.testing.assert_array_equal(a, identity.neutral_vertices(s))
    b = identity.neutral_vertices(s + 1e-4)
    assert 0 < np.abs(a - b).max() < 0.01  # mm: a small change of s moves the face a little


def test_identity_modes_are_nonlinear():
    e = np.zeros(identity.NUM_MODES)
    e[identity.IDENTITY_MODES.index("jaw_width")] = 1.0
    base = identity.neutral_vertices(0 * e)
    one, three = identity.neutral_vertices(e) - base, identity.neutral_vertices(3 * e) - base
    assert np.linalg.norm(three - 3 * one) > 0.2 * np.linalg.norm(three)


@pytest.mark.parametrize("bad", [np.zeros(3), np.full(identity.NUM_MODES, np.nan), np.zeros((2, identity.NUM_MODES))])
def test_bad_identity_coefficients(bad):
    with pytest.raises(ValueError, match="identity coefficients"):
        identity.neutral_vertices(bad)


def test_zero_weights_give_the_neutral_face():
    f = Face(sample_identity(5))
    np.testing.assert_allclose(f.expression(np.zeros(NUM_AUS)), f.neutral, atol=1e-9)
    np.testing.assert_allclose(f.landmarks(np.zeros((4, NUM_AUS))), np.broadcast_to(
        f.neutral[get_template().landmark_index], (4, 68, 3)), atol=1e-9)


def test_expression_of_a_subset_matches_the_full_mesh():
    f = Face(sample_identity(6))
    w = au_vector(AU12L=1.0, AU26=0.8, AU25=1.0, AU6=0.5)
    full = f.expression(w)
    np.testing.assert_allclose(f.landmarks(w), full[get_template().landmark_index], atol=1e-9)


def test_every_au_moves_the_landmarks_and_depends_on_identity():
    for name in AU_NAMES:  # the blink least: the lids of every face meet (chapter 01)
        rel = measures.identity_dependence(name, num_pairs=6, seed=2)
        assert rel.mean() >= (0.05 if name == "AU45" else 0.2), name
    f = Face(sample_identity(7))
    for name in AU_NAMES:
        d = f.landmarks(au_vector(**{name: 1.0})) - f.landmarks(np.zeros(NUM_AUS))
        assert np.linalg.norm(d, axis=1).max() > 0.5, name  # at least half a millimetre somewhere


def test_jaw_drop_is_a_rotation_nonlinear_in_intensity():
    f = Face(sample_identity(8))
    chin = [f.landmarks(au_vector(AU26=v))[8] for v in (0.0, 0.5, 1.0)]
    linear_mid = 0.5 * (chin[0] + chin[2])
    assert np.linalg.norm(chin[1] - linear_mid) > 0.1  # mm off the chord: an arc
    assert chin[2][1] < chin[0][1] - 5  # the chin goes down
    top = f.landmarks(au_vector(AU26=1.0))[17:27]  # brows do not follow the jaw
    np.testing.assert_allclose(top, f.landmarks(np.zeros(NUM_AUS))[17:27], atol=1e-6)


def test_au_pairs_interact():
    f = Face(sample_identity(9))
    corrective = f.correctives[("AU12L", "AU26")]
    corner = get_template().landmark_index[54]
    assert np.linalg.norm(corrective[corner]) > 1.0  # the left mouth corner gets a corrective...
    assert np.abs(corrective[get_template().landmark_index[17:27]]).max() < 1e-3  # ...the brows do not
    w12, w26 = au_vector(AU12L=1.0), au_vector(AU26=1.0)
    n = f.landmarks(np.zeros(NUM_AUS))
    both = f.landmarks(w12 + w26) - n
    assert np.linalg.norm(both - (f.landmarks(w12) - n) - (f.landmarks(w26) - n)) > 0.5  # not additive


def test_blink_closes_the_eye():
    f = Face(sample_identity(10))
    lm = f.landmarks(au_vector(AU45=1.0))
    opening = lambda l: np.linalg.norm(l[37] - l[41]) + np.linalg.norm(l[38] - l[40])
    assert opening(lm) < 0.2 * opening(f.landmarks(np.zeros(NUM_AUS)))


@pytest.mark.parametrize("weights", [np.zeros(5), np.full(NUM_AUS, np.nan), np.zeros((3, NUM_AUS + 1))])
def test_bad_au_weights(weights):
    with pytest.raises(ValueError, match="AU weights"):
        Face(sample_identity(1)).expression(weights)


def test_unknown_action_unit():
    with pytest.raises(ValueError, match="unknown action unit 'AU99'; allowed: AU1"):
        au_vector(AU99=1.0)
