"""Rectified flow on the DDPM's path (facelib/flow.py): the path is the DDPM's rescaled,
its Euler step is a DDIM step, its loss is a weighted eps-loss, and its sampler carries
noise to the data on a Gaussian world where the exact velocity is known."""
import numpy as np
import pytest
import torch

from facelib import config, tasks, training
from facelib.diffusion import GaussianDiffusion, flow_alphas_bar, named_betas
from facelib.flow import RectifiedFlow, flow_scale
from facelib.models.denoiser import Denoiser, DenoiserConfig

T = 2000


def small(prediction="u", schedule="flow", seed=0, zero_residual=False):
    torch.manual_seed(seed)
    model = Denoiser(DenoiserConfig(width=32, depth=1, heads=2, ff=32,
                                    schedule=schedule, prediction=prediction))
    if not zero_residual:  # a network that is not just its Gaussian estimate
        torch.nn.init.normal_(model.out.weight, std=0.05)
    return model.eval()


def test_the_straight_path_is_the_ddpm_path_rescaled():
    g = torch.Generator().manual_seed(0)
    x0, eps = torch.randn(5, 8, 68, 3, generator=g), torch.randn(5, 8, 68, 3, generator=g)
    tau = torch.tensor([0.0, 0.1, 0.5, 0.9, 1.0])
    x_tau = RectifiedFlow(T).interpolate(x0, tau, eps)
    abar = flow_alphas_bar(tau.double()).float().reshape(-1, 1, 1, 1)
    vp = abar.sqrt() * x0 + (1 - abar).sqrt() * eps
    s = flow_scale(tau).reshape(-1, 1, 1, 1)
    torch.testing.assert_close(x_tau / s, vp, atol=1e-6, rtol=1e-5)


def test_the_flow_schedule_has_the_flow_noise_levels():
    abar = np.cumprod(1 - named_betas("flow", T))
    tau = np.arange(1, T + 1) / T
    np.testing.assert_allclose(abar[:-1], flow_alphas_bar(tau[:-1]), rtol=1e-9)
    assert 0 < abar[-1] < 1e-6  # clipped: abar_T > 0, as the cosine schedule's


@pytest.mark.parametrize("prediction", ["eps", "x0", "v", "u"])
def test_every_target_converts_to_eps_and_back(prediction):
    model = small(prediction, "linear" if prediction != "u" else "flow")
    g = torch.Generator().manual_seed(1)
    x, eps = torch.randn(4, 6, 68, 3, generator=g), torch.randn(4, 6, 68, 3, generator=g)
    t = torch.tensor([10.0, 500.0, 1000.0, 1990.0])
    back = model.to_eps(x, t, model.from_eps(x, t, eps))
    torch.testing.assert_close(back, eps, atol=1e-4, rtol=1e-4)


def test_the_gaussian_velocity_is_the_gaussian_eps_minus_the_gaussian_x0():
    model = small()
    model.fit_prior(torch.randn(500, 68, 3) * torch.linspace(0.2, 2.0, 204).reshape(68, 3))
    x = torch.randn(3, 5, 68, 3)
    t = torch.tensor([200.0, 1000.0, 1800.0])
    eps = model.gaussian_eps(x, t)
    abar = model._abar(t, x)
    x0 = (x - (1 - abar).sqrt() * eps) / abar.sqrt()
    torch.testing.assert_close(model.gaussian_u(x, t), eps - x0, atol=1e-4, rtol=1e-4)
    # finite where x_0 cannot be had from eps: pure noise, abar = 0
    u_end = model.gaussian_u(x, torch.full((3,), float(T)))
    torch.testing.assert_close(u_end, x)  # E[x_0 | noise] = 0, so u = eps = x


def test_one_euler_step_is_one_ddim_step():
    """x_tau' = x_tau + (tau' - tau) u is DDIM (eta = 0) between abar(tau) and
    abar(tau') in the variance-preserving coordinates x / s."""
    model = small()
    flow = RectifiedFlow(T)
    x = torch.randn(2, 6, 68, 3, generator=torch.Generator().manual_seed(3))
    for tau, nxt in ((0.9, 0.7), (0.5, 0.45), (0.2, 0.0)):
        with torch.no_grad():
            euler = x + (nxt - tau) * flow.velocity(model, x, tau)
            y = x / flow_scale(tau)
            t = torch.full((2,), tau * T)
            eps = model(y, t)
            a, a_next = flow_alphas_bar(tau), flow_alphas_bar(nxt)
            x0 = (y - (1 - a) ** 0.5 * eps) / a**0.5
            ddim = (a_next**0.5 * x0 + (1 - a_next) ** 0.5 * eps) * flow_scale(nxt)
        torch.testing.assert_close(euler, ddim, atol=2e-5, rtol=1e-4)


