"""What guidance climbs: scores ``score(x, t) -> (B,)`` of candidate sequences x at the
chain's step t.

Every score shares one interface.  ``score(x, t)`` takes x (B, F, 68, 3) in the
normalised space and t, the chain's step, as a (B,) tensor.  It returns one value per
sequence, and the hooks of facelib/guidance/hooks.py climb its gradient.
``score.for_chain(diffusion)`` returns the same score for a (respaced) chain: its
networks are wrapped so that they receive their own time labels
(:meth:`GaussianDiffusion.wrap`).  A batch of K x n sequences (K particles of n,
particle-major) is scored against the n texts or labels repeated K times.

* :class:`ClassifierScore`: log p_phi(y | x, t) of a noisy classifier (Alg. 1).
* :class:`CosineScore`: cos(BiT(x, t), E(c)) of the text head (Alg. 2, Eq. 10).
* :class:`ContrastiveScore` (not in the paper): log sum_n w_n p(r_n | x, t), the head's
  probability of the descriptions r_n that the text c matches.
* :class:`AUCurveScore` (not in the paper): log N(c | R(x, t), tau^2) of requested
  AU-intensity curves c under the noisy AU regressor R, on the constrained AUs and
  frames only.
* :class:`DenoisedCosineScore` (not in the paper; the "forward universal guidance" of
  Bansal et al. 2023): Eq. 10 read on the denoiser's estimate x0_hat(x, t) instead of on
  x.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from ..config import MATCH_TEMPERATURE
from ..diffusion import GaussianDiffusion
from ..checks import check_positive


def _repeated(values, batch):
    """Per-sequence values (n, ...) for a batch of K x n sequences (particle-major), K =
    batch / n."""
    if batch % len(values):
        raise ValueError(
            f"a batch of {batch} sequences is not a whole number of repeats of"
            f" {len(values)}"
        )
    return values.repeat(batch // len(values), *([1] * (values.ndim - 1)))


def _unit(values):
    return torch.nn.functional.normalize(
        torch.as_tensor(values, dtype=torch.float32), dim=-1
    )


class _ChainScore:
    """for_chain: the same score with its ``network`` wrapped for a chain's steps."""

    def for_chain(self, diffusion: GaussianDiffusion):
        return replace(self, network=diffusion.wrap(self.network))


@dataclass
class ClassifierScore(_ChainScore):
    """score(x, t) = log p_phi(y | x, t) (B,) of a guidance classifier for class indices
    ``labels`` (n,)."""

    network: torch.nn.Module
    labels: torch.Tensor

    def __post_init__(self):
        self.labels = torch.as_tensor(self.labels, dtype=torch.long)

    def __call__(self, x, t):
        return self.network.log_prob(x, t, _repeated(self.labels, len(x)).to(x.device))


@dataclass
class CosineScore(_ChainScore):
    """score(x, t) = cos(BiT(x, t), E(c)) (B,) of the text head for text embeddings E(c)
    (n, D) (Eq. 10)."""

    network: torch.nn.Module
    text_embeddings: torch.Tensor

    def __call__(self, x, t):
        return self.network.cosine(
            x, t, _repeated(torch.as_tensor(self.text_embeddings), len(x)).to(x.device)
        )


