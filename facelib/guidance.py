"""Guiding the reverse process of the unconditional DDPM (paper §3.2, App. C Alg. 1, 2 and 4).

The model is never changed: guidance is a function ``guide(x_hat, xt, t, out)`` handed to
:meth:`GaussianDiffusion.p_sample`, which receives the unguided sample x_hat_{t-1} ~ p_theta(. | x_t)
(Alg. 1 lines 3-8) and returns the x_{t-1} to continue with.

* :class:`OptimisationGuidance`, the paper's choice (after Diffusion-LM [51]):
      x_{t-1} = argmax_x [ lambda log p_theta(x | x_t) + score(x, t-1) ]       (Alg. 1 line 10)
  approximated by a few Adagrad steps started from x_hat_{t-1}.  score is log p_phi(y | x, t-1)
  for label control (Alg. 1) and cos(BiT(x, t-1), E(c)) for text control (Alg. 2, Eq. 10), or
  (not in the paper) cos(BiT(x0_hat(x, t-1), 0), E(c)), the head reading the denoiser's estimate of
  the clean sequence (:func:`denoised_text_score`), or (not in the paper) the head's log-probability
  of the training descriptions that c matches, log sum_n w_n p(r_n | x, t-1) (:func:`contrastive_text_score`).
  With sigma_t^2 the variance of p_theta, lambda log p_theta(x | x_t) = -lambda ||x - mu||^2 /
  (2 sigma_t^2) + const: a spring that holds x near the model's mean, stiffer at small t.
* :class:`ReconstructionGuidance` (not in the paper; Ho et al. 2022, "video diffusion models", with
  the normalised step of Chung et al. 2023, DPS): pull x_{t-1} along -grad_{x_t} ||x_0_hat(x_t)|S_K -
  x_0|S_K||, so that the *unknown* frames agree with known ones (the remedy of chapter 08 for
  Alg. 4's disharmony).
* :func:`best_particles` (not in the paper): of several guided chains per sequence, keep the one
  the guide scores highest at a chosen step, a one-step particle filter (chapter 06 section 11).
* :class:`MeanShiftGuidance`, the classic classifier guidance (Sohl-Dickstein et al.; Dhariwal
  & Nichol 2021, Alg. 1): x_{t-1} ~ N(mu + s sigma_t^2 grad_{x_t} log p_phi(y | x_t, t), sigma_t^2 I).
  Paper §3.2 writes the shift with grad p_phi; the correct form has grad log p_phi.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

from .diffusion import GaussianDiffusion

ADAGRAD_STEPS = 3  # paper §3.2: "3 steps of the Adagrad update for each diffusion step"
GUIDANCE_WEIGHT = 0.01  # paper §4: lambda = 0.01 "as in [51]"
# contrastive_text_score: how sharply a text is matched to the training descriptions (our choice: an
# enriched sentence and its other order, at a cosine of about 0.985, get weights of about 0.95 and 0.05)
MATCH_TEMPERATURE = 0.005


def log_p_theta(x, out):
    """log p_theta(x | x_t) = log N(x; mu_theta(x_t, t), sigma_t^2 I) + const, per sequence (B,)."""
    return -((x - out["mean"]) ** 2 / (2 * out["variance"])).flatten(1).sum(1)


def classifier_score(classifier, labels):
    """score(x, t) = log p_phi(y | x, t) (B,) of a guidance classifier for class indices ``labels``."""
    labels = torch.as_tensor(labels, dtype=torch.long)
    return lambda x, t: classifier.log_prob(x, t, labels.to(x.device))


def text_score(head, text_embeddings):
    """score(x, t) = cos(BiT(x, t), E(c)) (B,) of the text head for text embeddings (B, D) (Eq. 10)."""
    return lambda x, t: head.cosine(x, t, text_embeddings.to(x.device))


def nearest_wording(description_table, text_embeddings):
    """For each text (B, D), the training descriptions in its nearest wording: (B, labels * 2, D).

    description_table (labels, 2 orders, K wordings, D) holds E of every training description
    (:func:`facelib.text.description_embeddings`; wording k is the k-th description of every
    (label, order): the raw text, a paraphrase, an enriched template...).  The wording picked for a
    text is the one holding the description nearest to it (cosine), so "from the neutral face to
    happy" is contrasted with the 36 sentences of its template, "happy" with the 18 raw texts (each
    twice: a raw text has no order)."""
    table = torch.nn.functional.normalize(torch.as_tensor(description_table, dtype=torch.float32), dim=-1)
    e = torch.nn.functional.normalize(torch.as_tensor(text_embeddings, dtype=torch.float32), dim=-1)
    if table.ndim != 4 or e.ndim != 2 or table.shape[-1] != e.shape[-1]:
        raise ValueError(f"need a description table (labels, 2, K, D) and text embeddings (B, D), got "
                         f"{tuple(table.shape)} and {tuple(e.shape)}")
    by_wording = table.permute(2, 0, 1, 3).flatten(1, 2)  # (K, labels * 2, D)
    nearest = torch.einsum("bd,knd->bkn", e, by_wording).amax(-1).argmax(-1)  # (B,)
    return by_wording[nearest]


def match_log_weights(text_embeddings, references, match_temperature=MATCH_TEMPERATURE):
    """log w_n, w_n = softmax_n cos(E(c), E(r_n)) / match_temperature (B, N): how a text (B, D)
    matches its references (B, N, D), the w of :func:`contrastive_text_score`."""
    _check_positive("the match temperature", match_temperature)
    e = torch.nn.functional.normalize(torch.as_tensor(text_embeddings, dtype=torch.float32), dim=-1)
    refs = torch.nn.functional.normalize(torch.as_tensor(references, dtype=torch.float32), dim=-1)
    return torch.log_softmax(torch.einsum("bd,bnd->bn", e, refs) / match_temperature, -1)


def vocabulary_log_weights(text_embeddings, vocabulary, match_temperature=MATCH_TEMPERATURE):
    """log w_n, w_n = softmax_n max_k cos(E(c), E(v_nk)) / match_temperature (B, N): how a text (B, D)
    matches N classes, each known by K descriptions v_nk (vocabulary (N, K, D); a class with fewer
    repeats some, which changes no maximum).  A class is as near as its nearest description: a
    nearest-neighbour match, in which one more way to say a label raises that label's weight for the
    texts near it, and for no others.  With K = 1 it is :func:`match_log_weights`."""
    _check_positive("the match temperature", match_temperature)
    e = torch.nn.functional.normalize(torch.as_tensor(text_embeddings, dtype=torch.float32), dim=-1)
    v = torch.nn.functional.normalize(torch.as_tensor(vocabulary, dtype=torch.float32), dim=-1)
    if e.ndim != 2 or v.ndim != 3 or v.shape[-1] != e.shape[-1]:
        raise ValueError(f"need text embeddings (B, D) and a vocabulary (classes, K, D), got {tuple(e.shape)} and "
                         f"{tuple(v.shape)}")
    return torch.log_softmax(torch.einsum("bd,nkd->bnk", e, v).amax(-1) / match_temperature, -1)


def contrastive_text_score(head, text_embeddings, references, temperature, match_temperature=MATCH_TEMPERATURE,
                           vocabulary=None):
    """score(x, t) = log sum_n w_n p(r_n | x, t) (B,): the text head's probability of the reference
    descriptions r_n (B, N, D) that the text c matches (not in the paper; chapter 06 section 10).

    * p(r_n | x, t) = softmax_n cos(BiT(x, t), E(r_n)) / tau: the head's InfoNCE softmax, with which it
      is trained at this tau (facelib/train.py), over references such as :func:`nearest_wording`;
    * w_n = softmax_n cos(E(c), E(r_n)) / match_temperature: what c means, as references.  A training
      description matches itself (w is one-hot on it: the score is log p(c | x, t), Alg. 1's score
      with the head as a classifier over descriptions); a phrasing never seen in training matches
      the descriptions nearest to it in the encoder's space.  With a ``vocabulary`` (N, K, D), the
      descriptions whose meaning is known for each reference's class (not in the paper; chapter 06
      section 12), w is :func:`vocabulary_log_weights` instead: c is matched against all of them.

    Why not the cosine of Eq. 10: its gradient is mostly the direction that every description of
    the wording shares, and the order of an enriched sentence is a small angle next to it (chapter
    06).  For a one-hot w, the gradient of log p(c | x, t) is (grad cos(o, E(c)) - E_p[grad cos(o, E(r))])
    / tau: the shared part cancels, and what is left is the direction that tells c from the
    references it is being confused with, the label while the label is wrong, the order once the
    label is right."""
    shape = torch.as_tensor(text_embeddings).shape
    refs = torch.nn.functional.normalize(torch.as_tensor(references, dtype=torch.float32), dim=-1)
    if len(shape) != 2 or refs.ndim != 3 or refs.shape[0] != shape[0] or refs.shape[-1] != shape[-1]:
        raise ValueError(f"need references (B, N, D) for text embeddings (B, D) = {tuple(shape)}, "
                         f"got {tuple(refs.shape)}")
    _check_positive("the temperature", temperature)
    if vocabulary is None:
        log_w = match_log_weights(text_embeddings, references, match_temperature)
    else:
        log_w = vocabulary_log_weights(text_embeddings, vocabulary, match_temperature)
        if log_w.shape != refs.shape[:2]:
            raise ValueError(f"the vocabulary knows {log_w.shape[1]} classes, the references are {refs.shape[1]}")

    def score(x, t):
        logits = torch.einsum("bd,bnd->bn", head.embed(x, t), refs.to(x.device)) / temperature
        return torch.logsumexp(log_w.to(x.device) + torch.log_softmax(logits, -1), -1)
    return score


def denoised_text_score(head, model, diffusion, text_embeddings):
    """score(x, t) = cos(BiT(x0_hat(x, t), 0), E(c)) (B,): Eq. 10 read on the denoiser's estimate
    x0_hat(x, t) = (x - sqrt(1 - abar_t) eps_theta(x, t)) / sqrt(abar_t) (Eq. 6 inverted) instead of
    on x itself (not in the paper; the "forward universal guidance" of Bansal et al. 2023).

    At large t, x holds a factor sqrt(abar_t) of the sequence (a few per cent at t = 1000), too little
    for a head to read the order of the expression, which the chain settles there (chapter 06); the
    denoiser's estimate is a clean-looking sequence at every t, read by the head as at t = 0, and
    the gradient reaches x through the denoiser.  Being a function of x, the estimate holds no more
    of the order than x does: chapter 06 section 8 measures no gain.  Costs a denoiser forward and
    backward pass per Adagrad step.  ``diffusion`` must be the model's full (not respaced) schedule:
    t is the time label fed to the networks, which is a step of that schedule (t = 0: x0_hat = x)."""
    def score(x, t):
        steps = t.detach().round().long().cpu()
        x0_hat = diffusion.predict_x0(x, steps, model(x, t))
        return head.cosine(x0_hat, torch.zeros_like(t), text_embeddings.to(x.device))
    return score


def gradient_at(xt, fn):
    """grad_x sum(fn(x)) at x = x_t (fn returns one value per sequence), with gradients enabled
    even inside the sampler's no-grad loop."""
    with torch.enable_grad():
        x = xt.detach().clone().requires_grad_(True)
        return torch.autograd.grad(fn(x).sum(), x)[0]


