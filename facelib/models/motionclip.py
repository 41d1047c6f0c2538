"""MotionCLIP-style baseline of Table 2 (Tevet et al. 2022, paper §5.2): text -> one
sequence.

MotionCLIP aligns a motion auto-encoder's latent space with CLIP's text space and
generates by decoding the text embedding itself: one text, one motion.  Our version
keeps exactly that property with the book's offline encoder (all-MiniLM-L6-v2,
facelib/text.py):

* Decoder: the text embedding E(c) (384-d, unit norm) through a linear layer is the
  single memory token of a transformer decoder whose queries are the positional
  encodings of the F frames (as MotionCLIP's and ACTOR's decoders); a linear layer gives
  each frame's Delta L = L_f - L.
* Loss: mean squared error to the training sequence's Delta L (normalised by one global
  scale), with c a random training description of it (facelib/descriptions.py), the text
  head's texts.
* Output: Delta L plus the mean neutral face of the training subjects.

It is deterministic: the same text always gives the same sequence.  The squared loss
makes it decode the *average* motion of everything its text describes, which is the
diversity argument of §5.2: realistic-looking, but far from the spread of real sequences
(high FID).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from .bit import sinusoidal_embedding


@dataclass(frozen=True)
class MotionClipConfig:
    embedding_dim: int = 384
    num_landmarks: int = 68
    width: int = 128
    depth: int = 2
    heads: int = 4
    ff: int = 256


class TextToMotion(nn.Module):
    """E(c) (B, embedding_dim) -> Delta L (B, F, 68, 3), then plus the mean neutral
    face."""

    def __init__(self, config):
        super().__init__()
        c = self.config = config
        self.text_in = nn.Linear(c.embedding_dim, c.width)
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
        # mean training neutral face (mm)
        self.register_buffer("neutral", torch.zeros(c.num_landmarks, 3))

    def decode(self, text_embeddings, num_frames):
        """Delta L (B, F, 68, 3) in normalised units."""
        frames = torch.arange(1, num_frames + 1, device=text_embeddings.device)
        queries = sinusoidal_embedding(
            frames, self.config.width, dtype=text_embeddings.dtype
        )[None]
        queries = queries.expand(len(text_embeddings), -1, -1)
        h = self.decoder(queries, self.text_in(text_embeddings)[:, None])
        return self.out(h).reshape(
            len(text_embeddings), num_frames, self.config.num_landmarks, 3
        )

    @torch.no_grad()
    def generate(self, text_embeddings, num_frames=40):
        """Landmark sequences (n, F, 68, 3) float32 in mm, one per text embedding (n,
        embedding_dim)."""
        e = torch.as_tensor(np.asarray(text_embeddings, dtype=np.float32))
        if e.ndim != 2 or e.shape[1] != self.config.embedding_dim:
            raise ValueError(
                f"text embeddings must be (n, {self.config.embedding_dim}), got"
                f" {tuple(e.shape)}"
            )
        return (
            (self.decode(e.to(self.scale), num_frames) * self.scale + self.neutral)
            .cpu()
            .numpy()
            .astype(np.float32)
        )


def config_dict(model):
    return asdict(model.config)


def build(config):
    return TextToMotion(MotionClipConfig(**config))
