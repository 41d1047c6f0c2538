"""Closed forms of the DDPM (paper §3.1) against Monte-Carlo and against each other."""
import numpy as np
import pytest
import torch

from facelib.diffusion import GaussianDiffusion, cosine_betas, linear_betas, named_betas


@pytest.fixture(autouse=True)
def _float64():
    torch.set_default_dtype(torch.float64)
    yield
    torch.set_default_dtype(torch.float32)


def test_schedules():
    b = linear_betas(2000)
    assert b.shape == (2000,) and b[0] == pytest.approx(1e-4) and b[-1] == pytest.approx(0.02)
    d = GaussianDiffusion(b)
    assert d.alphas_bar[0] == 1.0 and d.betas[0] == 0.0  # t = 0 is the data
    assert d.alphas_bar[-1] < 1e-8  # x_T is (almost) pure noise
    c = GaussianDiffusion(cosine_betas(2000))
    assert np.all(np.diff(c.alphas_bar) < 0)
    with pytest.raises(ValueError, match="unknown noise schedule 'quadratic'; allowed: linear, cosine, flow$"):
        named_betas("quadratic", 10)
    with pytest.raises(ValueError, match="positive integer"):
        linear_betas(0)
    with pytest.raises(ValueError, match="variance must be one of"):
        GaussianDiffusion(b, variance="learned")


def test_closed_form_matches_iterating_the_chain():
    """Eq. 3: x_t ~ N(sqrt(abar_t) x_0, (1 - abar_t) I), checked by iterating Eq. 2."""
    d = GaussianDiffusion(linear_betas(100, 1e-3, 0.05))
    g = torch.Generator().manual_seed(0)
    x0 = torch.full((40_000,), 1.5)
    x = x0.clone()
    for t in range(1, 61):
        x = d.q_step(x, t, generator=g)
    n = len(x)
    mean, var = d.sqrt_alphas_bar[60] * 1.5, 1 - d.alphas_bar[60]
    assert abs(x.mean().item() - mean) < 4 * np.sqrt(var / n)
    assert abs(x.var().item() - var) < 4 * var * np.sqrt(2 / n)
    direct = d.q_sample(x0, 60, generator=g)
    assert abs(direct.mean().item() - mean) < 4 * np.sqrt(var / n)


def test_reparameterisation_is_eq6():
    d = GaussianDiffusion(linear_betas(50))
    x0, eps = torch.randn(3, 5), torch.randn(3, 5)
    t = torch.tensor([1, 20, 50])
    xt = d.q_sample(x0, t, eps)
    abar = torch.as_tensor(d.alphas_bar[t.numpy()])[:, None]
    expected = abar.sqrt() * x0 + (1 - abar).sqrt() * eps
    torch.testing.assert_close(xt, expected)
    torch.testing.assert_close(d.predict_x0(xt, t, eps), x0)


def test_posterior_matches_regression_of_the_joint():
    """q(x_{t-1} | x_t, x_0) is the linear regression of x_{t-1} on x_t under the forward process."""
    d = GaussianDiffusion(linear_betas(100, 1e-3, 0.05))
    g = torch.Generator().manual_seed(1)
    t, x0 = 30, 0.7
    x_prev = d.q_sample(torch.full((200_000,), x0), t - 1, generator=g)
    x_t = d.q_step(x_prev, t, generator=g)
    slope, intercept = np.polyfit(x_t.numpy(), x_prev.numpy(), 1)
    resid = x_prev.numpy() - (slope * x_t.numpy() + intercept)
    assert slope == pytest.approx(d.posterior_coef_xt[t], abs=0.01)
    assert intercept == pytest.approx(d.posterior_coef_x0[t] * x0, abs=0.01)
    assert resid.var() == pytest.approx(d.posterior_variance[t], rel=0.02)


