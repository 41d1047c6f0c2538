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
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn


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

    def forward(self, xt, t, mask=None):
        """Noise estimate for x_t at steps t; ``mask`` (B, F) bool marks the valid frames."""
        b, f = xt.shape[:2]
        frames = torch.arange(1, f + 1, device=xt.device)
        h = (self.fe(xt.reshape(b, f, -1))
             + sinusoidal_embedding(frames, self.config.width)[None]
             + self.te(sinusoidal_embedding(t.to(xt.device), self.config.width))[:, None])
        h = self.encoder(h, src_key_padding_mask=None if mask is None else ~mask)
        return self.out(self.norm(h)).reshape(xt.shape)

    def config_dict(self):
        return asdict(self.config)
