"""Every default of the book in one place: paper values, CPU-scaled values, fast-mode
values.

Each value carries its source: the paper section, or "our choice" with the reason.
``FACELIB_FAST=1`` (set by ``make test``) selects the fast-mode values so that every
notebook executes in seconds; the default ("book") mode uses the full values.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, fields, replace
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parent.parent
NUM_LANDMARKS = 68  # the iBUG-68 landmarks a frame holds (paper §3.1)
NUM_FRAMES = 40  # frames per sequence (paper §4)
NUM_DIFFUSION_STEPS = 2000  # T of the paper's chain (paper §4)
# The shipped checkpoints and dataset fingerprints live in the repository's data/, not
# in the package: `pip install .` installs code only, and FACELIB_DATA_DIR then names a
# clone's data/ (checkpoints.load_checkpoint says so).
DATA_DIR = Path(os.environ.get("FACELIB_DATA_DIR", PROJECT_ROOT / "data"))

# The synthetic world's version.  Version 2 (issue 25; facelib/face/tissue.py: tissue
# mechanics, magnitudes calibrated to published measurements of real faces) replaced
# version 1, whose faces moved far less than real ones.  The dataset caches are named
# after the version, and every checkpoint records it with the fingerprints of the
# datasets it read: one of another version, or of a dataset since changed, is refused
# with the command that retrains it (checkpoints.check_world), and a stored result whose
# checkpoints or datasets changed is flagged stale (tests/test_results.py).
# ``face.Face(..., world=1)`` remains only for chapter 01's comparison of the two
# versions (WORLDS).
WORLD = 2
WORLDS = (1, 2)
SYNTHETIC_DIR = DATA_DIR / "synthetic"
# Checkpoints live in a folder named after the world version they were trained on: a
# retrain on a new version writes beside the old ones until it replaces them.
CHECKPOINT_DIR = DATA_DIR / "checkpoints" / f"world{WORLD}"
RESULTS_DIR = PROJECT_ROOT / "results"


def fast_mode():
    """True when FACELIB_FAST is set to a true value (1/true/yes): small, quick runs for
    tests."""
    return os.environ.get("FACELIB_FAST", "").strip().lower() in (
        "1",
        "true",
        "yes",
        "on",
    )


def cache_dir():
    """Where generated datasets are cached: $FACELIB_CACHE_DIR or data/synthetic/cache
    (every world's)."""
    return Path(os.environ.get("FACELIB_CACHE_DIR", DATA_DIR / "synthetic" / "cache"))


@dataclass(frozen=True)
class DatasetSpec:
    """How a synthetic dataset is generated (see data/synthetic/README.md)."""

    name: str
    label_set: str  # "coma" or "bu": which expression labels
    num_subjects: int
    num_sequences: int
    num_test_subjects: int  # subjects held out for the "test" split
    # base number of sequences per (subject, label), N2E and E2N alternating
    takes_per_pair: int
    seed: int
    # how differently subjects perform a label (expressions.StyleSpread)
    style_gain_sigma: float
    style_leak_probability: float
    style_leak_max: float
    style_blend_max: float
    num_frames: int = NUM_FRAMES  # paper §4: sequences of 40 frames


DATASETS = {
    # Paper §4: 689 CoMA sequences from 12 subjects performing 12 actions.  CoMA's
    # labels are instructions ("lips up") that subjects interpret freely: our choice of
    # a wide style spread makes them as hard to recognise on unseen subjects as the
    # paper's GT row (83.8 %).  World 2's broad, saturating expressions blur the labels
    # into each other more than world 1's did (the IC read 76 % with a blend of 0.3):
    # mixing at most 0.22 of another label in keeps the ground truth near
    # 83.8 %.  Our choice: 4 takes per (subject, label) plus one extra take for 113
    # random pairs gives exactly 689; 3 subjects (a quarter) are held out for testing.
    "coma": DatasetSpec(
        "coma",
        "coma",
        num_subjects=12,
        num_sequences=689,
        num_test_subjects=3,
        takes_per_pair=4,
        seed=1001,
        style_gain_sigma=0.45,
        style_leak_probability=0.9,
        style_leak_max=0.4,
        style_blend_max=0.22,
    ),
    # Paper §4: 606 BU-4DFE recordings of 101 subjects x 6 emotions, each cut into an
    # N2E and an E2N sequence: 1212 sequences.  Our choice: 20 subjects held out for
    # testing.
    "bu": DatasetSpec(
        "bu",
        "bu",
        num_subjects=101,
        num_sequences=1212,
        num_test_subjects=20,
        takes_per_pair=2,
        seed=2002,
        style_gain_sigma=0.25,
        style_leak_probability=0.5,
        style_leak_max=0.2,
        style_blend_max=0.2,
    ),
}
SPLITS = ("train", "test", "all")


# ====================================================================================
# training Every model is trained by the one loop of facelib/training/loop.py; these are
# its recipes' settings. A field's comment says where its value comes from: the paper
# (§, Eq.) or "our choice" and why.
OPTIMIZERS = ("adam", "adamw")
# What a denoiser's network outputs (models.denoiser converts each to eps): the noise
# (paper, Eq. 8), the clean sequence x_0 (MDM, Tevet et al. 2023) or the velocity v =
# sqrt(abar_t) eps - sqrt(1 - abar_t) x_0 (Salimans & Ho 2022)
# "u": the velocity eps - x_0 of rectified flow (facelib/flow.py; schedule "flow")
PREDICTIONS = ("eps", "x0", "v", "u")


def check_prediction(prediction):
    if prediction not in PREDICTIONS:
        raise ValueError(
            f"unknown prediction target {prediction!r}; allowed:"
            f" {', '.join(PREDICTIONS)}"
        )


def _check_positive_int(name, value):
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")


@dataclass(frozen=True)
class Optimisation:
    """How the training loop optimises (the fields every recipe shares; each recipe sets
    its own values).

    The learning rate rises linearly over ``warmup`` steps, then follows a cosine from
    ``lr`` down to ``lr * final_lr_fraction`` (1.0: constant).  ``grad_clip``: clip the
    gradient norm (None: no clipping). ``ema_decay``: keep an exponential moving average
    of the weights and return it (None: no EMA). ``epochs``: None draws each of the
    ``steps`` batches uniformly with replacement; an integer walks that many times
    through a new permutation of the data (the last batch of a pass may be smaller), and
    the number of steps follows from the data's size."""

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
            raise ValueError(
                f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}"
            )
        if self.epochs is not None:
            _check_positive_int("epochs", self.epochs)
        if not isinstance(self.warmup, int) or not 0 <= self.warmup < self.steps:
            raise ValueError(
                f"warmup must be an integer in 0..steps-1 = {self.steps - 1}, got"
                f" {self.warmup!r}"
            )
        if not self.lr > 0 or not 0 <= self.final_lr_fraction <= 1:
            raise ValueError(
                f"need lr > 0 and final_lr_fraction in [0, 1], got {self.lr},"
                f" {self.final_lr_fraction}"
            )
        if self.ema_decay is not None and not 0 < self.ema_decay < 1:
            raise ValueError(
                f"ema_decay must be in (0, 1) or None, got {self.ema_decay}"
            )

    def with_steps(self, steps):
        """The same recipe for ``steps`` steps, its warm-up kept at most a tenth of the
        run."""
        return replace(self, steps=steps, warmup=min(self.warmup, steps // 10))

    def fast(self):
        """The fast-mode version (tests, FACELIB_FAST chapters): 20 steps."""
        return self.with_steps(20)


@dataclass(frozen=True)
class DenoiserTraining(Optimisation):
    """The DDPM denoiser eps_theta (§3.1, §4).  Paper §4: 200K iterations, lr 1e-4,
    batch 256.  A CPU budget of about an hour on 2 cores allows about 1/30 of that
    compute: a smaller transformer (models.denoiser.DenoiserConfig), fewer, smaller
    steps with a higher rate, and an EMA.  Measured against coverage (chapter 03,
    section 8; results/denoiser_ablation.json), training length decides it."""

    # our choice: ~60 min on 2 cores (paper: 200K); coverage 0.43 at 12,000, 0.53 here
    steps: int = 24_000
    batch_size: int = 64  # our choice (paper: 256): CPU time per step
    # our choice (paper: 1e-4): 13x fewer, 4x smaller steps need a larger rate
    lr: float = 5e-4
    warmup: int = 500  # our choice: linear warm-up, then cosine decay to lr / 20
    final_lr_fraction: float = 0.05
    grad_clip: float | None = 1.0  # our choice: stabilises the first steps
    # our choice: visibly cleaner samples for short runs
    ema_decay: float | None = 0.999
    dataset: str = "coma"  # paper §4: "unless otherwise specified, solely CoMA"
    # paper §4: 40 frames; (35, 45) for the variable-length model of App. A
    num_frames: object = NUM_FRAMES
    num_diffusion_steps: int = NUM_DIFFUSION_STEPS  # paper §4: T = 2000
    # paper §4: linear betas from 1e-4 to 0.02 ("flow": a rectified flow, see flow.py)
    schedule: str = "linear"
    # paper, Eq. 8: the network predicts the noise
    # ("x0": MDM's; "v": Salimans & Ho 2022; "u": the flow's velocity)
    prediction: str = "eps"
    # paper: None (the simple loss); a number: min-SNR-gamma (Hang et al. 2023)
    min_snr_gamma: float | None = None
    # our option: probability that a training sequence is mirrored left to right
    mirror: float = 0.0
    # our choice: training faces of these datasets (9 + 81)
    anatomy_pool: tuple = ("coma", "bu")
    # our choice: probability that a sequence gets another anatomy
    anatomy_swap: float = 0.5
    # True: label-conditional, for classifier-free guidance (Ho & Salimans 2022)
    conditional: bool = False
    # conditional only: the label is dropped (-> "no label") this often (MDM: 0.1)
    condition_dropout: float = 0.1
    # > 0: a join denoiser (DenoiserConfig.known_input; CondMDI, Cohan et al. 2024):
    # this often a training sequence's first 1..F/2 frames (and half the time its last)
    # are given as input, as a long sequence's window knows them (0: never; no input)
    known_frames: float = 0.0
    # fine-tune: start from this denoiser checkpoint's weights (None: from scratch)
    start_from: str | None = None

    def __post_init__(self):
        super().__post_init__()
        if not 0 <= self.known_frames <= 1:
            raise ValueError(
                f"known_frames is a probability in [0, 1], got {self.known_frames}"
            )
        if self.known_frames and not isinstance(self.num_frames, int):
            raise ValueError(
                "known_frames gives a sequence's first and last frames: train on one"
                " length (num_frames an int), not on lengths"
                f" {self.num_frames}"
            )
        if self.start_from is not None and not (
            isinstance(self.start_from, str) and self.start_from.startswith("denoiser")
        ):
            raise ValueError(
                "start_from names a denoiser checkpoint (denoiser_<dataset>...), got"
                f" {self.start_from!r}"
            )
        if not 0 <= self.anatomy_swap <= 1:
            raise ValueError(
                f"anatomy_swap is a probability in [0, 1], got {self.anatomy_swap}"
            )
        if not 0 <= self.condition_dropout < 1:
            raise ValueError(
                "condition_dropout is a probability in [0, 1), "
                f"got {self.condition_dropout}"
            )
        if not 0 <= self.mirror <= 1:
            raise ValueError(f"mirror is a probability in [0, 1], got {self.mirror}")
        check_prediction(self.prediction)
        if self.schedule == "flow" and self.prediction != "u":
            raise ValueError(
                "a rectified flow (schedule 'flow') predicts its velocity: use"
                f" prediction='u', not {self.prediction!r}"
            )
        if self.schedule == "flow" and self.min_snr_gamma is not None:
            raise ValueError("min_snr_gamma weighs the DDPM's loss, not the flow's")
        if self.min_snr_gamma is not None and not self.min_snr_gamma > 0:
            raise ValueError(
                "min_snr_gamma must be a positive number or None, "
                f"got {self.min_snr_gamma}"
            )


@dataclass(frozen=True)
class GuideTraining(Optimisation):
    """The guidance classifiers p_phi(y | x_t, t) of Alg. 1 (type I) and Alg. 4 (type
    S)."""

    # our choice: ~3 min on 2 CPU cores; accuracy against t is shown in the
    # label-control chapter
    steps: int = 3000
    lr: float = 3e-4
    warmup: int = 200
    final_lr_fraction: float = 0.05
    weight_decay: float = 0.01
    grad_clip: float | None = 1.0
    dataset: str = "coma"
    # paper §5.1: type I for label control, type S for Alg. 4
    classifier_type: str = "I"
    # the DDPM's schedule (paper §4): x_t must look like the sampler's
    num_diffusion_steps: int = NUM_DIFFUSION_STEPS
    schedule: str = "linear"


@dataclass(frozen=True)
class DistillationTraining(Optimisation):
    """One round of progressive distillation (Salimans & Ho 2022, Alg. 2): a student of
    ``teacher_steps / 2`` deterministic (DDIM) steps learns to land, in one step, where
    two steps of the teacher's ``teacher_steps``-step chain land.  Each round's student
    is the next round's teacher (256 -> 128 -> ... -> 1).  The student starts from the
    teacher's weights and predicts v (their choice: eps is unstable at few steps, where
    x_0 = (x_t - sqrt(1 - abar) eps) / sqrt(abar) divides by a small number)."""

    # a denoiser checkpoint (name or path): the DDPM, or the previous round's student
    teacher: str = "denoiser_coma"
    teacher_steps: int = 256  # their choice for the first teacher; even, so it halves
    steps: int = 2000  # our choice (theirs: 50K per round on far larger models)
    batch_size: int = 64
    lr: float = 2e-4  # our choice (theirs: 1e-4 at batch 128-2048)
    warmup: int = 100
    final_lr_fraction: float = 0.1
    grad_clip: float | None = 1.0
    ema_decay: float | None = 0.999
    # ours: "landing" (DISTILLATION_WEIGHTINGS); theirs: "truncated_snr"
    weighting: str = "landing"
    # a label-conditional DDPM teacher (denoiser_<dataset>_cfg): the classifier-free
    # weight w distilled into the student, which then samples guided in one call per
    # step (Meng et al. 2023, with one fixed w; None: CFG_SCALE); a student teacher
    # carries its w already
    guidance_scale: float | None = None

    def __post_init__(self):
        super().__post_init__()
        _check_positive_int("teacher_steps", self.teacher_steps)
        if self.teacher_steps % 2 or self.teacher_steps > NUM_DIFFUSION_STEPS:
            raise ValueError(
                "teacher_steps must be even and at most T ="
                f" {NUM_DIFFUSION_STEPS}: the student takes every other step, got"
                f" {self.teacher_steps}"
            )
        if self.weighting not in DISTILLATION_WEIGHTINGS:
            raise ValueError(
                f"unknown distillation weighting {self.weighting!r}; allowed:"
                f" {', '.join(DISTILLATION_WEIGHTINGS)}"
            )
        _check_number("guidance_scale", self.guidance_scale, allow_none=True)

    def fast(self):
        return replace(self, steps=20, warmup=5)


# The student's error: "landing": where its one step lands against where the teacher's
# two land, in units of the noise there (sqrt(1 - abar_t'')), and the x_0 error weighted
# by max(SNR_t, 1) on the last step.  Our choice: on the linear schedule the x_0 target
# divides by sqrt(abar_t'') - (sigma_t'' / sigma_t) sqrt(abar_t), which is ~3e-4 near
# T, so the x_0 error of "truncated_snr" (Salimans & Ho: max(SNR_t, 1) on the x_0
# error) or "snr" (the eps error) is dominated by the teacher's rounding there.
DISTILLATION_WEIGHTINGS = ("landing", "truncated_snr", "snr")


@dataclass(frozen=True)
class AURegressorTraining(Optimisation):
    """The noisy AU-intensity regressor R(x_t, t) of the fine-control chapter (not in
    the paper): the mean squared error of its per-frame AU intensities against the
    curves that made x_0."""

    steps: int = 3000  # our choice: the guidance classifier's budget
    lr: float = 3e-4
    warmup: int = 200
    final_lr_fraction: float = 0.05
    weight_decay: float = 0.01
    grad_clip: float | None = 1.0
    dataset: str = "coma"  # the unconditional DDPM it steers (denoiser_coma)
    # the DDPM's schedule: x_t must look like the sampler's
    num_diffusion_steps: int = NUM_DIFFUSION_STEPS
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
    # our addition (0 = the paper's cosine loss alone): see training.recipes
    contrastive_weight: float = 1.0
    # of the contrastive term (CLIP learns 0.01; 0.07 at its start)
    temperature: float = 0.05
    num_diffusion_steps: int = NUM_DIFFUSION_STEPS
    schedule: str = "linear"


@dataclass(frozen=True)
class EvaluatorTraining(Optimisation):
    """The independent classifier (IC) of the evaluation (§5): Adam, 30 epochs (our
    choices)."""

    epochs: int | None = 30  # our choice: the loss has flattened
    batch_size: int = 32
    lr: float = 1e-3
    optimizer: str = "adam"
    dataset: str = "coma"
    classifier_type: str = "I"
    hidden: int = 128  # §5: one LSTM layer; its width is our choice
    # the face-world chapter: motion generalises to unseen faces, absolute coordinates
    # do not
    inputs: str = "motion"

    def fast(self):
        return replace(self, epochs=2)


@dataclass(frozen=True)
class ActorTraining(Optimisation):
    """The ACTOR-style transformer CVAE baseline of Table 1."""

    # Issue 25: the same compute and parameter budget as the denoiser had then (12,000
    # steps; three decoder layers, 596 k parameters against its 616 k), and the KL
    # weight of the tuning sweep.  Issue 43 doubled the denoiser's steps; the ACTOR
    # baseline keeps its 12,000.
    steps: int = 12000
    # our choice: at 2e-4 the decoder underfits in this budget and ignores the label
    lr: float = 1e-3
    weight_decay: float = 0.01  # torch's AdamW default
    dataset: str = "coma"
    # The tuning sweep's pick (ACTOR: 1e-5 with its loss scaling;
    # benchmarks/baseline_sweep.py: best accuracy - 2 FID among 1e-3, 1e-2, 3e-2 at a
    # quarter budget; results/baseline_sweep.json).
    kl_weight: float = 1e-2
    depth: int = 3  # transformer layers of the encoder and of the decoder


@dataclass(frozen=True)
class MotionClipTraining(Optimisation):
    """The MotionCLIP-style text-to-motion decoder of Table 2."""

    # our choice: a few minutes on 2 CPU cores; the loss has flattened by then
    steps: int = 3000
    lr: float = 1e-3
    weight_decay: float = 0.01  # torch's AdamW default
    dataset: str = "coma+bu"  # paper §5.2


@dataclass(frozen=True)
class Motion3DGANTraining(Optimisation):
    """The Motion3DGAN-style WGAN-GP on SRVFs of Table 1 (Otberdout et al.)."""

    # Issue 25: the denoiser's parameter budget (160 channels: a 643 k-parameter
    # generator against its 616 k) and a comparable compute budget (3,000 generator
    # steps, 15,000 critic steps).
    steps: int = 3000  # generator steps
    # The tuning sweep's pick (benchmarks/baseline_sweep.py: best accuracy - 2 FID among
    # 1e-4 ... 5e-3 at a quarter budget; the Motion3DGAN paper's 1e-4 reads 12 %, 2e-3
    # 60 %).
    lr: float = 2e-3
    optimizer: str = "adam"
    betas: tuple = (0.5, 0.9)  # WGAN-GP's Adam
    dataset: str = "coma"
    critic_steps: int = 5  # n_critic (WGAN-GP default; not given)
    gp_weight: float = 10.0  # lambda of Eq. 4 (WGAN-GP default; not given)
    adversarial_weight: float = 1.0  # alpha_1 (the Motion3DGAN paper)
    reconstruction_weight: float = 10.0  # alpha_2 (the Motion3DGAN paper)
    # our choice: Gaussian sigma (frames) applied before the SRVF
    # (models.motion3dgan.prepare)
    smoothing: float = 1.0
    channels: int = 160  # of the generator's and the critic's convolutions


@dataclass(frozen=True)
class LSTMFillerTraining(Optimisation):
    """The bidirectional-LSTM filler of Table 3 (Berson et al.: Adam, lr 1e-3)."""

    # our choice: ~9 min on one CPU core (a 2x40-step BiLSTM is sequential)
    steps: int = 1500
    lr: float = 1e-3
    optimizer: str = "adam"
    dataset: str = "coma"
    alpha_gt: float = 10.0  # Berson et al.'s weight of the known frames


# §6: the deformation experiments use CoMA.  Our choice (issue 25): the faces of both
# datasets, 90 training identities, so that the deformers can learn how identity changes
# the deformation.
DEFORMATION_DATASET = "coma+bu"
# §6's expression split holds out 3 expressions; the paper does not name them.  Our
# choice: one smile, one jaw opening and a pucker, each with relatives left in training.
# Not the asymmetric mouth_side, whose sideways jaw (AD30) no other label has: holding
# it out would test extrapolation to an action unit never seen, not generalisation to a
# new combination.
HELD_OUT_EXPRESSIONS = ("high_smile", "mouth_open", "mouth_middle")


@dataclass(frozen=True)
class DeformationTraining(Optimisation):
    """The deformation networks of Table 5 (S2D: Adam, lr 1e-3, batch 16 meshes)."""

    # Our choice: 90 training faces give many pairs; 10,000 steps are 10 to 19 minutes
    # on one core.
    steps: int = 10000
    # sequences per batch (our choice), frames_per_batch meshes each: S2D's 16
    batch_size: int = 4
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


# ====================================================================================
# sampling tasks Guidance (paper §3.2, §4) and the book's choices, named once.  Each
# task below gathers its defaults in a frozen dataclass: the book's best measured
# settings; ``paper()`` gives the paper's printed algorithm (``--paper``) and ``fast()``
# a few steps (tests, FACELIB_FAST chapters). steps: reverse steps of a chain respaced
# from the paper's T = 2000 (None: all 2000).
ADAGRAD_STEPS = 3  # paper §3.2: "3 steps of the Adagrad update for each diffusion step"
GUIDANCE_WEIGHT = 0.01  # paper §4: lambda = 0.01 "as in [51]"
# Alg. 1; classic classifier guidance (Dhariwal & Nichol)
GUIDANCE_METHODS = ("adagrad", "mean_shift")
# What steers label control: a noisy classifier on the unconditional denoiser (the
# paper's), or classifier-free guidance (Ho & Salimans 2022), a label-conditional
# denoiser with no classifier (DenoiserTraining.conditional)
LABEL_GUIDANCE = ("classifier", "cfg")
# The mean shift's gradient scale s: at 1 (Dhariwal & Nichol's) it steers too weakly
# here; 10 is the book's pick (results/fast_sampling_guidance.json: s = 1, 3, 10, 30
# with both samplers at 50 and 200 steps)
MEAN_SHIFT_SCALE = 10.0
CFG_SCALE = 2.5  # classifier-free guidance's weight w: MDM's (Tevet et al. 2023)
# Our choice: below this abar_t, x_t holds no signal (the rectified flow's t = T: abar
# 2.5e-10; the linear schedule's abar_T is 1.6e-9, below 1e-6 from t = 1652), and the
# mean shift under DDIM, whose x0_hat moves by 1 / sqrt(abar_t) times its change of
# eps, guides nothing there (chapter 14: one guided step from the flow's pure noise
# moved x_t 90 times its norm)
GUIDANCE_MIN_ABAR = 1e-6
# The mean shift's scale for editing (config.Edit; our choice): 20, where 3 edits in 4
# read the new label with the neutral frame kept (results/fast_sampling_edit.json: 56 %
# at 10, 75 % at 20, 88 % at 30; the first regenerated frame then steps 0.6, 1.3 and 1.7
# mm further from the neutral one than the original's does)
EDIT_MEAN_SHIFT_SCALE = 20.0
# Alg. 1's Adagrad learning rate, per dataset, for a chain of LR_REFERENCE_STEPS reverse
# steps: not in the paper; each is the pick of the label-control chapter's sweep (48
# guided sequences per rate, 200 steps, best accuracy - 2 FID).
# A rate is a step length in the normalised landmark space, so it depends on the data
# (tasks.adagrad_lr). results/label_sweep.json: coma 0.03 (89.6 % at FID 2.35), bu 0.03
# (100 % at FID 0.13).
ADAGRAD_LR = {"coma": 0.03, "bu": 0.03}
LR_REFERENCE_STEPS = 200
# The Adagrad rate of Alg. 4's type-S guidance (our choice): the pick of
# results/geometry_lr.json (the smallest rate whose accuracy interval overlaps the best
# rate's, with the faces moving at most 1.5 times the data's)
GEOMETRY_LR = 0.03
HARMONISING_PASSES = 5  # Alg. 4 line 1: "for i = 1 to 5"
# our choice for reconstruction guidance: the sweep of the geometry-adaptive chapter
RECONSTRUCTION_SCALE = 2.0
# paper §5.2: text control works on CoMA and BU-4DFE merged (18 actions)
TEXT_DATASET = "coma+bu"
# Alg. 2's lambda (paper: 0.01) and Adagrad rate (not in the paper) for a chain of
# TEXT_LR_REFERENCE_STEPS reverse steps: the pick of the text-control chapter's sweep
# (72 raw-text sequences, 100 steps, best accuracy - 2 FID)
# results/text_sweep_cosine.json: lambda 0.001, rate 0.1 (79.2 % at FID 19.6).
TEXT_GUIDANCE_WEIGHT = 0.001
TEXT_LR = 0.1
TEXT_LR_REFERENCE_STEPS = 100
# What the text head reads in Eq. 10: x_t itself (Alg. 2 as written) or, not in the
# paper, the denoiser's estimate x0_hat of the clean sequence
# (guidance.DenoisedCosineScore)
HEAD_INPUTS = ("x_t", "x0_hat")
# The score that Alg. 2 climbs: the cosine of Eq. 10 (as written) or, not in the paper,
# the head's own log-probability of the text against the training descriptions of its
# wording (guidance.ContrastiveScore)
TEXT_SCORES = ("cosine", "contrastive")
# The contrastive score's lambda (the paper's 0.01) and Adagrad rate at
# TEXT_LR_REFERENCE_STEPS steps: at the paper's lambda, the pick of appendix A1's stored
# sweep (72 enriched texts, best Acc - 2 FID)
CONTRASTIVE_GUIDANCE_WEIGHT = 0.01
# results/text_sweep_contrastive.json: rate 0.06 (56.9 % at FID 25.0).
CONTRASTIVE_LR = 0.06
# How sharply a text is matched to the training descriptions by the contrastive score
# (our choice: an enriched sentence and its other order, at a cosine of about 0.985, get
# weights of about 0.95 and 0.05)
MATCH_TEMPERATURE = 0.005
# Best-of-K particles (not in the paper): the time label at which the K guided chains of
# each text are compared by the text head, and the time above which they are left
# unguided (the head reads nothing there); our choices from appendix A1's measurements
# (when the chains decide the order, what the head reads)
SELECT_TIME = 600
PARTICLE_MAX_TIME = 1400
# decoder_then_diffusion's re-noising step (not in the paper): our choice, appendix A1
DECODER_START = 400


def _check_choice(name, value, allowed):
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}")


def _check_number(name, value, low=0.0, allow_none=False):
    if value is None and allow_none:
        return
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not low <= value <= 3.4e38
    ):
        raise ValueError(
            f"{name} must be a"
            f" {'non-negative number' if low == 0 else f'number >= {low}'} (and finite,"
            f" at most 3.4e38: the networks compute in float32), got {value!r}"
        )