def test_eq7_is_the_posterior_mean_with_the_true_noise_and_the_typo_is_not():
    d = GaussianDiffusion(linear_betas(2000))
    x0, eps = torch.randn(8, 4), torch.randn(8, 4)
    for t in (2, 100, 1000, 2000):
        xt = d.q_sample(x0, t, eps)
        oracle = lambda x, tm, mask: eps  # noqa: E731  (the perfect noise predictor)
        mean = d.p_mean_variance(oracle, xt, t)["mean"]
        post, _ = d.q_posterior(x0, xt, t)
        torch.testing.assert_close(mean, post)
        typo = (xt - d.betas[t] / np.sqrt(1 - d.alphas[t]) * eps) / np.sqrt(d.alphas[t])
        if t >= 100:  # the printed coefficient sqrt(beta_t) removes several times too much noise
            assert d.betas[t] / np.sqrt(1 - d.alphas[t]) > 3 * d.eps_coef[t]
            removed = post - xt / np.sqrt(d.alphas[t])  # the noise the correct step removes
            assert (typo - post).norm() > 2 * removed.norm()


def test_kl_term_is_the_weighted_simple_loss():
    """L_{t-1} = KL(q(x_{t-1}|x_t,x_0) || p_theta) = beta_t^2 / (2 sigma_t^2 alpha_t (1 - abar_t)) ||eps - eps_theta||^2 + C."""
    d = GaussianDiffusion(linear_betas(1000))
    x0, eps, eps_hat = torch.randn(6), torch.randn(6), torch.randn(6)
    t = 400
    xt = d.q_sample(x0, t, eps)
    post_mean, post_var = d.q_posterior(x0, xt, t)
    post_var = float(post_var)
    p_mean = d.p_mean_variance(lambda x, tm, mask: eps_hat, xt, t)["mean"]
    s2 = d.sigmas[t] ** 2
    kl = 0.5 * (6 * post_var / s2 + ((post_mean - p_mean) ** 2).sum() / s2 - 6 + 6 * np.log(s2 / post_var))
    const = 0.5 * 6 * (post_var / s2 - 1 + np.log(s2 / post_var))
    weight = d.betas[t] ** 2 / (2 * s2 * d.alphas[t] * (1 - d.alphas_bar[t]))
    assert float(kl - const) == pytest.approx(weight * float(((eps - eps_hat) ** 2).sum()), rel=1e-9)


def test_sampling_with_the_exact_noise_recovers_a_gaussian():
    """With the exact eps of Gaussian data, the reverse chain (Eq. 5, 7) samples that Gaussian."""
    d = GaussianDiffusion(linear_betas(300, 1e-4, 0.04))
    m, s = 2.0, 0.5

    def oracle(xt, t_model, mask):
        abar = torch.as_tensor(d.alphas_bar[t_model.long().numpy()])[:, None]
        return (1 - abar).sqrt() * (xt - abar.sqrt() * m) / (abar * s * s + 1 - abar)

    x = d.sample(oracle, (20_000, 1), seed=3, progress=False)
    assert x.mean().item() == pytest.approx(m, abs=0.03)
    assert x.std().item() == pytest.approx(s, abs=0.03)
    x50 = d.respace(50).sample(oracle, (20_000, 1), seed=3, progress=False)
    assert x50.mean().item() == pytest.approx(m, abs=0.05) and x50.std().item() == pytest.approx(s, abs=0.05)


def test_sampling_is_deterministic_and_last_step_adds_no_noise():
    d = GaussianDiffusion(linear_betas(20))
    model = lambda x, t, mask: 0.1 * x  # noqa: E731
    a = d.sample(model, (4, 3), seed=5, progress=False)
    b = d.sample(model, (4, 3), seed=5, progress=False)
    torch.testing.assert_close(a, b)
    x1 = torch.randn(4, 3)
    s1, out = d.p_sample(model, x1, 1, torch.Generator().manual_seed(0))
    s2, _ = d.p_sample(model, x1, 1, torch.Generator().manual_seed(9))
    torch.testing.assert_close(s1, out["mean"])
    torch.testing.assert_close(s1, s2)


