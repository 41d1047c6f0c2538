"""The settings of every training recipe (facelib/training/recipes.py): a frozen
dataclass per model, all run by the one loop of facelib/training/loop.py.

A field's comment says where its value comes from: the paper (§, Eq.) or "our choice"
and why; ``fast()`` is the fast-mode run (tests, FACELIB_FAST chapters).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass, replace

from ..checks import (
    check_choice,
    check_number,
    check_positive_int,
    check_probability,
)
from ..config import (
    NUM_DIFFUSION_STEPS,
    NUM_FRAMES,
    check_prediction,
)
from ..data import CLASSIFIER_TYPES, MODEL_DATASETS
from ..deformation import METHODS as DEFORMATION_METHODS, SPLITS as DEFORMATION_SPLITS
from ..models.classifier import ARCHITECTURES
from ..options import option, option_text


OPTIMIZERS = ("adam", "adamw")


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

    steps: int = option(1000, help="training steps")
    batch_size: int = option(
        64, help="global batch, split over the processes (distributed training)"
    )
    lr: float = 1e-3
    optimizer: str = "adamw"
    betas: tuple = (0.9, 0.999)
    weight_decay: float = 0.0
    warmup: int = 0
    final_lr_fraction: float = 1.0
    grad_clip: float | None = None
    ema_decay: float | None = None
    epochs: int | None = None
    seed: int = option(0, help="seed of the initial weights and the batches")

    def __post_init__(self):
        for f in fields(self):  # a setting with choices (dataset, method, ...)
            allowed = option_text(type(self), f.name, "choices", settings_classes())
            if allowed is not None:
                check_choice(f.name, getattr(self, f.name), allowed)
        check_positive_int("steps", self.steps)
        check_positive_int("batch_size", self.batch_size)
        check_choice("optimizer", self.optimizer, OPTIMIZERS)
        if self.epochs is not None:
            check_positive_int("epochs", self.epochs)
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
    # paper §4: "unless otherwise specified, solely CoMA"
    dataset: str = option("coma", help="the dataset trained on", choices=MODEL_DATASETS)
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
    # paper: 1 (the simple loss); > 1 weighs the error in what moves over the error in
    # the static anatomy (diffusion.motion_weighted)
    motion_weight: float = 1.0
    # issue 58 (chapter 03, section 8): the Gaussian part of the estimate over whole
    # sequences, a variance per temporal frequency (models/denoiser.py, prior_length);
    # False: frames independent, as every denoiser shipped before it
    temporal_prior: bool = True
    # our option: probability that a training sequence is mirrored left to right
    mirror: float = 0.0
    # our choice: training faces of these datasets (9 + 81)
    anatomy_pool: tuple = ("coma", "bu")
    # our choice: probability that a sequence gets another anatomy
    anatomy_swap: float = 0.5
    # True: label-conditional, for classifier-free guidance (Ho & Salimans 2022)
    conditional: bool = option(
        False,
        help=(
            "denoiser: label-conditional, for classifier-free guidance (labels dropped"
            " with probability condition_dropout; checkpoint denoiser_<dataset>_cfg)"
        ),
    )
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
        check_probability("known_frames", self.known_frames)
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
        check_probability("anatomy_swap", self.anatomy_swap)
        if self.temporal_prior and not isinstance(self.num_frames, int):
            raise ValueError(
                "temporal_prior fits the Gaussian to sequences of one length: train on"
                f" one length (num_frames an int), not on lengths {self.num_frames},"
                " or set temporal_prior=False (a Gaussian per frame)"
            )
        check_probability(
            "condition_dropout", self.condition_dropout, include_one=False
        )
        check_probability("mirror", self.mirror)
        check_number("motion_weight", self.motion_weight, low=0.01)
        if self.motion_weight != 1 and self.schedule == "flow":
            raise ValueError("motion_weight weighs the DDPM's loss, not the flow's")
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
    classifier_type: str = option(
        "I",
        help="guide, evaluator: I = label, S = label x N2E/E2N",
        choices=CLASSIFIER_TYPES,
        flag="--type",
    )
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
        check_positive_int("teacher_steps", self.teacher_steps)
        if self.teacher_steps % 2 or self.teacher_steps > NUM_DIFFUSION_STEPS:
            raise ValueError(
                "teacher_steps must be even and at most T ="
                f" {NUM_DIFFUSION_STEPS}: the student takes every other step, got"
                f" {self.teacher_steps}"
            )
        check_choice("weighting", self.weighting, DISTILLATION_WEIGHTINGS)
        check_number("guidance_scale", self.guidance_scale, allow_none=True)

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
    # "lstm": the IC of §5; "cnn": the second reader of the coverage protocol (issue
    # 58), a temporal CNN of ``hidden`` channels (models.classifier)
    architecture: str = option(
        "lstm",
        help="evaluator: the IC's LSTM (§5) or the second reader's temporal CNN",
        choices=ARCHITECTURES,
    )
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
    method: str = option(
        "ours", help="deformer: a row of Table 5", choices=tuple(DEFORMATION_METHODS)
    )
    split: str = option(
        "identity",
        help="deformer: 3 subjects or 3 expressions held out, as §6",
        choices=DEFORMATION_SPLITS,
    )
    frames_per_batch: int = 4
    frames_per_sequence: int = 10  # frames kept per training sequence
    max_sequences: int | None = None  # fast mode: a subset of the training sequences

    def fast(self):
        return replace(self, steps=20, max_sequences=16, frames_per_sequence=4)


def settings_classes():
    """Every recipe's settings class of this module, in the order they are written."""
    return [
        c
        for c in globals().values()
        if isinstance(c, type) and is_dataclass(c) and c.__module__ == __name__
    ]