def test_the_flow_loss_is_the_eps_loss_weighted_by_one_over_one_minus_tau_squared():
    model = small()
    flow = RectifiedFlow(T)
    g = torch.Generator().manual_seed(4)
    x0, eps = torch.randn(1, 6, 68, 3, generator=g), torch.randn(1, 6, 68, 3, generator=g)
    for tau in (0.05, 0.3, 0.8):
        tau_ = torch.tensor([tau], dtype=torch.float64)
        with torch.no_grad():
            loss = flow.training_loss(model, x0, tau=tau_, eps=eps)
            x_tau = flow.interpolate(x0, tau_, eps)
            eps_hat = model(x_tau / flow_scale(tau), torch.tensor([tau * T]))
            weighted = ((eps - eps_hat) ** 2).mean() / (1 - tau) ** 2
            # and GaussianDiffusion's weight of a u-target says the same, (1 + 1/sqrt(SNR))^2
            snr = flow_alphas_bar(tau) / (1 - flow_alphas_bar(tau))
            assert (1 + snr**-0.5) ** 2 == pytest.approx(1 / (1 - tau) ** 2)
        assert loss.item() == pytest.approx(weighted.item(), rel=1e-3)


def test_the_sampler_carries_noise_to_a_gaussian_world():
    """Frames drawn from N(0, Sigma): a denoiser that is its Gaussian estimate alone
    (zero residual) has the exact velocity, so the ODE carries noise to samples of
    covariance Sigma, Heun's second-order method closer than Euler's at equal steps; one
    Euler step lands on E[x_0 | noise] = 0."""
    model = small(zero_residual=True)
    std = torch.linspace(0.1, 1.5, 204)
    model.fit_prior(torch.randn(20_000, 204) * std)
    flow = RectifiedFlow(T)

    def error(steps, solver):  # |measured std / std - 1| over the 204 coordinates
        g = torch.Generator().manual_seed(5)
        x = flow.sample(model, (800, 4, 68, 3), steps, solver, generator=g)
        return (x.reshape(-1, 204).std(0) / std - 1).abs()

    fine = error(64, "heun")
    assert fine.mean() < 0.02 and fine.max() < 0.07, fine.aminmax()
    assert error(16, "heun").mean() < error(16, "euler").mean() / 2
    one = flow.sample(model, (10, 4, 68, 3), 1, generator=torch.Generator())
    assert one.abs().max() < 1e-5


def test_the_sampler_is_reproducible_and_heun_calls_the_network_2k_minus_1_times():
    model = small()
    flow = RectifiedFlow(T)
    a = flow.sample(model, (2, 6, 68, 3), 4, generator=torch.Generator().manual_seed(7))
    b = flow.sample(model, (2, 6, 68, 3), 4, generator=torch.Generator().manual_seed(7))
    torch.testing.assert_close(a, b, rtol=0, atol=0)
    calls = []
    model.register_forward_hook(lambda *args: calls.append(1))
    model.velocity = (lambda f: (lambda *a, **k: (calls.append(1), f(*a, **k))[1]))(model.velocity)
    calls.clear()
    flow.sample(model, (2, 6, 68, 3), 4, solver="heun", generator=torch.Generator().manual_seed(7))
    assert len(calls) == 2 * 4 - 1


def test_bad_flow_input_is_refused():
    model = small()
    flow = RectifiedFlow(T)
    with pytest.raises(ValueError, match="solver 'rk4'; allowed: euler, heun"):
        flow.sample(model, (1, 4, 68, 3), 4, solver="rk4")
    for steps in (0, 2.5, True):
        with pytest.raises(ValueError, match="positive integer"):
            flow.sample(model, (1, 4, 68, 3), steps)
    with pytest.raises(ValueError, match=r"tau must lie in \[0, 1\]"):
        flow.training_loss(model, torch.zeros(1, 4, 68, 3), tau=torch.tensor([1.5]))
    with pytest.raises(ValueError, match="prediction='u', not 'eps'"):
        training.DenoiserTraining(schedule="flow")
    with pytest.raises(ValueError, match="not the flow's"):
        training.DenoiserTraining(schedule="flow", prediction="u", min_snr_gamma=5.0)


def test_a_flow_denoisers_chain_of_k_steps_is_eulers_uniform_grid():
    from facelib.tasks import TrainedDenoiser, load_denoiser
    ref = load_denoiser("denoiser_coma")
    flow = TrainedDenoiser(small(), ref.normalizer,
                           GaussianDiffusion(named_betas("flow", T)),
                           {"training": {"num_diffusion_steps": T, "schedule": "flow",
                                         "dataset": "coma"}, "name": "a small flow"})
    for k in (1, 4, 7):
        grid = RectifiedFlow(T).times(k).numpy() * T
        np.testing.assert_allclose(flow.diffusion_with(k, eta=0.0).timesteps[::-1], grid, atol=0.5)
    # the linear model keeps its own respacing unless told to trail
    assert ref.diffusion_with(4).timesteps.tolist() == [0, 1, 667, 1334, 2000]
    assert ref.diffusion_with(4, spacing="trailing").timesteps.tolist() == [0, 500, 1000, 1500, 2000]
    assert ref.diffusion_with(1).timesteps.tolist() == [0, 2000]  # one step starts at T
    with pytest.raises(ValueError, match="unknown spacing 'leading'; allowed: uniform, trailing"):
        ref.diffusion_with(4, spacing="leading")
    with pytest.raises(ValueError, match="spacing must be one of"):
        tasks.Unconditional(spacing="leading")