def _check_positive(name, value, allow_zero=False):
    if not isinstance(value, (int, float)) or isinstance(value, bool) or value != value or value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"{name} must be a {'non-negative' if allow_zero else 'positive'} number, got {value!r}")


@dataclass
class OptimisationGuidance:
    """Alg. 1 line 10: ``num_steps`` Adagrad steps (a fresh optimiser at every diffusion step)
    maximising guidance_weight * log p_theta(x | x_t) + score(x, t-1), started from x_hat_{t-1}.

    max_time (not in the paper): leave the steps whose time label t is above it unguided, where the
    guide reads nothing but noise (None: guide every step, as Alg. 1 and 2 do)."""

    score: Callable
    diffusion: GaussianDiffusion
    guidance_weight: float = GUIDANCE_WEIGHT
    lr: float = 0.01
    num_steps: int = ADAGRAD_STEPS
    max_time: float | None = None

    def __post_init__(self):
        _check_positive("guidance_weight (lambda)", self.guidance_weight, allow_zero=True)
        _check_positive("the Adagrad learning rate", self.lr)
        if not isinstance(self.num_steps, int) or self.num_steps < 1:
            raise ValueError(f"num_steps must be a positive integer, got {self.num_steps!r}")
        if self.max_time is not None:
            _check_positive("max_time", self.max_time)

    def objective(self, x, out, t_prev):
        """lambda log p_theta(x | x_t) + score(x, t-1), per sequence (B,)."""
        return self.guidance_weight * log_p_theta(x, out) + self.score(x, t_prev)

    def __call__(self, x_hat, xt, t, out):
        if self.max_time is not None and float(self.diffusion.timesteps[t]) > self.max_time:
            return x_hat
        t_prev = self.diffusion.model_time(t - 1, len(x_hat)).to(x_hat.device)
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
    """Classic classifier guidance: shift the sample by scale * sigma_t^2 * grad_{x_t} score(x_t, t)."""

    score: Callable
    diffusion: GaussianDiffusion
    scale: float = 1.0

    def __post_init__(self):
        _check_positive("scale", self.scale, allow_zero=True)

    def __call__(self, x_hat, xt, t, out):
        grad = gradient_at(xt, lambda x: self.score(x, self.diffusion.model_time(t, len(x)).to(x.device)))
        return x_hat + self.scale * out["variance"] * grad


