"""The bidirectional-transformer denoiser eps_theta (models/denoiser.py): any length, padding, attention, the
Gaussian estimate, bad input."""
import numpy as np
import pytest
import scipy.fft
import torch

from facelib.guidance import ClassifierFree
from facelib.models.denoiser import Denoiser, DenoiserConfig


SMALL = DenoiserConfig(width=32, depth=2, heads=2, ff=64)
PLAIN = DenoiserConfig(width=32, depth=2, heads=2, ff=64, gaussian_skip=False)  # output layer not zeroed


def test_any_length_and_shape():
    m = Denoiser(SMALL).eval()
    for f in (2, 20, 40, 57, 80):
        x = torch.randn(3, f, 68, 3)
        assert m(x, torch.tensor([1.0, 500.0, 2000.0])).shape == x.shape


def test_padded_frames_do_not_change_the_valid_ones():
    torch.manual_seed(0)
    m = Denoiser(PLAIN).eval()
    x = torch.randn(1, 40, 68, 3)
    padded = torch.cat([x, torch.randn(1, 5, 68, 3) * 10], dim=1)
    mask = torch.tensor([[True] * 40 + [False] * 5])
    t = torch.tensor([300.0])
    with torch.no_grad():
        torch.testing.assert_close(m(padded, t, mask)[:, :40], m(x, t), atol=1e-5, rtol=1e-4)


def test_attention_is_bidirectional():
    torch.manual_seed(0)
    m = Denoiser(PLAIN).eval()
    x = torch.randn(1, 40, 68, 3)
    y = x.clone()
    y[:, 30] += 1.0  # a change in the future...
    t = torch.tensor([100.0])
    with torch.no_grad():
        assert (m(x, t)[:, 5] - m(y, t)[:, 5]).abs().max() > 1e-4  # ...is seen by an earlier frame


def test_gaussian_estimate_is_the_optimal_noise_estimate_for_gaussian_frames():
    """With the transformer output at zero, eps_theta is E[eps | x_t] for frames ~ N(0, Sigma)."""
    torch.manual_seed(0)
    m = Denoiser(SMALL).eval()
    a = torch.randn(204, 6) * torch.tensor([3.0, 2.0, 1.0, 0.5, 0.2, 0.1])
    frames = (torch.randn(20_000, 6) @ a.T).reshape(-1, 68, 3)
    m.fit_prior(frames)
    x0 = frames[:4000].reshape(200, 20, 68, 3)
    for t in (50, 400, 1500):
        eps = torch.randn_like(x0)
        abar = float(m.alphas_bar[t])
        xt = abar ** 0.5 * x0 + (1 - abar) ** 0.5 * eps
        with torch.no_grad():
            mse = ((m(xt, torch.full((200,), float(t))) - eps) ** 2).mean().item()
        lam = m.prior_variances.double()
        optimum = 1 - ((1 - abar) / (abar * lam + 1 - abar)).mean().item()  # per-dimension posterior variance
        assert mse == pytest.approx(optimum, abs=0.01)
        assert mse < ((xt * (1 - abar) ** 0.5 - eps) ** 2).mean().item()  # beats the isotropic estimate


def _dense_gaussian_eps(model, xt, t):
    """E[eps | x_t] = sqrt(1 - abar) (abar S + (1 - abar) I)^-1 x_t with the whole
    sequence's covariance S written out (frames x features), solved densely."""
    length, features = model.prior_spectrum.shape
    c = torch.as_tensor(scipy.fft.dct(np.eye(length), norm="ortho", axis=0))  # rows: DCT-II
    u = model.prior_basis.double()
    basis = torch.kron(c.T.contiguous(), u)  # columns: the Gaussian's eigenvectors
    cov = basis @ torch.diag(model.prior_spectrum.double().reshape(-1)) @ basis.T
    abar = float(model.alphas_bar[t])
    a = abar * cov + (1 - abar) * torch.eye(len(cov), dtype=torch.float64)
    flat = xt.double().reshape(len(xt), -1)
    return ((1 - abar) ** 0.5 * torch.linalg.solve(a, flat.T).T).reshape(xt.shape)


