"""ACTOR-style baseline (Petrovich et al. 2021): a label-conditioned transformer VAE of
motion.

* Input: the paper's expression part Delta L_f = L_f - L (each frame minus the subject's
  neutral landmarks, §3.3), normalised by one global scale.
* Encoder: the frames (FE + PE tokens) behind two label-specific tokens mu_y and sigma_y
  through a bidirectional transformer (models/bit.py, with TE(0) as a constant bias);
  the outputs of the two tokens are the mean and log-variance of q(z | x, y).
* Decoder: a transformer decoder whose queries are the positional encodings of the F
  frames and whose memory is the single token z + b_y (a learned label bias); a linear
  layer gives each frame.
* Loss: mean squared reconstruction error + kl_weight * KL(q(z | x, y) || N(0, I)).
* Sampling: z ~ N(0, I), decode, add the neutral landmarks of a training face.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from .bit import BiT, sinusoidal_embedding


@dataclass(frozen=True)
class ActorConfig:
    num_classes: int
    num_landmarks: int = 68
    width: int = 128
    depth: int = 2
    heads: int = 4
    ff: int = 256
    num_neutrals: int = 1


class ActorCVAE(nn.Module):
    def __init__(self, config):
        super().__init__()
        c = self.config = config
        self.encoder = BiT(c.num_landmarks, c.width, c.depth, c.heads, c.ff)
        # mu_y, sigma_y
        self.dist_tokens = nn.Parameter(torch.randn(c.num_classes, 2, c.width) * 0.02)
        self.to_mu, self.to_logvar = nn.Linear(c.width, c.width), nn.Linear(
            c.width, c.width
        )
        self.label_bias = nn.Parameter(torch.zeros(c.num_classes, c.width))
        layer = nn.TransformerDecoderLayer(
            c.width,
            c.heads,
            c.ff,
            0.0,
            activation="gelu",
            batch_first=True,
            norm_first=True,
        )
        self.decoder = nn.TransformerDecoder(layer, c.depth)
        self.out = nn.Sequential(
            nn.LayerNorm(c.width), nn.Linear(c.width, c.num_landmarks * 3)
        )
        self.register_buffer("scale", torch.ones(()))  # mm per unit of Delta L
        self.register_buffer(
            "neutrals", torch.zeros(c.num_neutrals, c.num_landmarks, 3)
        )

    def encode(self, delta, labels):
        """Mean and log-variance (B, width) of q(z | Delta L, y)."""
        h = self.encoder.encode(
            delta,
            torch.zeros(len(delta), device=delta.device),
            prefix=self.dist_tokens[labels],
        )
        return self.to_mu(h[:, 0]), self.to_logvar(h[:, 1])

    def decode(self, z, labels, num_frames):
        """Delta L (B, F, 68, 3) in normalised units from z (B, width) and labels
        (B,)."""
        frames = torch.arange(1, num_frames + 1, device=z.device)
        queries = sinusoidal_embedding(frames, self.config.width, dtype=z.dtype)[
            None
        ].expand(len(z), -1, -1)
        h = self.decoder(queries, (z + self.label_bias[labels])[:, None])
        return self.out(h).reshape(len(z), num_frames, self.config.num_landmarks, 3)

    @torch.no_grad()
    def sample(self, labels, num_frames=40, seed=0):
        """Landmark sequences (n, F, 68, 3) in mm, a tensor where the model is, for
        class indices ``labels`` (n,). The draws are made on the CPU, so that a seed
        gives the same sequences on every device.
        """
        gen = torch.Generator().manual_seed(seed)
        n = len(labels)
        z = torch.randn(n, self.config.width, generator=gen).to(self.scale)
        picks = torch.randint(0, len(self.neutrals), (n,), generator=gen)
        labels = torch.as_tensor(
            np.asarray(labels), dtype=torch.long, device=self.scale.device
        )
        neutral = self.neutrals[picks.to(self.scale.device)]
        return self.decode(z, labels, num_frames) * self.scale + neutral[:, None]

    def generate(self, labels, num_frames=40, seed=0):
        """Landmark sequences (n, F, 68, 3) float32 in mm (numpy) for class indices
        ``labels`` (n,)."""
        return self.sample(labels, num_frames, seed).cpu().numpy().astype(np.float32)


def config_dict(model):
    return asdict(model.config)


def build(config):
    return ActorCVAE(ActorConfig(**config))
