"""Known frames (Alg. 3): masks, the known-frame step, the non-learned baselines."""
import numpy as np
import pytest
import torch

from facelib import inpainting
from facelib.diffusion import GaussianDiffusion, linear_betas


def test_parse_known_and_mask_errors():
    m = inpainting.parse_known("0:10,30:40", 40)
    assert m.sum() == 20 and m[:10].all() and m[30:].all() and not m[10:30].any()
    assert inpainting.parse_known("5", 8).tolist() == [False] * 5 + [True] + [False] * 2
    for spec, msg in [("0:50", "outside 0:40"), ("a:b", "cannot read"), ("", "ranges like"), ("0:40", "no unknown")]:
        with pytest.raises(ValueError, match=msg):
            inpainting.parse_known(spec, 40)
    with pytest.raises(ValueError, match="no known frame"):
        inpainting.check_known_mask(np.zeros(40, bool))
    with pytest.raises(ValueError, match="has 30 frames but the sequence has 40"):
        inpainting.check_known_mask(np.ones(30, bool), 40)
    with pytest.raises(ValueError, match="boolean"):
        inpainting.check_known_mask(np.full(40, 0.5))


@pytest.mark.parametrize("setting", inpainting.FILL_SETTINGS)
def test_fill_masks_follow_section_5_3(setting):
    m = inpainting.fill_masks(setting, 500, 40, seed=1)
    n_known = m.sum(1)
    if setting == "FFM":  # l ~ U[5, 15] at each end
        assert m[:, 0].all() and m[:, -1].all() and not m[:, 19:21].any()
        assert n_known.min() == 10 and n_known.max() == 30 and (n_known % 2 == 0).all()
    else:  # l ~ U[10, 30]; FFB fills the beginning (the end is known), FFE fills the end
        assert (m[:, -1] if setting == "FFB" else m[:, 0]).all()
        assert n_known.min() == 10 and n_known.max() == 30
    with pytest.raises(ValueError, match="allowed: FFB, FFE, FFM"):
        inpainting.fill_masks("FFX", 2)


@pytest.mark.parametrize("t", [2, 10, 700])
@pytest.mark.parametrize("respaced", [False, True])
def test_known_frames_at_step_t_minus_1_have_the_exact_marginal_of_q(t, respaced):
    # Alg. 3 line 12 (with the errata's abar): after the reverse step t, the known frames are
    # x_{t-1} ~ N(sqrt(abar_{t-1}) x_0, (1 - abar_{t-1}) I).  At small t the traps are visible: abar_t
    # instead of abar_{t-1} doubles the variance at t = 2; alpha instead of abar, or the std used as
    # a variance, are off by orders of magnitude.
    diffusion = GaussianDiffusion(linear_betas(2000))
    if respaced:
        diffusion = diffusion.respace(100)
        t = min(t, 100)
    n = 20000
    x0 = torch.full((n, 2, 68, 3), 0.7, dtype=torch.float64)
    known = torch.tensor([[True, False]]).expand(n, 2)
    hook = inpainting.KnownFrames(diffusion, x0, known, torch.Generator().manual_seed(0))
    x_hat = torch.full_like(x0, 123.0)
    x = hook(x_hat, None, t, None)
    assert (x[:, 1] == 123.0).all()  # unknown frames: the model's sample, untouched
    k = x[:, 0].flatten()
    abar = diffusion.alphas_bar[t - 1]
    var, mean = k.var().item(), k.mean().item()
    assert abs(var / (1 - abar) - 1) < 0.02, (var, 1 - abar)
    assert abs(mean - np.sqrt(abar) * 0.7) < 4 * np.sqrt((1 - abar) / k.numel()) + 1e-12
    assert torch.equal(hook(x_hat, None, 1, None)[:, 0], x0[:, 0])  # at t = 1, x_0|S_K is the data itself