def test_a_chain_stopped_at_end_step_continues_exactly_on_its_generator():
    # the particles of text control stop K chains at step k and continue one: with the same generator,
    # stopping and continuing is the uninterrupted chain, draw for draw
    d = GaussianDiffusion(linear_betas(20))
    model = lambda x, t, mask: 0.1 * x  # noqa: E731
    whole = d.sample(model, (4, 3), seed=5, progress=False)
    g = torch.Generator().manual_seed(5)
    x7 = d.run(model, torch.randn((4, 3), generator=g), g, d.schedule(end=7), progress=False)
    torch.testing.assert_close(d.run(model, x7, g, d.schedule(start=7), progress=False), whole)
    for bad in (-1, 20, 1.5, True):
        with pytest.raises(ValueError, match="the end step must be an integer in 0..19"):
            d.schedule(end=bad)


def test_the_schedule_repeats_each_step_for_repaint_and_runs_from_start_to_end():
    d = GaussianDiffusion(linear_betas(5))
    assert d.schedule() == [5, 4, 3, 2, 1] and d.schedule(start=3, end=1) == [3, 2]
    assert d.schedule(resample=2) == [5, 5, 4, 4, 3, 3, 2, 2, 1]  # step 1 is never re-noised
    with pytest.raises(ValueError, match="resample must be a positive integer"):
        d.schedule(resample=0)


def test_respacing_keeps_alpha_bar_and_time_labels():
    d = GaussianDiffusion(linear_betas(2000))
    r = d.respace(50)
    assert r.num_steps == 50 and r.timesteps[1] == 1 and r.timesteps[-1] == 2000
    np.testing.assert_allclose(r.alphas_bar[1:], d.alphas_bar[r.timesteps[1:]])
    full = d.respace(2000)
    np.testing.assert_allclose(full.betas, d.betas)
    with pytest.raises(ValueError, match="respace to 1..2000 steps"):
        d.respace(0)
    seen = []
    r.p_sample(lambda x, t, mask: seen.append(t) or 0 * x, torch.zeros(2, 1), 50)
    assert seen[0].tolist() == [2000.0, 2000.0]


def test_training_loss_ignores_padded_frames():
    d = GaussianDiffusion(linear_betas(100))
    x0 = torch.randn(2, 6, 68, 3)
    mask = torch.tensor([[True] * 6, [True] * 4 + [False] * 2])
    model = lambda x, t, m: torch.where(m[:, :, None, None], torch.zeros_like(x), torch.full_like(x, 1e6))  # noqa: E731
    loss = d.training_loss(model, x0, t=torch.tensor([10, 10]), generator=torch.Generator().manual_seed(0), mask=mask)
    assert loss.item() < 10  # the huge predictions on padded frames do not count


def test_motion_weight_one_is_the_simple_loss_and_more_weighs_only_what_moves():
    d = GaussianDiffusion(linear_betas(100))
    x0, t, noise = torch.randn(3, 6, 68, 3), torch.tensor([5, 50, 90]), torch.randn(3, 6, 68, 3)
    mask = torch.tensor([[True] * 6, [True] * 4 + [False] * 2, [True] * 6])
    error = torch.randn(3, 6, 68, 3)
    moving = error - (error * mask[:, :, None, None]).sum(1, keepdim=True) / mask.sum(1)[:, None, None, None]
    loss = lambda err, w=1.0: d.training_loss(  # noqa: E731
        lambda x, tt, m: noise + err, x0, t=t, eps=noise, mask=mask, motion_weight=w).item()
    simple = d.training_loss(lambda x, tt, m: noise + error, x0, t=t, eps=noise, mask=mask).item()
    assert loss(error) == pytest.approx(simple, rel=1e-6)
    still = error[:, :1].expand(-1, 6, -1, -1)  # the same error on every frame: the anatomy's
    assert loss(still, 4.0) == pytest.approx(loss(still), rel=1e-6)
    assert loss(moving, 4.0) == pytest.approx(4 * loss(moving), rel=1e-5)  # zero mean over the valid frames


