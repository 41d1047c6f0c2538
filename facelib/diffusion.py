"""Gaussian diffusion (DDPM, paper §3.1): schedules, the forward process, the reverse
process.

Time convention (said once, here): **t is 1-based, as in the paper**.  t = 1..T are the
noisy steps and t = 0 is the data; every coefficient array has length T + 1 and is
indexed by the paper's t, e.g. ``alphas_bar[t]`` is alpha_bar_t with ``alphas_bar[0] =
1`` and ``betas[0] = 0``.

Schedules are free functions; :class:`GaussianDiffusion` precomputes every coefficient
in float64 (numpy) and owns every closed form:

* ``q_sample``: x_t ~ q(x_t | x_0) = N(sqrt(abar_t) x_0, (1 - abar_t) I)  (Eq. 3, 6)
* ``q_posterior``: q(x_{t-1} | x_t, x_0) = N(mu~_t, beta~_t I)
* ``p_mean_variance``: mu_theta(x_t, t) = (x_t - beta_t / sqrt(1 - abar_t) eps_theta)
  / sqrt(alpha_t)  (Eq. 7, in its correct form: the paper prints sqrt(1 - alpha_t))
* ``p_sample``: x_{t-1} ~ p_theta(x_{t-1} | x_t) = N(mu_theta, sigma_t^2 I),
  sigma_t^2 = beta_t  (Eq. 5, §4)
* ``sample``, ``run``: the reverse chain from x_T ~ N(0, I), or any part of it from a
  given x (``schedule``)
* ``training_loss``: E ||eps - eps_theta(x_t, t)||^2  (Eq. 8), weighted per step
  (``loss_weights``): the loss of an x0 or v prediction target, min-SNR-gamma
* ``respace``: the same model on a subset of the steps (fewer steps, no retraining)
* ``eta``: DDIM (Song et al. 2021, Eq. 12) instead of the ancestral step: the same
  trained model, x_{t-1} = sqrt(abar_{t-1}) x0_hat + sqrt(1 - abar_{t-1} - sigma_t^2)
  eps_theta + sigma_t z with sigma_t^2 = eta^2 beta~_t: deterministic at eta = 0, the
  DDPM posterior at eta = 1
* ``invert``: DDIM inversion (eta = 0 run backwards): x_0 -> x_T, from which ``run``
  regenerates x_0

Respacing (Nichol & Dhariwal 2021; guided-diffusion's ``respace.py``): a respaced chain
keeps the steps ``timesteps`` of the original schedule and numbers them 1..K.
Everything outside this module speaks in the chain's own steps t;
:meth:`GaussianDiffusion.wrap` gives a network (denoiser, classifier, text head) that is
called with the chain's step and receives its own time label, ``timesteps[t]``, inside
the call.
"""

from __future__ import annotations

import itertools

import numpy as np
import torch
from tqdm.auto import tqdm

from .config import check_prediction

VARIANCES = ("beta", "posterior")


def linear_betas(num_steps=2000, beta_start=1e-4, beta_end=0.02):
    """beta_1..beta_T growing linearly (paper §4: 1e-4 to 0.02, T = 2000), shape
    (T,)."""
    _check_steps(num_steps)
    return np.linspace(beta_start, beta_end, num_steps, dtype=np.float64)


def cosine_betas(num_steps=2000, s=0.008, max_beta=0.999):
    """The cosine schedule of Nichol & Dhariwal (2021): abar_t = cos^2((t/T + s)/(1 + s)
    pi/2)/f(0)."""
    _check_steps(num_steps)
    t = np.arange(num_steps + 1, dtype=np.float64) / num_steps
    f = np.cos((t + s) / (1 + s) * np.pi / 2) ** 2
    abar = f / f[0]
    return np.clip(1.0 - abar[1:] / abar[:-1], 0.0, max_beta)


def flow_alphas_bar(tau):
    """abar(tau) = (1 - tau)^2 / ((1 - tau)^2 + tau^2): rectified flow's straight path
    x_tau = (1 - tau) x_0 + tau eps, divided by its scale sqrt((1 - tau)^2 + tau^2), is
    the variance-preserving x_t at this abar (facelib/flow.py; numpy or torch)."""
    return (1 - tau) ** 2 / ((1 - tau) ** 2 + tau**2)


def flow_betas(num_steps=2000, max_beta=0.999):
    """The betas whose abar_t is :func:`flow_alphas_bar` at tau = t / T (the last one
    clipped, as the cosine schedule's, so that abar_T > 0)."""
    _check_steps(num_steps)
    abar = flow_alphas_bar(np.arange(num_steps + 1, dtype=np.float64) / num_steps)
    return np.clip(1.0 - abar[1:] / abar[:-1], 0.0, max_beta)