@dataclass
class ReconstructionGuidance:
    """x_{t-1} = x_hat_{t-1} - scale * grad_{x_t} ||x0_hat(x_t)|S_K - x_0|S_K||  (per sequence).

    x0_hat(x_t) = (x_t - sqrt(1 - abar_t) eps_theta(x_t, t)) / sqrt(abar_t) is the model's estimate of
    the clean sequence (Eq. 6 inverted); its known frames should equal the given ones.  Replacing
    the known frames (Alg. 3) tells the model nothing about how the unknown frames must change to
    fit them; this gradient does, through the denoiser.  The norm (not its square) makes the step
    size independent of how far off the estimate is (DPS).  Costs one backward pass per step.
    """

    model: torch.nn.Module
    diffusion: GaussianDiffusion
    x0: torch.Tensor  # (B, F, 68, 3), normalised; only the known frames are read
    known: torch.Tensor  # (B, F) bool
    scale: float = 1.0

    def __post_init__(self):
        _check_positive("the reconstruction guidance scale", self.scale, allow_zero=True)

    def known_error(self, x, t):
        """||x0_hat(x)|S_K - x_0|S_K|| per sequence (B,)."""
        eps = self.model(x, self.diffusion.model_time(t, len(x)).to(x.device))
        return (((self.diffusion.predict_x0(x, t, eps) - self.x0) ** 2).sum((2, 3)) * self.known).sum(1).sqrt()

    def __call__(self, x_hat, xt, t, out):
        return x_hat - self.scale * gradient_at(xt, lambda x: self.known_error(x, t))


def best_particles(x, score, t, particles):
    """Best-of-K (not in the paper; chapter 06 section 11): x holds ``particles`` candidates of each
    of n sequences, particle-major ((particles * n, ...): candidate j of sequence i at j * n + i);
    returns (n, ...), for each sequence the candidate with the highest score(x, t) (B,).

    A one-step form of sequential Monte Carlo (particle filtering) with the guide as the potential:
    the chains are picked where the guide can read what the chain is committing to."""
    if isinstance(particles, bool) or not isinstance(particles, int) or particles < 1 or len(x) % particles:
        raise ValueError(f"particles must be a positive integer dividing the batch {len(x)}, got {particles!r}")
    n = len(x) // particles
    with torch.no_grad():
        s = score(x, t).reshape(particles, n)
    if not torch.isfinite(s).all():
        raise ValueError("the score of a particle is not finite")
    return x.reshape(particles, n, *x.shape[1:])[s.argmax(0), torch.arange(n)]


def chain(*guides):
    """One sampler hook that applies several guidance hooks in turn (None entries are skipped)."""
    guides = [g for g in guides if g is not None]

    def guide(x_hat, xt, t, out):
        for g in guides:
            x_hat = g(x_hat, xt, t, out)
        return x_hat
    return guide
