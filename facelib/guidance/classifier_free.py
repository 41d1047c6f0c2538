"""Classifier-free guidance (Ho & Salimans 2022): no classifier, a label-conditional
denoiser instead.

A denoiser trained with its label dropped now and then
(training.DenoiserTraining.conditional) estimates both eps(x_t, t, y) and eps(x_t, t, no
label).  Their difference is, up to -sqrt(1 - abar_t), the gradient of an implicit
classifier's log p(y | x_t) (Bayes: log p(y | x_t) = log p(x_t | y) - log p(x_t) +
const), so

    eps_w(x_t, t, y) = eps(x_t, t, no label) + w (eps(x_t, t, y) - eps(x_t, t, no
    label))

climbs that classifier with weight w - 1: w = 1 is the conditional model, w = 0 the
unconditional one, w > 1 guides harder.  The wrapper is a model like the denoiser, so
every sampler (DDPM, DDIM) runs it.
"""

from __future__ import annotations

import torch
from torch import nn


class ClassifierFree(nn.Module):
    """eps_w of a label-conditional denoiser for fixed ``labels`` (B,) and guidance
    weight ``scale`` = w >= 0."""

    def __init__(self, denoiser, labels, scale):
        super().__init__()
        if not getattr(denoiser.config, "num_classes", 0):
            raise ValueError(
                "classifier-free guidance needs a label-conditional denoiser"
                " (num_classes > 0; train one with"
                " training.DenoiserTraining(conditional=True)); this one is"
                " unconditional"
            )
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or scale < 0:
            raise ValueError(f"the guidance scale must be a number >= 0, got {scale!r}")
        self.denoiser, self.scale = denoiser, float(scale)
        self.register_buffer(
            "labels", torch.as_tensor(labels, dtype=torch.long), persistent=False
        )

    def forward(self, xt, t, mask=None):
        if self.scale == 1:  # free + (conditional - free): one call
            return self.denoiser(xt, t, mask, labels=self.labels)
        free = self.denoiser(xt, t, mask)
        if self.scale == 0:
            return free
        conditional = self.denoiser(xt, t, mask, labels=self.labels)
        return free + self.scale * (conditional - free)