def halving_steps(steps, num_steps=2000):
    """The chain of ``steps`` steps of the T = ``num_steps`` chain whose every other
    step is the chain of steps / 2: round(i T / steps), i = 0..steps (int array, 0
    first). Progressive distillation's student of steps / 2 steps spans two of these at
    a time."""
    _check_steps(steps)
    if steps > num_steps:
        raise ValueError(f"a chain of T = {num_steps} has at most {num_steps} steps")
    return np.round(np.arange(steps + 1) * num_steps / steps).astype(int)


def named_betas(name, num_steps):
    """Schedule by name: "linear" (the paper's), "cosine" or "flow" (rectified flow's
    path as a DDPM schedule)."""
    schedules = {"linear": linear_betas, "cosine": cosine_betas, "flow": flow_betas}
    if name not in schedules:
        raise ValueError(
            f"unknown noise schedule {name!r}; allowed: {', '.join(schedules)}"
        )
    return schedules[name](num_steps)


def _check_steps(num_steps):
    if (
        isinstance(num_steps, bool)
        or not isinstance(num_steps, (int, np.integer))
        or num_steps < 1
    ):
        raise ValueError(
            "the number of diffusion steps must be a positive integer, got"
            f" {num_steps!r}"
        )


def _extract(array, t, x):
    """array[t] as a float tensor on x's device, shaped to broadcast against x (batch
    first)."""
    t = torch.as_tensor(t, device="cpu").long()
    if t.numel() and (t.min() < 0 or t.max() >= len(array)):
        raise ValueError(
            f"timestep out of range: t must be in 0..{len(array) - 1}, got"
            f" {t.min().item()}..{t.max().item()}"
        )
    values = torch.as_tensor(array, dtype=torch.float64)[t].to(
        device=x.device, dtype=x.dtype
    )
    return values.reshape(values.shape + (1,) * (x.ndim - values.ndim))


def ddim_step(x, x0, a, a_next):
    """DDIM (eta = 0) from noise level abar = a to a_next given the clean estimate x0:
    sqrt(a_next) x0 + sqrt(1 - a_next) (x - sqrt(a) x0) / sqrt(1 - a)."""
    eps = (x - a.sqrt() * x0) / (1 - a).sqrt()
    return a_next.sqrt() * x0 + (1 - a_next).sqrt() * eps


def masked_mean(err, mask=None):
    """The mean of err (B, F, 68, 3) over the valid frames of ``mask`` (B, F) (all
    frames if None)."""
    if mask is None:
        return err.mean()
    m = mask[:, :, None, None].to(err.dtype)
    return (err * m).sum() / (m.sum() * err.shape[2] * err.shape[3])


def motion_weighted(err, weight, mask=None):
    """The residual err (B, F, 68, 3) split into its mean over the (valid) frames, the
    static part (the sequence's anatomy and held pose), and what moves, each squared:
    m^2 + weight (err - m)^2.  Averaged over frames it is ||err||^2 at weight 1 (the
    cross term averages to zero); weight > 1 counts an error in the motion more than one
    in the anatomy (issue 58's representation ablation)."""
    if mask is None:
        mask = torch.ones(err.shape[:2], dtype=torch.bool, device=err.device)
    m = mask.to(err.dtype)[:, :, None, None]
    static = (err * m).sum(1, keepdim=True) / m.sum(1, keepdim=True)
    return static**2 + weight * (err - static) ** 2


def device_of(network):
    """The device of a module's first parameter or buffer (None for a plain function or
    an empty module)."""
    if isinstance(network, torch.nn.Module):
        for tensor in itertools.chain(network.parameters(), network.buffers()):
            return tensor.device
    return None


class _Relabelled(torch.nn.Module):
    """A network called as ``net(x, t, ...)``, ``net.log_prob``, ``net.embed`` or
    ``net.cosine`` whose time argument is relabelled by ``self.time(t, x)`` first."""

    def forward(self, x, t, *args, **kwargs):
        return self.network(x, self.time(t, x), *args, **kwargs)

    def log_prob(self, x, t, *args, **kwargs):
        return self.network.log_prob(x, self.time(t, x), *args, **kwargs)

    def embed(self, x, t, *args, **kwargs):
        return self.network.embed(x, self.time(t, x), *args, **kwargs)

    def cosine(self, x, t, *args, **kwargs):
        return self.network.cosine(x, self.time(t, x), *args, **kwargs)

    def eps_and_x0(self, x, t, *args, **kwargs):
        return self.network.eps_and_x0(x, self.time(t, x), *args, **kwargs)


