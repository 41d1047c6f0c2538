"""Evaluation metrics: the seam step."""
import numpy as np
import pytest

from facelib import metrics


def test_seam_step_is_the_motion_across_the_seam():
    f = np.arange(12, dtype=np.float64)
    x = np.zeros((1, 12, 68, 3))
    x[0, :, :, 0] = f[:, None]  # every landmark moves 1 mm per frame
    known = np.zeros(12, bool)
    known[:4] = True
    assert np.allclose(metrics.seam_steps(x, known), 1.0)
    assert np.allclose(metrics.frame_speeds(x), 1.0) and metrics.frame_speeds(x).shape == (1, 11)
    y = x.copy()
    y[0, 4:, :, 0] += 2.0  # the generated part starts 2 mm off: one 3 mm step at the seam
    assert np.allclose(metrics.seam_steps(y, known), 3.0)
    both = np.zeros(12, bool)
    both[[0, 1, 10, 11]] = True  # two seams
    assert len(metrics.seam_steps(x, both)) == 2
    assert metrics.missing_frame_error(y, x, known) == pytest.approx(2.0)


def test_completion_spread_is_the_mean_pairwise_distance_on_the_unknown_frames():
    known = np.array([[True, False, False]])
    c = np.zeros((1, 3, 3, 68, 3))
    c[0, 1, 1:] = 3.0 / np.sqrt(3)  # completion 1 is 3 mm from completions 0 and 2 on the unknown frames
    c[0, :, 0] = 100.0  # the known frame does not count
    assert np.isclose(metrics.completion_spread(c, known)[0], (3 + 0 + 3) / 3)
    with pytest.raises(ValueError, match="K >= 2"):
        metrics.completion_spread(c[:, :1], known)


def test_pair_distance_is_the_distance_of_the_named_landmarks_per_frame():
    x = np.zeros((2, 3, 68, 3))
    x[..., 57, 1] = -np.arange(3.0)  # the lower lip drops 0, 1, 2 mm
    assert np.allclose(metrics.pair_distance(x, "mouth opening"), [[0, 1, 2]] * 2)
    with pytest.raises(ValueError, match="unknown landmark pair 'mouth'.*mouth opening"):
        metrics.pair_distance(x, "mouth")


def test_steps_away_from_seams_skip_every_step_that_touches_a_known_frame():
    known = np.array([[True, False, False, False, False, True]])  # frames 0 and 5 given
    # steps 0-1 and 4-5 cross a seam, 1-2 and 3-4 touch one: only 2-3 is away from both
    assert metrics.steps_away_from_seams(known).tolist() == [[False, False, True, False, False]]
    with pytest.raises(ValueError, match=r"\(n, F\) mask"):
        metrics.steps_away_from_seams(known[0])


def test_amplitudes_read_each_regions_largest_motion_in_mm():
    rng = np.random.default_rng(0)
    x = np.repeat(rng.normal(0, 30, (1, 1, 68, 3)), 10, axis=1)  # a still face: no motion
    x[0, :, 66] = x[0, :, 62]  # closed lips
    still = metrics.amplitudes(x)
    assert still["mouth opening"][0] == 0 and all(still[r][0] < 1e-9 for r in metrics.AMPLITUDE_REGIONS[1:])
    moved = x.copy()
    moved[0, 5, 66, 1] -= 20.0  # the lower inner lip drops 20 mm at frame 5
    moved[0, 7, 54, 0] += 8.0  # a mouth corner pulled 8 mm at frame 7
    moved[0, 3, [19, 24], 1] += 6.0  # both brows up 6 mm at frame 3
    a = metrics.amplitudes(moved)
    assert a["mouth opening"][0] == pytest.approx(20.0) and a["mouth-corner excursion"][0] == pytest.approx(8.0)
    assert 0 < a["brow raise"][0] <= 6.0 + 1e-9 and a["eye closure"][0] < 1e-9
    with pytest.raises(ValueError, match=r"\(n, F >= 2, 68, 3\)"):
        metrics.amplitudes(x[:, :1])


def test_label_mix_total_variation_and_its_real_subset_reference():
    assert metrics.total_variation([0.5, 0.5], [0.5, 0.5]) == 0 and metrics.total_variation([1, 0], [0, 1]) == 1
    labels = np.repeat(np.arange(4), 50)
    reference = metrics.label_histogram(labels, 4)
    chance = metrics.subset_total_variations(labels, reference, 40, num_subsets=200)
    skewed = metrics.total_variation(metrics.label_histogram(np.r_[np.zeros(30, int), np.arange(10) % 4], 4),
                                     reference)
    assert chance.shape == (200,) and skewed > np.percentile(chance, 95)  # a quarter as one label is no chance
    with pytest.raises(ValueError, match="classes in 0..3"):
        metrics.label_histogram([0, 4], 4)


def test_a_generator_that_drops_the_rare_wide_expressions_loses_recall_and_coverage_not_precision():
    rng = np.random.default_rng(1)
    real = np.r_[rng.normal(0, 1, (300, 4)), rng.normal(6, 1, (60, 4))]  # a rare, far mode
    faithful = np.r_[rng.normal(0, 1, (300, 4)), rng.normal(6, 1, (60, 4))]
    collapsed = rng.normal(0, 1, (360, 4))  # only the common mode
    good, bad = (metrics.precision_recall_coverage(real, g) for g in (faithful, collapsed))
    assert good["recall"] > 0.9 and good["coverage"] > 0.9
    assert bad["precision"] > 0.9 and bad["recall"] < 0.9 and bad["coverage"] < 0.9
    assert bad["recall"] < good["recall"] - 0.1 and bad["coverage"] < good["coverage"] - 0.1
    with pytest.raises(ValueError, match="k must be an integer"):
        metrics.precision_recall_coverage(real, faithful, k=0)
