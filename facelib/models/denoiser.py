"""The noise approximator eps_theta(x_t, t) of the paper (§3.1, Fig. 1): a bidirectional transformer.

Each frame of x_t (68 x 3 landmark coordinates, normalised) becomes one token.  The input of the
transformer is the sum of three embeddings (Fig. 1):

* FE(x_t)     feature embedding: one linear layer per frame, 204 -> width;
* PE(1..F)    positional encoding of the frame index (sinusoidal, so any length F works);
* TE(t)       temporal (diffusion-step) embedding: sinusoidal, then a 2-layer MLP.

The encoder is *bidirectional*: no causal mask, every frame attends to every other frame, past
and future, which is what expression filling (chapter 07) needs.  Padded frames of a batch of
mixed lengths are excluded with a key padding mask.  A linear layer maps each token back to 204
numbers, the noise estimate of that frame.

One addition of ours, measured in chapter 03: a token is narrower (128) than a frame (204 numbers),
so a plain transformer cannot even pass the noise through at large t (its loss stalls at the
fraction of dimensions it cannot represent).  We therefore add the closed-form *Gaussian* noise
estimate of each frame, E[eps | x_t] for frames drawn from N(0, Sigma) with Sigma the covariance
of the training frames,

    eps_gauss(x_t, t) = sqrt(1 - abar_t) (abar_t Sigma + (1 - abar_t) I)^-1 x_t,

and the transformer learns only the residual: eps_theta = eps_gauss + BiT(TE + PE + FE).  Its
output layer starts at zero, so training starts from the best linear per-frame denoiser.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn

from ..diffusion import named_betas


def sinusoidal_embedding(positions, dim, max_period=10_000.0):
    """Transformer sinusoids of (possibly fractional) positions (...,) -> (..., dim)."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, dtype=torch.float32, device=positions.device) / half)
    args = positions.float()[..., None] * freqs
    emb = torch.cat([torch.sin(args), torch.cos(args)], dim=-1)
    return torch.nn.functional.pad(emb, (0, dim % 2))


@dataclass(frozen=True)
class DenoiserConfig:
    """Sizes of the denoiser (our choice; the paper gives none: see chapter 03 for the CPU budget)."""

    num_landmarks: int = 68
    width: int = 128
    depth: int = 4
    heads: int = 4
    ff: int = 256
    dropout: float = 0.0
    gaussian_skip: bool = True  # our addition (see the module docstring)
    num_diffusion_steps: int = 2000  # the schedule the skip needs (paper §4)
    schedule: str = "linear"


class Denoiser(nn.Module):
    """eps_theta(x_t, t): (B, F, 68, 3) normalised landmarks, (B,) steps -> (B, F, 68, 3) noise."""

    def __init__(self, config=DenoiserConfig()):
        super().__init__()
        self.config = config
        c = config
        features = c.num_landmarks * 3
        self.fe = nn.Linear(features, c.width)
        self.te = nn.Sequential(nn.Linear(c.width, c.width), nn.SiLU(), nn.Linear(c.width, c.width))
        layer = nn.TransformerEncoderLayer(c.width, c.heads, c.ff, c.dropout, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, c.depth, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(c.width)
        self.out = nn.Linear(c.width, features)
        if c.gaussian_skip:
            nn.init.zeros_(self.out.weight)
            nn.init.zeros_(self.out.bias)
        abar = torch.cumprod(1 - torch.as_tensor(named_betas(c.schedule, c.num_diffusion_steps)), 0)
        self.register_buffer("alphas_bar", torch.cat([torch.ones(1, dtype=abar.dtype), abar]).float())
        self.register_buffer("prior_basis", torch.eye(features))  # eigenvectors of Sigma (columns)
        self.register_buffer("prior_variances", torch.ones(features))  # eigenvalues of Sigma

    @torch.no_grad()
    def fit_prior(self, frames):
        """Set Sigma from normalised training frames (N, 68, 3): the Gaussian part of the estimate."""
        x = torch.as_tensor(frames, dtype=torch.float64).reshape(len(frames), -1)
        cov = torch.cov(x.T)
        variances, basis = torch.linalg.eigh(cov)
        self.prior_basis.copy_(basis.float())
        self.prior_variances.copy_(variances.clamp_min(0).float())

    def gaussian_eps(self, xt, t):
        """E[eps | x_t] if every frame were drawn from N(0, Sigma): a per-frame linear filter."""
        abar = self.alphas_bar[t.round().long().clamp(0, len(self.alphas_bar) - 1)].to(xt.device)
        abar = abar.reshape(-1, 1, 1)
        y = xt.reshape(xt.shape[0], xt.shape[1], -1) @ self.prior_basis
        y = y * (1 - abar).sqrt() / (abar * self.prior_variances + 1 - abar)
        return (y @ self.prior_basis.T).reshape(xt.shape)

    def forward(self, xt, t, mask=None):
        """Noise estimate for x_t at steps t; ``mask`` (B, F) bool marks the valid frames."""
        if xt.ndim != 4 or xt.shape[2:] != (self.config.num_landmarks, 3):
            raise ValueError(f"x_t must have shape (batch, frames, {self.config.num_landmarks}, 3), got {tuple(xt.shape)}")
        if t.shape != (xt.shape[0],):
            raise ValueError(f"t must have shape ({xt.shape[0]},) (one step per sequence), got {tuple(t.shape)}")
        if mask is not None and mask.shape != xt.shape[:2]:
            raise ValueError(f"mask must have shape {tuple(xt.shape[:2])}, got {tuple(mask.shape)}")
        b, f = xt.shape[:2]
        t = t.to(xt.device)
        frames = torch.arange(1, f + 1, device=xt.device)
        h = (self.fe(xt.reshape(b, f, -1))
             + sinusoidal_embedding(frames, self.config.width)[None]
             + self.te(sinusoidal_embedding(t, self.config.width))[:, None])
        h = self.encoder(h, src_key_padding_mask=None if mask is None else ~mask)
        eps = self.out(self.norm(h)).reshape(xt.shape)
        return eps + self.gaussian_eps(xt, t) if self.config.gaussian_skip else eps

    def config_dict(self):
        return asdict(self.config)
