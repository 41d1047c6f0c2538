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