class TimeMapped(_Relabelled):
    """A network seen through a (respaced) chain: called as ``net(x, t, ...)``,
    ``net.log_prob(x, t, ...)``, ``net.embed(x, t, ...)`` or ``net.cosine(x, t, ...)``
    with the chain's step t (an int or a (B,) tensor), it feeds the network its own time
    label ``timesteps[t]`` (guided-diffusion's ``_WrappedModel``).

    ``network`` may be a module or a plain function ``f(x, time, ...)``: a reader's own
    classifier or score receives the noise level's time label like the book's networks
    (guided-diffusion's spaced ``cond_fn``).
    """

    def __init__(self, network, timesteps):
        super().__init__()
        self.network = network
        self.register_buffer(
            "timesteps",
            torch.as_tensor(timesteps, dtype=torch.float32),
            persistent=False,
        )

    def time(self, t, x):
        """The network's time labels (B,) for the chain's step t and a batch x."""
        t = torch.as_tensor(t, device=self.timesteps.device)
        labels = self.timesteps[t.round().long()]
        return (labels.expand(len(x)) if labels.ndim == 0 else labels).to(x.device)


def named_alphas_bar(name, num_steps):
    """abar_0 = 1, abar_1, ..., abar_T of a named schedule."""
    return np.concatenate([[1.0], np.cumprod(1.0 - named_betas(name, num_steps))])


class NoiseLevelMatched(_Relabelled):
    """A network trained on one noise schedule, read on another: called with a time
    label of the chain's schedule (abar ``chain_alphas_bar``, labels 0..T'), it feeds
    the network the label of its own schedule (``own_alphas_bar``) at the same noise
    level, log abar interpolated between steps.  The book's classifiers, trained on the
    linear schedule, guide the rectified flow this way (chapter 14): the same label is
    another noise level on each schedule.
    """

    def __init__(self, network, own_alphas_bar, chain_alphas_bar):
        super().__init__()
        self.network = network
        # log abar, increasing, against the labels, for np.interp
        self.own = np.log(np.asarray(own_alphas_bar, dtype=np.float64))[::-1]
        self.chain = np.log(np.asarray(chain_alphas_bar, dtype=np.float64))

    def time(self, t, x):
        t = torch.as_tensor(t, dtype=torch.float64).cpu().numpy()
        level = np.interp(t, np.arange(len(self.chain)), self.chain)
        labels = np.interp(level, self.own, np.arange(len(self.own))[::-1])
        labels = torch.as_tensor(labels, dtype=torch.float32)
        return (labels.expand(len(x)) if labels.ndim == 0 else labels).to(x.device)


