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