def _check_feather(feather, num_frames):
    if (
        isinstance(feather, bool)
        or not isinstance(feather, (int, float))
        or not 0 <= feather <= num_frames
    ):
        raise ValueError(
            f"feather must be a number of frames in 0..{num_frames} (a Gaussian's"
            f" sigma; 0: none), got {feather!r}"
        )


# "ddpm": the ancestral step of Eq. 5 (paper); "ddim": DDIM's step (Song et al. 2021);
# "student": a progressively distilled student of the DDIM chain, on the steps it was
# distilled for (Salimans & Ho 2022; checkpoints student_denoiser_<dataset>_<K>);
# "flow": Euler's steps of the rectified flow (denoiser_<dataset>_flow); chapter 14
SAMPLERS = ("ddpm", "ddim", "student", "flow")
# the samplers whose chain is deterministic whatever eta (their models were made for it)
DETERMINISTIC_SAMPLERS = ("student", "flow")
# where a respaced chain of K steps puts them: "uniform" (steps 1 and T and evenly
# between: Nichol & Dhariwal 2021, the book's), "trailing" (T/K, 2T/K, ..., T: Lin et
# al. 2024, the distilled students' and the flow's)
SPACINGS = ("uniform", "trailing")
# `animate --fast`: the distilled student of this many steps (chapter 14)
FAST_STUDENT_STEPS = 4