def test_posterior_equals_the_bayes_product_of_gaussians():
    """q(x_{t-1}|x_t,x_0) ∝ q(x_t|x_{t-1}) q(x_{t-1}|x_0): precisions add, means are precision-weighted."""
    d = GaussianDiffusion(linear_betas(2000))
    x0, xt = torch.randn(5), torch.randn(5)
    for t in (2, 37, 800, 2000):
        a, b, abar_prev = d.alphas[t], d.betas[t], d.alphas_bar[t - 1]
        # q(x_t | x_{t-1}) as a Gaussian in x_{t-1}: mean x_t / sqrt(a), variance b / a
        precision = a / b + 1 / (1 - abar_prev)
        mean = (np.sqrt(a) / b * xt + np.sqrt(abar_prev) / (1 - abar_prev) * x0) / precision
        got_mean, got_var = d.q_posterior(x0, xt, t)
        torch.testing.assert_close(got_mean, mean)
        assert float(got_var) == pytest.approx(1 / precision, rel=1e-12)


def test_bad_timesteps_and_betas():
    d = GaussianDiffusion(linear_betas(10))
    with pytest.raises(ValueError, match=r"timestep out of range: t must be in 0..10, got 11..11"):
        d.q_sample(torch.zeros(2), 11)
    with pytest.raises(ValueError, match="timestep out of range"):
        d.q_sample(torch.zeros(2, 3), torch.tensor([-1, 3]))
    for bad in ([0.0, 0.1], [0.5, 1.0], [], [[0.1]]):
        with pytest.raises(ValueError, match=r"betas must be a non-empty 1-D array with values in \(0, 1\)"):
            GaussianDiffusion(bad)


def test_trace_records_each_measure_after_every_step_and_samples_like_sample():
    diffusion = GaussianDiffusion(linear_betas(2000)).respace(10)
    model = lambda x, t, mask=None: torch.zeros_like(x)  # noqa: E731
    measures = {"norm": lambda t, x, out: float(x.norm())}
    x, record = diffusion.trace(model, (2, 3), measures, seed=4)
    assert torch.equal(x, diffusion.sample(model, (2, 3), seed=4, progress=False))
    assert len(record["t"]) == len(record["norm"]) == 10 and record["t"][-1] == 0
    assert record["t"] == sorted(record["t"], reverse=True)


def _gaussian_oracle(d, m, s):
    """The exact eps_theta of data N(m, s^2) on chain ``d``, called with d's time labels."""
    def oracle(xt, t_model, mask):
        abar = torch.as_tensor(d.alphas_bar[t_model.long().numpy()], dtype=xt.dtype)[:, None]
        return (1 - abar).sqrt() * (xt - abar.sqrt() * m) / (abar * s * s + 1 - abar)
    return oracle


def test_ddim_at_eta_1_is_the_ddpm_posterior_step_and_at_eta_0_is_deterministic():
    base = GaussianDiffusion(linear_betas(200), variance="posterior").respace(40)
    ddim1, ddim0 = base.with_eta(1.0), base.with_eta(0.0)
    model = lambda x, t, mask: 0.3 * x + 0.1  # noqa: E731
    x = torch.randn(5, 3, dtype=torch.float64)
    for t in (40, 17, 2):
        a, b = base.p_mean_variance(model, x, t), ddim1.p_mean_variance(model, x, t)
        torch.testing.assert_close(a["mean"], b["mean"])
        torch.testing.assert_close(a["variance"], b["variance"])
    torch.testing.assert_close(ddim0.sample(model, (4, 3), seed=1, progress=False)[1:],
                               ddim0.run(model, ddim0.sample(model, (4, 3), seed=1, progress=False) * 0 +
                                         torch.randn(4, 3, generator=torch.Generator().manual_seed(1)),
                                         seed=99, progress=False)[1:])
    assert repr(ddim0) == "GaussianDiffusion(T=40, DDIM eta=0)" and ddim0.respace(10).eta == 0.0


