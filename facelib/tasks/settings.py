"""The settings of every sampling task: a frozen dataclass per task, the book's best
measured values as its defaults.

A task is called as ``task(what, n, settings, ..., **overrides)`` (facelib/tasks); its
settings' ``paper()`` gives the paper's printed algorithm (``--paper``) and ``fast()`` a
few steps (tests, FACELIB_FAST chapters).  ``steps``: reverse steps of a chain respaced
from the paper's T = 2000 (None: all 2000).  The constants the defaults come from, with
their sources, are in facelib/config.py; the command line's ``sample TASK`` options are
these fields (facelib/cli_sample.py), each with the help and choices written once in
its :func:`option`.
"""

from __future__ import annotations

from dataclasses import dataclass, is_dataclass, replace

from .. import options
from ..checks import (
    check_choice,
    check_flag,
    check_integer,
    check_number,
    check_positive_int,
)
from ..config import (
    ADAGRAD_LR,
    AU_CURVE_LR,
    AU_CURVE_REFERENCE_STEPS,
    AU_CURVE_TOLERANCE,
    CFG_SCALE,
    CONTRASTIVE_GUIDANCE_WEIGHT,
    CONTRASTIVE_LR,
    DECODER_START,
    DETERMINISTIC_SAMPLERS,
    EDIT_MEAN_SHIFT_SCALE,
    GEOMETRY_LR,
    GUIDANCE_METHODS,
    GUIDANCE_WEIGHT,
    HARMONISING_PASSES,
    HEAD_INPUTS,
    JOIN_METHODS,
    KEYFRAME_FEATHER,
    KEYFRAME_METHODS,
    LABEL_GUIDANCE,
    LONG_FPS_RANGE,
    LR_REFERENCE_STEPS,
    MEAN_SHIFT_SCALE,
    NATIVE_FPS,
    NUM_DIFFUSION_STEPS,
    NUM_FRAMES,
    RECONSTRUCTION_SCALE,
    SAMPLERS,
    SELECT_TIME,
    SPACINGS,
    TEXT_DATASET,
    TEXT_GUIDANCE_WEIGHT,
    TEXT_LR,
    TEXT_LR_REFERENCE_STEPS,
    TEXT_SCORES,
)
from ..data import CLASSIFIER_TYPES, MODEL_DATASETS, KIND_NAMES
from ..options import option


def option_text(cls, name, key):
    """The ``key`` ("help" or "choices") of the field ``name`` of the task settings
    ``cls``: its own or its bases', else that of the first task settings class of this
    module that gives one for a field of that name (a field means the same in every
    task); None if none does."""
    return options.option_text(cls, name, key, settings_classes())


def settings_classes():
    """Every settings class of this module, in the order they are written."""
    return [
        c
        for c in globals().values()
        if isinstance(c, type) and is_dataclass(c) and c.__module__ == __name__
    ]


def step_scaled_lr(
    rate, reference_steps, steps=None, num_steps=NUM_DIFFUSION_STEPS, power=0.5
):
    """An Adagrad rate chosen for a chain of ``reference_steps`` reverse steps, for a
    chain of ``steps`` (None: T = ``num_steps``): scaled by (reference_steps / steps) **
    power, so that the guidance moves a sample about as far over the whole chain
    whatever its length (our choice).

    power 0.5: the guided displacements of successive steps add up like a random walk,
    as the square root of the number of steps (label control;
    benchmarks/label_control.py measures it at T = 2000, where the unscaled rate
    overshoots).  power 1: they add up like a drift, linearly (text control:
    benchmarks/text_control.py measures that the square root still overshoots at T =
    2000).
    """
    return rate * float((reference_steps / (steps or num_steps)) ** power)


def adagrad_lr(dataset, steps=None, num_steps=NUM_DIFFUSION_STEPS):
    """The default Adagrad rate of label control (Alg. 1) for a chain of ``steps``
    reverse steps (None: T): ADAGRAD_LR[dataset], chosen at LR_REFERENCE_STEPS, through
    :func:`step_scaled_lr`.
    """
    if dataset not in ADAGRAD_LR:
        raise ValueError(
            f"no default Adagrad learning rate for dataset {dataset!r} (defaults for "
            f"{', '.join(ADAGRAD_LR)}): pass lr="
        )
    return step_scaled_lr(ADAGRAD_LR[dataset], LR_REFERENCE_STEPS, steps, num_steps)


