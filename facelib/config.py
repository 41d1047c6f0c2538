"""Every default of the book in one place: paper values, CPU-scaled values, fast-mode values.

Each value carries its source: the paper section, or "our choice" with the reason.
``FACELIB_FAST=1`` (set by ``make test``) selects the fast-mode values so that every notebook
executes in seconds; the default ("book") mode uses the full values.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parent.parent
DATA_DIR = PROJECT_ROOT / "data"
SYNTHETIC_DIR = DATA_DIR / "synthetic"
CHECKPOINT_DIR = DATA_DIR / "checkpoints"


def fast_mode():
    """True when FACELIB_FAST is set to a true value (1/true/yes): small, quick runs for tests."""
    return os.environ.get("FACELIB_FAST", "").strip().lower() in ("1", "true", "yes", "on")


def cache_dir():
    """Where generated datasets are cached: $FACELIB_CACHE_DIR or data/synthetic/cache."""
    return Path(os.environ.get("FACELIB_CACHE_DIR", SYNTHETIC_DIR / "cache"))


@dataclass(frozen=True)
class DatasetSpec:
    """How a synthetic dataset is generated (see data/synthetic/README.md)."""

    name: str
    label_set: str  # "coma" or "bu": which expression labels
    num_subjects: int
    num_sequences: int
    num_test_subjects: int  # subjects held out for the "test" split
    takes_per_pair: int  # base number of sequences per (subject, label), N2E and E2N alternating
    seed: int
    style_gain_sigma: float  # how differently subjects perform a label (expressions.StyleSpread)
    style_leak_probability: float
    style_leak_max: float
    style_blend_max: float
    num_frames: int = 40  # paper §4: sequences of 40 frames


DATASETS = {
    # Paper §4: 689 CoMA sequences from 12 subjects performing 12 actions.  CoMA's labels are
    # instructions ("lips up") that subjects interpret freely: our choice of a wide style spread
    # makes them as hard to recognise on unseen subjects as the paper's GT row (83.8 %).  Our choice: 4 takes
    # per (subject, label) plus one extra take for 113 random pairs gives exactly 689; 3 subjects
    # (a quarter) are held out for testing.
    "coma": DatasetSpec("coma", "coma", num_subjects=12, num_sequences=689, num_test_subjects=3,
                        takes_per_pair=4, seed=1001, style_gain_sigma=0.45, style_leak_probability=0.9,
                        style_leak_max=0.4, style_blend_max=0.3),
    # Paper §4: 606 BU-4DFE recordings of 101 subjects x 6 emotions, each cut into an N2E and an
    # E2N sequence: 1212 sequences.  Our choice: 20 subjects held out for testing.
    "bu": DatasetSpec("bu", "bu", num_subjects=101, num_sequences=1212, num_test_subjects=20,
                      takes_per_pair=2, seed=2002, style_gain_sigma=0.25, style_leak_probability=0.5,
                      style_leak_max=0.2, style_blend_max=0.2),
}
SPLITS = ("train", "test", "all")


# ==================================================================================== training
# Every model is trained by the one loop of facelib/training/loop.py; these are its recipes' settings.
# A field's comment says where its value comes from: the paper (§, Eq.) or "our choice" and why.
OPTIMIZERS = ("adam", "adamw")


def _check_positive_int(name, value):
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")


@dataclass(frozen=True)
class Optimisation:
    """How the training loop optimises (the fields every recipe shares; each recipe sets its own values).

    The learning rate rises linearly over ``warmup`` steps, then follows a cosine from ``lr`` down to
    ``lr * final_lr_fraction`` (1.0: constant).  ``grad_clip``: clip the gradient norm (None: no clipping).
    ``ema_decay``: keep an exponential moving average of the weights and return it (None: no EMA).
    ``epochs``: None draws each of the ``steps`` batches uniformly with replacement; an integer walks
    that many times through a new permutation of the data (the last batch of a pass may be smaller),
    and the number of steps follows from the data's size."""

    steps: int = 1000
    batch_size: int = 64
    lr: float = 1e-3
    optimizer: str = "adamw"
    betas: tuple = (0.9, 0.999)
    weight_decay: float = 0.0
    warmup: int = 0
    final_lr_fraction: float = 1.0
    grad_clip: float | None = None
    ema_decay: float | None = None
    epochs: int | None = None
    seed: int = 0

    def __post_init__(self):
        _check_positive_int("steps", self.steps)
        _check_positive_int("batch_size", self.batch_size)
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if self.epochs is not None:
            _check_positive_int("epochs", self.epochs)
        if not isinstance(self.warmup, int) or not 0 <= self.warmup < self.steps:
            raise ValueError(f"warmup must be an integer in 0..steps-1 = {self.steps - 1}, got {self.warmup!r}")
        if not self.lr > 0 or not 0 <= self.final_lr_fraction <= 1:
            raise ValueError(f"need lr > 0 and final_lr_fraction in [0, 1], got {self.lr}, {self.final_lr_fraction}")
        if self.ema_decay is not None and not 0 < self.ema_decay < 1:
            raise ValueError(f"ema_decay must be in (0, 1) or None, got {self.ema_decay}")

    def with_steps(self, steps):
        """The same recipe for ``steps`` steps, its warm-up kept at most a tenth of the run."""
        return replace(self, steps=steps, warmup=min(self.warmup, steps // 10))

    def fast(self):
        """The fast-mode version (tests, FACELIB_FAST chapters): 20 steps."""
        return self.with_steps(20)


@dataclass(frozen=True)
class DenoiserTraining(Optimisation):
    """The DDPM denoiser eps_theta (§3.1, §4).  Paper §4: 200K iterations, lr 1e-4, batch 256.  A CPU
    budget of about 20 minutes on 2 cores allows about 1/50 of that compute: a smaller transformer
    (models.denoiser.DenoiserConfig), fewer, smaller steps with a higher rate, and an EMA."""

    steps: int = 12_000  # our choice: ~19 min on 2 CPU cores (paper: 200K iterations)
    batch_size: int = 64  # our choice (paper: 256): CPU time per step
    lr: float = 5e-4  # our choice (paper: 1e-4): 13x fewer, 4x smaller steps need a larger rate
    warmup: int = 500  # our choice: linear warm-up, then cosine decay to lr / 20
    final_lr_fraction: float = 0.05
    grad_clip: float | None = 1.0  # our choice: stabilises the first steps
    ema_decay: float | None = 0.999  # our choice: visibly cleaner samples for short runs
    dataset: str = "coma"  # paper §4: "unless otherwise specified, solely CoMA"
    num_frames: object = 40  # paper §4: 40 frames; (35, 45) for the variable-length model of App. A
    num_diffusion_steps: int = 2000  # paper §4: T = 2000
    schedule: str = "linear"  # paper §4: linear betas from 1e-4 to 0.02
    anatomy_pool: tuple = ("coma", "bu")  # our choice: training faces of these datasets (9 + 81)
    anatomy_swap: float = 0.5  # our choice: probability that a sequence gets another anatomy

    def __post_init__(self):
        super().__post_init__()
        if not 0 <= self.anatomy_swap <= 1:
            raise ValueError(f"anatomy_swap is a probability in [0, 1], got {self.anatomy_swap}")


@dataclass(frozen=True)
class GuideTraining(Optimisation):
    """The guidance classifiers p_phi(y | x_t, t) of Alg. 1 (type I) and Alg. 4 (type S)."""

    steps: int = 3000  # our choice: ~3 min on 2 CPU cores; accuracy against t is shown in chapter 05
    lr: float = 3e-4
    warmup: int = 200
    final_lr_fraction: float = 0.05
    weight_decay: float = 0.01
    grad_clip: float | None = 1.0
    dataset: str = "coma"
    classifier_type: str = "I"  # paper §5.1: type I for label control, type S for Alg. 4
    num_diffusion_steps: int = 2000  # the DDPM's schedule (paper §4): x_t must look like the sampler's
    schedule: str = "linear"


@dataclass(frozen=True)
class TextHeadTraining(Optimisation):
    """The text head BiT(x_t, t) of Alg. 2 (§3.2, §5.2)."""

    steps: int = 4000  # our choice: ~8 min on 2 CPU cores
    lr: float = 3e-4
    warmup: int = 200
    final_lr_fraction: float = 0.05
    weight_decay: float = 0.01
    grad_clip: float | None = 1.0
    dataset: str = "coma+bu"  # paper §5.2: CoMA and BU-4DFE merged (18 actions)
    contrastive_weight: float = 1.0  # our addition (0 = the paper's cosine loss alone): see training.recipes
    temperature: float = 0.05  # of the contrastive term (CLIP learns 0.01; 0.07 at its start)
    num_diffusion_steps: int = 2000
    schedule: str = "linear"


@dataclass(frozen=True)
class EvaluatorTraining(Optimisation):
    """The independent classifier (IC) of the evaluation (§5): Adam, 30 epochs (our choices)."""

    epochs: int | None = 30  # our choice: the loss has flattened
    batch_size: int = 32
    lr: float = 1e-3
    optimizer: str = "adam"
    dataset: str = "coma"
    classifier_type: str = "I"
    hidden: int = 128  # §5: one LSTM layer; its width is our choice
    inputs: str = "motion"  # chapter 01: motion generalises to unseen faces, absolute coordinates do not

    def fast(self):
        return replace(self, epochs=2)


@dataclass(frozen=True)
class ActorTraining(Optimisation):
    """The ACTOR-style transformer CVAE baseline of Table 1."""

    steps: int = 3000  # our choice: about 10 minutes on a CPU core
    lr: float = 1e-3  # our choice: at 2e-4 the decoder underfits in this budget and ignores the label
    weight_decay: float = 0.01  # torch's AdamW default
    dataset: str = "coma"
    kl_weight: float = 1e-3  # our choice (ACTOR: 1e-5 with its loss scaling)


@dataclass(frozen=True)
class MotionClipTraining(Optimisation):
    """The MotionCLIP-style text-to-motion decoder of Table 2."""

    steps: int = 3000  # our choice: a few minutes on 2 CPU cores; the loss has flattened by then
    lr: float = 1e-3
    weight_decay: float = 0.01  # torch's AdamW default
    dataset: str = "coma+bu"  # paper §5.2


@dataclass(frozen=True)
class Motion3DGANTraining(Optimisation):
    """The Motion3DGAN-style WGAN-GP on SRVFs of Table 1 (Otberdout et al.)."""

    steps: int = 1500  # generator steps (our choice: a few minutes on a CPU core)
    lr: float = 1e-4  # the Motion3DGAN paper
    optimizer: str = "adam"
    betas: tuple = (0.5, 0.9)  # WGAN-GP's Adam
    dataset: str = "coma"
    critic_steps: int = 5  # n_critic (WGAN-GP default; not given)
    gp_weight: float = 10.0  # lambda of Eq. 4 (WGAN-GP default; not given)
    adversarial_weight: float = 1.0  # alpha_1 (the Motion3DGAN paper)
    reconstruction_weight: float = 10.0  # alpha_2 (the Motion3DGAN paper)
    smoothing: float = 1.0  # our choice: Gaussian sigma (frames) applied before the SRVF (models.motion3dgan.prepare)


@dataclass(frozen=True)
class LSTMFillerTraining(Optimisation):
    """The bidirectional-LSTM filler of Table 3 (Berson et al.: Adam, lr 1e-3)."""

    steps: int = 1500  # our choice: ~9 min on one CPU core (a 2x40-step BiLSTM is sequential)
    lr: float = 1e-3
    optimizer: str = "adam"
    dataset: str = "coma"
    alpha_gt: float = 10.0  # Berson et al.'s weight of the known frames


@dataclass(frozen=True)
class DeformationTraining(Optimisation):
    """The deformation networks of Table 5 (S2D: Adam, lr 1e-3, batch 16 meshes)."""

    steps: int = 4000  # our choice: 6 to 14 minutes on one core for the spiral networks (chapter 09)
    batch_size: int = 4  # sequences per batch (our choice), frames_per_batch meshes each: S2D's 16
    lr: float = 1e-3  # S2D
    optimizer: str = "adam"
    final_lr_fraction: float = 0.1  # our choice: cosine decay to lr / 10
    method: str = "ours"  # a row of Table 5 (deformation.METHODS)
    split: str = "identity"  # "identity" or "expression" (§6)
    frames_per_batch: int = 4
    frames_per_sequence: int = 10  # frames kept per training sequence
    max_sequences: int | None = None  # fast mode: a subset of the training sequences

    def fast(self):
        return replace(self, steps=20, max_sequences=16, frames_per_sequence=4)


# ==================================================================================== sampling tasks
# The command line's defaults (``python -m facelib sample TASK``): the book's best measured settings.
# ``paper()`` gives the paper's printed algorithm (``--paper``); ``fast()`` a few steps, for tests.
# steps: reverse steps of a chain respaced from the paper's T = 2000 (None: all 2000).


@dataclass(frozen=True)
class UnconditionalSampling:
    steps: int | None = 500  # chapter 03 / results/sampling_respacing.json: 500 steps change none of its measures

    def paper(self):
        return replace(self, steps=None)  # §4: T = 2000

    def fast(self):
        return replace(self, steps=20)


@dataclass(frozen=True)
class LabelSampling:
    steps: int | None = 200  # chapter 05: the Adagrad rate was chosen at 200 steps (results/label_steps_coma.json)
    guidance_weight: float = 0.01  # §4: lambda = 0.01 "as in [51]"

    def paper(self):
        return replace(self, steps=None)  # Alg. 1 on all T = 2000 steps

    def fast(self):
        return replace(self, steps=20)


@dataclass(frozen=True)
class TextSampling:
    steps: int | None = 100  # chapter 06: the text guidance was chosen at 100 steps (results/text_sweep_cosine.json)
    score: str = "cosine"  # Eq. 10 (chapter 06 compares the contrastive score)

    def paper(self):
        return replace(self, steps=None, score="cosine")

    def fast(self):
        return replace(self, steps=20)


@dataclass(frozen=True)
class FillSampling:
    # Issue 24's measurement (32 coma test sequences, known 0:10,30:40; both seams within the real 95th
    # percentile of frame-to-frame speed): Alg. 3 at 200 steps 34 %, + RePaint r = 4 59 %, + reconstruction
    # guidance zeta = 2 72 %, zeta = 4 75 %; the real sequences themselves 97 %.
    steps: int | None = 200  # our choice: at 100 steps reconstruction guidance joins fewer seams (47 %)
    reconstruction_scale: float = 2.0  # chapter 07: reconstruction guidance joins the generated frames to the known
    resample: int = 1  # RePaint's r: with reconstruction guidance at 100 steps, r = 2 adds 6 points at twice the cost

    def paper(self):
        return replace(self, steps=None, reconstruction_scale=0.0, resample=1)  # Alg. 3 as printed

    def fast(self):
        return replace(self, steps=20)


@dataclass(frozen=True)
class GeometrySampling:
    steps: int | None = 100  # chapter 08 and 10: the respaced chain of `animate`
    passes: int = 1  # chapter 08: the harmonising passes of Alg. 4 add nothing measurable
    reconstruction_scale: float = 2.0  # chapter 08: the sweep of zeta; joins the frames to the given face

    def paper(self):
        return replace(self, steps=None, passes=5, reconstruction_scale=0.0)  # Alg. 4 as printed: 5 passes

    def fast(self):
        return replace(self, steps=10)


SAMPLING = {"unconditional": UnconditionalSampling(), "label": LabelSampling(), "text": TextSampling(),
            "fill": FillSampling(), "geometry": GeometrySampling()}