@pytest.mark.parametrize("eta", [0.0, 0.5])
def test_ddim_matches_the_diffusers_ddim_scheduler_step_by_step(eta):
    """The independent oracle: diffusers' DDIMScheduler, fed the same eps and noise.

    Index mapping: the book's t is 1-based (t = 1..T noisy, 0 the data); diffusers' timesteps are 0-based, so
    its timestep k is our paper step k + 1.  With "trailing" spacing and T = 2000, K = 50 diffusers keeps
    1999, 1959, ..., 39 and steps to k - 40 (the last step to its final alpha_bar of 1): our respaced chain
    on the paper steps 40, 80, ..., 2000, numbered 1..50 with abar_0 = 1."""
    import diffusers  # requirements-test.txt
    scheduler = diffusers.DDIMScheduler(num_train_timesteps=2000, beta_start=1e-4, beta_end=0.02,
                                        beta_schedule="linear", clip_sample=False, set_alpha_to_one=True,
                                        timestep_spacing="trailing", prediction_type="epsilon")
    scheduler.set_timesteps(50)
    ours = GaussianDiffusion(linear_betas(2000)).respace(list(range(40, 2001, 40))).with_eta(eta)
    assert [int(k) + 1 for k in scheduler.timesteps] == [int(v) for v in ours.timesteps[50:0:-1]]
    model = lambda x, t, mask: torch.tanh(x) * 0.9 + 0.05 * t.to(x.dtype)[:, None] / 2000  # noqa: E731
    gen = torch.Generator().manual_seed(0)
    x = theirs = torch.randn(3, 6, generator=gen)
    for t, k in zip(range(50, 0, -1), scheduler.timesteps):
        z = torch.randn(3, 6, generator=gen)
        out = ours.p_mean_variance(model, x, t)
        x = out["mean"] + ours.sigmas[t] * z
        theirs = scheduler.step(model(theirs, torch.full((3,), float(k) + 1), None), k, theirs, eta=eta,
                                variance_noise=z).prev_sample
        torch.testing.assert_close(x, theirs, rtol=1e-4, atol=1e-5)


