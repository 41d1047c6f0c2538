"""Geometry-adaptive generation (§3.2, Alg. 4): label-controlled sequences of a given
face, whose neutral landmarks are the known first (N2E) or last (E2N) frame."""

from __future__ import annotations

import numpy as np
import torch

from .. import data
from ..config import NUM_LANDMARKS
from ..guidance import (
    ClassifierScore,
    OptimisationGuidance,
    ReconstructionGuidance,
    chain,
)
from ..inpainting import KnownFrames, keep_known, neutral_faces
from .fill import known_noise
from .loading import guided_chain, load_guide, task_settings
from .settings import GeometryAdaptive


def order_sensitive_label(label, order=None):
    """("mouth_open", "N2E") or "mouth_open N2E" -> the type-S class name "mouth_open
    N2E"."""
    if not isinstance(label, str):
        raise ValueError(f"label must be a label name, got {label!r}")
    parts = label.split()
    if len(parts) not in (1, 2):
        raise ValueError(
            "label must be an expression label, e.g. 'mouth_open', or a label and its"
            f" order, e.g. 'mouth_open E2N', got {label!r}"
        )
    if len(parts) == 2:
        if order is not None and order != parts[1]:
            raise ValueError(
                f"label {label!r} already names the order, which differs from"
                f" order={order!r}"
            )
        label, order = parts
    order = order or "N2E"
    if order not in data.KIND_NAMES:
        raise ValueError(f"order must be one of {data.KIND_NAMES}, got {order!r}")
    return f"{label} {order}"


def _known_neutral(neutral_landmarks, names, num_frames):
    """The given frames (n, F, 68, 3) in mm and the mask S_K (n, F): the neutral face is
    frame 1 for N2E and frame F for E2N (§5.4)."""
    n = len(names)
    neutral = neutral_faces(neutral_landmarks, n, "the neutral landmarks")
    mask = np.zeros((n, num_frames), dtype=bool)
    mask[np.arange(n), [0 if y.endswith("N2E") else -1 for y in names]] = True
    given = np.zeros((n, num_frames, NUM_LANDMARKS, 3))
    given[mask] = neutral
    return given, mask


def _alg4_hook(settings, denoiser, diffusion, score, x0, known):
    """The sampler hook of Alg. 4: the label guidance of Alg. 1 (then, with a
    reconstruction scale, reconstruction guidance), and the given frames re-drawn from q
    as in Alg. 3."""
    guidance = OptimisationGuidance(
        score, diffusion, settings.guidance_weight, settings.lr
    )
    if settings.reconstruction_scale:
        guidance = chain(
            guidance,
            ReconstructionGuidance(
                denoiser.model, diffusion, x0, known, settings.reconstruction_scale
            ),
        )
    return KnownFrames(diffusion, x0, known, known_noise(settings.seed), inner=guidance)


def geometry_passes(
    neutral_landmarks,
    label,
    n=1,
    settings=GeometryAdaptive(),
    denoiser=None,
    guide=None,
    progress=True,
    **overrides,
):
    """Geometry-adaptive generation (Alg. 4), every harmonising pass: (passes, n, F, 68,
    3) float32 in mm.

    neutral_landmarks: (68, 3) (or (n, 68, 3)) neutral landmarks in mm of the face to
    animate. label: an expression label ("mouth_open") with settings.order "N2E"
    (default) or "E2N"; or a type-S class name such as "mouth_open E2N"; or a list of n
    such labels.  Guided by the type-S classifier through Alg. 1's Adagrad steps; pass i
    > 1 re-noises the previous result to ``settings.renoise_step`` with Eq. 3 (None: to
    T, as the paper).  settings: :class:`facelib.GeometryAdaptive`
    (reconstruction_scale > 0 adds reconstruction guidance after the label guidance,
    joining the generated frames to the given face; ``settings.paper()`` is Alg. 4 as
    printed); ``overrides`` change single fields."""
    settings, shape = task_settings(settings, overrides, n)
    if not isinstance(label, (str, list, tuple)):
        raise ValueError(
            f"label must be a label name or a list of n={n} label names, got {label!r}"
        )
    names = [
        order_sensitive_label(y, settings.order)
        for y in ([label] * n if isinstance(label, str) else list(label))
    ]
    if len(names) != n:
        raise ValueError(
            f"label must be a label name or a list of n={n} label names, got"
            f" {len(names)} labels"
        )
    given, mask = _known_neutral(neutral_landmarks, names, shape[1])
    guide = guide or load_guide(settings.dataset, "S")
    if guide.classifier_type != "S":
        raise ValueError(
            "geometry-adaptive generation needs a type-S guidance classifier (label x"
            " N2E/E2N)"
        )
    targets = guide.class_indices(names)
    denoiser, diffusion, guide = guided_chain(guide, denoiser, settings)
    restart = (
        diffusion.num_steps
        if settings.renoise_step is None
        else int(settings.renoise_step)
    )
    if not 1 <= restart <= diffusion.num_steps:
        raise ValueError(
            f"renoise_step must be in 1..{diffusion.num_steps} (steps of the sampler),"
            f" got {restart}"
        )
    x0, known = denoiser.to_model(given), torch.as_tensor(mask).to(denoiser.device)
    hook = _alg4_hook(
        settings, denoiser, diffusion, ClassifierScore(guide.model, targets), x0, known
    )
    results, x = [], None
    for i in range(settings.passes):
        gen = torch.Generator().manual_seed(settings.seed + 7919 * i)
        if x is None:  # Alg. 4 lines 3-4
            start, first = hook.start(gen), diffusion.num_steps
        # Alg. 4 line 6: x_k = sqrt(abar_k) x_0 + sqrt(1 - abar_k) eps on every frame
        else:
            start, first = diffusion.q_sample(x, restart, generator=gen), restart
        steps = diffusion.schedule(first, resample=settings.resample)
        # the chain continues the stream its start was drawn from
        x = diffusion.run(
            denoiser.model, start, gen, steps, hook, progress=progress
        ).detach()
        results.append(keep_known(denoiser.to_mm(x), given, mask))
    return np.stack(results)


def geometry_adaptive(
    neutral_landmarks,
    label,
    n=1,
    settings=GeometryAdaptive(),
    denoiser=None,
    guide=None,
    progress=True,
    **overrides,
):
    """Geometry-adaptive generation (Alg. 4): the last pass of :func:`geometry_passes`,
    (n, F, 68, 3) float32 in mm."""
    return geometry_passes(
        neutral_landmarks, label, n, settings, denoiser, guide, progress, **overrides
    )[-1]