@dataclass(frozen=True)
class Sampling:
    """What every sampling task shares: the chain's length, the sequences' length, the
    seed."""

    steps: int | None = None
    num_frames: int = NUM_FRAMES  # paper §4: 40 frames
    seed: int = 0
    # the sampler's sigma_t^2: "beta" (paper §4), "posterior" (beta~_t); None: the
    # model's
    variance: str | None = None
    # one of SAMPLERS
    sampler: str = "ddpm"
    # DDIM only: sigma_t^2 = eta^2 beta~_t, in [0, 1] (0: deterministic; 1: the DDPM
    # posterior)
    eta: float = 0.0
    # one of SPACINGS
    spacing: str = "uniform"

    def __post_init__(self):
        if self.variance is not None:
            _check_choice("variance", self.variance, ("beta", "posterior"))
        _check_choice("sampler", self.sampler, SAMPLERS)
        _check_choice("spacing", self.spacing, SPACINGS)
        if (
            isinstance(self.eta, bool)
            or not isinstance(self.eta, (int, float))
            or not 0 <= self.eta <= 1
        ):
            raise ValueError(
                "eta must be a number in [0, 1] (0: deterministic DDIM), got"
                f" {self.eta!r}"
            )
        if self.eta and self.sampler != "ddim":
            raise ValueError(
                f"eta = {self.eta} is DDIM's noise: it needs sampler 'ddim' (the"
                f" sampler is {self.sampler!r})"
            )
        if self.steps is not None:
            _check_positive_int("steps", self.steps)
        _check_positive_int("num_frames", self.num_frames)
        if (
            isinstance(self.seed, bool)
            or not isinstance(self.seed, int)
            or not 0 <= self.seed < 2**32
        ):
            raise ValueError(
                f"seed must be an integer in 0..2**32 - 1, got {self.seed!r}"
            )

    @property
    def ddim_eta(self):
        """DDIM's eta when the sampler is DDIM, 0 for the deterministic samplers (a
        student, the flow), else None (GaussianDiffusion's ``eta``)."""
        if self.sampler in DETERMINISTIC_SAMPLERS:
            return 0.0
        return self.eta if self.sampler == "ddim" else None

    def paper(self):
        # §4: T = 2000, sigma_t^2 = beta_t
        return replace(self, steps=None, variance="beta", sampler="ddpm", eta=0.0)

    # the chain of fast mode (FACELIB_FAST=1); a task whose demos need fewer names its
    # own
    fast_steps = 20

    def fast(self):
        # a student samples on the steps it was distilled for, and only there
        if self.sampler == "student":
            return self
        return replace(self, steps=self.fast_steps)


