"""Text control (§3.2, Alg. 2): the unconditional DDPM guided by the text head BiT(x_t,
t) and a text embedding E(c) of the offline sentence encoder (facelib/text.py)."""

from __future__ import annotations

import numpy as np
import torch

from .. import data
from ..guidance import (
    BestOfK,
    ContrastiveScore,
    CosineScore,
    DenoisedCosineScore,
    OptimisationGuidance,
    nearest_wording,
)
from ..text import description_embeddings, get_encoder
from .loading import check_n, guided_chain, load_text_head, task_settings
from .settings import TextControl


def text_list(text, n):
    """n texts from one text or a list of n (each is checked by the encoder)."""
    check_n(n)
    texts = (
        [text] * n
        if isinstance(text, str)
        else list(text) if isinstance(text, (list, tuple)) else None
    )
    if texts is None or len(texts) != n:
        raise ValueError(
            f"text must be a string or a list of n={n} strings, got {text!r}"
        )
    return texts


def text_score(settings, head, denoiser, embeddings):
    """The score that Alg. 2 climbs for text embeddings (n, D)
    (facelib/guidance/scores.py): the cosine of Eq. 10 on x_t or on the denoiser's
    x0_hat, or the contrastive score against the training descriptions of the text's
    nearest wording (or, with ``settings.vocabulary``, every description known).
    """
    if settings.score == "contrastive":
        train, encoder = data.load_dataset(head.dataset, "train"), get_encoder()
        references = nearest_wording(description_embeddings(train, encoder), embeddings)
        vocabulary = (
            description_embeddings(train, encoder, "vocabulary").flatten(0, 1)
            if settings.vocabulary
            else None
        )
        return ContrastiveScore(
            head.model,
            embeddings,
            references,
            head.meta["training"]["temperature"],
            vocabulary=vocabulary,
        )
    if settings.head_input == "x_t":
        return CosineScore(head.model, embeddings)
    return DenoisedCosineScore(
        head.model, denoiser.model, denoiser.diffusion, embeddings
    )


def text_control(
    text,
    n=8,
    settings=TextControl(),
    denoiser=None,
    head=None,
    progress=True,
    callback=None,
    **overrides,
):
    """Text control (Alg. 2): n sequences (n, F, 68, 3) float32 in mm that show what
    ``text`` says.

    text: a description ("disgust high smile", "from the neutral face to bareteeth"), or
    a list of n descriptions (one per sequence), each embedded once by the offline
    sentence encoder E (empty, non-string or too long texts are refused).  At every step
    3 Adagrad steps maximise lambda log p_theta(x | x_t) + score(x, t-1)
    (:func:`text_score`).  settings: :class:`facelib.TextControl` (lambda None:
    :func:`text_guidance_weight`; rate None: :func:`text_lr`; particles K > 1:
    :class:`~facelib.guidance.BestOfK` at the step nearest the time label select_time,
    no callback); ``overrides`` change single fields."""
    settings, shape = task_settings(settings, overrides, n)
    if settings.particles > 1 and callback is not None:
        raise ValueError(
            "text_control takes no callback with particles > 1 "
            "(the batch changes at select_time)"
        )
    texts = text_list(text, n)
    embeddings = torch.as_tensor(get_encoder().encode(texts))
    head = head or load_text_head(settings.dataset)
    if head.classifier_type != "text":
        raise ValueError(
            "text control needs a text head (load_text_head), not a label classifier"
        )
    denoiser, diffusion, head = guided_chain(head, denoiser, settings)
    score = text_score(settings, head, denoiser, embeddings)
    resolved = settings.resolved(head.meta["training"]["num_diffusion_steps"])
    weight, lr = resolved.guidance_weight, resolved.lr
    hook = OptimisationGuidance(
        score, diffusion, weight, lr, max_time=settings.max_time
    )
    if settings.particles == 1:
        x = diffusion.sample(
            denoiser.model,
            shape,
            seed=settings.seed,
            guide=hook,
            progress=progress,
            callback=callback,
        )
    else:
        first = float(diffusion.timesteps[-1])
        if settings.select_time > first:
            raise ValueError(
                f"select_time {settings.select_time:g} is above the chain's first step"
                f" (time label {first:g}): give a time label in 1..{first:g}"
            )
        # the chain's step nearest select_time, below its first (BestOfK picks
        # between chains that have run at least one step)
        nearest = int(np.argmin(np.abs(diffusion.timesteps - settings.select_time)))
        select = min(max(1, nearest), diffusion.num_steps - 1)
        x = BestOfK(score, settings.particles, select).sample(
            diffusion, denoiser.model, shape, hook, settings.seed, progress
        )
    return denoiser.to_mm(x)