def test_the_temporal_gaussian_is_the_dense_posterior_of_its_sequence_covariance():
    """prior_length: the Gaussian part is E[eps | x_t] for sequences ~ N(0, S) with S
    diagonal in (DCT-II along time) x (Sigma's eigenvectors), against a dense solve;
    fit_prior finds each coefficient's variance."""
    torch.manual_seed(0)
    m = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64, prior_length=4)).eval()
    slow = torch.tensor([3.0, 1.0, 0.3, 0.1])  # a variance per frequency
    c = torch.as_tensor(scipy.fft.dct(np.eye(4), norm="ortho", axis=0)).float()
    spatial = torch.randn(20_000, 4, 204) * torch.linspace(0.05, 1.0, 204)
    seqs = (c.T @ (spatial * slow.sqrt()[:, None])).reshape(-1, 4, 68, 3)
    m.fit_prior(seqs)
    # the fitted spectrum: the frequencies' variances, summed over components
    ratio = m.prior_spectrum.sum(1) / m.prior_spectrum.sum(1)[0]
    torch.testing.assert_close(ratio, slow / slow[0], atol=0.02, rtol=0.03)
    xt = torch.randn(3, 4, 68, 3)
    for t in (10, 300, 1500):
        with torch.no_grad():
            ours = m(xt, torch.full((3,), float(t)))
        torch.testing.assert_close(ours.double(), _dense_gaussian_eps(m, xt, t), atol=1e-4, rtol=1e-3)


def test_the_temporal_gaussian_reads_other_lengths_and_padded_frames():
    torch.manual_seed(0)
    m = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64, prior_length=8)).eval()
    m.fit_prior(torch.randn(500, 8, 68, 3) * torch.linspace(2.0, 0.2, 8)[None, :, None, None])
    t = torch.tensor([200.0, 200.0])
    x = torch.randn(2, 12, 68, 3)
    mask = torch.tensor([[True] * 12, [True] * 8 + [False] * 4])
    x = x * mask[:, :, None, None]
    with torch.no_grad():
        both = m.gaussian_eps(x, t, mask)
        alone = m.gaussian_eps(x[1:, :8], t[1:])
    torch.testing.assert_close(both[1, :8], alone[0])  # the valid frames, as an 8-frame sequence
    assert both[1, 8:].abs().max() == 0
    torch.testing.assert_close(m._spectrum(8), m.prior_spectrum)
    assert m._spectrum(12).shape == (12, 204)


def _performances(n, frames, seed):
    """n sequences (n, frames, 68, 3) of one slow motion per sequence on the time axis
    [0, 1], sampled at ``frames`` frames, plus white noise: the same performances at
    any length."""
    g = torch.Generator().manual_seed(seed)
    amplitude = torch.randn(n, 3, 204, generator=g) * torch.tensor([3.0, 1.0, 0.3])[None, :, None]
    u = (torch.arange(frames) + 0.5) / frames
    waves = torch.stack([torch.cos(torch.pi * k * u) for k in range(3)])  # (3, frames)
    x = torch.einsum("nkd,kf->nfd", amplitude, waves) + 0.1 * torch.randn(n, frames, 204, generator=g)
    return x.reshape(n, frames, 68, 3)


def test_the_temporal_gaussian_at_another_length_is_the_one_fitted_there():
    """A sequence of another length is the same performance at a finer or coarser time
    step: the spectrum read off at 12 or 30 frames is the one fitted on sequences of
    that length (the slow frequencies, which hold the variance, and the white floor)."""
    fitted = {}
    for frames in (12, 20, 30):
        m = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64, prior_length=frames))
        m.fit_prior(_performances(4000, frames, seed=frames))
        fitted[frames] = m
    for frames in (12, 30):
        read, true = fitted[20]._spectrum(frames).sum(1), fitted[frames].prior_spectrum.sum(1)
        torch.testing.assert_close(read[:3], true[:3], rtol=0.1, atol=0)
        torch.testing.assert_close(read[-3:], true[-3:], rtol=0.2, atol=0)


