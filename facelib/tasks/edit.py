"""Editing a given sequence (not in the paper): DDIM inversion, then regeneration under label control.

DDIM at eta = 0 is a deterministic map x_T -> x_0, and run backwards (:meth:`GaussianDiffusion.invert`) it
finds the x_T from which the chain regenerates a given sequence.  What the sequence is made of is then
written in x_T: its identity, its timing.  Regenerating that x_T with label guidance (classifier or
classifier-free, :func:`facelib.tasks.label.label_sampler`) changes what the guidance reads, the expression,
and leaves the rest where x_T put it.
"""
from __future__ import annotations

import numpy as np
import torch

from ..config import Edit
from ..guidance import ClassifierFree
from .label import check_labels, label_sampler
from .loading import task_settings


def check_sequences(sequences):
    """Landmark sequences (F, 68, 3) or (n, F, 68, 3) in mm as (n, F, 68, 3) float64 (a clear error for another
    shape or a value that is not finite)."""
    x = np.asarray(sequences, dtype=np.float64)
    if x.ndim not in (3, 4) or x.shape[-2:] != (68, 3):
        raise ValueError(f"the sequences to edit must be (F, 68, 3) or (n, F, 68, 3) landmarks in mm, got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("the sequences to edit hold NaN or infinite values")
    return x[None] if x.ndim == 3 else x


def invert(denoiser, sequences, settings=Edit(), model=None, progress=False):
    """x_T of each sequence (n, F, 68, 3) in mm under the chain of ``settings`` (DDIM inversion), normalised;
    ``model``: the eps network to invert with (default the denoiser's own)."""
    diffusion = denoiser.diffusion_with(settings.steps, settings.variance, 0.0)
    x0 = torch.as_tensor(denoiser.normalizer.normalize(check_sequences(sequences)), dtype=torch.float32)
    return diffusion.invert(model or denoiser.model, x0.to(denoiser.device), progress=progress, refine=settings.refine)


def edit(sequences, label, settings=Edit(), denoiser=None, guide=None, progress=True, **overrides):
    """``sequences`` (F, 68, 3) or (n, F, 68, 3) in mm, each regenerated from its DDIM inversion with label
    guidance towards ``label`` (a name, or one per sequence): (n, F, 68, 3) float32 in mm.

    settings: :class:`facelib.config.Edit` (a :class:`facelib.config.LabelControl` on a DDIM chain of 100
    steps).  Classifier-free guidance inverts with the conditional denoiser told "no label"."""
    x = check_sequences(sequences)
    settings, _ = task_settings(settings, {**overrides, "num_frames": x.shape[1]}, len(x))
    labels = check_labels(label, len(x))
    denoiser, diffusion, model, hook = label_sampler(labels, settings, denoiser, guide)
    free = ClassifierFree(model.denoiser, model.labels, 0.0) if isinstance(model, ClassifierFree) else model
    xT = invert(denoiser, x, settings, free, progress)
    return denoiser.to_mm(diffusion.run(model, xT, settings.seed, guide=hook, progress=progress))