@pytest.mark.parametrize("t", [2, 10, 40])
def test_on_a_ddim_chain_the_known_frames_take_its_own_step_continuous_in_eta(t):
    """KnownFrames on a DDIM chain: the known frames of x_{t-1} are sqrt(abar_{t-1}) x_0 + sqrt(1 - abar_{t-1} -
    sigma_t^2) eps_hat + sigma_t z: at eta = 0 no random number is drawn (two known-noise streams give the same
    chain; Alg. 3's fresh draw made them differ), the step tends to eta = 0's as eta -> 0, and at eta = 1 the
    spread around its mean is sigma_t's.  The ancestral chain keeps Alg. 3's draw (the test above)."""
    base = GaussianDiffusion(linear_betas(2000)).respace(50)
    n = 4000
    x0 = torch.full((n, 2, 68, 3), 0.7, dtype=torch.float64)
    known = torch.tensor([[True, False]]).expand(n, 2)
    eps_hat = torch.randn(x0.shape, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    out = {"eps": eps_hat, "x0": x0}
    x_hat = torch.full_like(x0, 123.0)

    def step(eta, seed):
        hook = inpainting.KnownFrames(base.with_eta(eta), x0, known, torch.Generator().manual_seed(seed))
        return hook(x_hat, None, t, out)

    abar = base.alphas_bar_prev[t]
    expected = np.sqrt(abar) * 0.7 + np.sqrt(1 - abar) * eps_hat[:, 0]
    assert torch.allclose(step(0.0, 0)[:, 0], expected) and torch.equal(step(0.0, 0), step(0.0, 1))
    assert (step(0.0, 0)[:, 1] == 123.0).all()
    assert (step(1e-4, 0) - step(0.0, 0)).abs().max() < 1e-3
    sigma = float(base.with_eta(1.0).sigmas[t])
    mean = np.sqrt(abar) * 0.7 + np.sqrt(max(1 - abar - sigma**2, 0.0)) * eps_hat[:, 0]
    spread = (step(1.0, 0)[:, 0] - mean).std().item()
    assert abs(spread / sigma - 1) < 0.05, (spread, sigma)


def test_feathered_replacement_shifts_the_neighbours_by_the_known_frames_signal_step():
    # KnownFrames(feather=sigma): every unknown coordinate moves by sqrt(abar_{t-1}) (x_0 - x0_hat) of
    # the known coordinates of its landmark, Gaussian-weighted by their distance in frames and
    # averaged where the weights add up to more than 1; the known coordinates are replaced as before,
    # and no random number is drawn for the shift.
    diffusion = GaussianDiffusion(linear_betas(50))
    t, sigma, frames = 7, 2.0, 9
    x0 = torch.zeros(1, frames, 68, 3, dtype=torch.float64)
    x0[0, 4, 10] = 1.0  # one keyed coordinate: landmark 10 at frame 4
    known = torch.zeros(1, frames, 68, dtype=torch.bool)
    known[0, 4, 10] = True
    x0_hat = torch.zeros_like(x0)
    x_hat = torch.full_like(x0, 5.0)
    plain = inpainting.KnownFrames(diffusion, x0, known, torch.Generator().manual_seed(0))
    soft = inpainting.KnownFrames(diffusion, x0, known, torch.Generator().manual_seed(0), feather=sigma)
    a, b = plain(x_hat, None, t, {"x0": x0_hat}), soft(x_hat, None, t, {"x0": x0_hat})
    assert torch.equal(a[0, 4, 10], b[0, 4, 10])  # the key: replaced as by Alg. 3, same noise drawn
    step = np.sqrt(diffusion.alphas_bar[t - 1])
    for f in range(frames):
        if f != 4:
            expected = 5.0 + step * np.exp(-0.5 * ((f - 4) / sigma) ** 2)
            assert torch.allclose(b[0, f, 10], torch.full((3,), expected, dtype=torch.float64))
    assert torch.equal(b[0, :, :10], a[0, :, :10]) and torch.equal(b[0, :, 11:], a[0, :, 11:])  # other landmarks
    # a block of known frames: the frame next to it moves by the block's step, not by a sum of steps
    block = torch.zeros(1, frames, dtype=torch.bool)
    block[0, :4] = True
    soft = inpainting.KnownFrames(diffusion, x0 * 0 + 1.0, block, torch.Generator().manual_seed(0), feather=sigma)
    c = soft(x_hat, None, t, {"x0": x0_hat})
    assert torch.allclose(c[0, 4], torch.full((68, 3), 5.0 + step, dtype=torch.float64))
    fade = c[0, 4:, 0, 0] - 5.0  # full while the weights add up to 1 or more, then fading out
    assert (fade <= step + 1e-12).all() and (torch.diff(fade) <= 1e-12).all() and fade[-1] < 0.1 * step


def test_mean_imputation_and_interpolation():
    f = np.arange(10, dtype=np.float64)
    x = np.broadcast_to(f[:, None, None] * np.array([1.0, -2.0, 0.5]), (10, 68, 3))[None].copy()
    known = np.zeros(10, bool)
    known[[0, 1, 8, 9]] = True
    lin = inpainting.linear_interpolation(x, known)
    np.testing.assert_allclose(lin, x, atol=1e-5)  # a linear motion is filled exactly
    mean = inpainting.mean_imputation(x, known)
    np.testing.assert_allclose(mean[0, 4], x[0, [0, 1, 8, 9]].mean(0), atol=1e-5)
    x_nan = x.copy()
    x_nan[0, ~known] = np.nan  # unknown frames may be missing values
    assert np.isfinite(inpainting.linear_interpolation(x_nan, known)).all()
    assert np.isfinite(inpainting.mean_imputation(x_nan, known)).all()
    head = np.zeros(10, bool)
    head[6:] = True  # FFB: frames before the first known one hold it
    np.testing.assert_allclose(inpainting.linear_interpolation(x, head)[0, :6], np.broadcast_to(x[0, 6], (6, 68, 3)), atol=1e-5)
    bad = x.copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="known frames contain NaN"):
        inpainting.mean_imputation(bad, known)
    with pytest.raises(ValueError, match=r"\(n, frames, 68, 3\)"):
        inpainting.mean_imputation(np.zeros((2, 10, 67, 3)), known)
