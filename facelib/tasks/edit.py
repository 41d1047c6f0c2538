"""Editing a given sequence (not in the paper): DDIM inversion, then regeneration under
label control.

DDIM at eta = 0 is a deterministic map x_T -> x_0, and run backwards
(:meth:`GaussianDiffusion.invert`) it finds the x_T from which the chain regenerates a
given sequence.  What the sequence is made of is then written in x_T: its identity, its
timing.  Regenerating that x_T with label guidance (classifier or classifier-free,
:func:`facelib.tasks.label.label_sampler`) changes what the guidance reads, the
expression, and leaves the rest where x_T put it.
"""

from __future__ import annotations

import numpy as np
import torch

from ..config import NUM_LANDMARKS
from ..guidance import ClassifierFree
from ..inpainting import (
    check_finite_landmarks,
    keep_known,
    landmark_array,
    parse_ranges,
)
from .label import check_labels, label_sampler
from .loading import task_settings
from .settings import Edit


def check_sequences(sequences):
    """Landmark sequences (F, 68, 3) or (n, F, 68, 3) in mm as (n, F, 68, 3) float64 (a
    clear error for another shape or a value that is not finite)."""
    x = landmark_array(sequences, "the sequences to edit")
    if x.ndim not in (3, 4) or x.shape[-2:] != (NUM_LANDMARKS, 3) or 0 in x.shape:
        raise ValueError(
            "the sequences to edit must be (F, 68, 3) or (n, F, 68, 3) landmarks in"
            f" mm, got {x.shape}"
        )
    check_finite_landmarks(x, "the sequences to edit")
    return x[None] if x.ndim == 3 else x


def invert(
    denoiser, sequences, settings=Edit(), model=None, progress=False, trajectory=False
):
    """x_T of each sequence (n, F, 68, 3) in mm under the chain of ``settings`` (DDIM
    inversion on the very chain that regenerates: its steps, spacing and variance),
    normalised; ``model``: the eps network to invert with (default the denoiser's own);
    ``trajectory``: every x_t, t = 0..K.
    """
    chain = denoiser.chain_for(settings)
    x0 = torch.as_tensor(
        denoiser.normalizer.normalize(check_sequences(sequences)), dtype=torch.float32
    )
    return chain.invert(
        model or denoiser.model,
        x0.to(denoiser.device),
        progress=progress,
        refine=settings.refine,
        trajectory=trajectory,
    )


def kept_frames(keep, shape):
    """The frames to keep (n, F) bool from ranges "0:1" or a mask (F,) or (n, F) (errors
    name what is allowed)."""
    mask = parse_ranges(keep, shape[1]) if isinstance(keep, str) else np.asarray(keep)
    mask = (
        np.broadcast_to(mask, shape)
        if mask.ndim == 1 and len(mask) == shape[1]
        else mask
    )
    if np.shape(mask) != tuple(shape) or not np.isin(mask, (0, 1)).all():
        raise ValueError(
            "keep must be frame ranges like '0:1' or a boolean mask of shape"
            f" ({shape[1]},) or {shape}"
        )
    if np.asarray(mask, dtype=bool).all(axis=1).any():
        raise ValueError(
            "keep holds every frame of a sequence: there is nothing left to edit"
        )
    return np.asarray(mask, dtype=bool).copy()


def keep_on_path(path, kept, inner=None):
    """A sampler hook: x_{t-1} from the hook ``inner`` (None: the sampler's), its
    ``kept`` frames (n, F) taken from the inversion path ``path`` (x_t for t = 0..K)
    instead: they end where they began, and the chain fills the other frames around them
    (Alg. 3's known frames, with the inverted noise in place of a fresh draw).
    """

    def hook(x_hat, xt, t, out):
        x = inner(x_hat, xt, t, out) if inner is not None else x_hat
        return torch.where(kept[:, :, None, None], path[t - 1], x)

    return hook


def edit(
    sequences,
    label,
    settings=Edit(),
    denoiser=None,
    guide=None,
    progress=True,
    **overrides,
):
    """``sequences`` (F, 68, 3) or (n, F, 68, 3) in mm, each regenerated from its DDIM
    inversion with label guidance towards ``label`` (a name, or one per sequence): (n,
    F, 68, 3) float32 in mm.

    settings.keep (or the override ``keep=``): frames returned as given, as ranges "0:1"
    (the default: the neutral frame of an N2E sequence) or a mask (F,) or (n, F); they
    follow their own inversion path while the others are regenerated; None regenerates
    every frame.  settings: :class:`facelib.Edit` (a
    :class:`facelib.LabelControl` on a DDIM chain of 100 steps).  Classifier-free
    guidance inverts with the conditional denoiser told "no label"."""
    x = check_sequences(sequences)
    if overrides.get("num_frames", x.shape[1]) != x.shape[1]:
        raise ValueError(
            f"num_frames {overrides['num_frames']} differs from the sequences'"
            f" {x.shape[1]} frames"
        )
    settings, _ = task_settings(
        settings, {**overrides, "num_frames": x.shape[1]}, len(x)
    )
    labels = check_labels(label, len(x))
    kept = None if settings.keep is None else kept_frames(settings.keep, x.shape[:2])
    denoiser, diffusion, model, hook = label_sampler(labels, settings, denoiser, guide)
    # no label: the free estimate
    free = model.denoiser if isinstance(model, ClassifierFree) else model
    path = invert(denoiser, x, settings, free, progress, trajectory=True)
    if kept is not None:
        hook = keep_on_path(path, torch.as_tensor(kept).to(denoiser.device), hook)
    edited = denoiser.to_mm(
        diffusion.run(model, path[-1], settings.seed, guide=hook, progress=progress)
    )
    return edited if kept is None else keep_known(edited, x, kept)
