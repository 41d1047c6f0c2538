"""The paper's sampling tasks as functions (§3.2, App. C), all on one unconditional DDPM.

So far: loading the trained denoiser and unconditional generation (§3.1).  Label control,
text control, filling and geometry-adaptive generation (Alg. 1-4) build on the same pieces.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checkpoints import load_checkpoint
from .data import LandmarkNormalizer
from .diffusion import GaussianDiffusion, named_betas
from .face.sequences import check_num_frames
from .models.denoiser import Denoiser, DenoiserConfig

DEFAULT_DENOISER = "denoiser_coma"


@dataclass
class TrainedDenoiser:
    """A trained eps_theta with everything needed to sample from it."""

    model: Denoiser
    normalizer: LandmarkNormalizer
    diffusion: GaussianDiffusion
    meta: dict

    def diffusion_with(self, steps=None):
        """The full T-step diffusion (steps=None) or a respaced one with ``steps`` steps."""
        return self.diffusion if steps is None or steps == self.diffusion.num_steps else self.diffusion.respace(steps)


def load_denoiser(name=DEFAULT_DENOISER, variance="beta"):
    """Load a shipped (or retrained) denoiser checkpoint from data/checkpoints (sha256 checked)."""
    model, meta = load_checkpoint(name, "denoiser", lambda c: Denoiser(DenoiserConfig(**c)))
    training = meta["training"]
    diffusion = GaussianDiffusion(named_betas(training["schedule"], training["num_diffusion_steps"]), variance)
    return TrainedDenoiser(model, LandmarkNormalizer.from_dict(meta["normalizer"]), diffusion, meta)


def unconditional(n, num_frames=40, seed=0, steps=None, denoiser=None, progress=True, callback=None):
    """Sample ``n`` landmark sequences (n, F, 68, 3) float32 in mm from the unconditional DDPM.

    steps: None for the full T = 2000 chain of the paper, or fewer (respaced, no retraining).
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    num_frames = check_num_frames(num_frames)
    denoiser = denoiser or load_denoiser()
    diffusion = denoiser.diffusion_with(steps)
    x = diffusion.sample(denoiser.model, (n, num_frames, 68, 3), seed=seed, progress=progress, callback=callback)
    return denoiser.normalizer.denormalize(x.detach()).numpy()
