"""Expression filling (§3.2, Alg. 3): the unknown frames of a sequence generated around
the known ones."""

from __future__ import annotations

import torch

from ..face.sequences import check_num_frames
from ..guidance import ReconstructionGuidance
from ..inpainting import KnownFrames, check_fill_input, keep_known
from .loading import denoiser_name, load_denoiser
from .settings import Fill
from ..checks import with_overrides


def known_noise(seed):
    """The generator of the known frames' noise: its own stream, so adding known frames
    never changes the noise that drives the unknown ones."""
    return torch.Generator().manual_seed(10_000 + seed)


def fill(
    sequences,
    known,
    settings=Fill(),
    denoiser=None,
    progress=True,
    callback=None,
    **overrides,
):
    """Expression filling (Alg. 3): complete the unknown frames of landmark sequences.

    sequences: (F, 68, 3) or (n, F, 68, 3) in mm; only the known frames are read (the
    others may hold anything, NaN included).  known: (F,) or (n, F) bool, True = known
    frame.  settings: :class:`facelib.Fill`: resample r > 1 adds RePaint's
    resampling (each step run r times); reconstruction_scale > 0 adds reconstruction
    guidance (not in the paper); ``settings.paper()`` is Alg. 3 as printed.
    Returns (n, F, 68, 3) float32 in mm whose known frames equal the given ones
    exactly."""
    settings = with_overrides(settings, overrides)
    x, mask = check_fill_input(sequences, known)
    check_num_frames(x.shape[1])
    denoiser = denoiser or load_denoiser(
        denoiser_name(settings.dataset, settings.sampler, settings.steps)
    )
    diffusion = denoiser.chain_for(settings)
    x0, mask_t = denoiser.to_model(x), torch.as_tensor(mask).to(denoiser.device)
    reconstruction = (
        ReconstructionGuidance(
            denoiser.model, diffusion, x0, mask_t, settings.reconstruction_scale
        )
        if settings.reconstruction_scale
        else None
    )
    hook = KnownFrames(
        diffusion, x0, mask_t, known_noise(settings.seed), inner=reconstruction
    )
    out = hook.sample(
        denoiser.model,
        settings.seed,
        diffusion.schedule(resample=settings.resample),
        callback,
        progress,
    )
    # the sampler returns the known frames through normalise/denormalise,
    # exact only to ~1e-6 mm
    return keep_known(denoiser.to_mm(out), x, mask)
