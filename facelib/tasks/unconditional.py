"""Unconditional generation (§3.1): the reverse chain from x_T ~ N(0, I)."""

from __future__ import annotations

from .loading import denoiser_name, load_denoiser, task_settings
from .settings import Unconditional


def unconditional(
    n,
    settings=Unconditional(),
    denoiser=None,
    progress=True,
    callback=None,
    **overrides,
):
    """Sample ``n`` landmark sequences (n, F, 68, 3) float32 in mm from the
    unconditional DDPM.

    settings: :class:`facelib.Unconditional` (steps: None for the paper's T =
    2000, or fewer, respaced without retraining); ``overrides`` change single fields,
    e.g. ``steps=100``.
    """
    settings, shape = task_settings(settings, overrides, n)
    denoiser = denoiser or load_denoiser(
        denoiser_name(settings.dataset, settings.sampler, settings.steps)
    )
    diffusion = denoiser.chain_for(settings)
    x = diffusion.sample(
        denoiser.model, shape, seed=settings.seed, progress=progress, callback=callback
    )
    return denoiser.to_mm(x)
