"""The bidirectional transformer (BiT) over frames shared by the paper's networks
(§3.1-3.2, Fig. 1).

Each frame of x_t (68 x 3 landmark coordinates, normalised) becomes one token, the sum
of

* FE(x_t)     feature embedding: one linear layer per frame, 204 -> width;
* PE(1..F)    positional encoding of the frame index (sinusoidal: any length F works);
* TE(t)       temporal (diffusion-step) embedding: sinusoidal, then a 2-layer MLP.

The encoder is *bidirectional*: no causal mask, every frame attends to every other
frame.  The denoiser eps_theta (models/denoiser.py) reads one output per frame; the
guidance classifier p_phi(y | x_t, t) (models/noisy_classifier.py) prepends a learnable
classification token and reads its output.
"""

from __future__ import annotations

import math

import torch
from torch import nn


def sinusoidal_embedding(positions, dim, max_period=10_000.0, dtype=torch.float32):
    """Transformer sinusoids of (possibly fractional) positions (...,) -> (..., dim), on
    the positions' device; computed in float32, returned as ``dtype`` (the network's, so
    that a float64 network stays float64).
    """
    half = dim // 2
    freqs = torch.exp(
        -math.log(max_period)
        * torch.arange(half, dtype=torch.float32, device=positions.device)
        / half
    )
    args = positions.float()[..., None] * freqs
    emb = torch.cat([torch.sin(args), torch.cos(args)], dim=-1)
    return torch.nn.functional.pad(emb, (0, dim % 2)).to(dtype)


def check_sequence_input(xt, t, mask, num_landmarks):
    """Validate (x_t, t, mask) of a BiT: (B, F, L, 3), (B,), (B, F) bool or None."""
    if xt.ndim != 4 or xt.shape[2:] != (num_landmarks, 3):
        raise ValueError(
            f"x_t must have shape (batch, frames, {num_landmarks}, 3), got"
            f" {tuple(xt.shape)}"
        )
    if t.shape != (xt.shape[0],):
        raise ValueError(
            f"t must have shape ({xt.shape[0]},) (one step per sequence), got"
            f" {tuple(t.shape)}"
        )
    if mask is not None and mask.shape != xt.shape[:2]:
        raise ValueError(
            f"mask must have shape {tuple(xt.shape[:2])}, got {tuple(mask.shape)}"
        )


class BiT(nn.Module):
    """FE + PE + TE tokens through a bidirectional transformer encoder (pre-norm), then
    LayerNorm."""

    def __init__(self, num_landmarks, width, depth, heads, ff, dropout=0.0):
        super().__init__()
        self.width = width
        self.fe = nn.Linear(num_landmarks * 3, width)
        self.te = nn.Sequential(
            nn.Linear(width, width), nn.SiLU(), nn.Linear(width, width)
        )
        layer = nn.TransformerEncoderLayer(
            width,
            heads,
            ff,
            dropout,
            activation="gelu",
            batch_first=True,
            norm_first=True,
        )
        self.encoder = nn.TransformerEncoder(layer, depth, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(width)

    def encode(self, xt, t, mask=None, prefix=None, added=None):
        """Output tokens (B, P + F, width) of x_t (B, F, L, 3) at steps t (B,);
        ``prefix`` (P, width) or (B, P, width) are extra tokens put before the frames
        (they also receive TE(t)); ``mask`` (B, F) bool marks the valid frames (prefix
        tokens are always valid); ``added`` (B, F, width) is added to the frames'
        tokens (the known frames' embedding of a join denoiser)."""
        b, f = xt.shape[:2]
        t = t.to(xt.device)
        frames = torch.arange(1, f + 1, device=xt.device)
        h = self.fe(xt.reshape(b, f, -1))
        h = h + sinusoidal_embedding(frames, self.width, dtype=h.dtype)[None]
        if added is not None:
            h = h + added
        if prefix is not None:
            prefix = prefix if prefix.ndim == 3 else prefix[None].expand(b, -1, -1)
            h = torch.cat([prefix, h], dim=1)
            if mask is not None:
                mask = torch.cat(
                    [
                        torch.ones(
                            b, prefix.shape[1], dtype=torch.bool, device=mask.device
                        ),
                        mask,
                    ],
                    dim=1,
                )
        h = h + self.te(sinusoidal_embedding(t, self.width, dtype=h.dtype))[:, None]
        h = self.encoder(h, src_key_padding_mask=None if mask is None else ~mask)
        return self.norm(h)
