"""The "Linear" baseline of Table 5 (paper §6, after Casas & Otaduy [10]; the
mesh-deformation chapter).

An autoencoder whose encoder and decoder are each three layers of "linear, nonlinear,
linear" units.  As in §6 the decoder, which originally decodes the latent code of the
input mesh, is modified to consume the concatenation of that code with the landmark
displacement Delta L_f:

    code = Linear(tanh(Linear(M - template)))            encoder, once per neutral mesh
    Delta M_f = Linear(tanh(Linear([code, Delta L_f])))    decoder, once per frame

No mesh structure at all: every vertex is a separate output of the last dense layer.
The same interface as :class:`~facelib.models.deformer.Deformer`: (neutral (B, V, 3),
Delta L (B, F, 68, 3))
-> Delta M (B, F, V, 3), all in mm.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from ..face import template as tpl


@dataclass(frozen=True)
class LinearDeformerConfig:
    # our choice: the two dense layers on 3V values dominate the size (1.2 M weights)
    hidden: int = 48
    latent: int = 32  # our choice
    num_landmarks: int = 68
    scale: float = 10.0  # mm per network unit, as the Deformer


class LinearDeformer(nn.Module):
    """(neutral (B, V, 3) mm, Delta L (B, F, 68, 3) mm) -> Delta M (B, F, V, 3) mm."""

    def __init__(self, config=LinearDeformerConfig()):
        super().__init__()
        c = self.config = config
        template = torch.tensor(tpl.get_template().vertices, dtype=torch.float32)
        self.register_buffer("template", template, persistent=False)
        size = template.numel()
        self.encoder = nn.Sequential(
            nn.Linear(size, c.hidden), nn.Tanh(), nn.Linear(c.hidden, c.latent)
        )
        self.decoder = nn.Sequential(
            nn.Linear(c.latent + 3 * c.num_landmarks, c.hidden),
            nn.Tanh(),
            nn.Linear(c.hidden, size),
        )

    def forward(self, neutral, delta):
        b, f = delta.shape[:2]
        # (B, latent)
        code = self.encoder(((neutral - self.template) / self.config.scale).flatten(1))
        z = torch.cat(
            [code[:, None].expand(-1, f, -1), delta.flatten(2) / self.config.scale], -1
        )
        return self.decoder(z).reshape(b, f, -1, 3) * self.config.scale


def config_dict(model):
    return asdict(model.config)


def build(config):
    return LinearDeformer(LinearDeformerConfig(**config))