def test_the_temporal_gaussian_refuses_frames_or_other_lengths_to_fit():
    m = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64, prior_length=8))
    with pytest.raises(ValueError, match="sequences of 8 frames"):
        m.fit_prior(torch.randn(100, 68, 3))
    with pytest.raises(ValueError, match="prior_length is 0"):
        Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64, prior_length=1))


@pytest.mark.parametrize("shape, t_shape, message", [
    ((2, 40, 204), (2,), "x_t must have shape"),
    ((2, 40, 60, 3), (2,), "x_t must have shape"),
    ((2, 40, 68, 3), (3,), "t must have shape"),
])
def test_denoiser_rejects_bad_shapes(shape, t_shape, message):
    with pytest.raises(ValueError, match=message):
        Denoiser(SMALL)(torch.zeros(shape), torch.zeros(t_shape))


def test_a_conditional_denoiser_reads_its_label_token_and_an_unconditional_one_refuses_labels():
    torch.manual_seed(0)
    model = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64, num_classes=3, gaussian_skip=False))
    torch.nn.init.normal_(model.out.weight)
    x, t = torch.randn(2, 5, 68, 3), torch.tensor([10.0, 900.0])
    free, none = model(x, t), model(x, t, labels=torch.tensor([3, 3]))
    torch.testing.assert_close(free, none)  # no label = the "no label" token
    assert (model(x, t, labels=torch.tensor([0, 2])) - free).abs().max() > 1e-3
    for bad in (torch.tensor([0, 4]), torch.tensor([-1, 0]), torch.tensor([0])):
        with pytest.raises(ValueError, match=r"labels must be \(2,\) class indices in 0..3"):
            model(x, t, labels=bad)
    with pytest.raises(ValueError, match="unconditional"):
        Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64))(x, t, labels=torch.tensor([0, 1]))


def test_classifier_free_guidance_mixes_the_conditional_and_free_estimates():
    torch.manual_seed(0)
    model = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64, num_classes=3, gaussian_skip=False))
    torch.nn.init.normal_(model.out.weight)
    x, t, y = torch.randn(2, 5, 68, 3), torch.tensor([10.0, 900.0]), torch.tensor([1, 2])
    free, conditional = model(x, t), model(x, t, labels=y)
    torch.testing.assert_close(ClassifierFree(model, y, 0.0)(x, t), free)
    torch.testing.assert_close(ClassifierFree(model, y, 1.0)(x, t), conditional)
    torch.testing.assert_close(ClassifierFree(model, y, 3.0)(x, t), free + 3 * (conditional - free))
    with pytest.raises(ValueError, match="needs a label-conditional denoiser"):
        ClassifierFree(Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=64)), y, 2.0)
    with pytest.raises(ValueError, match="scale must be a number >= 0"):
        ClassifierFree(model, y, -1.0)


def test_every_prediction_target_returns_the_noise_estimate_and_starts_from_the_gaussian_one():
    """x0 and v networks convert their output to eps (forward); with the zeroed output layer all three are the
    Gaussian estimate, and to_eps inverts from_eps."""
    torch.manual_seed(0)
    x, t = torch.randn(3, 10, 68, 3), torch.tensor([3.0, 700.0, 1990.0])
    with torch.no_grad():
        estimates = {p: Denoiser(DenoiserConfig(**{**SMALL.__dict__, "prediction": p})).eval()(x, t)
                     for p in ("eps", "x0", "v")}
        torch.testing.assert_close(estimates["x0"], estimates["eps"], rtol=1e-4, atol=1e-4)
        torch.testing.assert_close(estimates["v"], estimates["eps"], rtol=1e-4, atol=1e-4)
        for p in ("x0", "v"):
            m = Denoiser(DenoiserConfig(**{**SMALL.__dict__, "prediction": p}))
            eps = torch.randn_like(x)
            torch.testing.assert_close(m.to_eps(x, t, m.from_eps(x, t, eps)), eps, rtol=1e-4, atol=1e-4)
    with pytest.raises(ValueError, match="unknown prediction target 'score'; allowed: eps, x0, v, u$"):
        Denoiser(DenoiserConfig(prediction="score"))
