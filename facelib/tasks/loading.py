"""Loading what the tasks sample with: a trained denoiser with its normaliser and
diffusion, and the guidance networks (classifiers of Alg. 1 and 4, the text head of Alg.
2), each checked against its data.
"""

from __future__ import annotations

import dataclasses

from dataclasses import dataclass

import numpy as np
import torch

from .. import data
from ..checkpoints import checkpoint_name, load_checkpoint
from ..config import (
    CHECKPOINT_DIR,
    NUM_LANDMARKS,
    SAMPLERS,
    SPACINGS,
    TEXT_DATASET,
)
from ..data import LandmarkNormalizer
from ..diffusion import (
    GaussianDiffusion,
    NoiseLevelMatched,
    halving_steps,
    named_alphas_bar,
    named_betas,
)
from ..face.sequences import check_num_frames
from ..face.aus import AU_NAMES
from ..models.au_regressor import AURegressor, AURegressorConfig
from ..models.denoiser import Denoiser, DenoiserConfig
from ..models.noisy_classifier import (
    NoisyClassifier,
    NoisyClassifierConfig,
    NoisyTextHead,
    TextHeadConfig,
)
from ..text import EMBEDDING_DIM, MODEL_NAME
from ..checks import with_overrides


@dataclass
class TrainedDenoiser:
    """A trained eps_theta with everything needed to sample from it."""

    model: Denoiser
    normalizer: LandmarkNormalizer
    diffusion: GaussianDiffusion
    meta: dict

    @property
    def device(self):
        return next(self.model.parameters()).device

    def to_model(self, landmarks):
        """Landmarks in mm (numpy, any leading shape) as a normalised tensor on the
        model's device."""
        return torch.as_tensor(self.normalizer.normalize(landmarks)).to(self.device)

    def to_mm(self, x):
        """Normalised sequences (a tensor on any device) as numpy float32 in mm."""
        return self.normalizer.denormalize(x.detach().cpu()).numpy()

    def class_indices(self, labels):
        """The label indices of a label-conditional denoiser (classifier-free guidance)
        for label names."""
        names = self.meta.get("class_names")
        if not self.model.config.num_classes or not names:
            raise ValueError(
                "classifier-free guidance needs a label-conditional denoiser (train"
                " one with training.DenoiserTraining(conditional=True):"
                f" denoiser_<dataset>_cfg); {self.meta.get('name', 'this checkpoint')}"
                " is unconditional"
            )
        bad = [y for y in labels if y not in names]
        if bad:
            raise ValueError(
                f"unknown label {bad[0]!r} for this denoiser; allowed:"
                f" {', '.join(names)}"
            )
        return [names.index(y) for y in labels]

    def diffusion_with(self, steps=None, variance=None, eta=None, spacing="uniform"):
        """The full T-step diffusion (steps=None) or a respaced one with ``steps``
        steps, placed by ``spacing`` ("uniform": steps 1 and T and evenly between, as
        Nichol & Dhariwal; "trailing": T/K, 2T/K, ..., T, Lin et al. 2024; the flow's
        are always trailing, its Euler grid); ``variance`` ("beta", "posterior")
        replaces the sampler's sigma_t^2 (None: the denoiser's own); ``eta`` samples by
        DDIM.  A distilled student samples deterministically on the steps it was
        distilled for, and only there.
        """
        if spacing not in SPACINGS:
            raise ValueError(
                f"unknown spacing {spacing!r}; allowed: {', '.join(SPACINGS)}"
            )
        student_steps = self.meta.get("training", {}).get("sampler_steps")
        if student_steps is not None:
            if steps not in (None, len(student_steps)) or eta not in (None, 0):
                raise ValueError(
                    f"{self.meta.get('name', 'this checkpoint')} is a distilled student"
                    f" of {len(student_steps)} deterministic steps: sample it with"
                    f" steps={len(student_steps)} (or None) and eta 0 (or None), not"
                    f" steps={steps}, eta={eta}"
                )
            return self.diffusion.respace(student_steps).with_eta(0.0)
        diffusion = self.diffusion
        if variance is not None and variance != diffusion.variance:
            diffusion = GaussianDiffusion(diffusion.betas[1:], variance)
        if steps is not None and steps != diffusion.num_steps:
            flow = self.model.config.schedule == "flow"
            diffusion = diffusion.respace(
                halving_steps(steps, diffusion.num_steps)[1:]
                if flow or spacing == "trailing"
                else steps
            )
        return diffusion if eta is None else diffusion.with_eta(eta)

    @property
    def samplers(self):
        """The samplers this checkpoint was made for: a distilled student's ("student",
        on its own steps), a rectified flow's ("flow", Euler's steps), any other
        denoiser's ("ddpm", "ddim")."""
        if self.meta.get("training", {}).get("sampler_steps") is not None:
            return ("student",)
        if self.model.config.schedule == "flow":
            return ("flow",)
        return ("ddpm", "ddim")

    def chain_for(self, settings):
        """The chain of a task's settings (Sampling: steps, variance, sampler,
        spacing); a clear error for a sampler this checkpoint was not made for."""
        if settings.sampler not in self.samplers:
            raise ValueError(
                f"{self.meta.get('name', 'this checkpoint')} is sampled by"
                f" {' or '.join(map(repr, self.samplers))}, not by"
                f" {settings.sampler!r} (tasks.denoiser_name names the checkpoint of"
                " each sampler)"
            )
        return self.diffusion_with(
            settings.steps, settings.variance, settings.ddim_eta, settings.spacing
        )


