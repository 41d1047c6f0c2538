"""The paper's sampling tasks as functions (§3.2, App. C), all on one unconditional DDPM.

Loading the trained denoiser, unconditional generation (§3.1), label control (§3.2, Alg. 1),
text control (Alg. 2; and, not in the paper, a text decoder's sequence refined by the DDPM),
expression filling (Alg. 3) and geometry-adaptive generation (Alg. 4).  Every task uses the same
unconditional denoiser: it is never retrained, only its reverse process is guided.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from . import data
from .baselines import generate_from_text, load_baseline
from .checkpoints import load_checkpoint
from .data import LandmarkNormalizer
from .diffusion import GaussianDiffusion, named_betas
from .face.sequences import check_num_frames
from .guidance import (GUIDANCE_WEIGHT, MeanShiftGuidance, OptimisationGuidance, ReconstructionGuidance,
                       best_particles, chain, classifier_score, contrastive_text_score, denoised_text_score, nearest_wording,
                       text_score)
from .inpainting import KnownFrames, check_fill_input, keep_known
from .models.denoiser import Denoiser, DenoiserConfig
from .models.noisy_classifier import NoisyClassifier, NoisyClassifierConfig, NoisyTextHead, TextHeadConfig
from .text import EMBEDDING_DIM, MODEL_NAME, description_embeddings, get_encoder

DEFAULT_DENOISER = "denoiser_coma"
# Alg. 1's Adagrad learning rate, per dataset, for a chain of LR_REFERENCE_STEPS reverse steps: not in
# the paper; each is the pick of chapter 05's sweep (48 guided sequences per rate, 200 steps, best
# accuracy - 2 FID).  A rate is a step length in the normalised landmark space (Adagrad's first step
# moves every coordinate by it), so it depends on the data; see adagrad_lr for other step counts.
ADAGRAD_LR = {"coma": 0.03, "bu": 0.1}
LR_REFERENCE_STEPS = 200
GEOMETRY_LR = 0.01  # the Adagrad rate of Alg. 4's type-S guidance, with which chapter 08 is measured (our choice)
GUIDANCE_METHODS = ("adagrad", "mean_shift")
HARMONISING_PASSES = 5  # Alg. 4 line 1: "for i = 1 to 5"
RECONSTRUCTION_SCALE = 2.0  # our choice for Alg. 4 + reconstruction guidance: the sweep of chapter 08
TEXT_DATASET = "coma+bu"  # paper §5.2: text control works on CoMA and BU-4DFE merged (18 actions)
# Alg. 2's lambda (paper: 0.01) and Adagrad rate (not in the paper) for a chain of TEXT_LR_REFERENCE_STEPS
# reverse steps: the pick of chapter 06's sweep (72 raw-text sequences, 100 steps, best accuracy - 2 FID)
TEXT_GUIDANCE_WEIGHT = 0.0003
TEXT_LR = 0.2
TEXT_LR_REFERENCE_STEPS = 100
# What the text head reads in Eq. 10: x_t itself (Alg. 2 as written) or the denoiser's estimate x0_hat
# of the clean sequence (not in the paper: guidance.denoised_text_score, chapter 06 section 8)
HEAD_INPUTS = ("x_t", "x0_hat")
# The score that Alg. 2 climbs: the cosine of Eq. 10 (as written) or, not in the paper, the head's own
# log-probability of the text against the training descriptions of its wording (guidance.
# contrastive_text_score, chapter 06 section 10), whose lambda is the pick of that section's sweep
TEXT_SCORES = ("cosine", "contrastive")
# The contrastive score's lambda (the paper's 0.01) and Adagrad rate at TEXT_LR_REFERENCE_STEPS steps: the
# pick of chapter 06 section 10's sweep (72 sequences, two seeds, best Acc - 2 FID summed over both tasks)
CONTRASTIVE_GUIDANCE_WEIGHT = 0.01
CONTRASTIVE_LR = 0.042
# Best-of-K particles (not in the paper; chapter 06 section 11): the time label at which the K guided chains
# of each text are compared by the text head, and the time above which they are left unguided (the head
# reads nothing there); our choices from that section's measurements
SELECT_TIME = 600
PARTICLE_MAX_TIME = 1400
# decoder_then_diffusion's re-noising step (not in the paper): our choice from chapter 06 section 9's sweep
DECODER_START = 400


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


def _check_n(n, name="n"):
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"{name} must be a positive integer, got {n!r}")


@dataclass
class TrainedGuide:
    """A guidance network with its dataset, type and class names: the classifier p_phi(y | x_t, t)
    of Alg. 1 (type "I" or "S") or the text head BiT(x_t, t) of Alg. 2 (type "text"; its class
    names are the labels whose descriptions it was trained on)."""

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
    names = data.check_class_names(meta["class_names"], dataset, classifier_type, name)
    if meta["training"]["dataset"] != dataset:
        raise ValueError(f"checkpoint {name} was trained on {meta['training']['dataset']!r}, not {dataset!r}")
    return TrainedGuide(model, dataset, classifier_type, names, LandmarkNormalizer.from_dict(meta["normalizer"]), meta)


def load_text_head(dataset=TEXT_DATASET, name=None):
    """Load the shipped text head guide_<dataset>_text (sha256, labels and text encoder checked)."""
    data.check_dataset_name(dataset)
    name = name or f"guide_{dataset}_text"
    model, meta = load_checkpoint(name, "text_head", lambda c: NoisyTextHead(TextHeadConfig(**c)))
    names = data.check_class_names(meta["class_names"], dataset, "I", name)
    if meta["training"]["dataset"] != dataset:
        raise ValueError(f"checkpoint {name} was trained on {meta['training']['dataset']!r}, not {dataset!r}")
    if meta.get("text_encoder") != MODEL_NAME or model.config.embedding_dim != EMBEDDING_DIM:
        raise ValueError(f"checkpoint {name} was trained with the text encoder {meta.get('text_encoder')!r} "
                         f"({model.config.embedding_dim}-d), not {MODEL_NAME!r} ({EMBEDDING_DIM}-d)")
    return TrainedGuide(model, dataset, "text", names, LandmarkNormalizer.from_dict(meta["normalizer"]), meta)


def check_same_space(denoiser, guide):
    """The classifier must read x_t in the denoiser's normalised space and on its schedule."""
    a, b = denoiser.normalizer, guide.normalizer
    if abs(a.scale - b.scale) > 1e-6 * a.scale or not np.allclose(a.mean_shape, b.mean_shape, atol=1e-4):
        raise ValueError(f"guidance classifier ({guide.dataset}) and denoiser ({denoiser.meta['training']['dataset']}) "
                         "normalise landmarks differently: train them on the same dataset")
    if guide.meta["training"]["num_diffusion_steps"] != denoiser.diffusion.num_steps:
        raise ValueError("guidance classifier and denoiser use different diffusion schedules")