@dataclass(frozen=True)
class Unconditional(Sampling):
    # results/sampling_respacing.json: 500 steps change none of the denoiser's measures
    steps: int | None = 500
    dataset: str = "coma"  # the denoiser denoiser_<dataset>


@dataclass(frozen=True)
class LabelControl(Sampling):
    """Alg. 1: 3 Adagrad steps per reverse step on lambda log p_theta + log p_phi (or
    the classic mean shift); or, not in the paper, classifier-free guidance of a
    label-conditional denoiser."""

    # the Adagrad rate was chosen at 200 steps (results/label_steps_coma.json)
    steps: int | None = 200
    dataset: str = "coma"
    # the paper's; "cfg": classifier-free (the denoiser denoiser_<dataset>_cfg)
    guidance: str = "classifier"
    classifier_type: str = "I"  # paper §5.1: type I (label) for Alg. 1
    # classifier guidance by "adagrad" (Alg. 1) or "mean_shift" (Dhariwal & Nichol's);
    # None: the one measured best with the sampler (guidance_method)
    method: str | None = None
    guidance_weight: float = GUIDANCE_WEIGHT
    # None: ADAGRAD_LR of the dataset, scaled to the steps (tasks.adagrad_lr)
    lr: float | None = None
    # the mean shift's s or CFG's w; None: default_mean_shift_scale or CFG_SCALE
    scale: float | None = None
    # a class constant, not a field (Edit has its own)
    default_mean_shift_scale = MEAN_SHIFT_SCALE

    def __post_init__(self):
        super().__post_init__()
        _check_choice("guidance", self.guidance, LABEL_GUIDANCE)
        if self.method is not None:
            _check_choice("method", self.method, GUIDANCE_METHODS)
        _check_number("the guidance weight (lambda)", self.guidance_weight)
        _check_number("lr", self.lr, allow_none=True)
        _check_number("scale", self.scale, allow_none=True)

    @property
    def guidance_scale(self):
        """The scale this run uses: ``scale``, or the default of its guidance (CFG's w,
        the mean shift's s)."""
        if self.scale is not None:
            return self.scale
        return CFG_SCALE if self.guidance == "cfg" else self.default_mean_shift_scale

    @property
    def guidance_method(self):
        """The classifier guidance this run uses: ``method``, or Alg. 1 under DDPM and
        the mean shift under DDIM, whose deterministic chain keeps the jitter of Alg.
        1's Adagrad steps to the end (results/fast_sampling_steps.json)."""
        if self.method is not None:
            return self.method
        return "adagrad" if self.sampler == "ddpm" else "mean_shift"

    def paper(self):
        return replace(
            super().paper(),
            guidance="classifier",
            method="adagrad",
            guidance_weight=GUIDANCE_WEIGHT,
        )