@dataclass
class AUCurveScore(_ChainScore):
    """score(x, t) = -weight * sum over the constrained (frame, AU) of (R(x, t) - c)^2 /
    (2 tau^2) (B,): ``weight`` times the Gaussian log-likelihood (up to a constant) of
    requested AU curves c (n, F, A) under the AU regressor R, where ``constrained`` (n,
    F, A) is True (AUs a request leaves free do not count).

    With a ``denoiser`` (and the chain's ``diffusion``, see :meth:`for_chain`), R reads
    the denoiser's estimate x0_hat(x, t) at time 0 instead of x (as
    :class:`DenoisedCosineScore` for text): the gradient then reaches x through the
    denoiser, which keeps the change on motions the data have; read on x, guidance finds
    changes that please R without producing the action units (the fine-control chapter
    measures both).
    """

    network: torch.nn.Module
    curves: torch.Tensor
    constrained: torch.Tensor
    tolerance: float
    weight: float = 1.0  # its weight in the guided objective (AUControl.au_weight)
    denoiser: torch.nn.Module | None = None
    diffusion: GaussianDiffusion | None = None

    def __post_init__(self):
        self.curves = torch.as_tensor(self.curves, dtype=torch.float32)
        self.constrained = torch.as_tensor(self.constrained, dtype=torch.bool)
        if self.curves.ndim != 3 or self.constrained.shape != self.curves.shape:
            raise ValueError(
                "curves and constrained must be two (n, F, A) arrays of one shape, got"
                f" {tuple(self.curves.shape)} and {tuple(self.constrained.shape)}"
            )
        check_positive("tolerance", self.tolerance)
        # zero: no score at all (tasks.au.no_au_score)
        check_positive("weight", self.weight)

    def for_chain(self, diffusion):
        if self.denoiser is None:
            return super().for_chain(diffusion)
        return replace(
            self, denoiser=diffusion.wrap(self.denoiser), diffusion=diffusion
        )

    def __call__(self, x, t):
        c = _repeated(self.curves, len(x)).to(device=x.device, dtype=x.dtype)
        m = _repeated(self.constrained, len(x)).to(x.device)
        if self.denoiser is None:
            read = self.network(x, t)
        else:
            # the denoiser's own estimate (a flow's near T, where Eq. 6 inverted
            # would divide by sqrt(abar_t) ~ 1e-5)
            _, x0_hat = self.diffusion.model_estimates(self.denoiser, x, t)
            read = self.network(x0_hat, torch.zeros_like(t))
        squared = torch.where(
            m, (read - c) ** 2, torch.zeros((), dtype=x.dtype, device=x.device)
        )
        return -self.weight * squared.sum((1, 2)) / (2 * self.tolerance**2)


def nearest_wording(description_table, text_embeddings):
    """For each text (B, D), the training descriptions in its nearest wording: (B,
    labels * 2, D).

    description_table (labels, 2 orders, K wordings, D) holds E of every training
    description (:func:`facelib.text.description_embeddings`; wording k is the k-th
    description of every (label, order): the raw text, a paraphrase, an enriched
    template...).  The wording picked for a text is the one holding the description
    nearest to it (cosine), so "from the neutral face to happy" is contrasted with the
    36 sentences of its template, "happy" with the 18 raw texts (each twice: a raw text
    has no order)."""
    table, e = _unit(description_table), _unit(text_embeddings)
    if table.ndim != 4 or e.ndim != 2 or table.shape[-1] != e.shape[-1]:
        raise ValueError(
            "need a description table (labels, 2, K, D) and text embeddings (B, D),"
            f" got {tuple(table.shape)} and {tuple(e.shape)}"
        )
    by_wording = table.permute(2, 0, 1, 3).flatten(1, 2)  # (K, labels * 2, D)
    nearest = torch.einsum("bd,knd->bkn", e, by_wording).amax(-1).argmax(-1)  # (B,)
    return by_wording[nearest]


def match_log_weights(text_embeddings, references, match_temperature=MATCH_TEMPERATURE):
    """log w_n, w_n = softmax_n cos(E(c), E(r_n)) / match_temperature (B, N): how a text
    (B, D) matches its references (B, N, D), the w of :class:`ContrastiveScore`."""
    check_positive("the match temperature", match_temperature)
    return torch.log_softmax(
        torch.einsum("bd,bnd->bn", _unit(text_embeddings), _unit(references))
        / match_temperature,
        -1,
    )


def vocabulary_log_weights(
    text_embeddings, vocabulary, match_temperature=MATCH_TEMPERATURE
):
    """log w_n, w_n = softmax_n max_k cos(E(c), E(v_nk)) / match_temperature (B, N): how
    a text (B, D) matches N classes, each known by K descriptions v_nk (vocabulary (N,
    K, D); a class with fewer repeats some, which changes no maximum).  A class is as
    near as its nearest description: a nearest-neighbour match, in which one more way to
    say a label raises that label's weight for the texts near it, and for no others.
    With K = 1 it is :func:`match_log_weights`."""
    check_positive("the match temperature", match_temperature)
    e, v = _unit(text_embeddings), _unit(vocabulary)
    if e.ndim != 2 or v.ndim != 3 or v.shape[-1] != e.shape[-1]:
        raise ValueError(
            "need text embeddings (B, D) and a vocabulary (classes, K, D), got"
            f" {tuple(e.shape)} and {tuple(v.shape)}"
        )
    return torch.log_softmax(
        torch.einsum("bd,nkd->bnk", e, v).amax(-1) / match_temperature, -1
    )