def shipped_students(dataset, variant=None):
    """The step counts K of the distilled students student_denoiser_<dataset>_<K> (of
    denoiser_<dataset>_<variant>: student_denoiser_<dataset>_cfg_<K>, classifier-free
    guidance distilled in) in data/checkpoints, ascending."""
    prefix = f"student_{checkpoint_name('denoiser', dataset, variant)}_"
    return sorted(
        int(path.stem[len(prefix) :])
        for path in CHECKPOINT_DIR.glob(prefix + "*.pt")
        if path.stem[len(prefix) :].isdigit()
    )


def denoiser_name(dataset, sampler="ddpm", steps=None, variant=None):
    """The denoiser checkpoint a sampler runs: denoiser_<dataset>[_<variant>] for DDPM
    and DDIM, the student student_denoiser_<dataset>[_<variant>]_<steps> (distilled for
    exactly these steps), the rectified flow denoiser_<dataset>_flow."""
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r}; allowed: {', '.join(SAMPLERS)}")
    if sampler in ("ddpm", "ddim"):
        return checkpoint_name("denoiser", dataset, variant)
    if sampler == "flow":
        if variant is not None:
            raise ValueError(
                f"the flow sampler has no {variant!r} denoiser: only the unconditional"
                f" denoiser_{dataset}_flow was trained (use classifier guidance, or"
                " sampler 'ddim')"
            )
        return checkpoint_name("denoiser", dataset, "flow")
    teacher = checkpoint_name("denoiser", dataset, variant)
    shipped = shipped_students(dataset, variant)
    if steps not in shipped:
        raise ValueError(
            f"no student of {teacher} distilled for steps={steps}; the shipped"
            f" students take {', '.join(map(str, shipped)) or 'no'} steps (train"
            " another with `python -m facelib train student`)"
        )
    return f"student_{teacher}_{steps}"


def load_denoiser(name="denoiser_coma", variance="beta"):
    """Load a shipped (or retrained) denoiser checkpoint from data/checkpoints (sha256
    checked)."""
    model, meta = load_checkpoint(
        name, "denoiser", lambda c: Denoiser(DenoiserConfig(**c))
    )
    training, c = meta["training"], model.config
    # the sampler runs the recorded schedule; the network converts its output
    # (c.prediction) to eps on its own
    recorded = (
        training["schedule"],
        training["num_diffusion_steps"],
        training.get("prediction", "eps"),
    )
    if recorded != (c.schedule, c.num_diffusion_steps, c.prediction):
        raise ValueError(
            f"checkpoint {name}: its training (schedule, steps, prediction target)"
            f" {recorded} differs from its network's"
            f" {(c.schedule, c.num_diffusion_steps, c.prediction)}: it cannot be"
            " sampled correctly; retrain it"
        )
    diffusion = GaussianDiffusion(
        named_betas(training["schedule"], training["num_diffusion_steps"]), variance
    )
    return TrainedDenoiser(
        model,
        LandmarkNormalizer.from_dict(meta["normalizer"]),
        diffusion,
        {**meta, "name": name},
    )


# one call's sequences: 100000 x 40 frames are 3.3 GB (float32) per copy of x_t, and a
# chain holds several copies; a larger n is a mistake, refused before any memory is
# asked for
MAX_SEQUENCES = 100_000


def check_n(n, name="n"):
    if (
        isinstance(n, bool)
        or not isinstance(n, (int, np.integer))
        or not 1 <= n <= MAX_SEQUENCES
    ):
        raise ValueError(
            f"{name} must be a positive integer (at most {MAX_SEQUENCES}), got {n!r}"
        )


@dataclass
class TrainedGuide:
    """A guidance network with its dataset, type and class names: the classifier p_phi(y
    | x_t, t) of Alg. 1 (type "I" or "S") or the text head BiT(x_t, t) of Alg. 2 (type
    "text"; its class names are the labels whose descriptions it was trained on)."""

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
            raise ValueError(
                f"unknown label {bad[0]!r} for dataset {self.dataset!r}; "
                f"allowed: {', '.join(self.class_names)}"
            )
        return [self.class_names.index(y) for y in labels]


def load_guide(dataset="coma", classifier_type="I", name=None):
    """Load the shipped guidance classifier guide_<dataset>_<type> (sha256 and classes
    checked)."""
    data.check_dataset_name(dataset)
    data.check_classifier_type(classifier_type)
    name = name or checkpoint_name("guide", dataset, classifier_type)
    model, meta = load_checkpoint(
        name, "guide", lambda c: NoisyClassifier(NoisyClassifierConfig(**c))
    )
    names = data.check_class_names(meta["class_names"], dataset, classifier_type, name)
    if meta["training"]["dataset"] != dataset:
        raise ValueError(
            f"checkpoint {name} was trained on {meta['training']['dataset']!r}, not"
            f" {dataset!r}"
        )
    return TrainedGuide(
        model,
        dataset,
        classifier_type,
        names,
        LandmarkNormalizer.from_dict(meta["normalizer"]),
        meta,
    )