@dataclass(frozen=True)
class Edit(LabelControl):
    """Editing a given sequence (not in the paper): DDIM inversion to x_T, then
    regeneration with label control; what x_T encodes (timing, identity) is kept, the
    guidance changes the expression."""

    steps: int | None = 100  # issue 27: inversion at eta = 0 with 100 steps
    sampler: str = "ddim"  # inversion is DDIM's
    eta: float = 0.0
    # fixed-point iterations per inversion step (GaussianDiffusion.invert): 3 network
    # calls per step
    refine: int = 2
    # frames returned as given, 0-based ranges: the neutral frame of an N2E sequence,
    # which an edit would otherwise move (issue 42: 2.45 mm on a test sequence); None:
    # every frame regenerated
    keep: str | None = "0:1"
    default_mean_shift_scale = EDIT_MEAN_SHIFT_SCALE

    def __post_init__(self):
        super().__post_init__()
        if (
            isinstance(self.refine, bool)
            or not isinstance(self.refine, int)
            or self.refine < 0
        ):
            raise ValueError(
                "refine must be a number of fixed-point iterations >= 0, got"
                f" {self.refine!r}"
            )
        if self.sampler != "ddim" or self.eta != 0:
            raise ValueError(
                "editing inverts a sequence by deterministic DDIM and regenerates it"
                " on the same path: the sampler must be 'ddim' with eta 0, got"
                f" {self.sampler!r} with eta {self.eta!r}"
            )

    def paper(self):
        raise ValueError(
            "editing is not in the paper: there is no --paper version of it"
        )