def text_lr(steps=None, num_steps=NUM_DIFFUSION_STEPS, score="cosine"):
    """The default Adagrad rate of text control (Alg. 2) for a chain of ``steps``
    reverse steps (None: T): TEXT_LR (CONTRASTIVE_LR for the contrastive score), chosen
    at TEXT_LR_REFERENCE_STEPS, through :func:`step_scaled_lr` with power 1."""
    if score not in TEXT_SCORES:
        raise ValueError(f"score must be one of {TEXT_SCORES}, got {score!r}")
    rate = CONTRASTIVE_LR if score == "contrastive" else TEXT_LR
    return step_scaled_lr(rate, TEXT_LR_REFERENCE_STEPS, steps, num_steps, power=1.0)


def text_guidance_weight(score="cosine"):
    """The default lambda of text control for a score: TEXT_GUIDANCE_WEIGHT (cosine; not
    the paper's 0.01: the cosine's gradient is small, and Adagrad's steps follow the
    sign of the sum) or CONTRASTIVE_GUIDANCE_WEIGHT (contrastive)."""
    if score not in TEXT_SCORES:
        raise ValueError(f"score must be one of {TEXT_SCORES}, got {score!r}")
    return (
        CONTRASTIVE_GUIDANCE_WEIGHT if score == "contrastive" else TEXT_GUIDANCE_WEIGHT
    )


def check_feather(feather, num_frames):
    """A feather's sigma: a number of frames in 0..num_frames (0: none)."""
    if isinstance(feather, bool) or not isinstance(feather, (int, float)) or not (
        0 <= feather <= num_frames
    ):
        raise ValueError(
            f"feather must be a number of frames in 0..{num_frames} (a Gaussian's"
            f" sigma; 0: none), got {feather!r}"
        )


@dataclass(frozen=True)
class Sampling:
    """What every sampling task shares: the chain's length, the sequences' length, the
    seed."""

    steps: int | None = option(
        None,
        "reverse steps, respaced from T = 2000 ('none': all T)",
    )
    # paper §4: 40 frames
    num_frames: int = option(
        NUM_FRAMES,
        "frames per sequence",
    )
    seed: int = option(
        0,
        "the random seed (one random stream per chain)",
    )
    variance: str | None = option(
        None,
        "the DDPM sampler's sigma_t^2: beta_t (the paper's) or the posterior beta~_t"
        " ('none': the denoiser's own; DDIM's is eta^2 beta~_t)",
        choices=("beta", "posterior"),
    )
    sampler: str = option(
        "ddpm",
        "the reverse step: DDPM's ancestral step (Eq. 5), DDIM's, a distilled"
        " student's (--steps: one it was distilled for) or the rectified flow's Euler"
        " step (chapter 14)",
        choices=SAMPLERS,
    )
    eta: float = option(
        0.0,
        "DDIM's noise, in [0, 1] (0: deterministic)",
    )
    spacing: str = option(
        "uniform",
        "where a chain of K steps puts them: uniform (1, ..., T; the book's) or"
        " trailing (T/K, ..., T; Lin et al. 2024)",
        choices=SPACINGS,
    )

    def __post_init__(self):
        if self.variance is not None:
            check_choice("variance", self.variance, ("beta", "posterior"))
        check_choice("sampler", self.sampler, SAMPLERS)
        check_choice("spacing", self.spacing, SPACINGS)
        check_number("eta", self.eta, high=1)  # 0: deterministic DDIM
        if self.eta and self.sampler != "ddim":
            raise ValueError(
                f"eta = {self.eta} is DDIM's noise: it needs sampler 'ddim' (the"
                f" sampler is {self.sampler!r})"
            )
        if self.steps is not None:
            check_positive_int("steps", self.steps)
        check_positive_int("num_frames", self.num_frames)
        check_integer("seed", self.seed, 0, 2**32 - 1)

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

    def resolved(self, num_steps=NUM_DIFFUSION_STEPS):
        """The settings the run uses: every rate or weight left None replaced by its
        default for this chain (``steps`` respaced from ``num_steps``, the T its
        guidance network was trained on).  The command line records these; a task
        resolves its settings here once, so both use the same values."""
        return self

    def fast(self):
        # a student samples on the steps it was distilled for, and only there
        if self.sampler == "student":
            return self
        return replace(self, steps=self.fast_steps)


