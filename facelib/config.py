"""The book's paths, its synthetic world and datasets, and the constants that several
modules read (guidance weights and rates, samplers, frame rates, units).

The settings of each task and each model live beside the code that reads them:
facelib/tasks/settings.py (sampling tasks), facelib/training/settings.py (training
recipes), facelib/registration.py (a reader's mesh).  Each value carries its source:
the paper section, or "our choice" with the reason.
``FACELIB_FAST=1`` (set by ``make test``) selects the fast-mode values so that every
notebook executes in seconds; the default ("book") mode uses the full values.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
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
    # the takes of each (subject, label) are numbered from here: a spec with the seed
    # of another and a first take past its last plays new takes of the same people
    first_take: int = 0


# the style spread of CoMA-like people (the "coma" comment below says why), shared by
# every dataset of more CoMA-like people
COMA_STYLES = dict(
    style_gain_sigma=0.45,
    style_leak_probability=0.9,
    style_leak_max=0.4,
    style_blend_max=0.22,
)

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
        **COMA_STYLES,
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
    # Issue 58: the reference population of the coverage protocol (the evaluation
    # chapter): 50 new people performing CoMA's labels by CoMA's recipes, N2E and E2N
    # once each, never trained on; enough people for an interval over people (the
    # test split holds 3).  All of it is its "test" split.
    "coma_people": DatasetSpec(
        "coma_people",
        "coma",
        num_subjects=50,
        num_sequences=1200,
        num_test_subjects=50,
        takes_per_pair=2,
        seed=3003,
        **COMA_STYLES,
    ),
    # Issue 58: new takes of CoMA's own people (its seed, its styles; takes 5 and 6,
    # past CoMA's last): its train split holds new takes of the people a denoiser
    # learned from, which separates replaying the training sequences from meeting new
    # anatomy (the held-out loss of the denoiser chapter)
    "coma_retakes": DatasetSpec(
        "coma_retakes",
        "coma",
        num_subjects=12,
        num_sequences=288,
        num_test_subjects=3,
        takes_per_pair=2,
        seed=1001,
        **COMA_STYLES,
        first_take=5,
    ),
    # Issue 58's data ablation: 36 more people performing CoMA's labels by CoMA's
    # recipes, 4 takes each as CoMA's people (training only: "coma+crowd" trains on
    # CoMA's 9 training people and these, and keeps CoMA's test split)
    "coma_crowd": DatasetSpec(
        "coma_crowd",
        "coma",
        num_subjects=36,
        num_sequences=1728,
        num_test_subjects=0,
        takes_per_pair=4,
        seed=4004,
        **COMA_STYLES,
    ),
}
# the datasets made to evaluate with, never to train or sample on
EVALUATION_DATASETS = ("coma_people", "coma_retakes")
# the reference population of a dataset's coverage protocol (metrics.population_gap)
REFERENCE_POPULATIONS = {"coma": "coma_people"}
# new takes of a dataset's training people (its train split): replay against anatomy
NEW_TAKES = {"coma": "coma_retakes"}
SPLITS = ("train", "test", "all")


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


# ====================================================================================
# sampling tasks: guidance (paper §3.2, §4) and the book's choices, named once; the
# tasks' settings (facelib/tasks/settings.py) take their defaults from here.
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
# The mean shift's scale for editing (tasks.Edit; our choice): 20, where 3 edits in 4
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


# tau of AU-curve control: log N(c | R(x_t, t), tau^2), in AU intensity units (our
# choice)
AU_CURVE_TOLERANCE = 0.1
# the Adagrad rate of AU-curve control at 50 steps (our choice; the fine-control
# chapter)
AU_CURVE_LR = 0.03
AU_CURVE_REFERENCE_STEPS = 50  # AU_CURVE_LR is chosen for chains of this length
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


# millimetres per unit of a reader's mesh (the chapter "Your own face")
UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
# a mesh of the template's triangles in mm is animated as it is (no registration) when
# the rigid fit onto the template turns it by at most this many degrees and moves its
# centre by at most this many mm: twice the most the world's own identities need (0.78
# degrees, 4.4 mm over identity seeds 0-39, as `python -m facelib neutral` writes them)
CANONICAL_POSE_DEGREES = 1.5
CANONICAL_POSE_SHIFT_MM = 9.0


