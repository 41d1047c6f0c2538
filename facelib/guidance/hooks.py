"""Guiding the reverse process of the unconditional DDPM (paper §3.2, App. C Alg. 1, 2
and 4): sampler hooks.

The model is never changed: guidance is a hook ``guide(x_hat, xt, t, out)`` handed to
:meth:`GaussianDiffusion.p_sample`, which receives the unguided sample x_hat_{t-1} ~
p_theta(. | x_t) (Alg. 1 lines 3-8), the chain's step t and the model's mean and
variance ``out``, and returns the x_{t-1} to continue with.  Hooks speak in the chain's
steps (``out["time"]`` is the noise level's time label); the scores they climb
(facelib/guidance/scores.py, or a reader's plain function ``score(x, time)``) are made
for the chain when the hook is built and receive the networks' time labels.

* :class:`OptimisationGuidance`, the paper's choice (after Diffusion-LM [51]):
      x_{t-1} = argmax_x [ lambda log p_theta(x | x_t) + score(x, t-1) ]  (Alg. 1 l. 10)
  approximated by a few Adagrad steps started from x_hat_{t-1}.  With sigma_t^2 the
  variance of p_theta, lambda log p_theta(x | x_t) = -lambda ||x - mu||^2 / (2
  sigma_t^2) + const: a spring that holds x near the model's mean, stiffer at small t.
* :class:`MeanShiftGuidance`, the classic classifier guidance (Sohl-Dickstein et al.;
  Dhariwal & Nichol 2021, Alg. 1): x_{t-1} ~ N(mu + s sigma_t^2 grad_{x_t} log p_phi(y |
  x_t, t), sigma_t^2 I). Paper §3.2 writes the shift with grad p_phi; the correct form
  has grad log p_phi.  Under DDIM (their Alg. 2) the noise estimate moves instead:
  eps_hat = eps - s sqrt(1 - abar_t) grad_{x_t} log p_phi.
* :class:`ReconstructionGuidance` (not in the paper; Ho et al. 2022, "video diffusion
  models", with the normalised step of Chung et al. 2023, DPS): pull x_{t-1} along
  -grad_{x_t} ||x_0_hat(x_t)|S_K - x_0|S_K||, so that the *unknown* frames agree with
    known ones (the remedy for Alg. 3 and 4's seams).
* :class:`BestOfK` (not in the paper): K guided chains per sequence; at a chosen step
  the one the score rates highest continues alone, a one-step particle filter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

from ..config import ADAGRAD_STEPS, GUIDANCE_MIN_ABAR, GUIDANCE_WEIGHT
from ..diffusion import GaussianDiffusion
from ..checks import check_positive


def _for_chain(score, diffusion):
    """The score made for the chain's steps: the book's scores wrap their networks
    (``for_chain``); a plain function ``score(x, time)`` is wrapped whole, so that it
    too receives the network's time label of the noise level, not the respaced chain's
    step (guided-diffusion's spaced ``cond_fn``)."""
    return (
        score.for_chain(diffusion)
        if hasattr(score, "for_chain")
        else diffusion.wrap(score)
    )


def steps_of(t, x):
    """The chain's step t as a (B,) float tensor for the batch x (what scores and
    networks are given)."""
    return torch.full((len(x),), float(t), device=x.device)


def log_p_theta(x, out):
    """log p_theta(x | x_t) = log N(x; mu_theta(x_t, t), sigma_t^2 I) + const,
    per sequence (B,), with sigma_t^2 the step's guidance variance
    (under DDIM beta_t: :meth:`GaussianDiffusion.p_mean_variance`)."""
    return -((x - out["mean"]) ** 2 / (2 * out["guidance_variance"])).flatten(1).sum(1)


def gradient_at(xt, fn):
    """grad_x sum(fn(x)) at x = x_t (fn returns one value per sequence), with gradients
    enabled even inside the sampler's no-grad loop."""
    with torch.enable_grad():
        x = xt.detach().clone().requires_grad_(True)
        return torch.autograd.grad(fn(x).sum(), x)[0]


@dataclass
class OptimisationGuidance:
    """Alg. 1 line 10: ``num_steps`` Adagrad steps (a fresh optimiser at every diffusion
    step) maximising guidance_weight * log p_theta(x | x_t) + score(x, t-1), started
    from x_hat_{t-1}.

    max_time (not in the paper): leave the steps whose time label t is above it
    unguided, where the guide reads nothing but noise (None: guide every step, as Alg. 1
    and 2 do; :meth:`GaussianDiffusion.guides`)."""

    score: Callable
    diffusion: GaussianDiffusion
    guidance_weight: float = GUIDANCE_WEIGHT
    lr: float = 0.01
    num_steps: int = ADAGRAD_STEPS
    max_time: float | None = None

    def __post_init__(self):
        check_positive(
            "guidance_weight (lambda)", self.guidance_weight, allow_zero=True
        )
        check_positive("the Adagrad learning rate", self.lr)
        if not isinstance(self.num_steps, int) or self.num_steps < 1:
            raise ValueError(
                f"num_steps must be a positive integer, got {self.num_steps!r}"
            )
        if self.max_time is not None:
            check_positive("max_time", self.max_time)
        self.score = _for_chain(self.score, self.diffusion)

    def objective(self, x, out, t_prev):
        """lambda log p_theta(x | x_t) + score(x, t-1), per sequence (B,)."""
        return self.guidance_weight * log_p_theta(x, out) + self.score(x, t_prev)

    def __call__(self, x_hat, xt, t, out):
        if not self.diffusion.guides(t, self.max_time):
            return x_hat
        t_prev = steps_of(t - 1, x_hat)
        x = x_hat.detach().clone().requires_grad_(True)
        opt = torch.optim.Adagrad([x], lr=self.lr)
        with torch.enable_grad():
            for _ in range(self.num_steps):
                loss = -self.objective(x, out, t_prev).sum()
                opt.zero_grad()
                loss.backward()
                opt.step()
        return x.detach()


@dataclass
class MeanShiftGuidance:
    """Classic classifier guidance: shift the sample by scale * sigma_t^2 * grad_{x_t}
    score(x_t, t) on the ancestral chain; on a DDIM chain (any eta, the deterministic
    samplers included), take the step with eps - scale * sqrt(1 - abar_t) * grad_{x_t}
    score(x_t, t) instead.  The two agree to first order in beta_t at eta = 1, where
    DDIM's step is the ancestral one with the posterior variance.  Under DDIM the steps
    whose x_t holds less than config.GUIDANCE_MIN_ABAR of signal are left unguided
    (:meth:`GaussianDiffusion.guides`), and their score is not read.
    """

    score: Callable
    diffusion: GaussianDiffusion
    scale: float = 1.0

    def __post_init__(self):
        check_positive("scale", self.scale, allow_zero=True)
        self.score = _for_chain(self.score, self.diffusion)

    def __call__(self, x_hat, xt, t, out):
        d = self.diffusion
        # pure noise under DDIM: see config.GUIDANCE_MIN_ABAR
        if not d.guides(t, min_abar=0.0 if d.eta is None else GUIDANCE_MIN_ABAR):
            return x_hat
        grad = gradient_at(xt, lambda x: self.score(x, steps_of(t, x)))
        if d.eta is None:
            return x_hat + self.scale * out["guidance_variance"] * grad
        # DDIM (Dhariwal & Nichol 2021, Alg. 2):
        # eps_hat = eps - s sqrt(1 - abar_t) grad, the step taken with eps_hat (and the
        # x0_hat it implies: the model's own moved by Eq. 6's change for eps_hat - eps)
        shift = -self.scale * float(d.sqrt_one_minus_alphas_bar[t]) * grad
        x0 = (
            out["x0"]
            - float(d.sqrt_one_minus_alphas_bar[t] / d.sqrt_alphas_bar[t]) * shift
        )
        guided = d.mean_variance_from_eps(xt, t, out["eps"] + shift, x0)["mean"]
        return x_hat + guided - out["mean"]


@dataclass
class ReconstructionGuidance:
    """x_{t-1} = x_hat_{t-1} - scale * grad_{x_t} ||x0_hat(x_t)|S_K - x_0|S_K||
    (per sequence).

    x0_hat(x_t) = (x_t - sqrt(1 - abar_t) eps_theta(x_t, t)) / sqrt(abar_t) is the
    model's estimate of the clean sequence (Eq. 6 inverted); its known frames should
    equal the given ones.  Replacing the known frames (Alg. 3) tells the model nothing
    about how the unknown frames must change to fit them; this gradient does, through
    the denoiser.  The norm (not its square) makes the step size independent of how far
    off the estimate is (DPS).  Costs one backward pass per step.

    The step is ``scale * chain.guidance_push(t) * grad``: the gradient carries the 1 /
    sqrt(abar_t) of x0_hat (about 150 at t = T on the linear schedule; its norm is
    about 400 there), a push that the ancestral chain shrinks by sqrt(abar_t) on its
    way down but a deterministic one keeps to the end; the factor, sqrt(abar_t)^(1 -
    eta^2), makes every chain keep the same share of it, DDIM's at any eta included
    (:meth:`GaussianDiffusion.guidance_push`; filling with DDIM-50 at eta = 0: 57 mm
    off on the missing frames without the factor, 0.7 mm with it; chapter 14).
    """

    model: torch.nn.Module
    diffusion: GaussianDiffusion
    # (B, F, 68, 3), normalised; only the known frames (or landmarks) are read
    x0: torch.Tensor
    # (B, F) bool, or (B, F, 68) bool: known landmarks of a frame (keyframes)
    known: torch.Tensor
    scale: float = 1.0

    def __post_init__(self):
        check_positive(
            "the reconstruction guidance scale", self.scale, allow_zero=True
        )
        self.model = self.diffusion.wrap(self.model)

    def known_error(self, x, t):
        """||x0_hat(x)|S_K - x_0|S_K|| per sequence (B,); a sequence with nothing
        known (a window of a batch that shares none, chapter "Any length") is not
        pulled: its norm is clamped off zero, where the gradient of the norm is not
        defined."""
        _, x0_hat = self.diffusion.model_estimates(self.model, x, t)
        # (B, F, 68)
        squared = ((x0_hat - self.x0) ** 2).sum(-1)
        known = self.known if self.known.ndim == 3 else self.known[:, :, None]
        return (squared * known).sum((1, 2)).clamp_min(1e-20).sqrt()

    def __call__(self, x_hat, xt, t, out):
        push = self.scale * self.diffusion.guidance_push(t)  # see the class docstring
        return x_hat - push * gradient_at(xt, lambda x: self.known_error(x, t))


def best_particles(x, score, t, particles):
    """Of ``particles`` candidates of each of n sequences, particle-major ((particles *
    n, ...): candidate j of sequence i at j * n + i), for each sequence the one with the
    highest score(x, t) (B,): (n, ...).
    """
    if (
        isinstance(particles, bool)
        or not isinstance(particles, int)
        or particles < 1
        or len(x) % particles
    ):
        raise ValueError(
            f"particles must be a positive integer dividing the batch {len(x)}, got"
            f" {particles!r}"
        )
    n = len(x) // particles
    with torch.no_grad():
        s = score(x, t).reshape(particles, n)
    if not torch.isfinite(s).all():
        raise ValueError("the score of a particle is not finite")
    return x.reshape(particles, n, *x.shape[1:])[
        s.argmax(0), torch.arange(n, device=x.device)
    ]


@dataclass
class BestOfK:
    """Best-of-K around any guided chain (not in the paper): ``particles`` chains per
    sequence run down to the chain's step ``select_step``; there, for each sequence, the
    chain that ``score`` rates highest continues alone on the rest of the same random
    stream.  A one-step form of sequential Monte Carlo (particle filtering) with the
    score as the potential: chains are picked where the score can read what they are
    committing to.  About K times the cost above select_step."""

    score: Callable
    particles: int
    select_step: int

    def sample(self, diffusion, model, shape, guide=None, seed=0, progress=True):
        """n = shape[0] sequences from the chain ``diffusion`` with the hook ``guide``
        (any batch size)."""
        if not 1 <= self.select_step < diffusion.num_steps:
            raise ValueError(
                f"the selection step must be in 1..{diffusion.num_steps - 1} (below the"
                f" chain's first step), got {self.select_step}"
            )
        generator = torch.Generator().manual_seed(seed)
        x = torch.randn((self.particles * shape[0], *shape[1:]), generator=generator)
        x = diffusion.run(
            model,
            x,
            generator,
            diffusion.schedule(end=self.select_step),
            guide,
            progress=progress,
        )
        x = best_particles(
            x,
            _for_chain(self.score, diffusion),
            steps_of(self.select_step, x),
            self.particles,
        )
        return diffusion.run(
            model,
            x,
            generator,
            diffusion.schedule(self.select_step),
            guide,
            progress=progress,
        )


def chain(*guides):
    """One sampler hook that applies several guidance hooks in turn (None entries are
    skipped)."""
    guides = [g for g in guides if g is not None]

    def guide(x_hat, xt, t, out):
        for g in guides:
            x_hat = g(x_hat, xt, t, out)
        return x_hat

    return guide