def test_ddim_inversion_recovers_the_sequence_and_eta_outside_0_1_is_an_error():
    full = GaussianDiffusion(linear_betas(1000))
    d = full.respace(100).with_eta(0.0)
    oracle = _gaussian_oracle(full, 0.5, 0.8)  # the network sees the original time labels
    x0 = 0.5 + 0.8 * torch.randn(64, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    xt = d.invert(oracle, x0)
    assert abs(xt.std().item() - 1.0) < 0.2  # x_T looks like noise
    back = d.run(oracle, xt, progress=False)
    assert (back - x0).pow(2).mean().sqrt() < 0.02
    for bad in (-0.1, 1.5, True, "0"):
        with pytest.raises(ValueError, match="eta must be None"):
            GaussianDiffusion(linear_betas(10), eta=bad)


@pytest.mark.parametrize("prediction", ["eps", "x0", "v"])
def test_loss_weights_turn_the_eps_loss_into_each_targets_own_loss(prediction):
    """||x0 - x0_hat||^2 and ||v - v_hat||^2 of the x0 and v implied by an eps estimate are the eps-loss times
    loss_weights(t); min-SNR-gamma is one weighting whatever the target: min(SNR, gamma) / SNR on the eps-loss."""
    d = GaussianDiffusion(linear_betas(2000))
    gen = torch.Generator().manual_seed(0)
    x0, eps = torch.randn(6, 5, 68, 3, generator=gen), torch.randn(6, 5, 68, 3, generator=gen)
    t = torch.tensor([1, 10, 200, 900, 1500, 2000])
    eps_hat = eps + 0.3 * torch.randn(eps.shape, generator=gen)
    abar = torch.as_tensor(d.alphas_bar[t]).reshape(-1, 1, 1, 1)
    xt = abar.sqrt() * x0 + (1 - abar).sqrt() * eps
    x0_hat = d.predict_x0(xt, t, eps_hat)
    own = {"eps": (eps, eps_hat), "x0": (x0, x0_hat),
           "v": (abar.sqrt() * eps - (1 - abar).sqrt() * x0, abar.sqrt() * eps_hat - (1 - abar).sqrt() * x0_hat)}
    target, estimate = own[prediction]
    per_step = lambda a, b: ((a - b) ** 2).mean((1, 2, 3))  # noqa: E731
    torch.testing.assert_close(per_step(target, estimate),
                               torch.as_tensor(d.loss_weights(t.numpy(), prediction)) * per_step(eps, eps_hat))
    snr = d.alphas_bar[t] / (1 - d.alphas_bar[t])
    np.testing.assert_allclose(d.loss_weights(t.numpy(), prediction, min_snr_gamma=5.0), np.minimum(snr, 5) / snr)
    model = lambda x, time, mask: eps_hat  # noqa: E731
    loss = d.training_loss(model, x0, t=t, eps=eps, prediction=prediction)
    torch.testing.assert_close(loss, per_step(target, estimate).mean())


def test_v_and_x0_targets_match_the_diffusers_ddpm_scheduler():
    """The independent oracle: diffusers' velocity (get_velocity) is our v, and its DDPM step given a network's
    v or x0 output ("v_prediction", "sample") is our step given the eps that models.denoiser converts it to.
    Diffusers' timestep k is our paper step k + 1 (its timesteps are 0-based)."""
    import diffusers  # requirements-test.txt
    from facelib.models.denoiser import Denoiser, DenoiserConfig
    d = GaussianDiffusion(linear_betas(2000), variance="posterior")
    gen = torch.Generator().manual_seed(1)
    x0, eps = torch.randn(2, 4, 68, 3, generator=gen), torch.randn(2, 4, 68, 3, generator=gen)
    for prediction, kind in (("v", "v_prediction"), ("x0", "sample")):
        scheduler = diffusers.DDPMScheduler(num_train_timesteps=2000, beta_start=1e-4, beta_end=0.02,
                                            beta_schedule="linear", clip_sample=False, prediction_type=kind,
                                            variance_type="fixed_small")
        net = Denoiser(DenoiserConfig(width=16, depth=1, heads=2, ff=32, prediction=prediction)).double()
        for k in (5, 700, 1999):
            t = k + 1
            xt = d.q_sample(x0, torch.tensor([t, t]), eps)
            if prediction == "v":
                torch.testing.assert_close(scheduler.get_velocity(x0, eps, torch.tensor([k, k])),
                                           net.from_eps(xt, torch.tensor([t, t]), eps), rtol=1e-5, atol=1e-5)
            output = torch.randn(xt.shape, generator=gen)  # a network's raw output, read as its target
            z = torch.randn(xt.shape, generator=torch.Generator().manual_seed(k), dtype=xt.dtype)  # diffusers' draw
            eps_hat = net.to_eps(xt, torch.full((2,), float(t)), output)
            ours = d.mean_variance_from_eps(xt, t, eps_hat)
            theirs = scheduler.step(output, k, xt, generator=torch.Generator().manual_seed(k))
            # diffusers' abar (and the network's) is float32: agreement to 1e-4, where a wrong formula errs by O(1)
            torch.testing.assert_close(ours["x0"], theirs.pred_original_sample, rtol=1e-4, atol=1e-4)
            torch.testing.assert_close(ours["mean"] + ours["variance"].sqrt() * z, theirs.prev_sample, rtol=1e-4,
                                       atol=1e-4)
