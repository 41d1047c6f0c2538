"""The paper's sampling tasks as functions (§3.2, App. C), all on one unconditional DDPM.

So far: loading the trained denoiser, unconditional generation (§3.1) and label control
(§3.2, Alg. 1).  Text control, filling and geometry-adaptive generation (Alg. 2-4) build on the
same pieces: the denoiser is never retrained, only its reverse process is guided.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import data
from .checkpoints import load_checkpoint
from .data import LandmarkNormalizer
from .diffusion import GaussianDiffusion, named_betas
from .evaluation import check_class_names
from .face.sequences import check_num_frames
from .guidance import GUIDANCE_WEIGHT, MeanShiftGuidance, OptimisationGuidance, classifier_score
from .models.denoiser import Denoiser, DenoiserConfig
from .models.noisy_classifier import NoisyClassifier, NoisyClassifierConfig

DEFAULT_DENOISER = "denoiser_coma"
ADAGRAD_LR = 0.01  # Alg. 1's Adagrad learning rate: not in the paper; chosen by the sweep of chapter 05
GUIDANCE_METHODS = ("adagrad", "mean_shift")


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


def _check_n(n):
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive integer, got {n!r}")


@dataclass
class TrainedGuide:
    """A guidance classifier p_phi(y | x_t, t) with its dataset, type and class names."""

    model: NoisyClassifier
    dataset: str
    classifier_type: str
    class_names: tuple
    normalizer: LandmarkNormalizer
    meta: dict

    def class_indices(self, labels):
        """Class indices of label names (a clear error listing the valid ones)."""
        bad = [y for y in labels if y not in self.class_names]
        if bad:
            raise ValueError(f"unknown label {bad[0]!r} for dataset {self.dataset!r}; allowed: {', '.join(self.class_names)}")
        return [self.class_names.index(y) for y in labels]


def load_guide(dataset="coma", classifier_type="I", name=None):
    """Load the shipped guidance classifier guide_<dataset>_<type> (sha256 and classes checked)."""
    data.check_dataset_name(dataset)
    data.check_classifier_type(classifier_type)
    name = name or f"guide_{dataset}_{classifier_type}"
    model, meta = load_checkpoint(name, "guide", lambda c: NoisyClassifier(NoisyClassifierConfig(**c)))
    names = check_class_names(meta["class_names"], dataset, classifier_type, name)
    if meta["training"]["dataset"] != dataset:
        raise ValueError(f"checkpoint {name} was trained on {meta['training']['dataset']!r}, not {dataset!r}")
    return TrainedGuide(model, dataset, classifier_type, names, LandmarkNormalizer.from_dict(meta["normalizer"]), meta)


def check_same_space(denoiser, guide):
    """The classifier must read x_t in the denoiser's normalised space and on its schedule."""
    a, b = denoiser.normalizer, guide.normalizer
    if abs(a.scale - b.scale) > 1e-6 * a.scale or not np.allclose(a.mean_shape, b.mean_shape, atol=1e-4):
        raise ValueError(f"guidance classifier ({guide.dataset}) and denoiser ({denoiser.meta['training']['dataset']}) "
                         "normalise landmarks differently: train them on the same dataset")
    if guide.meta["training"]["num_diffusion_steps"] != denoiser.diffusion.num_steps:
        raise ValueError("guidance classifier and denoiser use different diffusion schedules")


def label_control(label, n=16, dataset="coma", num_frames=40, steps=None, guidance_weight=GUIDANCE_WEIGHT,
                  lr=ADAGRAD_LR, method="adagrad", scale=1.0, seed=0, denoiser=None, guide=None,
                  classifier_type="I", progress=True, callback=None):
    """Label control (Alg. 1): n sequences (n, F, 68, 3) float32 in mm showing ``label``.

    label: a label name of the dataset (e.g. "high_smile"), or a list of n names (one per sequence).
    method: "adagrad" (Alg. 1: 3 Adagrad steps on lambda log p_theta + log p_phi, lambda =
    ``guidance_weight``, rate ``lr``) or "mean_shift" (classic classifier guidance, ``scale``).
    steps: None for the paper's T = 2000, or fewer (respaced).
    """
    _check_n(n)
    num_frames = check_num_frames(num_frames)
    labels = [label] * n if isinstance(label, str) else list(label)
    if len(labels) != n or not all(isinstance(y, str) for y in labels):
        raise ValueError(f"label must be a label name or a list of n={n} label names, got {label!r}")
    if method not in GUIDANCE_METHODS:
        raise ValueError(f"method must be one of {GUIDANCE_METHODS}, got {method!r}")
    guide = guide or load_guide(dataset, classifier_type)
    targets = guide.class_indices(labels)
    denoiser = denoiser or load_denoiser(f"denoiser_{guide.dataset}")
    check_same_space(denoiser, guide)
    diffusion = denoiser.diffusion_with(steps)
    score = classifier_score(guide.model, targets)
    if method == "adagrad":
        guide_fn = OptimisationGuidance(score, diffusion, guidance_weight, lr)
    else:
        guide_fn = MeanShiftGuidance(score, diffusion, scale)
    x = diffusion.sample(denoiser.model, (n, num_frames, 68, 3), seed=seed, guide=guide_fn,
                         progress=progress, callback=callback)
    return denoiser.normalizer.denormalize(x.detach()).numpy()


def unconditional(n, num_frames=40, seed=0, steps=None, denoiser=None, progress=True, callback=None):
    """Sample ``n`` landmark sequences (n, F, 68, 3) float32 in mm from the unconditional DDPM.

    steps: None for the full T = 2000 chain of the paper, or fewer (respaced, no retraining).
    """
    _check_n(n)
    num_frames = check_num_frames(num_frames)
    denoiser = denoiser or load_denoiser()
    diffusion = denoiser.diffusion_with(steps)
    x = diffusion.sample(denoiser.model, (n, num_frames, 68, 3), seed=seed, progress=progress, callback=callback)
    return denoiser.normalizer.denormalize(x.detach()).numpy()
