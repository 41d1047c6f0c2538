"""The guidance classifier p_phi(y | x_t, t) of label control (paper §3.2, Alg. 1).

"The classification is conducted with a BiT by adopting the usual approach of adding an extra
learnable classification token": the same FE + PE + TE bidirectional transformer as the denoiser
(models/bit.py, its own weights), with one more token in front of the frames whose output goes
through a linear layer to the class logits.  It is trained on *noisy* sequences
x_t = q_sample(x_0, t) with t uniform in 0..T (t = 0 is the clean sequence), so that it can
score every intermediate x_t of the reverse process (guided-diffusion's ``--noised`` recipe).

Like the independent classifier, it reads *motion*: the frames of x_t minus their mean over the
(valid) frames, which removes the anatomy (our choice, chapter 01: with 9 training faces a
classifier of absolute coordinates learns faces, not expressions).  With ``out_features`` set
it becomes the text head of Alg. 2 (an embedding instead of logits).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from .bit import BiT, check_sequence_input


@dataclass(frozen=True)
class NoisyClassifierConfig:
    """Sizes of the guidance BiT (our choice: smaller than the denoiser, it only has to classify)."""

    num_classes: int
    num_landmarks: int = 68
    width: int = 128
    depth: int = 3
    heads: int = 4
    ff: int = 256
    dropout: float = 0.1
    inputs: str = "motion"  # "motion" (minus the mean frame) or "absolute"


class NoisyClassifier(BiT):
    """p_phi(y | x_t, t): (B, F, 68, 3) normalised landmarks, (B,) steps -> (B, num_classes) logits."""

    def __init__(self, config):
        c = config
        if c.inputs not in ("motion", "absolute"):
            raise ValueError(f"inputs must be 'motion' or 'absolute', got {c.inputs!r}")
        if c.num_classes < 2:
            raise ValueError(f"a classifier needs at least 2 classes, got {c.num_classes}")
        super().__init__(c.num_landmarks, c.width, c.depth, c.heads, c.ff, c.dropout)
        self.config = config
        self.cls_token = nn.Parameter(torch.randn(1, c.width) * 0.02)
        self.head = nn.Linear(c.width, c.num_classes)

    def forward(self, xt, t, mask=None):
        """Class logits (B, num_classes) of x_t at steps t; ``mask`` (B, F) bool marks the valid frames."""
        check_sequence_input(xt, t, mask, self.config.num_landmarks)
        if self.config.inputs == "motion":
            if mask is None:
                xt = xt - xt.mean(dim=1, keepdim=True)
            else:
                m = mask[:, :, None, None].to(xt.dtype)
                xt = (xt - (xt * m).sum(1, keepdim=True) / m.sum(1, keepdim=True)) * m
        return self.head(self.encode(xt, t, mask, prefix=self.cls_token)[:, 0])

    def log_prob(self, xt, t, labels, mask=None):
        """log p_phi(y | x_t, t) (B,) for class indices ``labels`` (B,)."""
        return torch.log_softmax(self.forward(xt, t, mask), dim=-1).gather(1, labels[:, None])[:, 0]

    def config_dict(self):
        return asdict(self.config)
