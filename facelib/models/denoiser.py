"""The noise approximator eps_theta(x_t, t) of the paper (§3.1, Fig. 1): a bidirectional
transformer.

The tokens are FE(x_t) + PE(1..F) + TE(t), one per frame (models/bit.py); the encoder is
bidirectional: every frame attends to every other frame, past and future, which is what
expression filling (the filling chapter) needs.  Padded frames of a batch of mixed
lengths are excluded with a key padding mask.  A linear layer maps each output token
back to 204 numbers, the noise estimate of that frame.

One addition of ours, measured in the denoiser chapter: a token is narrower (128) than a
frame (204 numbers), so a plain transformer cannot even pass the noise through at large
t (its loss stalls at the fraction of dimensions it cannot represent).  We therefore add
the closed-form *Gaussian* noise estimate of each frame, E[eps | x_t] for frames drawn
from N(0, Sigma) with Sigma the covariance of the training frames,

    eps_gauss(x_t, t) = sqrt(1 - abar_t) (abar_t Sigma + (1 - abar_t) I)^-1 x_t,

and the transformer learns only the residual: eps_theta = eps_gauss + BiT(TE + PE + FE).
Its output layer starts at zero, so training starts from the best linear per-frame
denoiser.

The Gaussian's form (``prior_length``; issue 58, chapter 03 section 8): frames drawn
independently (0, every checkpoint before it) under-draw a sequence's slowest part,
the only part x_t still holds at high noise, and the chain follows that Gaussian
there.  With ``prior_length`` L the Gaussian is over whole sequences, diagonal in the
DCT-II basis along time times Sigma's eigenvectors, a variance per (frequency,
component) fitted on the training sequences; the estimate is the same formula,
coefficient by coefficient.

What the network outputs (``prediction``, an ablation of the denoiser chapter): the
noise eps (the paper's), the clean sequence x_0 (MDM), the velocity v = sqrt(abar_t)
eps - sqrt(1 - abar_t) x_0 (Salimans & Ho 2022) or rectified flow's velocity u = eps -
x_0 (facelib/flow.py). The residual is added to the Gaussian estimate written as that
target, and :meth:`Denoiser.forward` always returns the noise estimate it implies (eps =
(x_t - sqrt(abar_t) x_0) / sqrt(1 - abar_t) = sqrt(1 - abar_t) x_t + sqrt(abar_t) v =
(x_t + sqrt(abar_t) u) / (sqrt(abar_t) + sqrt(1 - abar_t))), so every sampler and
guidance of the book runs any of them unchanged.

A join denoiser (``known_input``, not in the paper; Cohan et al. 2024's CondMDI, the
chapter "Any length") also reads the frames a task knows: KE([x_0 m, m]), a linear
embedding of the known frames' values and the mask m (B, F), is added to their tokens.
It starts at zero, so a join denoiser fine-tuned from an unconditional one starts as
that one, and is trained with random known frames
(training.DenoiserTraining.known_frames).

The schedule "flow" is rectified flow's path (diffusion.flow_alphas_bar): its time
labels are continuous, t = tau T with tau in [0, 1], and abar is computed, not looked
up.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from ..diffusion import check_prediction, flow_alphas_bar, named_betas
from .bit import BiT, check_sequence_input


def dct_matrix(n, dtype=torch.float32, device=None):
    """The orthonormal DCT-II matrix (n, n): row k is sqrt(2 / n) cos(pi (j + 1/2) k /
    n) over frames j (row 0 scaled by 1 / sqrt(2)); its transpose inverts it."""
    j = torch.arange(n, dtype=torch.float64)
    c = torch.cos(torch.pi * (j[None, :] + 0.5) * j[:, None] / n) * (2.0 / n) ** 0.5
    c[0] /= 2**0.5
    return c.to(dtype=dtype, device=device)


@dataclass(frozen=True)
class DenoiserConfig:
    """Sizes of the denoiser (our choice; the paper gives none: see the denoiser chapter
    for the CPU budget)."""

    num_landmarks: int = 68
    width: int = 128
    depth: int = 4
    heads: int = 4
    ff: int = 256
    dropout: float = 0.0
    gaussian_skip: bool = True  # our addition (see the module docstring)
    # the Gaussian's form: 0, frames drawn independently from N(0, Sigma); L > 0, whole
    # sequences, with a variance per temporal frequency of L frames (issue 58; the
    # module docstring).  0 for checkpoints that record none.
    prior_length: int = 0
    num_diffusion_steps: int = 2000  # the schedule the skip needs (paper §4)
    schedule: str = "linear"
    # what the network outputs: "eps" (paper), "x0" (MDM), "v" or "u" (rectified flow);
    # forward returns eps
    prediction: str = "eps"
    # > 0: label-conditional (classifier-free guidance), a label token before the frames
    num_classes: int = 0
    # True: a join denoiser, which also reads the known frames (the module docstring)
    known_input: bool = False


class Denoiser(BiT):
    """eps_theta(x_t, t): (B, F, 68, 3) normalised landmarks, (B,) steps -> (B, F, 68,
    3) noise."""

    def __init__(self, config=DenoiserConfig()):
        c = config
        check_prediction(c.prediction)
        super().__init__(c.num_landmarks, c.width, c.depth, c.heads, c.ff, c.dropout)
        self.config = config
        features = c.num_landmarks * 3
        self.out = nn.Linear(c.width, features)
        if c.gaussian_skip:
            nn.init.zeros_(self.out.weight)
            nn.init.zeros_(self.out.bias)
        abar = torch.cumprod(
            1 - torch.as_tensor(named_betas(c.schedule, c.num_diffusion_steps)), 0
        )
        self.register_buffer(
            "alphas_bar", torch.cat([torch.ones(1, dtype=abar.dtype), abar]).float()
        )
        # eigenvectors of Sigma (columns)
        self.register_buffer("prior_basis", torch.eye(features))
        # eigenvalues of Sigma
        self.register_buffer("prior_variances", torch.ones(features))
        if c.prior_length:
            if c.prior_length < 2:
                raise ValueError(
                    "prior_length is 0 (frames independent) or a sequence length of 2"
                    f" or more frames, got {c.prior_length}"
                )
            # the variance of each (temporal frequency, principal component) pair
            self.register_buffer(
                "prior_spectrum", torch.ones(c.prior_length, features)
            )
        # the label's token; index num_classes is "no label" (the unconditional model)
        if c.num_classes:
            self.label_embedding = nn.Embedding(c.num_classes + 1, c.width)
        # KE: the known frames' values and mask, zero at first
        if c.known_input:
            self.known_embedding = nn.Linear(features + 1, c.width)
            nn.init.zeros_(self.known_embedding.weight)
            nn.init.zeros_(self.known_embedding.bias)

    @torch.no_grad()
    def fit_prior(self, frames):
        """Set the Gaussian part of the estimate from normalised training data: frames
        (N, 68, 3) give Sigma, their covariance; a denoiser with ``prior_length`` L
        takes sequences (N, L, 68, 3) instead, whose frames give Sigma's eigenvectors
        and whose DCT-II coefficients along time, in that basis, give the variance of
        each (frequency, component) pair (the module docstring)."""
        x = torch.as_tensor(frames, dtype=torch.float64)
        length = self.config.prior_length
        if length and tuple(x.shape[1:2]) != (length,):
            raise ValueError(
                f"this denoiser's Gaussian is over sequences of {length} frames: give"
                f" (N, {length}, 68, 3) training sequences, got {tuple(x.shape)}"
            )
        cov = torch.cov(x.reshape(-1, len(self.prior_basis)).T)
        variances, basis = torch.linalg.eigh(cov)
        self.prior_basis.copy_(basis.float())
        self.prior_variances.copy_(variances.clamp_min(0).float())
        if length:
            y = dct_matrix(length, torch.float64) @ (
                x.reshape(len(x), length, -1) @ basis
            )
            self.prior_spectrum.copy_((y**2).mean(0).float())

    def _abar(self, t, xt):
        """abar_t for time labels t (B,), shaped (B, 1, 1, 1) on x_t's device (the flow
        schedule's computed at tau = t / T, any other's looked up at the nearest step).
        """
        if self.config.schedule == "flow":
            tau = (t.to(xt.device) / self.config.num_diffusion_steps).clamp(0, 1)
            return flow_alphas_bar(tau.double()).float().reshape(-1, 1, 1, 1)
        return (
            self.alphas_bar[t.round().long().clamp(0, len(self.alphas_bar) - 1)]
            .to(xt.device)
            .reshape(-1, 1, 1, 1)
        )

    def to_eps(self, xt, t, output):
        """The noise estimate that the network's ``output`` (eps, x_0, v or u:
        ``config.prediction``) implies."""
        abar = self._abar(t, xt)
        if self.config.prediction == "x0":
            return (xt - abar.sqrt() * output) / (1 - abar).sqrt()
        if self.config.prediction == "v":
            return (1 - abar).sqrt() * xt + abar.sqrt() * output
        if self.config.prediction == "u":
            return (xt + abar.sqrt() * output) / (abar.sqrt() + (1 - abar).sqrt())
        return output

    def from_eps(self, xt, t, eps):
        """A noise estimate written as the network's target (the inverse of
        :meth:`to_eps`)."""
        abar = self._abar(t, xt)
        x0 = (xt - (1 - abar).sqrt() * eps) / abar.sqrt()
        if self.config.prediction == "x0":
            return x0
        if self.config.prediction == "v":
            return abar.sqrt() * eps - (1 - abar).sqrt() * x0
        if self.config.prediction == "u":
            return eps - x0
        return eps

    def gaussian_eps(self, xt, t, mask=None):
        """E[eps | x_t] if every frame were drawn from N(0, Sigma) (a per-frame linear
        filter), or, with ``prior_length``, every sequence from the Gaussian of its
        temporal spectrum (a filter per frequency and component): either way
        sqrt(1 - abar_t) (abar_t Sigma + (1 - abar_t) I)^-1 x_t, in the basis where
        the Gaussian's covariance is diagonal."""
        return self._prior_filter(
            xt, t, mask, lambda abar, var: (1 - abar).sqrt() / (abar * var + 1 - abar)
        )

    def gaussian_u(self, xt, t, mask=None):
        """E[eps - x_0 | x_t] under the Gaussian of :meth:`gaussian_eps`: the Gaussian
        estimate as a rectified-flow velocity, finite at abar = 0 where x_0 cannot be
        had from eps (E[x_0 | x_t] = sqrt(abar) Sigma (abar Sigma + (1 - abar) I)^-1
        x_t)."""
        return self._prior_filter(
            xt,
            t,
            mask,
            lambda abar, var: ((1 - abar).sqrt() - abar.sqrt() * var)
            / (abar * var + 1 - abar),
        )

    def _prior_filter(self, xt, t, mask, gain):
        """x_t (B, F, 68, 3) multiplied, coefficient by coefficient in the Gaussian's
        eigenbasis, by gain(abar_t, variance): per frame in Sigma's eigenvectors, or,
        with ``prior_length`` L, on the DCT-II along time of each sequence's valid
        frames (``mask``, None: all) too, the variances of another length from the
        fitted ones (:meth:`_spectrum`)."""
        abar = self._abar(t, xt)[..., 0]  # (B, 1, 1)
        y = xt.reshape(xt.shape[0], xt.shape[1], -1) @ self.prior_basis
        if not self.config.prior_length:
            y = y * gain(abar, self.prior_variances)
            return (y @ self.prior_basis.T).reshape(xt.shape)
        lengths = (
            torch.full((len(xt),), xt.shape[1], device=xt.device)
            if mask is None
            else mask.sum(1)
        )
        filtered = torch.zeros_like(y)
        for n in lengths.unique().tolist():
            rows = (lengths == n).nonzero()[:, 0]
            c = dct_matrix(n, y.dtype, y.device)
            z = c @ y[rows, :n]
            z = z * gain(abar[rows], self._spectrum(n))
            filtered[rows, :n] = c.T @ z
        return (filtered @ self.prior_basis.T).reshape(xt.shape)

    def _spectrum(self, n):
        """The variances (n, 204) of an n-frame sequence's DCT-II coefficients: the
        fitted ones at n = prior_length L; at another length the same motion over n
        frames (the world's longer sequences are the same performance at a finer
        time step): coefficient k's variance above the white floor (the fastest
        frequency's, per component) grows as n / L, and frequencies beyond the L
        fitted ones are the floor."""
        spectrum = self.prior_spectrum
        length = len(spectrum)
        if n == length:
            return spectrum
        floor = spectrum[-1:]
        slow = floor + (spectrum[: min(n, length)] - floor) * (n / length)
        return torch.cat([slow, floor.expand(max(n - length, 0), -1)]).clamp_min(1e-12)

    def forward(self, xt, t, mask=None, labels=None, known=None):
        """Noise estimate for x_t at steps t; ``mask`` (B, F) bool marks the valid
        frames.  A label-conditional denoiser (``num_classes`` > 0) reads ``labels``
        (B,) class indices, ``num_classes`` meaning "no label" (None: no label for any);
        an unconditional one takes none.  A join denoiser (``known_input``) reads
        ``known`` = (x_0 (B, F, 68, 3), m (B, F) bool), the values of the frames m
        marks (None: none known); any other takes none."""
        return self.to_eps(xt, t, self.output(xt, t, mask, labels, known))

    def velocity(self, xt, t, mask=None, labels=None, known=None):
        """Rectified flow's velocity estimate u = eps - x_0 for x_t at steps t (the
        network's own output when it predicts u; otherwise from its noise estimate,
        which needs abar_t > 0)."""
        output = self.output(xt, t, mask, labels, known)
        if self.config.prediction == "u":
            return output
        eps = self.to_eps(xt, t, output)
        abar = self._abar(t, xt)
        return eps - (xt - (1 - abar).sqrt() * eps) / abar.sqrt()

    def x0(self, xt, t, mask=None, labels=None, known=None):
        """The clean-sequence estimate x0_hat(x_t, t), computed in the target's own form
        (x_0, sqrt(abar) x_t - sqrt(1 - abar) v, or from u), so that it stays exact
        where abar_t is small and eps would be divided by sqrt(abar_t)."""
        return self.x0_from(xt, t, self.output(xt, t, mask, labels, known))

    def eps_and_x0(self, xt, t, mask=None, labels=None, known=None):
        """(eps_hat, x0_hat) from one pass of the network: x0_hat in the target's own
        form (:meth:`x0`), or None for an eps network, whose x0_hat the sampler computes
        from eps (Eq. 6 inverted; the rectified flow's needs its own at t = T, where its
        eps is x_t itself)."""
        output = self.output(xt, t, mask, labels, known)
        eps = self.to_eps(xt, t, output)
        if self.config.prediction == "eps":
            return eps, None
        return eps, self.x0_from(xt, t, output)

    def x0_from(self, xt, t, output):
        """The clean estimate that the network's ``output`` implies (see :meth:`x0`)."""
        abar = self._abar(t, xt)
        if self.config.prediction == "x0":
            return output
        if self.config.prediction == "v":
            return abar.sqrt() * xt - (1 - abar).sqrt() * output
        if self.config.prediction == "u":
            return (xt - (1 - abar).sqrt() * output) / (abar.sqrt() + (1 - abar).sqrt())
        return (xt - (1 - abar).sqrt() * output) / abar.sqrt()

    def output(self, xt, t, mask=None, labels=None, known=None):
        """The network's estimate of its target (``config.prediction``), the Gaussian
        estimate included; arguments as :meth:`forward`'s."""
        check_sequence_input(xt, t, mask, self.config.num_landmarks)
        added = self._known_tokens(xt, known)
        k = self.config.num_classes
        if not k:
            if labels is not None:
                raise ValueError(
                    "this denoiser is unconditional (num_classes = 0): "
                    "it takes no labels"
                )
            tokens = self.encode(xt, t, mask, added=added)
        else:
            if labels is None:
                labels = torch.full((len(xt),), k, device=xt.device)
            else:
                # checked where the caller keeps them
                # (a list, a CPU tensor: no device round trip)
                labels = torch.as_tensor(labels)
                if labels.shape != (len(xt),) or labels.min() < 0 or labels.max() > k:
                    raise ValueError(
                        f"labels must be ({len(xt)},) class indices in 0..{k} "
                        f"({k}: no label)"
                    )
            tokens = self.encode(
                xt,
                t,
                mask,
                prefix=self.label_embedding(labels.to(xt.device))[:, None],
                added=added,
            )[:, 1:]
        # the network's estimate of its target (config.prediction)
        output = self.out(tokens).reshape(xt.shape)
        if self.config.gaussian_skip and self.config.prediction == "u":
            output = output + self.gaussian_u(xt, t.to(xt.device), mask)
        elif self.config.gaussian_skip:
            output = output + self.from_eps(
                xt, t, self.gaussian_eps(xt, t.to(xt.device), mask)
            )
        return output

    def _known_tokens(self, xt, known):
        """KE([x_0 m, m]) (B, F, width) of ``known`` = (x_0, m) (None: nothing known;
        a denoiser without ``known_input`` takes None only)."""
        if not self.config.known_input:
            if known is not None:
                raise ValueError(
                    "this denoiser does not read known frames (known_input = False):"
                    " give known=None, or use a join denoiser"
                )
            return None
        b, f = xt.shape[:2]
        if known is None:
            values = xt.new_zeros(b, f, xt.shape[2] * 3)
            m = xt.new_zeros(b, f, 1)
        else:
            x0, m = known
            if tuple(x0.shape) != tuple(xt.shape) or tuple(m.shape) != (b, f):
                raise ValueError(
                    f"known = (x_0, m) must be shaped {tuple(xt.shape)} and {(b, f)},"
                    f" got {tuple(x0.shape)} and {tuple(m.shape)}"
                )
            m = m.to(xt.device, torch.bool)[..., None]
            values = torch.where(m, x0.to(xt.device, xt.dtype).reshape(b, f, -1), 0.0)
            m = m.to(xt.dtype)
        return self.known_embedding(torch.cat([values, m], dim=-1))

    def config_dict(self):
        return asdict(self.config)