def step_scaled_lr(rate, reference_steps, steps=None, num_steps=2000, power=0.5):
    """An Adagrad rate chosen for a chain of ``reference_steps`` reverse steps, for a chain of ``steps``
    (None: T = ``num_steps``): scaled by (reference_steps / steps) ** power, so that the guidance moves a
    sample about as far over the whole chain whatever its length (our choice).

    power 0.5: the guided displacements of successive steps add up like a random walk, as the square
    root of the number of steps (label control; benchmarks/label_control.py measures it at T = 2000,
    where the unscaled rate overshoots).  power 1: they add up like a drift, linearly (text control:
    benchmarks/text_control.py measures that the square root still overshoots at T = 2000)."""
    return rate * float((reference_steps / (steps or num_steps)) ** power)


def adagrad_lr(dataset, steps=None, num_steps=2000):
    """The default Adagrad rate of label control (Alg. 1) for a chain of ``steps`` reverse steps
    (None: T): ADAGRAD_LR[dataset], chosen at 200 steps, through :func:`step_scaled_lr`."""
    if dataset not in ADAGRAD_LR:
        raise ValueError(f"no default Adagrad learning rate for dataset {dataset!r} (defaults for "
                         f"{', '.join(ADAGRAD_LR)}): pass lr=")
    return step_scaled_lr(ADAGRAD_LR[dataset], LR_REFERENCE_STEPS, steps, num_steps)


