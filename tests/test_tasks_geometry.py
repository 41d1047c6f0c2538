"""Geometry-adaptive generation (Alg. 4) as a task."""
import numpy as np
import pytest

from facelib import tasks


def test_geometry_adaptive_keeps_the_neutral_frame_and_checks_input(coma_test, denoiser):
    guide = tasks.load_guide("coma", "S")
    neutral = coma_test.subject_neutrals()[0]
    out = tasks.geometry_passes(neutral, "mouth_open", n=2, steps=8, passes=2, denoiser=denoiser, guide=guide,
                                progress=False)
    assert out.shape == (2, 2, 40, 68, 3)
    assert np.array_equal(out[:, :, 0], np.broadcast_to(neutral, (2, 2, 68, 3)).astype(np.float32))
    e2n = tasks.geometry_adaptive(neutral, "mouth_open E2N", n=1, steps=8, passes=1, denoiser=denoiser, guide=guide,
                                  progress=False)
    assert np.array_equal(e2n[0, -1], neutral.astype(np.float32))  # E2N: S_K = {F}
    for bad, msg in [(dict(neutral_landmarks=neutral[:67]), r"\(68, 3\)"),
                     (dict(neutral_landmarks=np.full((68, 3), np.nan)), "NaN"),
                     (dict(label="smile"), "allowed: bareteeth N2E"),
                     (dict(order="sideways"), "order must be one of"),
                     (dict(passes=0), "passes must be a positive integer"),
                     (dict(renoise_step=9), "renoise_step must be in 1..8")]:
        kwargs = dict(neutral_landmarks=neutral, label="mouth_open", steps=8, passes=1, denoiser=denoiser,
                      guide=guide, progress=False) | bad
        with pytest.raises(ValueError, match=msg):
            tasks.geometry_adaptive(**kwargs)


def test_geometry_adaptive_takes_one_label_per_sequence(coma_test, denoiser):
    neutral = coma_test.subject_neutrals()[:2]
    out = tasks.geometry_adaptive(neutral, ["mouth_open", "eyebrow E2N"], n=2, steps=5, passes=1, denoiser=denoiser,
                                  progress=False)
    assert np.array_equal(out[0, 0], neutral[0].astype(np.float32))  # N2E: first frame given
    assert np.array_equal(out[1, -1], neutral[1].astype(np.float32))  # E2N: last frame given
    with pytest.raises(ValueError, match="list of n=3"):
        tasks.geometry_adaptive(neutral[0], ["mouth_open"] * 2, n=3, steps=5, denoiser=denoiser)