@dataclass(frozen=True)
class TextControl(Sampling):
    """Alg. 2: Adagrad steps on lambda log p_theta + score(x, t-1), the score reading
    the text head."""

    # the text guidance was chosen at 100 steps (results/text_sweep_cosine.json)
    steps: int | None = 100
    dataset: str = TEXT_DATASET
    # Eq. 10 (the text-control chapter compares the contrastive score)
    score: str = "cosine"
    head_input: str = "x_t"  # Alg. 2 (x0_hat: not in the paper)
    # contrastive score only: match the text against every known description
    vocabulary: bool = False
    # None: TEXT_GUIDANCE_WEIGHT, CONTRASTIVE_GUIDANCE_WEIGHT for "contrastive"
    guidance_weight: float | None = None
    # None: TEXT_LR (CONTRASTIVE_LR), scaled to the steps (tasks.text_lr)
    lr: float | None = None
    # best-of-K: K guided chains per sequence until SELECT_TIME (1: Alg. 2 as written)
    particles: int = 1
    select_time: float = SELECT_TIME
    # leave the steps above this time label unguided (None: guide all)
    max_time: float | None = None

    def __post_init__(self):
        super().__post_init__()
        _check_choice("score", self.score, TEXT_SCORES)
        _check_choice("head_input", self.head_input, HEAD_INPUTS)
        if self.score == "contrastive" and self.head_input != "x_t":
            raise ValueError(
                "the contrastive score reads x_t: use head_input='x_t' with"
                " score='contrastive'"
            )
        if self.vocabulary not in (False, True):
            raise ValueError(
                f"vocabulary must be True or False, got {self.vocabulary!r}"
            )
        if self.vocabulary and self.score != "contrastive":
            raise ValueError(
                "the vocabulary is matched by the contrastive score: use"
                " vocabulary=True with score='contrastive'"
            )
        _check_positive_int("particles", self.particles)
        _check_number("select_time", self.select_time, low=1)
        for name in ("guidance_weight", "lr", "max_time"):
            _check_number(name, getattr(self, name), allow_none=True)

    def paper(self):
        return replace(
            super().paper(),
            score="cosine",
            head_input="x_t",
            vocabulary=False,
            particles=1,
            max_time=None,
            guidance_weight=GUIDANCE_WEIGHT,
        )  # §4: lambda = 0.01


# tau of AU-curve control: log N(c | R(x_t, t), tau^2), in AU intensity units (our
# choice)
AU_CURVE_TOLERANCE = 0.1
# the Adagrad rate of AU-curve control at 50 steps (our choice; the fine-control
# chapter)
AU_CURVE_LR = 0.03
# our choice: AU-curve control is scored on the AUs that the rig fit recovers within
# this (mean absolute error, intensity units) on real test sequences
# (experiments.fit_floor), no others
AU_MEASURABLE_FIT_ERROR = 0.05
# our choice: a sequence activates an AU when its |intensity| exceeds this at some frame
# (tasks.au.active_aus, tasks.never_together): a clear activation (a fifth of a typical
# strong apex), not a trace
AU_ACTIVE = 0.2
# our choice: a random request's peak lies in [low, min(high, the data's highest)]
# (experiments.random_requests): strong enough for the rig fit to see, never beyond a
# typical strong apex (1)
AU_REQUEST_PEAK = (0.3, 1.0)
# our choice: the frames (inclusive) where a random request peaks, so the curve rises
# over at least 10 frames and falls over at least 14 of the 40
AU_REQUEST_PEAK_FRAMES = (10, 25)


@dataclass(frozen=True)
class AUControl(Sampling):
    """AU-curve control (not in the paper; the fine-control chapter): Alg. 1's 3 Adagrad
    steps per reverse step on lambda log p_theta + log N(c | R(x, t-1), tau^2), R the
    noisy AU regressor and c the requested curves of the constrained AUs; or the classic
    mean shift along the same score."""

    steps: int | None = 50
    # the unconditional denoiser denoiser_<dataset> and the regressor
    # au_regressor_<dataset>
    dataset: str = "coma"
    method: str = "adagrad"  # "adagrad" (Alg. 1's optimisation) or "mean_shift"
    guidance_weight: float = GUIDANCE_WEIGHT  # lambda (Alg. 1's)
    # None: AU_CURVE_LR at 50 steps, scaled to the steps as label control's rate
    lr: float | None = None
    scale: float = MEAN_SHIFT_SCALE  # the mean shift's s
    tolerance: float = AU_CURVE_TOLERANCE
    # what R reads: "x0_hat", the denoiser's estimate (the fine-control chapter), or
    # "x_t"
    read: str = "x0_hat"
    # with a given face: joins the frames to it (as Alg. 4's)
    reconstruction_scale: float = RECONSTRUCTION_SCALE
    # the weight of log N(c | R, tau^2); 0: "AU guidance off" (tasks.au.AU_GUIDANCE_OFF)
    au_weight: float = 1.0

    def __post_init__(self):
        super().__post_init__()
        _check_choice("method", self.method, GUIDANCE_METHODS)
        _check_choice("read", self.read, HEAD_INPUTS)
        _check_number("the AU score's weight", self.au_weight)
        _check_number("the reconstruction guidance scale", self.reconstruction_scale)
        _check_number("the guidance weight (lambda)", self.guidance_weight)
        _check_number("lr", self.lr, allow_none=True)
        _check_number("scale", self.scale)
        _check_number("tolerance", self.tolerance, low=1e-6)


