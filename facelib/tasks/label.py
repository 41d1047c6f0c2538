"""Label control (§3.2, Alg. 1): the unconditional DDPM guided by a noisy classifier
p_phi(y | x_t, t); or, not in the paper, classifier-free guidance of a label-conditional
denoiser."""

from __future__ import annotations

from ..guidance import (
    ClassifierFree,
    ClassifierScore,
    MeanShiftGuidance,
    OptimisationGuidance,
)
from .loading import (
    denoiser_name,
    guided_chain,
    load_denoiser,
    load_guide,
    task_settings,
)
from .settings import LabelControl


def label_control(
    label,
    n=16,
    settings=LabelControl(),
    denoiser=None,
    guide=None,
    progress=True,
    callback=None,
    **overrides,
):
    """Label control (Alg. 1): n sequences (n, F, 68, 3) float32 in mm showing
    ``label``.

    label: a label name of the dataset (e.g. "high_smile"), or a list of n names (one
    per sequence). settings: :class:`facelib.LabelControl`: the guidance
    ("classifier": a noisy classifier steers the unconditional denoiser, by Alg. 1's 3
    Adagrad steps on lambda log p_theta + log p_phi or by the classic mean shift; "cfg":
    classifier-free guidance of the label-conditional denoiser), lambda, the rate (None:
    :func:`adagrad_lr`), the scale, the steps (None: the paper's T = 2000), the sampler;
    ``overrides`` change single fields."""
    settings, shape = task_settings(settings, overrides, n)
    labels = check_labels(label, n)
    denoiser, diffusion, model, hook = label_sampler(labels, settings, denoiser, guide)
    x = diffusion.sample(
        model,
        shape,
        seed=settings.seed,
        guide=hook,
        progress=progress,
        callback=callback,
    )
    return denoiser.to_mm(x)


def check_labels(label, n):
    """n label names from one name or a list of n names (a clear error otherwise)."""
    labels = [label] * n if isinstance(label, str) else list(label)
    if len(labels) != n or not all(isinstance(y, str) for y in labels):
        raise ValueError(
            f"label must be a label name or a list of n={n} label names, got {label!r}"
        )
    return labels


def load_conditional_denoiser(dataset, sampler="ddpm", steps=None):
    """denoiser_<dataset>_cfg, the label-conditional denoiser of classifier-free
    guidance, or the sampler's (its student of ``steps`` steps, w distilled in); an
    error naming the command that trains it when it is missing."""
    name = denoiser_name(dataset, sampler, steps, variant="cfg")
    try:
        return load_denoiser(name)
    except FileNotFoundError:
        raise FileNotFoundError(
            f"classifier-free guidance needs the label-conditional denoiser {name}:"
            " train it with `python -m facelib train denoiser --conditional --dataset"
            f" {dataset}`"
        ) from None


def distilled_scale(denoiser, scale=None):
    """1 (its conditional output, one call a step) for a student with classifier-free
    guidance distilled in (a clear error when another weight is asked of it); None for
    any other denoiser."""
    distilled = denoiser.meta.get("training", {}).get("cfg_scale")
    if distilled is None:
        return None
    if scale not in (None, distilled):
        raise ValueError(
            f"{denoiser.meta.get('name', 'this student')} samples with w = {distilled}"
            f" distilled in, not scale = {scale} (give scale None, or use sampler"
            " 'ddim' with denoiser_<dataset>_cfg)"
        )
    return 1.0


def label_sampler(labels, settings, denoiser=None, guide=None):
    """What label control samples with: (denoiser, chain, the model the chain runs, the
    sampler hook).

    Classifier guidance: the unconditional denoiser and a hook that climbs log p_phi(y |
    x_t) (Alg. 1 or the mean shift).  Classifier-free guidance: denoiser_<dataset>_cfg
    inside :class:`ClassifierFree`, no hook.
    """
    if settings.guidance == "cfg":
        denoiser = denoiser or load_conditional_denoiser(
            settings.dataset, settings.sampler, settings.steps
        )
        model = ClassifierFree(
            denoiser.model,
            denoiser.class_indices(labels),
            distilled_scale(denoiser, settings.scale) or settings.guidance_scale,
        )
        return (
            denoiser,
            denoiser.chain_for(settings),
            model,
            None,
        )
    guide = guide or load_guide(settings.dataset, settings.classifier_type)
    denoiser, diffusion, guide = guided_chain(guide, denoiser, settings)
    score = ClassifierScore(guide.model, guide.class_indices(labels))
    if settings.guidance_method == "adagrad":
        lr = settings.resolved(guide.meta["training"]["num_diffusion_steps"]).lr
        hook = OptimisationGuidance(score, diffusion, settings.guidance_weight, lr)
    else:
        hook = MeanShiftGuidance(score, diffusion, settings.guidance_scale)
    return denoiser, diffusion, denoiser.model, hook
