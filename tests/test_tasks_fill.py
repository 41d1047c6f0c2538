"""Expression filling (Alg. 3) as a task: known frames kept, determinism, resampling."""
import numpy as np
import pytest

from facelib import inpainting, tasks


def test_fill_keeps_known_frames_exactly_and_is_deterministic(coma_test, denoiser):
    x = coma_test.landmarks[:3].copy()
    known = inpainting.fill_masks("FFM", 3, 40, seed=0)
    x[~known] = np.nan  # the unknown frames are not read
    a = tasks.fill(x, known, steps=10, seed=3, denoiser=denoiser, progress=False)
    b = tasks.fill(x, known, steps=10, seed=3, denoiser=denoiser, progress=False)
    assert a.shape == (3, 40, 68, 3) and a.dtype == np.float32 and np.isfinite(a).all()
    assert np.array_equal(a[known], coma_test.landmarks[:3][known])
    assert np.array_equal(a, b)
    c = tasks.fill(x, known, steps=10, seed=4, denoiser=denoiser, progress=False)
    assert not np.allclose(a[~known], c[~known])  # another seed, another completion
    with pytest.raises(ValueError, match="no unknown frame"):
        tasks.fill(x, np.ones((3, 40), bool), denoiser=denoiser)
    with pytest.raises(ValueError, match="has 30 frames but the sequence has 40"):
        tasks.fill(x, np.ones(30, bool), denoiser=denoiser)


def test_resampling_is_checked_and_one_means_plain_alg_3(coma_test, denoiser):
    x, known = coma_test.landmarks[:2], inpainting.fill_masks("FFE", 2, 40, seed=1)
    plain = tasks.fill(x, known, steps=6, seed=0, denoiser=denoiser, progress=False)
    assert np.array_equal(plain, tasks.fill(x, known, steps=6, resample=1, seed=0, denoiser=denoiser, progress=False))
    twice = tasks.fill(x, known, steps=6, resample=2, seed=0, denoiser=denoiser, progress=False)
    assert not np.array_equal(plain, twice)
    with pytest.raises(ValueError, match="resample must be a positive integer"):
        tasks.fill(x, known, steps=6, resample=0, denoiser=denoiser)


def test_the_default_is_the_measured_best_and_paper_is_alg_3_as_printed(coma_test, denoiser):
    """tasks.Fill: reconstruction guidance with the posterior variance (results/fill_defaults.json)."""
    defaults, paper = tasks.Fill(), tasks.Fill().paper()
    assert (defaults.variance, defaults.reconstruction_scale, defaults.resample) == ("posterior", 2.0, 1)
    assert (paper.steps, paper.variance, paper.reconstruction_scale, paper.resample) == (None, "beta", 0.0, 1)
    chain = denoiser.diffusion_with(6, "posterior")
    np.testing.assert_allclose(chain.sigmas[2:] ** 2, chain.posterior_variance[2:])
    assert denoiser.diffusion_with(6).variance == "beta"  # the denoiser's own
    x, known = coma_test.landmarks[:2], inpainting.parse_known("0:10,30:40", 40)
    as_printed = tasks.fill(x, known, paper, steps=6, denoiser=denoiser, progress=False)
    spelled = tasks.fill(x, known, steps=6, variance="beta", reconstruction_scale=0.0, denoiser=denoiser, progress=False)
    assert np.array_equal(as_printed, spelled)
    assert not np.array_equal(as_printed, tasks.fill(x, known, steps=6, denoiser=denoiser, progress=False))


def test_reconstruction_guidance_on_a_deterministic_chain_steps_in_clean_units(coma_test, denoiser):
    """Near T the gradient through x0_hat carries 1 / sqrt(abar_t); a deterministic chain
    never forgets that push, so there the step is weighted by sqrt(abar_t), and DDIM
    fills as well as the ancestral chain (57 mm off without the weight at 50 steps)."""
    import torch
    from facelib.guidance import ReconstructionGuidance
    truth = coma_test.landmarks[:4]
    known = inpainting.fill_masks("FFM", 4, 40, seed=0)
    x0 = denoiser.to_model(truth)
    mask = torch.as_tensor(known)
    ancestral = denoiser.diffusion_with(10)
    xt = torch.randn(x0.shape, generator=torch.Generator().manual_seed(0))
    steps = []
    for chain in (ancestral, ancestral.with_eta(0.0)):
        guide = ReconstructionGuidance(denoiser.model, chain, x0, mask, 2.0)
        steps.append(guide(torch.zeros_like(xt), xt.clone(), 10, {}))
    torch.testing.assert_close(steps[1], steps[0] * float(ancestral.sqrt_alphas_bar[10]))
    errors = {}
    for sampler in ("ddpm", "ddim"):
        x = tasks.fill(truth, known, steps=20, sampler=sampler, denoiser=denoiser, progress=False)
        errors[sampler] = np.linalg.norm(x - truth, axis=-1)[~known].mean()
    assert errors["ddim"] < 2 * errors["ddpm"] < 4.0, errors
