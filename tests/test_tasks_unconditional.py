"""Unconditional sampling (§3.1) with the shipped denoisers."""
import numpy as np
import pytest

from facelib import tasks


def test_shipped_denoisers_load_and_sample_deterministically():
    for name in ("denoiser_coma", "denoiser_coma_var"):
        d = tasks.load_denoiser(name)
        assert d.meta["training"]["num_diffusion_steps"] == 2000 and d.meta["training"]["schedule"] == "linear"
    d = tasks.load_denoiser()
    a = tasks.unconditional(2, num_frames=24, seed=4, steps=5, denoiser=d, progress=False)
    b = tasks.unconditional(2, num_frames=24, seed=4, steps=5, denoiser=d, progress=False)
    assert a.shape == (2, 24, 68, 3) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="n must be a positive integer"):
        tasks.unconditional(0, denoiser=d)
    with pytest.raises(ValueError, match="num_frames must be in"):
        tasks.unconditional(2, num_frames=1, denoiser=d)


def test_ddim_samples_unconditional_sequences():
    d = tasks.load_denoiser()
    a = tasks.unconditional(2, seed=4, steps=10, sampler="ddim", eta=0.0, denoiser=d, progress=False)
    ancestral = tasks.unconditional(2, seed=4, steps=10, denoiser=d, progress=False)
    assert a.shape == (2, 40, 68, 3) and np.all(np.isfinite(a)) and np.abs(a - ancestral).max() > 0.1
    with pytest.raises(ValueError, match="eta must be a number in"):
        tasks.unconditional(2, steps=10, sampler="ddim", eta=1.5, denoiser=d)
    with pytest.raises(ValueError, match="sampler must be one of"):
        tasks.unconditional(2, steps=10, sampler="euler", denoiser=d)