@dataclass(frozen=True)
class DecoderThenDiffusion(Sampling):
    """Not in the paper: the MotionCLIP-style decoder's sequence, re-noised to ``start``
    and denoised (SDEdit)."""

    # the text-control chapter measures it on the chain of text control
    steps: int | None = 100
    dataset: str = TEXT_DATASET
    start: int = DECODER_START  # a step of the paper's chain, 1..T

    def __post_init__(self):
        super().__post_init__()
        if (
            isinstance(self.start, bool)
            or not isinstance(self.start, int)
            or self.start < 1
        ):
            raise ValueError(
                "start must be a step of the paper's chain (an integer >= 1), got"
                f" {self.start!r}"
            )


@dataclass(frozen=True)
class Fill(Sampling):
    """Alg. 3 (expression filling), with the book's additions."""

    # results/fill_defaults.json (benchmarks/fill_defaults.py): of the candidates,
    # reconstruction guidance with the posterior variance beta~_t at 100 steps joins the
    # most seams smoothly, at the best accuracy and FID, in half the time of 200 steps;
    # with sigma_t^2 = beta_t the generated frames jitter more than the data.
    steps: int | None = 100
    variance: str | None = "posterior"  # our choice (the paper samples with beta_t)
    dataset: str = "coma"
    # joins the generated frames to the known (filling chapter)
    reconstruction_scale: float = RECONSTRUCTION_SCALE
    # RePaint's r: r = 2 joins more seams (89 %) but reads the label less (82.8 %), in
    # twice the time
    resample: int = 1

    def __post_init__(self):
        super().__post_init__()
        _check_number("the reconstruction guidance scale", self.reconstruction_scale)
        _check_positive_int("resample", self.resample)

    def paper(self):
        # Alg. 3 as printed
        return replace(super().paper(), reconstruction_scale=0.0, resample=1)


KEYFRAME_METHODS = ("replace", "reconstruction", "both")
# mm, our choice: a key counts as met within this distance (and no jump); 2.5 x the
# 0.2 mm std of the world's capture noise per coordinate
# (face.sequences.Timing.noise_mm), so a key is met when the landmark is where a real
# capture of that pose could put it
KEYFRAME_TOLERANCE = 0.5
# frames, our choice: "no jump" is read on the keyed landmark's speed over every frame
# pair within this distance of the key, not only into and out of it: a jump that
# feathering moves off the key still counts
KEYFRAME_SPEED_RADIUS = 3


# sigma (frames) of the feathered replacement of keyframes (inpainting.KnownFrames):
# the smallest of the best of 1, 2, 3, 4, 6 on 64 keys drawn apart from the
# benchmark's (results/fine_control_keyframes_choice.json: python
# benchmarks/fine_control.py --experiment keyframes --keys-seed 6 --n 64 --feather 1 2
# 3 4 6 --save fine_control_keyframes_choice); chapter 12
KEYFRAME_FEATHER = 4.0


@dataclass(frozen=True)
class Keyframes(Sampling):
    """Landmark keyframes (not in the paper; the fine-control chapter): chosen landmarks
    at chosen frames. "replace": Alg. 3 on coordinates (the constrained landmarks
    re-drawn from q(x_{t-1} | x_0)); "reconstruction": reconstruction guidance on them;
    "both": the two together, as OmniControl's spatial guidance with inpainting."""

    steps: int | None = 100  # the filling chapter's chain (Fill)
    variance: str | None = "posterior"
    dataset: str = "coma"
    method: str = "both"
    reconstruction_scale: float = RECONSTRUCTION_SCALE
    # the keyed landmark's other frames shifted by the key's gap to the model's estimate
    # (frames, sigma; 0: Alg. 3 as printed; inpainting.KnownFrames)
    feather: float = KEYFRAME_FEATHER

    def __post_init__(self):
        super().__post_init__()
        _check_choice("method", self.method, KEYFRAME_METHODS)
        _check_number("the reconstruction guidance scale", self.reconstruction_scale)
        _check_feather(self.feather, self.num_frames)

    def paper(self):
        # replacement as Alg. 3 prints it
        return replace(super().paper(), feather=0.0)


# the chapter "Any length" (facelib/tasks/long.py)
# our choice: the world's 40 frames are then 1.33 s, and an expression's rise (0.35-0.6
# of them, face.sequences.Timing) takes 0.5-0.8 s, as a posed smile's onset does
NATIVE_FPS = 30
LONG_FPS_RANGE = (10, 60)  # the frame rates a long sequence is written at
LONG_MAX_SECONDS = 3600  # one hour: 108,000 frames, 3,600 windows
# `animate --schedule` writes an OBJ per frame (about 0.3 MB for the template): one
# minute at 30 fps is 1,800 files
ANIMATE_MAX_SECONDS = 60
# how consecutive windows are joined: "fill" (the later window's first frames known,
# Alg. 3 with the book's reconstruction guidance), "replace" (Alg. 3 as printed),
# "handshake" (PriorMDM's DoubleTake, first take: all windows at once, their shared
# frames averaged at every step), "concat" (independent windows end to end: the naive
# baseline), "learned" (fill by a join denoiser, which reads the known frames)
JOIN_METHODS = ("fill", "replace", "handshake", "concat", "learned")
# the words of a schedule that are not labels: the given face at rest; free motion
SCHEDULE_NEUTRAL, SCHEDULE_FREE = "neutral", "free"


@dataclass(frozen=True)
class Long(Sampling):
    """Sequences of any length (not in the paper): windows of the model's length, each
    overlapping the one before by ``transition`` frames, joined by ``join``
    (JOIN_METHODS); a label's windows are guided by Alg. 1, a text's by Alg. 2, a
    neutral segment's end at the given face."""

    steps: int | None = 100  # the filling chapter's chain (Fill)
    variance: str | None = "posterior"
    dataset: str = "coma"
    join: str = "fill"
    transition: int = 10  # frames each window shares with the one before (native)
    fps: int = NATIVE_FPS  # the frame rate written (resampled from NATIVE_FPS)
    reconstruction_scale: float = RECONSTRUCTION_SCALE
    guidance_weight: float = GUIDANCE_WEIGHT
    # None: ADAGRAD_LR of the dataset, scaled to the steps (tasks.adagrad_lr)
    lr: float | None = None
    # a label segment's first window sets out from where the stream is: guided by the
    # type-S classifier as this order, at this rate (None: type I, as its other windows)
    opening: str | None = "N2E"
    opening_lr: float = GEOMETRY_LR
    # a segment's later windows guided by the type-I classifier too (False: they
    # continue what the first set out, unguided; guided again, a label escalates: an
    # open mouth opens further in every window, chapter 15)
    guide_continuation: bool = False
    # the new frames next to the known ones shifted by their gap to the model's estimate
    # (frames, sigma; 0: none; inpainting.KnownFrames; it does not remove the joins'
    # kink, chapter 15)
    feather: float = 0.0
    # a schedule with a text ("'a broad grin':2s") runs on the text head's data: its
    # denoiser, and Alg. 2 for every segment, a label read as its raw text (no label
    # classifier is trained on it)
    text_dataset: str = TEXT_DATASET
    # a text segment's first window guided by its text said in this order ("from the
    # neutral face to ..."; None: as written, which shows the text more often, chapter
    # 15)
    text_opening: str | None = None
    # lambda and the Adagrad rate of the text segments (None: text control's)
    text_guidance_weight: float | None = None
    text_lr: float | None = None

    def __post_init__(self):
        super().__post_init__()
        _check_choice("join", self.join, JOIN_METHODS)
        _check_feather(self.feather, self.num_frames)
        if self.feather and self.join == "handshake":
            raise ValueError(
                "feather spreads the replacement of known frames (joins fill, replace,"
                " concat, learned); the handshake averages its windows: give feather 0"
            )
        if self.opening is not None:
            _check_choice("opening", self.opening, ("N2E", "E2N"))
        if self.text_opening is not None:
            _check_choice("text_opening", self.text_opening, ("N2E", "E2N"))
        _check_number("opening_lr", self.opening_lr)
        _check_number("the reconstruction guidance scale", self.reconstruction_scale)
        _check_number("the guidance weight (lambda)", self.guidance_weight)
        _check_number("lr", self.lr, allow_none=True)
        _check_number(
            "the text guidance weight", self.text_guidance_weight, allow_none=True
        )
        _check_number("text_lr", self.text_lr, allow_none=True)
        low, high = LONG_FPS_RANGE
        if (
            isinstance(self.fps, bool)
            or not isinstance(self.fps, int)
            or not low <= self.fps <= high
        ):
            raise ValueError(
                f"fps must be an integer in {low}..{high}, got {self.fps!r}"
            )
        if (
            isinstance(self.transition, bool)
            or not isinstance(self.transition, int)
            or not 1 <= self.transition <= self.num_frames // 2
        ):
            raise ValueError(
                "transition must be a number of frames in 1.."
                f"{self.num_frames // 2} (half a window of {self.num_frames}), got"
                f" {self.transition!r}"
            )

    def paper(self):
        # the joins by Alg. 3 as printed
        return replace(
            super().paper(), join="replace", reconstruction_scale=0.0, feather=0.0
        )

    fast_steps = 10


