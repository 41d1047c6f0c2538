"""The guidance classifier p_phi(y | x_t, t) of label control (paper §3.2, Alg. 1).

"The classification is conducted with a BiT by adopting the usual approach of adding an
extra learnable classification token": the same FE + PE + TE bidirectional transformer
as the denoiser (models/bit.py, its own weights), with one more token in front of the
frames whose output goes through a linear layer to the class logits.  It is trained on
*noisy* sequences x_t = q_sample(x_0, t) with t uniform in 0..T (t = 0 is the clean
  sequence), so that it can
score every intermediate x_t of the reverse process (guided-diffusion's ``--noised``
recipe).

Like the independent classifier, it reads *motion*: the frames of x_t minus their mean
over the (valid) frames, which removes the anatomy (our choice, the face-world chapter:
with 9 training faces a classifier of absolute coordinates learns faces, not
expressions).

The text head of Alg. 2 (§3.2, "the softmax layer is removed") is the same network with
an embedding instead of logits: :class:`NoisyTextHead`, trained so that its output has a
high cosine similarity with the text embedding of x_0's description (MotionCLIP-style,
§5.2).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from .bit import BiT, check_sequence_input


@dataclass(frozen=True)
class NoisyClassifierConfig:
    """Sizes of the guidance BiT (our choice: smaller than the denoiser, it only has to
    classify)."""

    num_classes: int
    num_landmarks: int = 68
    width: int = 128
    depth: int = 3
    heads: int = 4
    ff: int = 256
    dropout: float = 0.1
    inputs: str = "motion"  # "motion" (minus the mean frame) or "absolute"


def motion_input(xt, mask=None):
    """x_t minus its mean frame over the valid frames (``mask`` (B, F) bool): the
    motion, not the face."""
    if mask is None:
        return xt - xt.mean(dim=1, keepdim=True)
    m = mask[:, :, None, None].to(xt.dtype)
    return (xt - (xt * m).sum(1, keepdim=True) / m.sum(1, keepdim=True)) * m


class NoisyBiT(BiT):
    """A BiT over x_t with a learnable classification token in front of the frames; the
    token's output goes through one linear layer to ``out_features`` values (logits or
    an embedding).
    """

    def __init__(self, config, out_features):
        c = config
        if c.inputs not in ("motion", "absolute"):
            raise ValueError(f"inputs must be 'motion' or 'absolute', got {c.inputs!r}")
        super().__init__(c.num_landmarks, c.width, c.depth, c.heads, c.ff, c.dropout)
        self.config = config
        self.cls_token = nn.Parameter(torch.randn(1, c.width) * 0.02)
        self.head = nn.Linear(c.width, out_features)

    def forward(self, xt, t, mask=None):
        """(B, out_features) from x_t (B, F, 68, 3) at steps t (B,);
        ``mask`` (B, F) bool marks the valid frames."""
        check_sequence_input(xt, t, mask, self.config.num_landmarks)
        if self.config.inputs == "motion":
            xt = motion_input(xt, mask)
        return self.head(self.encode(xt, t, mask, prefix=self.cls_token)[:, 0])

    def config_dict(self):
        return asdict(self.config)


class NoisyClassifier(NoisyBiT):
    """p_phi(y | x_t, t): (B, F, 68, 3) normalised landmarks, (B,) steps -> (B,
    num_classes) logits."""

    def __init__(self, config):
        if config.num_classes < 2:
            raise ValueError(
                f"a classifier needs at least 2 classes, got {config.num_classes}"
            )
        super().__init__(config, config.num_classes)

    def log_prob(self, xt, t, labels, mask=None):
        """log p_phi(y | x_t, t) (B,) for class indices ``labels`` (B,)."""
        return torch.log_softmax(self.forward(xt, t, mask), dim=-1).gather(
            1, labels[:, None]
        )[:, 0]


@dataclass(frozen=True)
class TextHeadConfig:
    """Sizes of the text head BiT(x_t, t) of Alg. 2 (the guidance classifier's, our
    choice)."""

    # the text encoder's (all-MiniLM-L6-v2; the paper's CLIP gives 512)
    embedding_dim: int = 384
    num_landmarks: int = 68
    width: int = 128
    depth: int = 3
    heads: int = 4
    ff: int = 256
    dropout: float = 0.1
    inputs: str = "motion"


class NoisyTextHead(NoisyBiT):
    """BiT(x_t, t) of Alg. 2: (B, F, 68, 3), (B,) -> (B, embedding_dim) unit vectors in
    the text space."""

    def __init__(self, config):
        super().__init__(config, config.embedding_dim)

    def embed(self, xt, t, mask=None):
        """The unit-norm motion embedding (B, embedding_dim)."""
        return torch.nn.functional.normalize(self.forward(xt, t, mask), dim=-1)

    def cosine(self, xt, t, text_embeddings, mask=None):
        """cos(BiT(x_t, t), E(c)) (B,) for text embeddings (B, embedding_dim) or
        (embedding_dim,) (Eq. 10)."""
        e = torch.nn.functional.normalize(
            torch.as_tensor(text_embeddings, dtype=xt.dtype, device=xt.device), dim=-1
        )
        return (self.embed(xt, t, mask) * e).sum(-1)
