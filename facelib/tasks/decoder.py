"""Decoder then diffusion (not in the paper): the MotionCLIP-style decoder's sequence
for a text, re-noised and denoised by the unconditional DDPM (SDEdit, Meng et al.
2022)."""

from __future__ import annotations

import numpy as np
import torch

from ..baselines import generate_from_text, load_baseline
from .loading import denoiser_name, load_denoiser, task_settings
from .text import text_list
from .settings import DecoderThenDiffusion


def decoder_then_diffusion(
    text,
    n=8,
    settings=DecoderThenDiffusion(),
    denoiser=None,
    decoder=None,
    progress=True,
    **overrides,
):
    """The decoder's sequence for ``text``, re-noised to step ``settings.start`` with
    Eq. 3 and denoised from there.  The deterministic decoder hears the words (the order
    of an enriched text too); the reverse chain from x_start ~ q(x_start | x_0 =
    decoder(text)) gives every call another sequence near it: the larger ``start``, the
    more diverse and the less faithful.

    start: a step of the paper's chain, 1..T (respaced chains start at their nearest
    step). Returns (n, F, 68, 3) float32 in mm."""
    settings, shape = task_settings(settings, overrides, n)
    texts, dataset = text_list(text, n), settings.dataset
    decoder = decoder or load_baseline("motionclip", dataset)
    denoiser = denoiser or load_denoiser(
        denoiser_name(dataset, settings.sampler, settings.steps)
    )
    if denoiser.meta["training"]["dataset"] != dataset:
        raise ValueError(
            f"the denoiser was trained on {denoiser.meta['training']['dataset']!r}, the"
            f" decoder's sequences are of {dataset!r}: use denoiser_{dataset}"
        )
    diffusion = denoiser.chain_for(settings)
    last = denoiser.diffusion.num_steps
    if not 1 <= settings.start <= last:
        raise ValueError(f"start must be a step in 1..{last}, got {settings.start!r}")
    k = max(1, int(np.argmin(np.abs(diffusion.timesteps - settings.start))))
    x0 = denoiser.to_model(generate_from_text(decoder, texts, shape[1]))
    # one stream: x_start's noise, then every step's
    generator = torch.Generator().manual_seed(settings.seed)
    x_start = diffusion.q_sample(x0, k, generator=generator)
    x = diffusion.run(
        denoiser.model, x_start, generator, diffusion.schedule(k), progress=progress
    )
    return denoiser.to_mm(x)