def text_lr(steps=None, num_steps=2000, score="cosine"):
    """The default Adagrad rate of text control (Alg. 2) for a chain of ``steps`` reverse steps
    (None: T): TEXT_LR (CONTRASTIVE_LR for the contrastive score), chosen at 100 steps, through
    :func:`step_scaled_lr` with power 1."""
    if score not in TEXT_SCORES:
        raise ValueError(f"score must be one of {TEXT_SCORES}, got {score!r}")
    rate = CONTRASTIVE_LR if score == "contrastive" else TEXT_LR
    return step_scaled_lr(rate, TEXT_LR_REFERENCE_STEPS, steps, num_steps, power=1.0)


def text_guidance_weight(score="cosine"):
    """The default lambda of text control for a score: TEXT_GUIDANCE_WEIGHT (cosine) or
    CONTRASTIVE_GUIDANCE_WEIGHT (contrastive)."""
    if score not in TEXT_SCORES:
        raise ValueError(f"score must be one of {TEXT_SCORES}, got {score!r}")
    return CONTRASTIVE_GUIDANCE_WEIGHT if score == "contrastive" else TEXT_GUIDANCE_WEIGHT


def label_control(label, n=16, dataset="coma", num_frames=40, steps=None, guidance_weight=GUIDANCE_WEIGHT,
                  lr=None, method="adagrad", scale=1.0, seed=0, denoiser=None, guide=None,
                  classifier_type="I", progress=True, callback=None):
    """Label control (Alg. 1): n sequences (n, F, 68, 3) float32 in mm showing ``label``.

    label: a label name of the dataset (e.g. "high_smile"), or a list of n names (one per sequence).
    method: "adagrad" (Alg. 1: 3 Adagrad steps on lambda log p_theta + log p_phi, lambda =
    ``guidance_weight``, rate ``lr``, default :func:`adagrad_lr`) or "mean_shift" (classic
    classifier guidance, ``scale``).
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
    score = classifier_score(guide.model, targets)
    lr = adagrad_lr(guide.dataset, steps, guide.meta["training"]["num_diffusion_steps"]) if lr is None else lr
    make_guidance = ((lambda diffusion: OptimisationGuidance(score, diffusion, guidance_weight, lr)) if method == "adagrad"
                     else (lambda diffusion: MeanShiftGuidance(score, diffusion, scale)))
    return _guided_sample(guide, denoiser, steps, n, num_frames, seed, progress, callback, make_guidance)


def _guided_chain(guide, denoiser, steps):
    """The denoiser of the guide's dataset (or the given one, checked to share the guide's space) and its
    chain of ``steps`` steps."""
    denoiser = denoiser or load_denoiser(f"denoiser_{guide.dataset}")
    check_same_space(denoiser, guide)
    return denoiser, denoiser.diffusion_with(steps)


def _guided_sample(guide, denoiser, steps, n, num_frames, seed, progress, callback, make_guidance):
    """Sample n sequences (n, F, 68, 3) float32 mm with ``make_guidance(diffusion)`` injected, from the
    denoiser of the guide's dataset (or the given one, checked to share the guide's space)."""
    denoiser, diffusion = _guided_chain(guide, denoiser, steps)
    x = diffusion.sample(denoiser.model, (n, num_frames, 68, 3), seed=seed, guide=make_guidance(diffusion),
                         progress=progress, callback=callback)
    return denoiser.normalizer.denormalize(x.detach()).numpy()


def _best_of_particles(guide, denoiser, steps, n, num_frames, seed, progress, make_guidance, score, particles,
                       select_time):
    """Best-of-K (not in the paper; chapter 06 section 11): ``particles`` guided chains per sequence
    (make_guidance(diffusion, repeat) for a batch of repeat * n) down to the step nearest the time label
    ``select_time``; for each sequence the chain with the highest score(repeat) there continues alone
    (:func:`~facelib.guidance.best_particles`), on the rest of the same random stream."""
    denoiser, diffusion = _guided_chain(guide, denoiser, steps)
    k = max(1, int(np.argmin(np.abs(diffusion.timesteps - select_time))))
    if k >= diffusion.num_steps:
        raise ValueError(f"select_time {select_time} is the chain's first step: pick one below "
                         f"{diffusion.timesteps[-1]}")
    generator = torch.Generator().manual_seed(seed)
    shape = (particles * n, num_frames, 68, 3)
    x = diffusion.sample(denoiser.model, shape, guide=make_guidance(diffusion, particles), progress=progress,
                         end_step=k, generator=generator)
    x = best_particles(x, score(particles), diffusion.model_time(k, len(x)).to(x.device), particles)
    x = diffusion.sample(denoiser.model, x.shape, x_T=x, start_step=k, guide=make_guidance(diffusion, 1),
                         progress=progress, generator=generator)
    return denoiser.normalizer.denormalize(x.detach()).numpy()


def text_control(text, n=8, dataset=TEXT_DATASET, num_frames=40, steps=None, guidance_weight=None,
                 lr=None, head_input="x_t", score="cosine", vocabulary=False, particles=1, select_time=SELECT_TIME,
                 max_time=None, seed=0, denoiser=None, head=None, encoder=None, progress=True, callback=None):
    """Text control (Alg. 2): n sequences (n, F, 68, 3) float32 in mm that show what ``text`` says.

    text: a description ("disgust high smile", "from the neutral face to bareteeth"), or a list of
    n descriptions (one per sequence).  Each is embedded once by the offline sentence encoder
    E (facelib/text.py; empty, non-string or too long texts are refused); at every step 3 Adagrad
    steps maximise lambda log p_theta(x | x_t) + cos(BiT(x, t-1), E(c)) (Eq. 10), lambda =
    ``guidance_weight`` (None: TEXT_GUIDANCE_WEIGHT for the cosine, not the paper's 0.01: the
    cosine's gradient is small, and Adagrad's steps follow the sign of the sum; chapter 06), rate
    ``lr`` (default :func:`text_lr`).  steps: None for the paper's T = 2000, or fewer (respaced).
    score: "cosine" (Eq. 10) or "contrastive" (not in the paper: the head's log-probability of the
    training descriptions that c matches, in c's nearest wording, :func:`~facelib.guidance.contrastive_text_score`,
    at the head's training temperature; default lambda CONTRASTIVE_GUIDANCE_WEIGHT and rate
    CONTRASTIVE_LR; chapter 06 section 10 measures that it steers the order of enriched texts, which
    the cosine cannot).
    vocabulary (not in the paper; chapter 06 section 12; contrastive score only): match the text
    against every description of the "vocabulary" (facelib/descriptions.py: the training ones and
    phrasings and templates written blind, which no network has seen) instead of its nearest
    wording's training descriptions alone, so that more ways to say a label are understood.
    head_input: "x_t" (Alg. 2: the head reads the candidate x_{t-1}) or "x0_hat" (not in the paper:
    it reads the denoiser's estimate of the clean sequence, :func:`~facelib.guidance.denoised_text_score`;
    twice the cost; chapter 06 section 8 measures that it does not fix the order of enriched texts).
    particles (not in the paper; chapter 06 section 11): K > 1 guided chains per sequence down to the
    time label ``select_time``, where the one the score rates highest continues alone (about K times
    the cost before select_time; no callback).  max_time: leave the steps above this time label
    unguided (None: guide them all; section 11 uses PARTICLE_MAX_TIME with its particles).
    """
    if head_input not in HEAD_INPUTS:
        raise ValueError(f"head_input must be one of {HEAD_INPUTS}, got {head_input!r}")
    if score not in TEXT_SCORES:
        raise ValueError(f"score must be one of {TEXT_SCORES}, got {score!r}")
    if score == "contrastive" and head_input != "x_t":
        raise ValueError("the contrastive score reads x_t: use head_input='x_t' with score='contrastive'")
    if vocabulary not in (False, True):
        raise ValueError(f"vocabulary must be True or False, got {vocabulary!r}")
    if vocabulary and score != "contrastive":
        raise ValueError("the vocabulary is matched by the contrastive score: use vocabulary=True with "
                         "score='contrastive'")
    if isinstance(particles, bool) or not isinstance(particles, (int, np.integer)) or particles < 1:
        raise ValueError(f"particles must be a positive integer, got {particles!r}")
    if particles > 1 and callback is not None:
        raise ValueError("text_control takes no callback with particles > 1 (the batch changes at select_time)")
    if isinstance(select_time, bool) or not isinstance(select_time, (int, float, np.integer)) or select_time <= 0:
        raise ValueError(f"select_time must be a positive time label, got {select_time!r}")
    texts, num_frames = _text_list(text, n), check_num_frames(num_frames)
    encoder = encoder or get_encoder()
    embeddings = torch.as_tensor(encoder.encode(texts))
    head = head or load_text_head(dataset)
    if head.classifier_type != "text":
        raise ValueError("text control needs a text head (load_text_head), not a label classifier")
    denoiser = denoiser or load_denoiser(f"denoiser_{head.dataset}")
    if score == "contrastive":
        train = data.load_dataset(head.dataset, "train")
        references = nearest_wording(description_embeddings(train, encoder), embeddings)
        known = description_embeddings(train, encoder, "vocabulary").flatten(0, 1) if vocabulary else None

    def score_for(repeat):  # the score of every chain, for a batch of repeat * n (particle-major)
        e = embeddings.repeat(repeat, 1)
        if score == "contrastive":
            return contrastive_text_score(head.model, e, references.repeat(repeat, 1, 1),
                                          head.meta["training"]["temperature"], vocabulary=known)
        if head_input == "x_t":
            return text_score(head.model, e)
        return denoised_text_score(head.model, denoiser.model, denoiser.diffusion, e)

    guidance_weight = text_guidance_weight(score) if guidance_weight is None else guidance_weight
    lr = text_lr(steps, head.meta["training"]["num_diffusion_steps"], score) if lr is None else lr

    def make_guidance(diffusion, repeat=1):
        return OptimisationGuidance(score_for(repeat), diffusion, guidance_weight, lr, max_time=max_time)
    if particles == 1:
        return _guided_sample(head, denoiser, steps, n, num_frames, seed, progress, callback, make_guidance)
    return _best_of_particles(head, denoiser, steps, n, num_frames, seed, progress, make_guidance, score_for,
                              int(particles), select_time)


def _text_list(text, n):
    """n texts from one text or a list of n (each is checked by the encoder)."""
    _check_n(n)
    texts = [text] * n if isinstance(text, str) else list(text) if isinstance(text, (list, tuple)) else None
    if texts is None or len(texts) != n:
        raise ValueError(f"text must be a string or a list of n={n} strings, got {text!r}")
    return texts


def decoder_then_diffusion(text, n=8, start=DECODER_START, dataset=TEXT_DATASET, num_frames=40, steps=None, seed=0,
                           denoiser=None, decoder=None, encoder=None, progress=True):
    """Not in the paper (chapter 06 section 9): the MotionCLIP-style decoder's sequence for ``text``,
    re-noised to step ``start`` with Eq. 3 and denoised by the unconditional DDPM from there (SDEdit,
    Meng et al. 2022).  The deterministic decoder hears the words (the order of an enriched text
    too); the reverse chain from x_start ~ q(x_start | x_0 = decoder(text)) gives every call another
    sequence near it: the larger ``start``, the more diverse and the less faithful.

    start: a step of the paper's chain, 1..T (respaced chains start at their nearest step).
    Returns (n, F, 68, 3) float32 in mm."""
    texts, num_frames = _text_list(text, n), check_num_frames(num_frames)
    decoder = decoder or load_baseline("motionclip", dataset)
    denoiser = denoiser or load_denoiser(f"denoiser_{dataset}")
    if denoiser.meta["training"]["dataset"] != dataset:
        raise ValueError(f"the denoiser was trained on {denoiser.meta['training']['dataset']!r}, the decoder's "
                         f"sequences are of {dataset!r}: use denoiser_{dataset}")
    diffusion = denoiser.diffusion_with(steps)
    last = denoiser.diffusion.num_steps
    if isinstance(start, bool) or not isinstance(start, (int, np.integer)) or not 1 <= start <= last:
        raise ValueError(f"start must be a step in 1..{last}, got {start!r}")
    k = max(1, int(np.argmin(np.abs(diffusion.timesteps - start))))
    x0 = torch.as_tensor(denoiser.normalizer.normalize(generate_from_text(decoder, texts, num_frames, encoder)))
    x_start = diffusion.q_sample(x0, torch.full((n,), k), generator=torch.Generator().manual_seed(seed))
    x = diffusion.sample(denoiser.model, x0.shape, seed=seed, x_T=x_start, start_step=k, progress=progress)
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


def _known_noise(seed):
    """The generator of the known frames' noise: its own stream, so adding known frames never
    changes the noise that drives the unknown ones."""
    return torch.Generator().manual_seed(10_000 + seed)


def fill(sequences, known, steps=None, resample=1, reconstruction_scale=0.0, seed=0, denoiser=None, dataset="coma",
         progress=True, callback=None):
    """Expression filling (Alg. 3): complete the unknown frames of landmark sequences.

    sequences: (F, 68, 3) or (n, F, 68, 3) in mm; only the known frames are read (the others may
    hold anything, NaN included).  known: (F,) or (n, F) bool, True = known frame.
    resample: 1 for Alg. 3 as written; r > 1 adds RePaint's resampling (each step run r times).
    reconstruction_scale > 0 adds reconstruction guidance (not in the paper; chapters 07-08).
    Returns (n, F, 68, 3) float32 in mm whose known frames equal the given ones exactly.
    """
    x, mask = check_fill_input(sequences, known)
    denoiser = denoiser or load_denoiser(f"denoiser_{dataset}")
    diffusion = denoiser.diffusion_with(steps)
    x0 = torch.as_tensor(denoiser.normalizer.normalize(x))
    mask_t = torch.as_tensor(mask)
    reconstruction = (ReconstructionGuidance(denoiser.model, diffusion, x0, mask_t, reconstruction_scale)
                      if reconstruction_scale else None)
    hook = KnownFrames(diffusion, x0, mask_t, _known_noise(seed), inner=reconstruction)
    out = diffusion.sample(denoiser.model, x0.shape, seed=seed, x_T=hook.start(torch.Generator().manual_seed(seed)),
                           guide=hook, progress=progress, callback=callback, resample=resample)
    # the sampler returns the known frames through normalise/denormalise, exact only to ~1e-6 mm
    return keep_known(denoiser.normalizer.denormalize(out.detach()).numpy(), x, mask)


def order_sensitive_label(label, order=None):
    """("mouth_open", "N2E") or "mouth_open N2E" -> the type-S class name "mouth_open N2E"."""
    if not isinstance(label, str):
        raise ValueError(f"label must be a label name, got {label!r}")
    parts = label.split()
    if len(parts) == 2:
        if order is not None and order != parts[1]:
            raise ValueError(f"label {label!r} already names the order, which differs from order={order!r}")
        label, order = parts
    order = order or "N2E"
    if order not in data.KIND_NAMES:
        raise ValueError(f"order must be one of {data.KIND_NAMES}, got {order!r}")
    return f"{label} {order}"


def geometry_adaptive(neutral_landmarks, label, order=None, n=1, num_frames=40, passes=HARMONISING_PASSES,
                      steps=None, renoise_step=None, resample=1, reconstruction_scale=0.0,
                      guidance_weight=GUIDANCE_WEIGHT, lr=GEOMETRY_LR, seed=0, dataset="coma", denoiser=None,
                      guide=None, return_passes=False, progress=True):
    """Geometry-adaptive generation with label control (Alg. 4): n sequences of a given face.

    neutral_landmarks: (68, 3) (or (n, 68, 3)) neutral landmarks in mm of the face to animate.
    label: an expression label ("mouth_open") with order "N2E" (default; the neutral face is frame 1,
    S_K = {1}) or "E2N" (it is frame F); or a type-S class name such as "mouth_open E2N"; or a list
    of n such labels (one per sequence).
    passes: the harmonising passes of Alg. 4; pass i > 1 re-noises the previous result to step
    ``renoise_step`` with Eq. 3 (None: to T, as the paper).  Guided by the type-S guidance
    classifier through Alg. 1's Adagrad steps.  resample: RePaint's resampling within each pass
    (1 = Alg. 4 as written).  reconstruction_scale > 0 adds reconstruction guidance
    (:class:`~facelib.guidance.ReconstructionGuidance`; not in the paper, chapter 08) after the label
    guidance: it makes the generated frames join the given neutral face.
    Returns (n, F, 68, 3) float32 in mm, or with ``return_passes`` (passes, n, F, 68, 3).
    """
    _check_n(n)
    num_frames = check_num_frames(num_frames)
    _check_n(passes, "passes")
    neutral = np.asarray(neutral_landmarks, dtype=np.float64)
    if neutral.shape == (68, 3):
        neutral = np.broadcast_to(neutral, (n, 68, 3))
    if neutral.shape != (n, 68, 3):
        raise ValueError(f"neutral landmarks must have shape (68, 3) or (n={n}, 68, 3), got {np.shape(neutral_landmarks)}")
    if not np.isfinite(neutral).all():
        raise ValueError("the neutral landmarks contain NaN or infinite values")
    names = [order_sensitive_label(y, order) for y in ([label] * n if isinstance(label, str) else list(label))]
    if len(names) != n:
        raise ValueError(f"label must be a label name or a list of n={n} label names, got {len(names)} labels")
    guide = guide or load_guide(dataset, "S")
    if guide.classifier_type != "S":
        raise ValueError("geometry-adaptive generation needs a type-S guidance classifier (label x N2E/E2N)")
    targets = guide.class_indices(names)
    denoiser = denoiser or load_denoiser(f"denoiser_{guide.dataset}")
    check_same_space(denoiser, guide)
    diffusion = denoiser.diffusion_with(steps)
    restart = diffusion.num_steps if renoise_step is None else int(renoise_step)
    if not 1 <= restart <= diffusion.num_steps:
        raise ValueError(f"renoise_step must be in 1..{diffusion.num_steps} (steps of the sampler), got {renoise_step}")

    mask = np.zeros((n, num_frames), dtype=bool)
    mask[np.arange(n), [0 if y.endswith("N2E") else -1 for y in names]] = True  # S_K = {1} for N2E, {F} for E2N (§5.4)
    given = np.zeros((n, num_frames, 68, 3))
    given[mask] = neutral
    x0 = torch.as_tensor(denoiser.normalizer.normalize(given))
    guidance = OptimisationGuidance(classifier_score(guide.model, targets), diffusion, guidance_weight, lr)
    if reconstruction_scale:
        guidance = chain(guidance, ReconstructionGuidance(denoiser.model, diffusion, x0, torch.as_tensor(mask),
                                                          reconstruction_scale))
    hook = KnownFrames(diffusion, x0, torch.as_tensor(mask), _known_noise(seed), inner=guidance)
    results, x = [], None
    for i in range(passes):
        gen = torch.Generator().manual_seed(seed + 7919 * i)
        if x is None:  # Alg. 4 lines 3-4
            start, first = hook.start(gen), diffusion.num_steps
        else:  # Alg. 4 line 6: x_k = sqrt(abar_k) x_0 + sqrt(1 - abar_k) eps on every frame
            start, first = diffusion.q_sample(x, torch.full((n,), restart), generator=gen), restart
        x = diffusion.sample(denoiser.model, x0.shape, seed=seed + 7919 * i, x_T=start, guide=hook,
                             progress=progress, start_step=first, resample=resample).detach()
        results.append(keep_known(denoiser.normalizer.denormalize(x).numpy(), given, mask))
    return np.stack(results) if return_passes else results[-1]