@dataclass(frozen=True)
class GeometryAdaptive(Sampling):
    """Alg. 4 (geometry-adaptive generation with the type-S classifier), with the book's
    additions."""

    # the geometry-adaptive and end-to-end chapters: the respaced chain of `animate`
    steps: int | None = 100
    dataset: str = "coma"
    # the neutral face first ("N2E", the default) or last ("E2N"), unless the label says
    order: str | None = None
    # the geometry-adaptive chapter: the harmonising passes of Alg. 4 add nothing
    # measurable
    passes: int = 1
    # pass i > 1 re-noises to this step (None: to T, as the paper)
    renoise_step: int | None = None
    resample: int = 1  # RePaint's r within each pass (1: Alg. 4 as written)
    # the sweep of zeta (geometry-adaptive chapter)
    reconstruction_scale: float = RECONSTRUCTION_SCALE
    guidance_weight: float = GUIDANCE_WEIGHT
    lr: float = GEOMETRY_LR

    def __post_init__(self):
        super().__post_init__()
        _check_positive_int("passes", self.passes)
        _check_positive_int("resample", self.resample)
        _check_number("the reconstruction guidance scale", self.reconstruction_scale)
        _check_number("the guidance weight (lambda)", self.guidance_weight)
        _check_number("lr", self.lr)

    def paper(self):
        return replace(
            super().paper(),
            passes=HARMONISING_PASSES,
            reconstruction_scale=0.0,
            resample=1,
        )

    fast_steps = 10


# millimetres per unit of a reader's mesh (the chapter "Your own face")
UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
# a mesh of the template's triangles in mm is animated as it is (no registration) when
# the rigid fit onto the template turns it by at most this many degrees and moves its
# centre by at most this many mm: twice the most the world's own identities need (0.78
# degrees, 4.4 mm over identity seeds 0-39, as `python -m facelib neutral` writes them)
CANONICAL_POSE_DEGREES = 1.5
CANONICAL_POSE_SHIFT_MM = 9.0


@dataclass(frozen=True)
class Registration:
    """Fitting the template to a reader's own face mesh (facelib/registration.py, the
    chapter "Your own face")."""

    # "mm", "cm" or "m"; None: detected from the mesh's size (FACE_EXTENT_MM)
    units: str | None = None
    # our choice: points sampled on the mesh's surface, area-weighted (the fit's target)
    samples: int = 40_000
    # similarity ICP (Umeyama): a third from each of 24 starts, the rest from the best
    rigid_iterations: int = 30
    # our choice: each ICP step keeps this share of the closest correspondences (holes,
    # extras)
    trim: float = 0.9
    # our choice: correspondence rounds of the identity-model fit (point to plane)
    model_rounds: int = 30
    # our choice: Gauss-Newton evaluations per round (new correspondences converge
    # faster)
    model_steps: int = 3
    # weight of the N(0, I) prior on the identity coefficients (a 3DMM's prior)
    model_prior: float = 1.0
    # Non-rigid ICP (Amberg et al. 2007, trimesh.registration.nricp_amberg): (stiffness,
    # landmark weight, normal weight, iterations) per stage, the stiffness annealed from
    # stiff to supple.  Our choice (the chapter "Your own face", section 4): stiffer
    # than trimesh's default, since the identity model already brought the template
    # close.
    stiffness: tuple = (
        (1.0, 0.0, 1.0, 10),
        (0.3, 0.0, 1.0, 10),
        (0.1, 0.0, 1.0, 10),
        (0.03, 0.0, 0.5, 10),
    )
    match_distance_mm: float = 10.0  # NRICP ignores correspondences farther than this
    # Our choice (measured in the chapter "Your own face"): after rigid alignment every
    # face of the truth set is within 2.5 mm (trimmed RMS), a sphere, a cube, a hand and
    # a plane at 4.5 mm or more.  A worse fit is refused.
    max_residual_mm: float = 3.5
    # motion carried in full within 5 mm of the fitted face, fading out by 40 mm
    falloff_mm: tuple = (5.0, 40.0)

    def __post_init__(self):
        if self.units is not None:
            _check_choice("units", self.units, tuple(UNITS_MM))
        _check_positive_int("samples", self.samples)
        _check_positive_int("rigid_iterations", self.rigid_iterations)
        _check_positive_int("model_rounds", self.model_rounds)
        if not 0.5 <= self.trim <= 1.0:
            raise ValueError(f"trim must be in [0.5, 1], got {self.trim}")
        near, far = self.falloff_mm
        if not 0 <= near < far:
            raise ValueError(
                "falloff_mm must be (near, far) with 0 <= near < far, got"
                f" {self.falloff_mm}"
            )

    def fast(self):
        return replace(self, samples=20_000, rigid_iterations=15)


def with_overrides(settings, overrides):
    """``settings`` with the fields named in ``overrides`` changed (a clear error for a
    name it has not)."""
    allowed = [f.name for f in fields(settings)]
    unknown = sorted(set(overrides) - set(allowed))
    if unknown:
        raise ValueError(
            f"{type(settings).__name__} has no setting {', '.join(unknown)}; its"
            f" settings: {', '.join(allowed)}"
        )
    return replace(settings, **overrides)