@dataclass(frozen=True)
class Unconditional(Sampling):
    # results/sampling_respacing.json: 500 steps change none of the denoiser's measures
    steps: int | None = 500
    # the denoiser denoiser_<dataset>
    dataset: str = option(
        "coma",
        "the data the networks were trained on",
        choices=MODEL_DATASETS,
    )


@dataclass(frozen=True)
class LabelControl(Sampling):
    """Alg. 1: 3 Adagrad steps per reverse step on lambda log p_theta + log p_phi (or
    the classic mean shift); or, not in the paper, classifier-free guidance of a
    label-conditional denoiser."""

    # the Adagrad rate was chosen at 200 steps (results/label_steps_coma.json)
    steps: int | None = 200
    dataset: str = "coma"
    # the paper's; "cfg": classifier-free (the denoiser denoiser_<dataset>_cfg)
    guidance: str = option(
        "classifier",
        "classifier: a noisy classifier steers the unconditional denoiser (the"
        " paper's); cfg: classifier-free guidance of the label-conditional denoiser"
        " denoiser_<dataset>_cfg",
        choices=LABEL_GUIDANCE,
    )
    # paper §5.1: type I (label) for Alg. 1
    classifier_type: str = option(
        "I",
        "the guidance classifier's type: I = label (Alg. 1), S = label x N2E/E2N",
        choices=CLASSIFIER_TYPES,
    )
    method: str | None = option(
        None,
        "classifier guidance by adagrad (Alg. 1's steps) or mean_shift ('none':"
        " adagrad with the ddpm sampler, mean_shift with ddim)",
        choices=GUIDANCE_METHODS,
    )
    guidance_weight: float = option(
        GUIDANCE_WEIGHT,
        "lambda of Alg. 1-2, the weight of log p_theta",
    )
    lr: float | None = option(
        None,
        "Adagrad learning rate of the guidance ('none': the book's choice for the"
        " dataset and the steps)",
    )
    scale: float | None = option(
        None,
        "the mean shift's gradient scale s, or CFG's weight w >= 0 ('none': the book's"
        " choice)",
    )
    # a class constant, not a field (Edit has its own)
    default_mean_shift_scale = MEAN_SHIFT_SCALE

    def __post_init__(self):
        super().__post_init__()
        check_choice("guidance", self.guidance, LABEL_GUIDANCE)
        if self.method is not None:
            check_choice("method", self.method, GUIDANCE_METHODS)
        check_number("the guidance weight (lambda)", self.guidance_weight)
        check_number("lr", self.lr, allow_none=True)
        check_number("scale", self.scale, allow_none=True)

    def resolved(self, num_steps=NUM_DIFFUSION_STEPS):
        # classifier-free guidance has no classifier, no Adagrad rate
        if self.guidance == "cfg" or self.lr is not None:
            return self
        return replace(self, lr=adagrad_lr(self.dataset, self.steps, num_steps))

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
    refine: int = option(
        2,
        "fixed-point iterations per inversion step (0: the plain DDIM inversion)",
    )
    # frames returned as given, 0-based ranges: the neutral frame of an N2E sequence,
    # which an edit would otherwise move (issue 42: 2.45 mm on a test sequence); None:
    # every frame regenerated
    keep: str | None = option(
        "0:1",
        "frames kept as given, as 0-based ranges ('0:1': the neutral frame of an N2E"
        " sequence; 'none': every frame is regenerated)",
    )
    default_mean_shift_scale = EDIT_MEAN_SHIFT_SCALE

    def __post_init__(self):
        super().__post_init__()
        check_integer(
            "refine", self.refine, 0, what="a number of fixed-point iterations"
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
    score: str = option(
        "cosine",
        "what Alg. 2 climbs: the cosine of Eq. 10 or the text head's log-probability"
        " of the text among the training descriptions",
        choices=TEXT_SCORES,
    )
    # Alg. 2 (x0_hat: not in the paper)
    head_input: str = option(
        "x_t",
        "what the head reads: x_t (Alg. 2) or the denoiser's estimate x0_hat",
        choices=HEAD_INPUTS,
    )
    vocabulary: bool = option(
        False,
        "with --score contrastive: match the text against every description known,"
        " also those no network has seen",
    )
    guidance_weight: float | None = option(
        None,
        "lambda of Alg. 2, the weight of log p_theta ('none': the book's choice for"
        " the score)",
    )
    lr: float | None = None
    # best-of-K: K guided chains per sequence until SELECT_TIME (1: Alg. 2 as written)
    particles: int = option(
        1,
        "best-of-K: K guided chains per sequence, the head keeps one at the time label"
        " --select-time",
    )
    select_time: float = option(
        SELECT_TIME,
        "the time label where best-of-K picks",
    )
    max_time: float | None = option(
        None,
        "leave the steps above this time label unguided ('none': guide every step)",
    )

    def __post_init__(self):
        super().__post_init__()
        check_choice("score", self.score, TEXT_SCORES)
        check_choice("head_input", self.head_input, HEAD_INPUTS)
        if self.score == "contrastive" and self.head_input != "x_t":
            raise ValueError(
                "the contrastive score reads x_t: use head_input='x_t' with"
                " score='contrastive'"
            )
        check_flag("vocabulary", self.vocabulary)
        if self.vocabulary and self.score != "contrastive":
            raise ValueError(
                "the vocabulary is matched by the contrastive score: use"
                " vocabulary=True with score='contrastive'"
            )
        check_positive_int("particles", self.particles)
        check_number("select_time", self.select_time, low=1)
        for name in ("guidance_weight", "lr", "max_time"):
            check_number(name, getattr(self, name), allow_none=True)

    def resolved(self, num_steps=NUM_DIFFUSION_STEPS):
        weight, lr = self.guidance_weight, self.lr
        return replace(
            self,
            guidance_weight=(
                text_guidance_weight(self.score) if weight is None else weight
            ),
            lr=text_lr(self.steps, num_steps, self.score) if lr is None else lr,
        )

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
    method: str = option(
        "adagrad",
        "adagrad (Alg. 1's steps) or mean_shift",
    )
    guidance_weight: float = GUIDANCE_WEIGHT  # lambda (Alg. 1's)
    lr: float | None = option(
        None,
        "Adagrad learning rate ('none': the book's choice for the steps)",
    )
    scale: float = option(
        MEAN_SHIFT_SCALE,
        "the mean shift's gradient scale s",
    )
    tolerance: float = option(
        AU_CURVE_TOLERANCE,
        "tau of log N(curve | R(x, t), tau^2), in intensity units",
    )
    read: str = option(
        "x0_hat",
        "what the AU regressor reads: x0_hat, the denoiser's estimate, or x_t",
        choices=HEAD_INPUTS,
    )
    reconstruction_scale: float = option(
        RECONSTRUCTION_SCALE,
        "reconstruction guidance zeta (0: none)",
    )
    # the weight of log N(c | R, tau^2); 0: "AU guidance off" (tasks.au.AU_GUIDANCE_OFF)
    au_weight: float = option(
        1.0,
        "the weight of the AU score (0: AU guidance off)",
    )

    def __post_init__(self):
        super().__post_init__()
        check_choice("method", self.method, GUIDANCE_METHODS)
        check_choice("read", self.read, HEAD_INPUTS)
        check_number("the AU score's weight", self.au_weight)
        check_number("the reconstruction guidance scale", self.reconstruction_scale)
        check_number("the guidance weight (lambda)", self.guidance_weight)
        check_number("lr", self.lr, allow_none=True)
        check_number("scale", self.scale)
        check_number("tolerance", self.tolerance, low=1e-6)

    def resolved(self, num_steps=NUM_DIFFUSION_STEPS):
        if self.method != "adagrad" or self.lr is not None:
            return self
        lr = step_scaled_lr(
            AU_CURVE_LR, AU_CURVE_REFERENCE_STEPS, self.steps, num_steps
        )
        return replace(self, lr=lr)


@dataclass(frozen=True)
class DecoderThenDiffusion(Sampling):
    """Not in the paper: the MotionCLIP-style decoder's sequence, re-noised to ``start``
    and denoised (SDEdit)."""

    # the text-control chapter measures it on the chain of text control
    steps: int | None = 100
    dataset: str = TEXT_DATASET
    start: int = option(
        DECODER_START,
        "the step of the paper's chain the decoder's sequence is re-noised to",
    )

    def __post_init__(self):
        super().__post_init__()
        check_integer(
            "start", self.start, 1, what="a step of the paper's chain, an integer"
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
    resample: int = option(
        1,
        "RePaint's resampling r (1: none)",
    )

    def __post_init__(self):
        super().__post_init__()
        check_number("the reconstruction guidance scale", self.reconstruction_scale)
        check_positive_int("resample", self.resample)

    def paper(self):
        # Alg. 3 as printed
        return replace(super().paper(), reconstruction_scale=0.0, resample=1)


@dataclass(frozen=True)
class Keyframes(Sampling):
    """Landmark keyframes (not in the paper; the fine-control chapter): chosen landmarks
    at chosen frames. "replace": Alg. 3 on coordinates (the constrained landmarks
    re-drawn from q(x_{t-1} | x_0)); "reconstruction": reconstruction guidance on them;
    "both": the two together, as OmniControl's spatial guidance with inpainting."""

    steps: int | None = 100  # the filling chapter's chain (Fill)
    variance: str | None = "posterior"
    dataset: str = "coma"
    method: str = option(
        "both",
        "replace (Alg. 3 on coordinates), reconstruction (guidance) or both",
        choices=KEYFRAME_METHODS,
    )
    reconstruction_scale: float = RECONSTRUCTION_SCALE
    # the keyed landmark's other frames shifted by the key's gap to the model's estimate
    # (frames, sigma; 0: Alg. 3 as printed; inpainting.KnownFrames)
    feather: float = option(
        KEYFRAME_FEATHER,
        "shift the frames next to the known ones by the known ones' gap to the model's"
        " estimate, a Gaussian's sigma in frames (0: Alg. 3 as printed)",
    )

    def __post_init__(self):
        super().__post_init__()
        check_choice("method", self.method, KEYFRAME_METHODS)
        check_number("the reconstruction guidance scale", self.reconstruction_scale)
        check_feather(self.feather, self.num_frames)

    def paper(self):
        # replacement as Alg. 3 prints it
        return replace(super().paper(), feather=0.0)


@dataclass(frozen=True)
class Long(Sampling):
    """Sequences of any length (not in the paper): windows of the model's length, each
    overlapping the one before by ``transition`` frames, joined by ``join``
    (JOIN_METHODS); a label's windows are guided by Alg. 1, a text's by Alg. 2, a
    neutral segment's end at the given face."""

    steps: int | None = 100  # the filling chapter's chain (Fill)
    variance: str | None = "posterior"
    dataset: str = "coma"
    join: str = option(
        "fill",
        "how windows join: fill (the shared frames known, with reconstruction"
        " guidance), replace (Alg. 3 as printed), handshake (DoubleTake: all windows"
        " at once, shared frames averaged), concat (independent windows), learned"
        " (fill by a join denoiser, which reads the known frames)",
        choices=JOIN_METHODS,
    )
    transition: int = option(
        10,
        "frames each window shares with the one before (at the native rate)",
    )
    fps: int = option(
        NATIVE_FPS,
        "frames per second written",
    )
    reconstruction_scale: float = RECONSTRUCTION_SCALE
    guidance_weight: float = GUIDANCE_WEIGHT
    lr: float | None = None
    # a label segment's first window sets out from where the stream is: guided by the
    # type-S classifier as this order, at this rate (None: type I, as its other windows)
    opening: str | None = option(
        "N2E",
        "a label segment's first window is guided by the type-S classifier as this"
        " order ('none': by the type-I classifier, as the segment's other windows)",
        choices=KIND_NAMES,
    )
    opening_lr: float = option(
        GEOMETRY_LR,
        "Adagrad learning rate of a segment's first window",
    )
    # a segment's later windows guided by the type-I classifier too (False: they
    # continue what the first set out, unguided; guided again, a label escalates: an
    # open mouth opens further in every window, chapter 15)
    guide_continuation: bool = option(
        False,
        "guide a segment's later windows by the type-I classifier too (default: they"
        " continue unguided)",
    )
    # the new frames next to the known ones shifted by their gap to the model's estimate
    # (frames, sigma; 0: none; inpainting.KnownFrames; it does not remove the joins'
    # kink, chapter 15)
    feather: float = 0.0
    # a schedule with a text ("'a broad grin':2s") runs on the text head's data: its
    # denoiser, and Alg. 2 for every segment, a label read as its raw text (no label
    # classifier is trained on it)
    text_dataset: str = option(
        TEXT_DATASET,
        "the data of a schedule with a text: its denoiser and text head (labels read"
        " as their raw text)",
    )
    # a text segment's first window guided by its text said in this order ("from the
    # neutral face to ..."; None: as written, which shows the text more often, chapter
    # 15)
    text_opening: str | None = option(
        None,
        "a text segment's first window guided by its text said in this order ('from"
        " the neutral face to ...'; 'none': as written)",
        choices=KIND_NAMES,
    )
    text_guidance_weight: float | None = option(
        None,
        "lambda of Alg. 2 for a schedule's texts ('none': text control's)",
    )
    text_lr: float | None = option(
        None,
        "Adagrad learning rate of a schedule's texts ('none': text control's for the"
        " steps)",
    )

    def __post_init__(self):
        super().__post_init__()
        check_choice("join", self.join, JOIN_METHODS)
        check_feather(self.feather, self.num_frames)
        if self.feather and self.join == "handshake":
            raise ValueError(
                "feather spreads the replacement of known frames (joins fill, replace,"
                " concat, learned); the handshake averages its windows: give feather 0"
            )
        if self.opening is not None:
            check_choice("opening", self.opening, ("N2E", "E2N"))
        if self.text_opening is not None:
            check_choice("text_opening", self.text_opening, ("N2E", "E2N"))
        check_number("opening_lr", self.opening_lr)
        check_number("the reconstruction guidance scale", self.reconstruction_scale)
        check_number("the guidance weight (lambda)", self.guidance_weight)
        check_number("lr", self.lr, allow_none=True)
        check_number(
            "the text guidance weight", self.text_guidance_weight, allow_none=True
        )
        check_number("text_lr", self.text_lr, allow_none=True)
        check_integer("fps", self.fps, *LONG_FPS_RANGE)
        check_integer(
            "transition",
            self.transition,
            1,
            self.num_frames // 2,
            what=f"a number of frames (at most half a window of {self.num_frames})",
        )

    def resolved(self, num_steps=NUM_DIFFUSION_STEPS):
        # the label windows' rate (Alg. 1), the text windows' lambda and rate (Alg. 2)
        lr, weight, text_rate = self.lr, self.text_guidance_weight, self.text_lr
        return replace(
            self,
            lr=adagrad_lr(self.dataset, self.steps, num_steps) if lr is None else lr,
            text_guidance_weight=text_guidance_weight() if weight is None else weight,
            text_lr=text_lr(self.steps, num_steps) if text_rate is None else text_rate,
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
    order: str | None = option(
        None,
        "neutral face first (N2E) or last (E2N) ('none': N2E unless the label says)",
        choices=KIND_NAMES,
    )
    # the geometry-adaptive chapter: the harmonising passes of Alg. 4 add nothing
    # measurable
    passes: int = option(
        1,
        "harmonising passes of Alg. 4",
    )
    renoise_step: int | None = option(
        None,
        "the step a pass after the first re-noises to ('none': T, as Alg. 4)",
    )
    resample: int = 1  # RePaint's r within each pass (1: Alg. 4 as written)
    # the sweep of zeta (geometry-adaptive chapter)
    reconstruction_scale: float = RECONSTRUCTION_SCALE
    guidance_weight: float = GUIDANCE_WEIGHT
    lr: float = option(
        GEOMETRY_LR,
        "Adagrad learning rate of the guidance",
    )

    def __post_init__(self):
        super().__post_init__()
        check_positive_int("passes", self.passes)
        check_positive_int("resample", self.resample)
        if self.renoise_step is not None:
            check_integer(
                "renoise_step",
                self.renoise_step,
                1,
                NUM_DIFFUSION_STEPS,
                what="a step of the paper's chain or None (T)",
            )
        check_number("the reconstruction guidance scale", self.reconstruction_scale)
        check_number("the guidance weight (lambda)", self.guidance_weight)
        check_number("lr", self.lr)

    def paper(self):
        return replace(
            super().paper(),
            passes=HARMONISING_PASSES,
            reconstruction_scale=0.0,
            resample=1,
        )

    fast_steps = 10