def test_a_guide_of_another_schedule_reads_the_chains_noise_level():
    from facelib.diffusion import NoiseLevelMatched, named_alphas_bar
    seen = []
    net = lambda x, t: seen.append(t) or x.sum()
    linear, flow = named_alphas_bar("linear", T), named_alphas_bar("flow", T)
    same = NoiseLevelMatched(net, linear, linear)
    same(torch.zeros(3, 1), torch.tensor([1.0, 700.0, 1999.0]))
    np.testing.assert_allclose(seen[-1].numpy(), [1, 700, 1999], atol=1e-3)
    matched = NoiseLevelMatched(net, linear, flow)
    t = torch.tensor([20.0, 500.0, 1000.0, 1500.0])
    matched(torch.zeros(4, 1), t)
    # the linear schedule's abar at the label it was given is the flow's abar at t
    ab_lin = np.interp(seen[-1].numpy(), np.arange(T + 1), linear)
    np.testing.assert_allclose(ab_lin, flow_alphas_bar(t.numpy() / T), rtol=0.02)


def test_label_control_guides_the_flow_with_the_linear_schedules_classifier():
    from facelib import tasks
    from facelib.diffusion import NoiseLevelMatched
    ref, guide = tasks.load_denoiser("denoiser_coma"), tasks.load_guide("coma")
    flow = tasks.TrainedDenoiser(small(), ref.normalizer,
                                 GaussianDiffusion(named_betas("flow", T)),
                                 {"training": {"num_diffusion_steps": T, "schedule": "flow",
                                               "dataset": "coma"}, "name": "a small flow"})
    settings = tasks.LabelControl(steps=4, sampler="flow")
    _, chain, matched = tasks.loading.guided_chain(guide, flow, settings)
    assert isinstance(matched.model, NoiseLevelMatched) and chain.eta == 0.0
    _, _, same = tasks.loading.guided_chain(guide, ref, tasks.LabelControl(steps=4, sampler="ddim"))
    assert same is guide  # its own schedule: unchanged
    with pytest.raises(ValueError, match="denoiser_coma is sampled by 'ddpm' or 'ddim', not by 'flow'"):
        tasks.loading.guided_chain(guide, ref, settings)
    x = tasks.label_control("high_smile", 2, steps=4, sampler="flow", denoiser=flow,
                            guide=guide, progress=False)
    assert x.shape == (2, 40, 68, 3) and np.isfinite(x).all()


def test_the_sampler_names_the_denoiser_it_runs_and_refuses_what_is_not_shipped(monkeypatch):
    from facelib import tasks
    monkeypatch.setattr(tasks.loading, "shipped_students", lambda dataset, variant=None: [1, 4])
    assert tasks.denoiser_name("coma", "ddim") == "denoiser_coma"
    assert tasks.denoiser_name("coma", "ddpm", variant="cfg") == "denoiser_coma_cfg"
    assert tasks.denoiser_name("coma", "flow") == "denoiser_coma_flow"
    assert tasks.denoiser_name("coma", "student", 4) == "student_denoiser_coma_4"
    with pytest.raises(ValueError, match="no student of denoiser_coma distilled for steps=50; the shipped students take 1, 4 steps"):
        tasks.denoiser_name("coma", "student", 50)
    with pytest.raises(ValueError, match="the flow sampler has no 'cfg' denoiser"):
        tasks.denoiser_name("coma", "flow", variant="cfg")
    with pytest.raises(ValueError, match="unknown sampler 'x'; allowed: ddpm, ddim, student, flow"):
        tasks.denoiser_name("coma", "x")
    s = tasks.Unconditional(sampler="student", steps=4)
    assert s.fast().steps == 4 and s.ddim_eta == 0.0
    assert tasks.Unconditional(sampler="flow").fast().steps == 20


def test_the_mean_shift_guides_nothing_from_the_flows_pure_noise():
    """At the flow's t = T (abar ~ 2.5e-10) the mean shift's x0_hat would move by 1 /
    sqrt(abar) times its change of eps; below config.GUIDANCE_MIN_ABAR it leaves the
    step alone, and guides the steps after it."""
    from facelib.guidance import MeanShiftGuidance
    chain = GaussianDiffusion(named_betas("flow", T)).respace([500, 1000, 1500, 2000]).with_eta(0.0)
    assert chain.alphas_bar[4] < config.GUIDANCE_MIN_ABAR < chain.alphas_bar[3]
    hook = MeanShiftGuidance(lambda x, t: x.sum(dim=(1, 2, 3)), chain, scale=10.0)
    x = torch.randn(2, 5, 68, 3, generator=torch.Generator().manual_seed(0))
    out = chain.model_estimates(lambda x, t, mask=None: x, x, 3)
    out = chain.mean_variance_from_eps(x, 3, *out)
    x_hat = out["mean"]
    assert torch.equal(hook(x_hat, x, 4, {**out}), x_hat)
    assert not torch.equal(hook(x_hat, x, 3, out), x_hat)