@dataclass
class ContrastiveScore(_ChainScore):
    """score(x, t) = log sum_n w_n p(r_n | x, t) (B,): the text head's probability of
    the reference descriptions r_n (n, N, D) that the text c matches (not in the paper).

    * p(r_n | x, t) = softmax_n cos(BiT(x, t), E(r_n)) / tau: the head's InfoNCE
      softmax, with which it is trained at this tau (facelib/training/recipes.py), over
      references such as :func:`nearest_wording`;
    * w_n = softmax_n cos(E(c), E(r_n)) / match_temperature: what c means, as
      references.  A training description matches itself (w is one-hot on it: the score
      is log p(c | x, t), Alg. 1's score with the head as a classifier over
      descriptions); a phrasing never seen in training matches the descriptions nearest
      to it in the encoder's space.  With a ``vocabulary`` (N, K, D), the descriptions
      whose meaning is known for each reference's class, w is
      :func:`vocabulary_log_weights` instead: c is matched against all of them.

    Why not the cosine of Eq. 10: its gradient is mostly the direction that every
    description of the wording shares, and the order of an enriched sentence is a small
    angle next to it.  For a one-hot w, the gradient of log p(c | x, t) is
    (grad cos(o, E(c)) - E_p[grad cos(o, E(r))]) / tau: the shared part cancels, and
    what is left is the direction that tells c from the references it is being confused
    with, the label while the label is wrong, the order once the label is right."""

    network: torch.nn.Module
    text_embeddings: torch.Tensor
    references: torch.Tensor
    temperature: float
    match_temperature: float = MATCH_TEMPERATURE
    vocabulary: torch.Tensor | None = None

    def __post_init__(self):
        shape = torch.as_tensor(self.text_embeddings).shape
        self.references = _unit(self.references)
        if (
            len(shape) != 2
            or self.references.ndim != 3
            or self.references.shape[0] != shape[0]
            or self.references.shape[-1] != shape[-1]
        ):
            raise ValueError(
                "need references (B, N, D) for text embeddings (B, D) = "
                f"{tuple(shape)}, got {tuple(self.references.shape)}"
            )
        check_positive("the temperature", self.temperature)
        if self.vocabulary is None:
            self.log_weights = match_log_weights(
                self.text_embeddings, self.references, self.match_temperature
            )
        else:
            self.log_weights = vocabulary_log_weights(
                self.text_embeddings, self.vocabulary, self.match_temperature
            )
            if self.log_weights.shape != self.references.shape[:2]:
                raise ValueError(
                    f"the vocabulary knows {self.log_weights.shape[1]} classes, "
                    f"the references are {self.references.shape[1]}"
                )

    def __call__(self, x, t):
        refs = _repeated(self.references, len(x)).to(x.device)
        logits = (
            torch.einsum("bd,bnd->bn", self.network.embed(x, t), refs)
            / self.temperature
        )
        return torch.logsumexp(
            _repeated(self.log_weights, len(x)).to(x.device)
            + torch.log_softmax(logits, -1),
            -1,
        )


@dataclass
class DenoisedCosineScore:
    """score(x, t) = cos(BiT(x0_hat(x, t), 0), E(c)) (B,): Eq. 10 read on the denoiser's
    estimate x0_hat(x, t) (its own, :meth:`GaussianDiffusion.model_estimates`: for an
    eps network (x - sqrt(1 - abar_t) eps_theta(x, t)) / sqrt(abar_t), Eq. 6 inverted)
    instead of on x (not in the paper; the "forward universal guidance" of Bansal et al.
    2023).

    At large t, x holds a factor sqrt(abar_t) of the sequence (a few per cent at t =
    1000), too little for a head to read the order of an expression; the denoiser's
    estimate is a clean-looking sequence at every t, read by the head as at t = 0, and
    the gradient reaches x through the denoiser.  Being a function of x, the estimate
    holds no more of the order than x does.  Costs a denoiser forward and backward pass
    per Adagrad step.  ``diffusion``: the chain whose steps t are (see
    :meth:`for_chain`).
    """

    network: torch.nn.Module  # the text head, read at time 0
    denoiser: torch.nn.Module
    diffusion: GaussianDiffusion
    text_embeddings: torch.Tensor

    def for_chain(self, diffusion):
        return replace(
            self, denoiser=diffusion.wrap(self.denoiser), diffusion=diffusion
        )

    def __call__(self, x, t):
        _, x0_hat = self.diffusion.model_estimates(self.denoiser, x, t)
        e = _repeated(torch.as_tensor(self.text_embeddings), len(x)).to(x.device)
        return self.network.cosine(x0_hat, torch.zeros_like(t), e)