class GaussianDiffusion:
    """Every closed form of a DDPM with the given betas (beta_1..beta_T), t 1-based.

    variance: "beta" uses sigma_t^2 = beta_t (paper §4); "posterior" uses beta~_t.
    timesteps: the model's time label of each step (default 1..T; respacing keeps the
    original ones). eta: None for the ancestral DDPM step (Eq. 5); a number in [0, 1]
    for DDIM's step with sigma_t^2 = eta^2 beta~_t (``variance`` then does not apply).
    """

    def __init__(self, betas, variance="beta", timesteps=None, eta=None):
        betas = np.asarray(betas, dtype=np.float64)
        if betas.ndim != 1 or len(betas) == 0 or not np.all((betas > 0) & (betas < 1)):
            raise ValueError(
                "betas must be a non-empty 1-D array with values in (0, 1)"
            )
        if variance not in VARIANCES:
            raise ValueError(f"variance must be one of {VARIANCES}, got {variance!r}")
        if eta is not None and (
            isinstance(eta, bool)
            or not isinstance(eta, (int, float))
            or not 0 <= eta <= 1
        ):
            raise ValueError(
                "eta must be None (DDPM) or a number in [0, 1] (DDIM; 0:"
                f" deterministic), got {eta!r}"
            )
        self.num_steps = len(betas)
        self.variance = variance
        self.eta = None if eta is None else float(eta)
        self.betas = np.concatenate([[0.0], betas])
        self.alphas = 1.0 - self.betas
        self.alphas_bar = np.cumprod(self.alphas)
        # abar_{t-1}
        self.alphas_bar_prev = np.concatenate([[1.0], self.alphas_bar[:-1]])
        self.sqrt_alphas_bar = np.sqrt(self.alphas_bar)
        self.sqrt_one_minus_alphas_bar = np.sqrt(1.0 - self.alphas_bar)
        with np.errstate(divide="ignore", invalid="ignore"):
            # q(x_{t-1} | x_t, x_0) = N(coef_x0 x_0 + coef_xt x_t, beta~_t I), defined
            # for t >= 1.
            self.posterior_variance = np.nan_to_num(
                self.betas * (1.0 - self.alphas_bar_prev) / (1.0 - self.alphas_bar)
            )
            self.posterior_coef_x0 = np.nan_to_num(
                np.sqrt(self.alphas_bar_prev) * self.betas / (1.0 - self.alphas_bar)
            )
            self.posterior_coef_xt = np.nan_to_num(
                np.sqrt(self.alphas)
                * (1.0 - self.alphas_bar_prev)
                / (1.0 - self.alphas_bar)
            )
            # Eq. 7: mu = (x_t - eps_coef * eps) / sqrt(alpha_t), eps_coef = beta_t /
            # sqrt(1 - abar_t).
            self.eps_coef = np.nan_to_num(self.betas / self.sqrt_one_minus_alphas_bar)
        # DDIM: sigma_t^2 = eta^2 (1 - abar_{t-1}) / (1 - abar_t) (1 - abar_t /
        # abar_{t-1})
        if self.eta is not None:
            self.sigmas = self.eta * np.sqrt(self.posterior_variance)
        else:
            self.sigmas = np.sqrt(
                self.betas if variance == "beta" else self.posterior_variance
            )
        self.timesteps = (
            np.arange(self.num_steps + 1)
            if timesteps is None
            else np.asarray(timesteps)
        )
        # the networks' time of each step
        self.time_labels = torch.as_tensor(self.timesteps, dtype=torch.float32)

    @property
    def deterministic(self):
        """Whether a step adds no noise: DDIM at eta = 0 (the chain of a distilled
        student and of the flow's Euler steps too), the chains that keep every push a
        guidance hook gives them to the end."""
        return self.eta == 0

    def guidance_push(self, t):
        """The factor sqrt(abar_t)^(1 - eta^2) by which a guidance hook scales a push
        along grad_{x_t} of a clean-estimate loss at step t (1 for the ancestral
        chain, eta = None).

        A push of x_{t-1} enters x0_hat = (x - sqrt(1 - abar) eps) / sqrt(abar) at the
        next steps.  While x_t is mostly noise, a DDIM step carries a push by
        sqrt((1 - abar_{t-1} - sigma_t^2) / (1 - abar_t)) into x_{t-2}: about 1 at eta
        = 0 and sqrt(alpha_t) at eta = 1 (the ancestral chain's own contraction), so
        that down the chain eta keeps sqrt(abar_t)^(eta^2) of it relative to eta = 0.
        Scaling the push by the rest, sqrt(abar_t)^(1 - eta^2), makes every chain
        keep sqrt(abar_t) of it: the gradient's 1 / sqrt(abar_t) (about 150 at t = T
        on the linear schedule) is undone whatever eta, and the hook is continuous in
        eta (filling by DDIM-50 missed the unknown frames by 57 mm at eta = 0.02 when
        only eta = 0 was scaled; tests/test_guidance.py)."""
        eta = 1.0 if self.eta is None else self.eta
        return float(self.sqrt_alphas_bar[t]) ** (1.0 - eta**2)

    def guides(self, t, max_time=None, min_abar=0.0):
        """Whether guidance acts at step t: its time label is at most ``max_time``
        (None: no bound; text control's best-of-K leaves the noisiest steps alone) and
        x_t holds at least ``min_abar`` of signal (the mean shift under DDIM asks for
        config.GUIDANCE_MIN_ABAR: its x0_hat moves by 1 / sqrt(abar_t) times its change
        of eps).  The one place every hook asks."""
        return bool(self.alphas_bar[t] >= min_abar) and (
            max_time is None or float(self.timesteps[t]) <= max_time
        )

    def __repr__(self):
        sampler = (
            f"variance={self.variance!r}"
            if self.eta is None
            else f"DDIM eta={self.eta:g}"
        )
        return f"GaussianDiffusion(T={self.num_steps}, {sampler})"

    # -----------------------------------------------------------------------------
    # forward process
    def q_sample(self, x0, t, eps=None, generator=None):
        """Sample x_t ~ q(x_t | x_0) = N(sqrt(abar_t) x_0, (1 - abar_t) I)
        (Eq. 3; Eq. 6 with eps)."""
        if eps is None:
            eps = torch.randn(x0.shape, generator=generator, dtype=x0.dtype).to(
                x0.device
            )
        return (
            _extract(self.sqrt_alphas_bar, t, x0) * x0
            + _extract(self.sqrt_one_minus_alphas_bar, t, x0) * eps
        )

    def q_step(self, x_prev, t, generator=None):
        """Sample x_t ~ q(x_t | x_{t-1}) = N(sqrt(1 - beta_t) x_{t-1}, beta_t I)
        (Eq. 2)."""
        eps = torch.randn(x_prev.shape, generator=generator, dtype=x_prev.dtype).to(
            x_prev.device
        )
        return (
            _extract(np.sqrt(self.alphas), t, x_prev) * x_prev
            + _extract(np.sqrt(self.betas), t, x_prev) * eps
        )

    def q_posterior(self, x0, xt, t):
        """Mean and variance of q(x_{t-1} | x_t, x_0) = N(mu~_t(x_t, x_0), beta~_t
        I)."""
        mean = (
            _extract(self.posterior_coef_x0, t, xt) * x0
            + _extract(self.posterior_coef_xt, t, xt) * xt
        )
        return mean, _extract(self.posterior_variance, t, xt)

    def predict_x0(self, xt, t, eps):
        """x_0 implied by x_t and a noise estimate: invert Eq. 6."""
        return (xt - _extract(self.sqrt_one_minus_alphas_bar, t, xt) * eps) / _extract(
            self.sqrt_alphas_bar, t, xt
        )

    # -----------------------------------------------------------------------------
    # reverse process
    def model_time(self, t, batch):
        """The time label fed to the network for step t of this (maybe respaced)
        schedule, shape (batch,)."""
        return torch.full((batch,), float(self.timesteps[t]))

    def wrap(self, network):
        """``network`` called with this chain's steps (see :class:`TimeMapped`); a
        network already wrapped for this chain is returned as it is."""
        if isinstance(network, TimeMapped) and torch.equal(
            network.timesteps.cpu(), self.time_labels
        ):
            return network
        mapped = TimeMapped(network, self.time_labels)
        device = device_of(network)
        return mapped if device is None else mapped.to(device)

    def p_mean_variance(self, model, xt, t, mask=None):
        """Mean and variance of p_theta(x_{t-1} | x_t) from eps_theta, and x0_hat: Eq. 7
        (correct form), or with ``eta`` DDIM's sqrt(abar_{t-1}) x0_hat + sqrt(1 -
        abar_{t-1} - sigma_t^2) eps_theta.

        "guidance_variance" is the variance the guidance of Alg. 1-4 weighs its pull
        with: the step's own under DDPM (beta_t where that is 0, the posterior variance
        of the last step); under DDIM, whose own is eta^2 beta~_t (0 at
        eta = 0), the paper's sigma_t^2 = beta_t, so that guidance pulls about as hard
        whatever the sampler's noise (our choice).  "time" is the network's time label
        of step t (what hooks and callbacks, which are given the chain's step, read the
        noise level by).
        """
        eps, x0 = self.model_estimates(model, xt, t, mask)
        return {
            **self.mean_variance_from_eps(xt, t, eps, x0),
            "time": float(self.timesteps[t]),
        }

    def model_estimates(self, model, xt, t, *inputs):
        """(eps_hat, x0_hat) of ``model`` at the chain's step t, called with x_t, its
        time label and ``inputs`` (the sampler passes the frame mask, None or not;
        guidance hooks pass nothing, so that a reader's f(x, t) works): a Denoiser's own
        x0_hat where its target gives one (Denoiser.eps_and_x0), else eps inverted (Eq.
        6)."""
        network = self.wrap(model)
        if hasattr(network.network, "eps_and_x0"):
            eps, x0 = network.eps_and_x0(xt, t, *inputs)
        else:
            eps, x0 = network(xt, t, *inputs), None
        return eps, (self.predict_x0(xt, t, eps) if x0 is None else x0)

    def mean_variance_from_eps(self, xt, t, eps, x0=None):
        """:meth:`p_mean_variance` for a given noise estimate eps (the mean is linear in
        eps) and the model's clean estimate x0 (None: from eps, Eq. 6 inverted)."""
        if x0 is None:
            x0 = self.predict_x0(xt, t, eps)
        variance = _extract(self.sigmas**2, t, xt)
        if self.eta is None:
            mean = (xt - _extract(self.eps_coef, t, xt) * eps) / _extract(
                np.sqrt(self.alphas), t, xt
            )
            # the posterior variance beta~_1 is 0: Alg. 1's pull would divide by it;
            # there it weighs with beta_1 (guided-diffusion clips the same zero)
            guidance_variance = torch.where(
                variance > 0, variance, _extract(self.betas, t, xt)
            )
        else:
            abar_prev = _extract(self.alphas_bar_prev, t, xt)
            mean = (
                abar_prev.sqrt() * x0
                + (1.0 - abar_prev - variance).clamp_min(0.0).sqrt() * eps
            )
            guidance_variance = _extract(self.betas, t, xt)
        return {
            "mean": mean,
            "variance": variance,
            "guidance_variance": guidance_variance,
            "eps": eps,
            "x0": x0,
        }

    def p_sample(self, model, xt, t, generator=None, mask=None, guide=None):
        """Sample x_{t-1} ~ p_theta(x_{t-1} | x_t) = N(mu_theta(x_t, t), sigma_t^2 I)
        (Eq. 5).

        ``guide(x_hat, xt, t, out)``, if given, receives the unguided sample x_hat_{t-1}
        and the model's mean/variance ``out`` and returns the x_{t-1} to use (the hook
        of Alg. 1-4).
        """
        with torch.no_grad():
            out = self.p_mean_variance(model, xt, t, mask)
        z = (
            torch.randn(xt.shape, generator=generator, dtype=xt.dtype).to(xt.device)
            if t > 1
            else torch.zeros_like(xt)
        )
        x = out["mean"] + _extract(self.sigmas, t, xt) * z
        if guide is not None:
            x = guide(x, xt, t, out)
        if mask is not None:
            x = x * mask[:, :, None, None]
        return x, out

    def schedule(self, start=None, end=0, resample=1):
        """The chain's steps in the order they are run, from ``start`` (None: T) down to
        ``end`` + 1.

        resample: RePaint's resampling (Lugmayr et al. 2022, jump length 1): every step
        t > 1 appears ``resample`` times in a row; between two runs of it, x_{t-1} is
        re-noised back to x_t ~ q(x_t | x_{t-1}) (Eq. 2), so that conditioned parts (the
        known frames of Alg. 3) and generated parts can harmonise. end > 0 stops at
        x_end (to pick among chains half-way; ``start=end`` continues them).
        """
        start = self.num_steps if start is None else start
        if (
            isinstance(resample, bool)
            or not isinstance(resample, (int, np.integer))
            or resample < 1
        ):
            raise ValueError(f"resample must be a positive integer, got {resample!r}")
        if (
            isinstance(start, bool)
            or not isinstance(start, (int, np.integer))
            or not 1 <= start <= self.num_steps
        ):
            raise ValueError(
                f"the start step must be an integer in 1..{self.num_steps}, got"
                f" {start!r}"
            )
        if (
            isinstance(end, bool)
            or not isinstance(end, (int, np.integer))
            or not 0 <= end < start
        ):
            raise ValueError(
                f"the end step must be an integer in 0..{start - 1} (below the start),"
                f" got {end!r}"
            )
        return [
            t for t in range(start, end, -1) for _ in range(resample if t > 1 else 1)
        ]

    def sample(
        self, model, shape, seed=0, guide=None, callback=None, progress=True, mask=None
    ):
        """x_0 from the whole reverse chain, started at x_T ~ N(0, I) of ``shape``
        (batch, frames, 68, 3).

        callback(t, x_{t-1}, out) is called after every step (for animations and the
        downstream tasks); ``guide`` is the sampler hook of Alg. 1-4 (:meth:`p_sample`).
        Deterministic for a given seed.
        """
        generator = (
            seed
            if isinstance(seed, torch.Generator)
            else torch.Generator().manual_seed(seed)
        )
        return self.run(
            model,
            torch.randn(shape, generator=generator),
            generator,
            None,
            guide,
            callback,
            progress,
            mask,
        )

    def trace(self, model, shape, measures, seed=0, guide=None):
        """:meth:`sample`, recording after every reverse step each of ``measures``
        ({name: fn(t, x_{t-1}, out)
        -> a number}, evaluated without gradients).  Returns (x_0, {"t": the time label
          of each x_{t-1} on the
        paper's scale, name: the values}): how a chain gets where it goes."""
        record = {"t": [], **{name: [] for name in measures}}

        def callback(t, x, out):
            record["t"].append(int(self.timesteps[t - 1]))
            with torch.no_grad():
                for name, fn in measures.items():
                    record[name].append(fn(t, x, out))

        return (
            self.sample(
                model, shape, seed=seed, guide=guide, callback=callback, progress=False
            ),
            record,
        )

    def run(
        self,
        model,
        x,
        seed=0,
        steps=None,
        guide=None,
        callback=None,
        progress=True,
        mask=None,
    ):
        """Run the chain's ``steps`` (:meth:`schedule`; None: all, from T) on x, which
        holds x at the first of them (x_T, or x_k to continue a chain or re-noised data,
        SDEdit); returns x after the last.

        seed: an int, or a torch.Generator to continue its random stream (a chain
        stopped half-way continues exactly as if it had not stopped).  A step that
        repeats the one before is RePaint's resampling: x_{t-1} is first re-noised back
        to x_t (Eq. 2)."""
        generator = (
            seed
            if isinstance(seed, torch.Generator)
            else torch.Generator().manual_seed(seed)
        )
        steps = self.schedule() if steps is None else list(steps)
        # a module without parameters or buffers, or a plain function: the CPU
        device = device_of(model) or torch.device("cpu")
        x = x.to(device)
        if mask is not None:
            x = x * mask[:, :, None, None]
        for i, t in enumerate(
            tqdm(steps, desc="sampling", disable=not progress, leave=False)
        ):
            if i > 0 and t == steps[i - 1]:
                x = self.q_step(x, t, generator)
            x, out = self.p_sample(model, x, t, generator, mask, guide)
            if callback is not None and (i + 1 == len(steps) or steps[i + 1] != t):
                callback(t, x, out)
        return x

    def invert(self, model, x0, mask=None, progress=False, refine=0, trajectory=False):
        """DDIM inversion: x_0 -> x_T by the deterministic DDIM step run forwards,
        x_t = sqrt(abar_t) x0_hat + sqrt(1 - abar_t) eps.  The step from x_t back to
        x_{t-1} reads eps_theta(x_t, t), which is not known before x_t is: the usual
        inversion takes it at x_{t-1} (an error of first order in the step), and
        ``refine`` fixed-point iterations then re-read it at the x_t found, so that the
        DDIM step from x_t lands on x_{t-1} again (Pan et al. 2023, AIDI; a fixed number
        of iterations, no convergence test: each one shrinks the residual by a factor
        that is smaller the shorter the step).  ``run`` with eta = 0 on this chain
        brings x_T back to x_0; regenerating it with guidance edits x_0 keeping what x_T
        encodes.  Every step reads the model's own (eps, x0_hat)
        (:meth:`model_estimates`), as the chain that regenerates does, so an x0, v or u
        network is inverted by its own estimate and nothing divides by sqrt(abar_t).
        ``trajectory``: return every x_t, t = 0..T, instead of x_T alone."""
        if (
            isinstance(refine, bool)
            or not isinstance(refine, (int, np.integer))
            or refine < 0
        ):
            raise ValueError(
                "refine must be a number of fixed-point iterations >= 0, "
                f"got {refine!r}"
            )
        path = [x0]
        with torch.no_grad():
            for t in tqdm(
                range(1, self.num_steps + 1),
                desc="inverting",
                disable=not progress,
                leave=False,
            ):
                x = path[-1]
                abar_prev, abar = (
                    _extract(self.alphas_bar_prev, t, x),
                    _extract(self.alphas_bar, t, x),
                )
                xt = x
                for _ in range(1 + refine):
                    # the DDIM step back from this x_t, with the model's own (eps,
                    # x0_hat), lands off x_{t-1} by r; x_t moves by sqrt(abar_t /
                    # abar_{t-1}) r, the step's change with eps held (the x0_hat that
                    # makes the step land on x_{t-1}, and the x_t it implies)
                    eps, x0_hat = self.model_estimates(model, xt, t, mask)
                    landed = abar_prev.sqrt() * x0_hat + (1.0 - abar_prev).sqrt() * eps
                    xt = xt + (abar / abar_prev).sqrt() * (x - landed)
                path.append(xt)
        return path if trajectory else path[-1]

    # -----------------------------------------------------------------------------
    # training
    def snr(self, t):
        """The signal-to-noise ratio SNR_t = abar_t / (1 - abar_t) of x_t (float64
        numpy, t >= 1)."""
        t = np.asarray(t)
        if t.size and t.min() < 1:
            raise ValueError(
                "the signal-to-noise ratio is defined for the noisy steps t >= 1"
            )
        return self.alphas_bar[t] / (1.0 - self.alphas_bar[t])

    def loss_weights(self, t, prediction="eps", min_snr_gamma=None):
        """The weight w_t of step t's eps-loss ||eps - eps_hat||^2 that makes it another
        objective (float64).

        A network's x0, v or u estimate is a fixed linear function of its eps estimate
        at step t, so each target's loss is the eps-loss times a function of SNR_t:
        ||x0 - x0_hat||^2 = ||eps - eps_hat||^2 / SNR_t, ||v - v_hat||^2 = (1 + 1 /
        SNR_t) ||eps - eps_hat||^2 and ||u - u_hat||^2 = (1 + 1 / sqrt(SNR_t))^2 ||eps -
        eps_hat||^2 (u = eps - x0, rectified flow's velocity).  Min-SNR-gamma (Hang et
        al. 2023) weighs the x0-loss by min(SNR_t, gamma), i.e. the eps-loss by
        min(SNR_t, gamma) / SNR_t, whatever the target (``prediction`` then only changes
        what the network outputs, not the loss)."""
        check_prediction(prediction)
        snr = self.snr(t)
        if min_snr_gamma is not None:
            return np.minimum(snr, min_snr_gamma) / snr
        return {
            "eps": np.ones_like(snr),
            "x0": 1.0 / snr,
            "v": 1.0 + 1.0 / snr,
            "u": (1.0 + 1.0 / np.sqrt(snr)) ** 2,
        }[prediction]

    def training_loss(
        self,
        model,
        x0,
        t=None,
        generator=None,
        mask=None,
        eps=None,
        prediction="eps",
        min_snr_gamma=None,
        motion_weight=1.0,
        **model_inputs,
    ):
        """The simple loss of Eq. 8, E_{t, x_0, eps} ||eps - eps_theta(x_t, t)||^2 (mean
        over valid entries), or with ``prediction`` "x0" / "v" or ``min_snr_gamma`` that
        objective (:meth:`loss_weights`); ``motion_weight`` != 1 weighs the residual's
        moving part against its static part (:func:`motion_weighted`).

        t (B,) and eps (like x0) are drawn from ``generator`` unless given;
        ``model_inputs`` (a conditional denoiser's ``labels``) go to the model, which
        returns its noise estimate whatever it predicts."""
        if t is None:
            t = torch.randint(
                1, self.num_steps + 1, (x0.shape[0],), generator=generator
            )
        if eps is None:
            eps = torch.randn(x0.shape, generator=generator, dtype=x0.dtype).to(
                x0.device
            )
        xt = self.q_sample(x0, t, eps)
        pred = model(
            xt,
            torch.as_tensor(self.timesteps[t.cpu().numpy()], dtype=torch.float32).to(
                x0.device
            ),
            mask,
            **model_inputs,
        )
        if motion_weight == 1.0:
            err = (eps - pred) ** 2
        else:
            err = motion_weighted(eps - pred, motion_weight, mask)
        if prediction != "eps" or min_snr_gamma is not None:
            weights = self.loss_weights(t.cpu().numpy(), prediction, min_snr_gamma)
            err = err * torch.as_tensor(
                weights, dtype=err.dtype, device=err.device
            ).reshape(-1, 1, 1, 1)
        return masked_mean(err, mask)

    # -----------------------------------------------------------------------------
    # respacing
    def respace(self, steps):
        """The same trained model on fewer steps: keep the steps in ``steps`` (an int K
        for K evenly spaced steps, or a list of paper steps), with betas recomputed from
        the kept abar (Nichol & Dhariwal 2021).  The result feeds the model the original
        time labels.
        """
        if isinstance(steps, (int, np.integer)) and not isinstance(steps, bool):
            if not 1 <= steps <= self.num_steps:
                raise ValueError(f"respace to 1..{self.num_steps} steps, got {steps}")
            # one step starts from pure noise, at T
            first = self.num_steps if steps == 1 else 1
            kept = np.unique(
                np.round(np.linspace(first, self.num_steps, steps)).astype(int)
            )
        else:
            kept = np.unique(np.asarray(steps, dtype=int))
            if len(kept) == 0 or kept.min() < 1 or kept.max() > self.num_steps:
                raise ValueError(f"respaced steps must lie in 1..{self.num_steps}")
        abar = self.alphas_bar[kept]
        betas = 1.0 - abar / np.concatenate([[1.0], abar[:-1]])
        return GaussianDiffusion(
            betas,
            self.variance,
            timesteps=np.concatenate([[0], self.timesteps[kept]]),
            eta=self.eta,
        )

    def with_eta(self, eta):
        """The same chain (steps, time labels) sampled by DDIM with ``eta`` (None: the
        ancestral DDPM step)."""
        return GaussianDiffusion(
            self.betas[1:], self.variance, timesteps=self.timesteps, eta=eta
        )
