"""A learned filling baseline in the spirit of Berson et al. (2020, paper 002): a
bidirectional LSTM trained with random masks to regenerate the missing frames of an
animation.

As in their generator: 2 bidirectional LSTM layers of 128 units, dropout 0.3, a dense
output layer; per frame the input is the masked animation (1 - M) * X, the mask and one
N(0, 1) noise value.  Their GAN critic is left out (optional in the issue): the model is
trained with the reconstruction loss of their Eq. 1 alone,

    L_feat = alpha_gt (1 - M) |G(X_i) - X| + M |G(X_i) - X|,  alpha_gt = 10 (theirs),

with M = 1 on the missing frames.  Our one change, for the landmark space: the network
predicts a correction to the mean of the known frames (mean imputation), so the anatomy
given by the known frames is kept without having to be relearned.  Frames are in the
denoiser's normalised space.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn


@dataclass
class LSTMFillerConfig:
    num_landmarks: int = 68
    hidden: int = 128
    layers: int = 2
    dropout: float = 0.3


class LSTMFiller(nn.Module):
    """G(X_i): (masked sequence, mask, noise) -> the whole sequence (B, F, 68, 3)."""

    def __init__(self, config=LSTMFillerConfig()):
        super().__init__()
        self.config = config
        d = config.num_landmarks * 3
        self.lstm = nn.LSTM(
            d + 2,
            config.hidden,
            num_layers=config.layers,
            dropout=config.dropout,
            bidirectional=True,
            batch_first=True,
        )
        self.out = nn.Linear(2 * config.hidden, d)

    def forward(self, x, known, z=None, generator=None):
        """x: (B, F, 68, 3) (unknown frames ignored), known: (B, F) bool;
        returns (B, F, 68, 3).  ``z`` (B, F, 1): the noise (None: drawn with
        ``generator``)."""
        b, f = known.shape
        k = known.to(x.dtype)[:, :, None]
        flat = torch.where(
            known[:, :, None],
            x.flatten(2),
            torch.zeros((), dtype=x.dtype, device=x.device),
        )
        # mean imputation, (B, 1, D)
        mean = flat.sum(1, keepdim=True) / k.sum(1, keepdim=True)
        if z is None:
            # drawn on the generator's device
            # (the CPU's by default: the same noise on every device)
            z = torch.randn(
                (b, f, 1),
                generator=generator,
                dtype=x.dtype,
                device=None if generator is None else generator.device,
            ).to(x.device)
        h, _ = self.lstm(torch.cat([flat - k * mean, k, z], dim=2))
        return (mean + self.out(h)).reshape(x.shape)


def masked_l1(prediction, target, known, alpha_gt=10.0):
    """Berson et al. Eq. 1: alpha_gt |G - X| on the known frames + |G - X| on the
    missing ones (each a mean over its frames' coordinates)."""
    err = (prediction - target).abs().flatten(2).mean(2)  # (B, F)
    k = known.to(err.dtype)
    return alpha_gt * (err * k).sum() / k.sum().clamp(min=1) + (err * (1 - k)).sum() / (
        1 - k
    ).sum().clamp(min=1)