def load_text_head(dataset=TEXT_DATASET, name=None):
    """Load the shipped text head guide_<dataset>_text (sha256, labels and text encoder
    checked)."""
    data.check_dataset_name(dataset)
    name = name or checkpoint_name("guide", dataset, "text")
    model, meta = load_checkpoint(
        name, "text_head", lambda c: NoisyTextHead(TextHeadConfig(**c))
    )
    names = data.check_class_names(meta["class_names"], dataset, "I", name)
    if meta["training"]["dataset"] != dataset:
        raise ValueError(
            f"checkpoint {name} was trained on {meta['training']['dataset']!r}, not"
            f" {dataset!r}"
        )
    if (
        meta.get("text_encoder") != MODEL_NAME
        or model.config.embedding_dim != EMBEDDING_DIM
    ):
        raise ValueError(
            f"checkpoint {name} was trained with the text encoder"
            f" {meta.get('text_encoder')!r} ({model.config.embedding_dim}-d), not"
            f" {MODEL_NAME!r} ({EMBEDDING_DIM}-d)"
        )
    return TrainedGuide(
        model,
        dataset,
        "text",
        names,
        LandmarkNormalizer.from_dict(meta["normalizer"]),
        meta,
    )


def load_au_regressor(dataset="coma", name=None):
    """Load the shipped AU regressor au_regressor_<dataset> (R(x_t, t) of AU-curve
    control; sha256 and its AUs checked), as a guidance network whose "classes" are the
    world's AU names."""
    data.check_dataset_name(dataset)
    name = name or checkpoint_name("au_regressor", dataset)
    model, meta = load_checkpoint(
        name, "au_regressor", lambda c: AURegressor(AURegressorConfig(**c))
    )
    if model.config.num_aus != len(AU_NAMES):
        raise ValueError(
            f"checkpoint {name} regresses {model.config.num_aus} AUs; the world has"
            f" {len(AU_NAMES)}"
        )
    if meta["training"]["dataset"] != dataset:
        raise ValueError(
            f"checkpoint {name} was trained on {meta['training']['dataset']!r}, not"
            f" {dataset!r}"
        )
    return TrainedGuide(
        model,
        dataset,
        "au",
        AU_NAMES,
        LandmarkNormalizer.from_dict(meta["normalizer"]),
        meta,
    )


def check_same_space(denoiser, guide):
    """The classifier must read x_t in the denoiser's normalised space (its schedule
    may differ: :func:`guided_chain` matches the noise levels)."""
    a, b = denoiser.normalizer, guide.normalizer
    if abs(a.scale - b.scale) > 1e-6 * a.scale or not np.allclose(
        a.mean_shape, b.mean_shape, atol=1e-4
    ):
        raise ValueError(
            f"guidance classifier ({guide.dataset}) and denoiser"
            f" ({denoiser.meta['training']['dataset']}) normalise landmarks"
            " differently: train them on the same dataset"
        )


def schedule_of(trained):
    """(T, noise schedule) a trained network reads x_t on (its recorded training)."""
    training = trained.meta["training"]
    return training["num_diffusion_steps"], training.get("schedule", "linear")


def guided_chain(guide, denoiser, settings):
    """The denoiser of the guide's dataset (or the given one, checked to share the
    guide's space), its chain for the task's settings (steps, variance, sampler), and
    the guide reading that chain's noise levels: unchanged on its own schedule, else its
    network NoiseLevelMatched (the same time label is another noise level on another
    schedule: the rectified flow's, chapter 14)."""
    denoiser = denoiser or load_denoiser(
        denoiser_name(guide.dataset, settings.sampler, settings.steps)
    )
    check_same_space(denoiser, guide)
    guide.model.to(denoiser.device)
    own, chain = schedule_of(guide), schedule_of(denoiser)
    if own != chain:
        matched = NoiseLevelMatched(
            guide.model,
            named_alphas_bar(own[1], own[0]),
            named_alphas_bar(chain[1], chain[0]),
        )
        guide = dataclasses.replace(guide, model=matched)
    return (
        denoiser,
        denoiser.chain_for(settings),
        guide,
    )


def task_settings(settings, overrides, n):
    """The settings of a call (its defaults with the overrides given) and its checked
    shape (n, F, 68, 3)."""
    if not dataclasses.is_dataclass(settings) or isinstance(settings, type):
        raise TypeError(
            "settings must be a task's settings (a facelib.config dataclass instance),"
            f" got {type(settings).__name__}: {settings!r}; give single fields by"
            " keyword, e.g. keep='0:1'"
        )
    settings = with_overrides(settings, overrides)
    check_n(n)
    return settings, (n, check_num_frames(settings.num_frames), NUM_LANDMARKS, 3)
