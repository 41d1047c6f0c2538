"""One recipe per trained model: its settings (training/settings.py), its data, its
model and the loss of a batch.

A recipe is what :func:`facelib.training.loop.fit` needs: ``name``, ``settings``,
``size`` (number of training examples), ``build(generator)`` (a fresh model,
data-dependent buffers fitted), ``objectives(model)`` (the losses to optimise and the
modules they train, all of which a training state saves; one, except for the GAN),
``model_config(model)`` and ``metadata(model)`` (what its checkpoint records besides the
weights).  Every random draw of a loss goes through the step's
:class:`~facelib.training.loop.Draws`, so that distributed training sees the draws of
one process.
"""

from __future__ import annotations

from dataclasses import asdict, fields, replace
from pathlib import Path

import numpy as np
import torch
from torch import nn

from .. import config, data, deformation, srvf
from ..face import Face, aus, get_template, sample_identity
from ..checkpoints import checkpoint_name
from ..diffusion import GaussianDiffusion, ddim_step, halving_steps, named_betas
from ..flow import RectifiedFlow
from ..inpainting import FILL_SETTINGS, fill_masks
from ..models import actor, lstm_filler, motion3dgan, motionclip
from ..models.au_regressor import AURegressor, AURegressorConfig
from ..models.classifier import classifier_from_config
from ..models.denoiser import Denoiser, DenoiserConfig
from ..models.deformer import deformation_loss
from ..models.noisy_classifier import (
    NoisyClassifier,
    NoisyClassifierConfig,
    NoisyTextHead,
    TextHeadConfig,
)
from ..tasks import load_denoiser
from ..text import MODEL_NAME, description_embeddings, get_encoder
from .loop import Draws, Objective
from .settings import (
    AURegressorTraining,
    ActorTraining,
    DeformationTraining,
    DenoiserTraining,
    DistillationTraining,
    EvaluatorTraining,
    GuideTraining,
    LSTMFillerTraining,
    Motion3DGANTraining,
    MotionClipTraining,
    TextHeadTraining,
)


class Recipe:
    """The parts every recipe shares: one objective, the model's own loss, metadata from
    the settings."""

    name = "model"
    kind = "model"  # the checkpoint kind
    # False: its draws are not per example, so it trains on one process only
    distributed = True
    device = torch.device("cpu")  # the training device (Recipe.to)

    def objectives(self, model):
        return [Objective(model, lambda draws: self.loss(model, draws))]

    def to(self, device):
        """Move the recipe's data (tensors, lists of tensors) and helper networks to the
        training device."""
        self.device = device
        for name, value in list(vars(self).items()):
            if isinstance(value, (torch.Tensor, nn.Module)):
                setattr(self, name, value.to(device))
            elif (
                isinstance(value, list)
                and value
                and all(isinstance(v, torch.Tensor) for v in value)
            ):
                setattr(self, name, [v.to(device) for v in value])
        return self

    def model_config(self, model):
        return asdict(model.config)

    def metadata(self, model):
        return {"training": asdict(self.settings), "torch_version": torch.__version__}

    def checkpoint_name(self):
        return f"{self.kind}_{self.settings.dataset}"


# --------------------------------------------------------------------------- the DDPM
# the pool entry "world": this many new identities drawn from the world's identity
# model (face.sample_identity, seeds [WORLD_ANATOMY_SEED, k]), in no dataset
WORLD_ANATOMIES = 500
WORLD_ANATOMY_SEED = 5005


def training_anatomies(datasets):
    """Neutral landmarks (K, 68, 3) in mm of every training subject of the given
    datasets ("world": WORLD_ANATOMIES identities of no dataset)."""
    return np.concatenate(
        [
            world_anatomies()
            if name == "world"
            else data.load_dataset(name, "train").subject_neutrals()
            for name in datasets
        ]
    )


def world_anatomies():
    """Neutral landmarks (WORLD_ANATOMIES, 68, 3) in mm of new identities of the
    world."""
    zero = np.zeros(aus.NUM_AUS)
    return np.stack(
        [
            Face(sample_identity(np.random.default_rng([WORLD_ANATOMY_SEED, k])))
            .landmarks(zero)
            .astype(np.float32)
            for k in range(WORLD_ANATOMIES)
        ]
    )


def swap_anatomy(x, own, pool, swap, draws):
    """Anatomy augmentation (our addition): x (B, F, 68, 3) minus each sequence's own
    neutral frame ``own`` (B, 68, 3), plus a random neutral frame of ``pool`` (K, 68,
    3), with probability ``swap``.

    CoMA-like data has only 9 training faces, so a DDPM trained on it alone can only
    draw those 9 anatomies; the motion is kept, the anatomy is new.  Only training
    splits enter the pool.
    """
    other = pool[draws.randint(0, len(pool))]
    keep = draws.rand() >= swap
    shift = torch.where(keep[:, None, None], torch.zeros_like(own), other - own)
    return x + shift[:, None]


def mirror_faces(x, normalizer, probability, draws):
    """Left-right mirroring (our option): each normalised sequence of x (B, F, 68, 3)
    is, with ``probability``, replaced by its mirror image (x -> -x in mm, the landmarks
    renamed by the template's mirror, iBUG-68 0 <-> 16, 36 <-> 45, 48 <-> 54, ...).  The
    world's faces are symmetric up to a mild identity asymmetry, and its one-sided
    labels (mouth_side, a one-sided smile) go either way, so a mirrored sequence is a
    plausible one of the same label.  No draw is made at probability 0 (the draws of a
    run without mirroring are unchanged).
    """
    if probability == 0:
        return x
    flip = draws.rand() < probability
    order = torch.tensor(get_template().landmark_mirror, device=x.device)
    sign = torch.tensor([-1.0, 1.0, 1.0], device=x.device, dtype=x.dtype)
    mirrored = normalizer.normalize(normalizer.denormalize(x)[:, :, order] * sign)
    return torch.where(flip[:, None, None, None], mirrored, x)


# paper steps t, a quarter of T each
HELD_OUT_BUCKETS = ((1, 500), (501, 1000), (1001, 1500), (1501, 2000))
# at most this many test sequences: a held-out curve costs a few forward passes
HELD_OUT_SEQUENCES = 256


class DenoiserRecipe(Recipe):
    """eps_theta trained with the simple loss of Eq. 8 on anatomy-augmented sequences
    (or, by its settings, another prediction target, min-SNR-gamma weighting, left-right
    mirroring; or, with the schedule "flow", the same network as a rectified flow: the
    velocity loss of facelib/flow.py at tau ~ U(0, 1))."""

    kind = "denoiser"

    def __init__(self, settings=DenoiserTraining(), model_config=None):
        self.settings = settings
        train = data.load_dataset(
            settings.dataset, "train", num_frames=settings.num_frames
        )
        self.architecture = model_config or DenoiserConfig(
            num_diffusion_steps=settings.num_diffusion_steps,
            schedule=settings.schedule,
            prediction=settings.prediction,
            num_classes=len(train.label_names) * settings.conditional,
            known_input=settings.known_frames > 0,
            prior_length=settings.num_frames if settings.temporal_prior else 0,
        )
        a = self.architecture
        if (a.num_diffusion_steps, a.schedule, a.prediction) != (
            settings.num_diffusion_steps,
            settings.schedule,
            settings.prediction,
        ):
            raise ValueError(
                "the denoiser's schedule and prediction target must match the training"
                " settings'"
            )
        if a.prior_length != (settings.num_frames if settings.temporal_prior else 0):
            raise ValueError(
                f"the denoiser's prior_length ({a.prior_length}) must be the training"
                " settings' num_frames with temporal_prior, 0 without (temporal_prior ="
                f" {settings.temporal_prior}, num_frames = {settings.num_frames})"
            )
        self.name = f"denoiser ({settings.dataset})"
        self.variable = not isinstance(settings.num_frames, int)
        self.labels, self.label_names = torch.as_tensor(train.labels), list(
            train.label_names
        )
        self.normalizer = data.LandmarkNormalizer.fit(train)
        self.lengths = train.lengths
        x = torch.as_tensor(self.normalizer.normalize(train.landmarks))
        self.mask_all = (
            torch.arange(x.shape[1])[None, :] < torch.as_tensor(train.lengths)[:, None]
        )
        self.x_all = x * self.mask_all[:, :, None, None]
        self.own = torch.as_tensor(train.sequence_neutrals()) / self.normalizer.scale
        pool = (
            training_anatomies(settings.anatomy_pool)
            if settings.anatomy_swap > 0
            else np.zeros((1, config.NUM_LANDMARKS, 3))
        )
        self.pool = (torch.as_tensor(pool) / self.normalizer.scale).float()
        self.size = len(self.x_all)
        self.flow = settings.schedule == "flow"
        self.diffusion = (
            RectifiedFlow(settings.num_diffusion_steps)
            if self.flow
            else GaussianDiffusion(
                named_betas(settings.schedule, settings.num_diffusion_steps)
            )
        )
        self.held_out = self._held_out_batch(settings)

    def _held_out_batch(self, settings):
        """Fixed draws on the test split for :meth:`validate`: per bucket, each sequence
        at one step of the bucket (scaled to T) with one noise draw, made once from seed
        0 (every run sees the same).
        """
        test = data.load_dataset(
            settings.dataset, "test", num_frames=settings.num_frames
        )
        g = torch.Generator().manual_seed(0)
        keep = (
            torch.randperm(len(test), generator=g)[:HELD_OUT_SEQUENCES]
            .sort()
            .values.numpy()
        )
        x0 = torch.as_tensor(self.normalizer.normalize(test.landmarks[keep]))
        mask = (
            torch.arange(x0.shape[1])[None, :]
            < torch.as_tensor(test.lengths[keep])[:, None]
        )
        x0 = x0 * mask[:, :, None, None]
        scale = settings.num_diffusion_steps / config.NUM_DIFFUSION_STEPS
        buckets = {}
        for low, high in HELD_OUT_BUCKETS:
            lo, hi = max(1, round(low * scale)), max(1, round(high * scale))
            t = torch.randint(lo, hi + 1, (len(x0),), generator=g)
            buckets[f"t {low}-{high}"] = (t, torch.randn(x0.shape, generator=g))
        return x0, mask, buckets

    def _times(self, t):
        """The objective's time argument for steps t (B,): {"t": t}, or the flow's
        {"tau": t / T}."""
        if self.flow:
            return {"tau": t.double() / self.settings.num_diffusion_steps}
        return {"t": t}

    @torch.no_grad()
    def validate(self, model):
        """Eq. 8's loss ||eps - eps_theta(x_t, t)||^2 on held-out (test) sequences per
        noise-level bucket, with the same draws at every call: {"t 1-500": loss, ...}.
        The eps-loss whatever the prediction target, so that runs with different targets
        compare (the training loss of an x0 or v run is weighted otherwise); a flow's
        own velocity loss at tau = t / T.
        """
        x0, mask, buckets = self.held_out
        was_training = model.training
        model.eval()
        losses = {}
        # a conditional denoiser sees no label (its free estimate)
        for name, (t, eps) in buckets.items():
            losses[name] = self.diffusion.training_loss(
                model,
                x0.to(self.device),
                **self._times(t),
                eps=eps.to(self.device),
                mask=mask.to(self.device) if self.variable else None,
            ).item()
        model.train(was_training)
        return losses

    def build(self, generator):
        model = Denoiser(self.architecture)
        # the Gaussian prior of the skip connection sees augmented frames too
        swapped = swap_anatomy(
            self.x_all,
            self.own,
            self.pool,
            self.settings.anatomy_swap,
            Draws(generator, self.size),
        )
        if model.config.prior_length:
            # one length: whole sequences
            model.fit_prior(torch.cat([self.x_all, swapped]))
        else:
            model.fit_prior(
                torch.cat(
                    [
                        seqs[i, :n]
                        for seqs in (self.x_all, swapped)
                        for i, n in enumerate(self.lengths)
                    ]
                )
            )
        if self.settings.start_from is not None:
            self._start_from(model, self.settings.start_from)
        return model

    def _start_from(self, model, name):
        """Fine-tuning: the weights (and Gaussian prior) of checkpoint ``name``, whose
        network must be this one's but for what this one adds (the known frames'
        embedding, which starts at zero)."""
        start = load_denoiser(name).model
        ours, theirs = asdict(model.config), asdict(start.config)
        differ = [k for k in ours if k != "known_input" and ours[k] != theirs.get(k)]
        if differ or (theirs.get("known_input") and not ours["known_input"]):
            hint = (
                f" (set temporal_prior={bool(theirs.get('prior_length'))}, as {name}"
                " was trained)"
                if "prior_length" in differ
                else ""
            )
            raise ValueError(
                f"cannot start from {name}: its network differs from this one's in"
                f" {differ or ['known_input']}{hint}"
            )
        missing, unexpected = model.load_state_dict(start.state_dict(), strict=False)
        if unexpected or any(not k.startswith("known_embedding.") for k in missing):
            raise ValueError(
                f"cannot start from {name}: missing {missing}, unexpected {unexpected}"
            )

    def clean_batch(self, draws):
        """A batch of training sequences as the denoiser sees them: (indices, x_0),
        anatomy-swapped, mirrored, padded frames zero."""
        idx = draws.examples(self.size)
        x0 = swap_anatomy(
            self.x_all[idx], self.own[idx], self.pool, self.settings.anatomy_swap, draws
        )
        x0 = mirror_faces(x0, self.normalizer, self.settings.mirror, draws)
        return idx, x0 * self.mask_all[idx][:, :, None, None]

    def loss(self, model, draws):
        idx, x0 = self.clean_batch(draws)
        if self.flow:
            # tau in (0, 1]
            objective = {"tau": 1 - draws.rand().double()}
        else:
            objective = {
                "t": draws.randint(1, self.settings.num_diffusion_steps + 1),
                "prediction": self.settings.prediction,
                "min_snr_gamma": self.settings.min_snr_gamma,
                "motion_weight": self.settings.motion_weight,
            }
        inputs = {}
        if self.architecture.known_input:
            inputs["known"] = (x0, self.known_mask(draws, x0.shape[1]))
        # classifier-free guidance: drop the label now and then
        if self.architecture.num_classes:
            dropped = draws.rand() < self.settings.condition_dropout
            inputs["labels"] = torch.where(
                dropped, self.architecture.num_classes, self.labels[idx]
            )
        loss = self.diffusion.training_loss(
            model,
            x0,
            eps=draws.randn(*x0.shape[1:]),
            mask=self.mask_all[idx] if self.variable else None,
            **objective,
            **inputs,
        )
        return loss, {"loss": loss.item()}

    def known_mask(self, draws, num_frames):
        """The known frames (B, F) of a join denoiser's training batch: with probability
        ``known_frames`` the first k ~ U{1..F/2} frames (the transition a window of a
        long sequence knows, tasks.Long), and half the time the last frame too (the
        anchor of a rest that ends with its window); else none.  A rest that ends inside
        a window (one that opens a schedule, or lasts no whole number of windows) is
        anchored at a frame it was not trained with."""
        frames = torch.arange(num_frames, device=self.device)[None]
        given = draws.rand() < self.settings.known_frames
        first = frames < draws.randint(1, num_frames // 2 + 1)[:, None]
        last = (draws.rand() < 0.5)[:, None] & (frames == num_frames - 1)
        return (first | last) & given[:, None]

    def metadata(self, model):
        training = asdict(self.settings) | {"model": asdict(model.config)}
        training["num_frames"] = (
            self.settings.num_frames
            if not self.variable
            else list(self.settings.num_frames)
        )
        labels = (
            {"class_names": self.label_names} if self.architecture.num_classes else {}
        )
        return {
            "training": training,
            "normalizer": self.normalizer.to_dict(),
            "torch_version": torch.__version__,
            "data_dir": str(config.SYNTHETIC_DIR.name),
            **labels,
        }

    def checkpoint_name(self):
        variant = "_".join(
            v
            for v, on in (
                ("var", self.variable),
                ("cfg", self.settings.conditional),
                ("join", self.settings.known_frames > 0),
            )
            if on
        )
        return checkpoint_name("denoiser", self.settings.dataset, variant or None)


class DistillationRecipe(Recipe):
    """A student of half the teacher's deterministic steps (progressive distillation,
    Salimans & Ho 2022, Alg. 2), trained on the teacher's own data.

    For a student step from t to t'' (two teacher steps, t -> t' -> t'', on
    :func:`~facelib.diffusion.halving_steps`), x_t is drawn from q(x_t | x_0), the
    teacher's two DDIM steps give x_t'', and the student's target is the x_0 from which
    one DDIM step lands there:

        x0~ = (x_t'' - (sigma_t'' / sigma_t) x_t) / (alpha_t'' - (sigma_t'' / sigma_t)
        alpha_t),

    with alpha = sqrt(abar), sigma = sqrt(1 - abar).  Salimans & Ho's loss is w_t ||x0~
    - x0_hat||^2, w_t = max(SNR_t, 1) (weighting "truncated_snr"); near T the
    denominator above is about 3e-4 on the linear schedule and the target explodes, so
    the book's default ("landing") measures where the student's step lands against the
    teacher's two, in units of the noise there: ||(x_t'' - DDIM(x_t, x0_hat)) /
    sigma_t''||^2 (on the last step, to t'' = 0, the x_0 error weighted as Salimans &
    Ho's).
    """

    kind = "denoiser"

    def __init__(self, settings=DistillationTraining(), model_config=None):
        self.settings = settings
        self.teacher = load_denoiser(settings.teacher)
        self.teacher.model.eval().requires_grad_(False)
        if self.teacher.model.config.schedule == "flow":
            raise ValueError(
                f"{settings.teacher}: distillation takes a DDPM denoiser (or a student"
                " of one), not a rectified flow"
            )
        recorded = self.teacher.meta["training"]
        self._check_teacher_grid(recorded.get("sampler_steps"))
        # the teacher's data as the teacher saw it (a student records its DDPM's)
        self.data = DenoiserRecipe(
            DenoiserTraining(
                **{
                    f.name: _as_setting(recorded[f.name])
                    for f in fields(DenoiserTraining)
                    if f.name in recorded
                    and f.name
                    not in ("steps", "warmup", "prediction", "temporal_prior")
                },
                # the teacher's own Gaussian (a checkpoint from before the setting
                # records none)
                temporal_prior=bool(self.teacher.model.config.prior_length),
            )
        )
        self.distilled_from = recorded.get(
            "distilled_from", Path(settings.teacher).name
        )
        t = self.teacher.model.config
        self.guidance_scale = self._guidance_scale(t, recorded)
        self.architecture = model_config or replace(t, prediction="v")
        self.name = (
            f"student of {settings.teacher} ({settings.teacher_steps // 2} steps)"
        )
        self.size = self.data.size
        self.grid = torch.as_tensor(
            halving_steps(settings.teacher_steps, t.num_diffusion_steps)
        )
        self.alphas_bar = torch.as_tensor(self.data.diffusion.alphas_bar)

    def _check_teacher_grid(self, sampler_steps):
        """A student teacher was distilled for its own steps only: the chain this round
        halves (halving_steps(teacher_steps)) must be that chain, or the student would
        learn from steps its teacher never took (and be saved under the name of
        another round's student)."""
        if sampler_steps is None:
            return
        t = self.teacher.model.config.num_diffusion_steps
        grid = halving_steps(self.settings.teacher_steps, t)[1:].tolist()
        if list(sampler_steps) != grid:
            raise ValueError(
                f"{self.settings.teacher} is a student of {len(sampler_steps)}"
                f" deterministic steps ({list(sampler_steps)[:3]}...): distil it with"
                f" teacher_steps={len(sampler_steps)}, not"
                f" {self.settings.teacher_steps}, whose chain it was not distilled for"
            )

    def _guidance_scale(self, teacher, recorded):
        """The classifier-free weight w the students of a label-conditional teacher
        sample with (None for an unconditional one): the settings' (or CFG_SCALE) for
        the DDPM teacher, the one recorded for a student teacher."""
        given, inherited = self.settings.guidance_scale, recorded.get("cfg_scale")
        if not teacher.num_classes:
            if given is not None:
                raise ValueError(
                    f"guidance_scale = {given}: {self.settings.teacher} is"
                    " unconditional, it has no classifier-free guidance to distil"
                )
            return None
        if "distillation" not in recorded:
            return config.CFG_SCALE if given is None else float(given)
        if given not in (None, inherited):
            raise ValueError(
                f"{self.settings.teacher} samples with w = {inherited} distilled in;"
                f" its students keep it (guidance_scale None or {inherited}, not"
                f" {given})"
            )
        return inherited

    def teacher_x0(self, x, t, labels):
        """The teacher's clean estimate: classifier-free guided by w, free + w
        (conditional - free) (x_0 is affine in eps at fixed x_t, t, so this is CFG's
        eps), for the DDPM teacher of a guided student; the plain estimate
        otherwise."""
        network = self.teacher.model
        if labels is None:
            return network.x0(x, t)
        conditional = network.x0(x, t, labels=labels)
        if "distillation" in self.teacher.meta["training"]:
            return conditional  # a guided student: w is in already
        free = network.x0(x, t)
        return free + self.guidance_scale * (conditional - free)

    def build(self, generator):
        model = Denoiser(self.architecture)
        # the teacher's weights (an eps teacher's residual read as v's: close at small
        # t)
        model.load_state_dict(self.teacher.model.state_dict())
        return model

    def to(self, device):
        super().to(device)
        self.teacher.model.to(device)
        self.data.to(device)
        return self

    def _ddim(self, x0_of, x, t, t_next, labels=None):
        """One deterministic DDIM step from steps t to t_next (B,) with the clean
        estimate ``x0_of(x, t, labels)``."""
        a, a_next = (
            self.alphas_bar[s].to(x.dtype).reshape(-1, 1, 1, 1) for s in (t, t_next)
        )
        return ddim_step(x, x0_of(x, t.to(x.dtype), labels), a, a_next)

    def loss(self, model, draws):
        idx, x0 = self.data.clean_batch(draws)
        labels = self.data.labels[idx] if self.architecture.num_classes else None
        j = draws.randint(1, self.settings.teacher_steps // 2 + 1)
        t, t_mid, t_end = self.grid[2 * j], self.grid[2 * j - 1], self.grid[2 * j - 2]
        a, a_end = (
            self.alphas_bar[s].to(x0.dtype).reshape(-1, 1, 1, 1) for s in (t, t_end)
        )
        eps = draws.randn(*x0.shape[1:])
        xt = a.sqrt() * x0 + (1 - a).sqrt() * eps
        with torch.no_grad():
            x_mid = self._ddim(self.teacher_x0, xt, t, t_mid, labels)
            x_end = self._ddim(self.teacher_x0, x_mid, t_mid, t_end, labels)
            ratio = ((1 - a_end) / (1 - a)).sqrt()
            target = (x_end - ratio * xt) / (a_end.sqrt() - ratio * a.sqrt())
        x0_hat = model.x0(xt, t.to(xt.dtype), labels=labels)
        snr = a / (1 - a)
        if self.settings.weighting == "landing":
            # where the student's step lands, against the teacher's two, in units of
            # the noise there; the last step (to t'' = 0) lands on x_0 itself
            landed = ddim_step(xt, x0_hat, a, a_end)
            scale = (1 - a_end).sqrt().clamp_min(1e-3)
            last = (t_end == 0).reshape(-1, 1, 1, 1)
            err = torch.where(
                last,
                snr.clamp_min(1) * (x_end - x0_hat) ** 2,
                ((x_end - landed) / scale) ** 2,
            )
        else:
            weight = (
                snr.clamp_min(1) if self.settings.weighting == "truncated_snr" else snr
            )
            err = weight * (target - x0_hat) ** 2
        loss = err.mean()
        return loss, {"loss": loss.item()}

    def metadata(self, model):
        training = {
            **asdict(self.data.settings),
            "steps": self.settings.steps,
            "prediction": model.config.prediction,
            "distilled_from": self.distilled_from,
            "distillation": asdict(self.settings),
            # the classifier-free weight a guided student samples with (None: none)
            "cfg_scale": self.guidance_scale,
            "sampler_steps": (
                halving_steps(
                    self.settings.teacher_steps // 2, model.config.num_diffusion_steps
                )[1:].tolist()
            ),
            "model": asdict(model.config),
        }
        names = self.teacher.meta.get("class_names")
        return {
            "training": training,
            **({"class_names": names} if names else {}),
            "normalizer": self.teacher.meta["normalizer"],
            "torch_version": torch.__version__,
            "data_dir": str(config.SYNTHETIC_DIR.name),
        }

    def checkpoint_name(self):
        return f"student_{self.distilled_from}_{self.settings.teacher_steps // 2}"


def _as_setting(value):
    """A recorded (JSON) setting as the dataclass holds it: lists become tuples."""
    return tuple(value) if isinstance(value, list) else value


# --------------------------------------------------------------------------- networks
# that read noisy x_t
class _NoisyRecipe(Recipe):
    """A network trained on x_t = q_sample(x_0, t), t ~ U{0..T} (t = 0 is the clean
    sequence), in the denoiser's normalised space (the normaliser is fitted on the same
    split)."""

    def _prepare(self, settings):
        self.settings = settings
        data.check_dataset_name(settings.dataset)
        self.train = data.load_dataset(settings.dataset, "train")
        self.normalizer = data.LandmarkNormalizer.fit(self.train)
        self.x_all = torch.as_tensor(self.normalizer.normalize(self.train.landmarks))
        self.size = len(self.x_all)
        self.diffusion = GaussianDiffusion(
            named_betas(settings.schedule, settings.num_diffusion_steps)
        )

    def noisy_batch(self, model, draws):
        """(model(x_t, t), indices) for a batch of training sequences."""
        idx = draws.examples(self.size)
        t = draws.randint(0, self.settings.num_diffusion_steps + 1)
        x0 = self.x_all[idx]
        return (
            model(
                self.diffusion.q_sample(x0, t, eps=draws.randn(*x0.shape[1:])),
                t.float(),
            ),
            idx,
        )

    def metadata(self, model):
        return {
            "training": asdict(self.settings) | {"model": asdict(model.config)},
            "normalizer": self.normalizer.to_dict(),
            "torch_version": torch.__version__,
        }


class GuideRecipe(_NoisyRecipe):
    """p_phi(y | x_t, t) of Alg. 1 and 4: cross-entropy on noisy sequences."""

    kind = "guide"

    def __init__(self, settings=GuideTraining(), model_config=None):
        data.check_classifier_type(settings.classifier_type)
        self._prepare(settings)
        self.name = f"guide ({settings.dataset}, type {settings.classifier_type})"
        self.class_names = list(self.train.class_names(settings.classifier_type))
        self.targets = torch.as_tensor(self.train.targets(settings.classifier_type))
        self.architecture = model_config or NoisyClassifierConfig(
            num_classes=len(self.class_names)
        )

    def build(self, generator):
        return NoisyClassifier(self.architecture)

    def loss(self, model, draws):
        logits, idx = self.noisy_batch(model, draws)
        y = self.targets[idx]
        loss = nn.functional.cross_entropy(logits, y)
        return loss, {
            "loss": loss.item(),
            "accuracy": (logits.argmax(1) == y).float().mean().item(),
        }

    def metadata(self, model):
        return super().metadata(model) | {"class_names": self.class_names}

    def checkpoint_name(self):
        return checkpoint_name(
            "guide", self.settings.dataset, self.settings.classifier_type
        )


class AURegressorRecipe(_NoisyRecipe):
    """R(x_t, t) of the fine-control chapter: mean squared error of the per-frame AU
    intensities of noisy sequences against the intensities that made them
    (``FaceDataset.au_weights``)."""

    kind = "au_regressor"

    def __init__(self, settings=AURegressorTraining(), model_config=None):
        self._prepare(settings)
        self.name = f"AU regressor ({settings.dataset})"
        self.au_weights = torch.as_tensor(self.train.au_weights, dtype=torch.float32)
        self.architecture = model_config or AURegressorConfig()

    def build(self, generator):
        return AURegressor(self.architecture)

    def loss(self, model, draws):
        predicted, idx = self.noisy_batch(model, draws)
        loss = nn.functional.mse_loss(predicted, self.au_weights[idx])
        return loss, {"loss": loss.item()}

    def checkpoint_name(self):
        return checkpoint_name("au_regressor", self.settings.dataset)


def text_head_loss(
    output, table, labels, kinds, choice, contrastive_weight=1.0, temperature=0.05
):
    """The loss of the text head for outputs (B, D), description table (labels, 2, K, D)
    and, per sequence, its label, order (kind) and the index of its drawn description.

    * MotionCLIP's cosine term (§5.2): 1 - cos(output, E(c)), c = the drawn description.
    * Our contrastive term (CLIP's InfoNCE, one direction): softmax over the
      descriptions *in the same wording* of every label (and, for an enriched sentence,
      of both orders) at temperature tau; the cross-entropy of the right one.  The
      cosine alone is nearly satisfied by pointing at the average description of a
      label: the two orders' sentences have a cosine of about 0.97-0.99 for the encoder,
      so it never learns the order.

    Returns (loss, cosine term, accuracy of the contrastive choice)."""
    out = nn.functional.normalize(output, dim=-1)
    # (B, labels, 2, D): the same wording for every class
    candidates = table[:, :, choice].permute(2, 0, 1, 3)
    logits = torch.einsum("bd,blkd->blk", out, candidates) / temperature
    cosine = (
        1
        - logits[torch.arange(len(out), device=out.device), labels, kinds].mean()
        * temperature
    )
    # the order is in the words
    enriched = (table[0, 0, choice] != table[0, 1, choice]).any(-1)
    flat = torch.where(
        enriched[:, None],
        logits.flatten(1),
        torch.cat([logits[:, :, 0], logits[:, :, 0]], 1).masked_fill(
            torch.arange(2 * table.shape[0], device=out.device) >= table.shape[0],
            -torch.inf,
        ),
    )
    target = torch.where(enriched, labels * 2 + kinds, labels)
    contrastive = nn.functional.cross_entropy(flat, target)
    return (
        cosine + contrastive_weight * contrastive,
        cosine,
        (flat.argmax(1) == target).float().mean(),
    )


class TextHeadRecipe(_NoisyRecipe):
    """BiT(x_t, t) of Alg. 2: cos(BiT(x_t, t), E(c)) high for c a random training
    description of x_0 (:func:`text_head_loss`)."""

    kind = "text_head"

    def __init__(
        self, settings=TextHeadTraining(), model_config=None, encoder=None
    ):
        self._prepare(settings)
        self.name = f"text head ({settings.dataset})"
        self.table = description_embeddings(self.train, encoder or get_encoder())
        self.labels, self.kinds = (
            torch.as_tensor(self.train.labels).long(),
            torch.as_tensor(self.train.kinds).long(),
        )
        self.architecture = model_config or TextHeadConfig()

    def build(self, generator):
        return NoisyTextHead(self.architecture)

    def loss(self, model, draws):
        output, idx = self.noisy_batch(model, draws)
        choice = draws.randint(0, self.table.shape[2])
        loss, cosine, hit = text_head_loss(
            output,
            self.table,
            self.labels[idx],
            self.kinds[idx],
            choice,
            self.settings.contrastive_weight,
            self.settings.temperature,
        )
        return loss, {
            "loss": loss.item(),
            "cosine_loss": cosine.item(),
            "accuracy": hit.item(),
        }

    def metadata(self, model):
        return super().metadata(model) | {
            "text_encoder": MODEL_NAME,
            "class_names": list(self.train.label_names),
        }

    def checkpoint_name(self):
        return checkpoint_name("guide", self.settings.dataset, "text")


# ------------------------------------------------------------------------------------
# the evaluation's IC
class EvaluatorRecipe(Recipe):
    """The independent classifier (IC, §5): an LSTM on clean sequences, cross-entropy,
    epochs; with architecture "cnn", the second reader (a temporal CNN)."""

    kind = "evaluator"

    def __init__(self, settings=EvaluatorTraining()):
        data.check_classifier_type(settings.classifier_type)
        self.settings = settings
        self.name = (
            f"IC ({settings.dataset}, type {settings.classifier_type},"
            f" {settings.inputs})"
        )
        train = data.load_dataset(settings.dataset, "train")
        self.class_names = list(train.class_names(settings.classifier_type))
        self.x = torch.as_tensor(train.landmarks, dtype=torch.float32)
        self.y = torch.as_tensor(
            train.targets(settings.classifier_type), dtype=torch.long
        )
        self.size = len(self.x)

    def build(self, generator):
        model = classifier_from_config(self.model_config(None))
        model.fit_normalization(self.x)
        return model

    def loss(self, model, draws):
        idx = draws.examples(self.size)
        loss = nn.functional.cross_entropy(model(self.x[idx]), self.y[idx])
        return loss, {"loss": loss.item()}

    def model_config(self, model):
        s = self.settings
        width = (
            {"hidden": s.hidden}
            if s.architecture == "lstm"
            else {"architecture": s.architecture, "channels": s.hidden}
        )
        return {
            "num_classes": len(self.class_names),
            **width,
            "num_landmarks": config.NUM_LANDMARKS,
            "inputs": s.inputs,
        }

    def metadata(self, model):
        return super().metadata(model) | {"class_names": self.class_names}

    def checkpoint_name(self):
        s = self.settings
        name = checkpoint_name("ic", s.dataset, s.classifier_type)
        return name if s.architecture == "lstm" else f"{name}_{s.architecture}"


# -------------------------------------------------------------------------- baselines
class _BaselineRecipe(Recipe):
    def _prepare(self, settings, name):
        data.check_dataset_name(settings.dataset)
        self.settings, self.kind = settings, name
        self.name = f"{name} ({settings.dataset})"
        self.train = data.load_dataset(settings.dataset, "train")

    def metadata(self, model):
        return super().metadata(model) | {"label_names": list(self.train.label_names)}


class ActorRecipe(_BaselineRecipe):
    """The ACTOR-style CVAE: reconstruction + kl_weight x KL."""

    def __init__(self, settings=ActorTraining()):
        self._prepare(settings, "actor")
        self.delta = torch.as_tensor(self.train.delta_landmarks())
        self.labels = torch.as_tensor(self.train.labels)
        self.size = len(self.delta)

    def build(self, generator):
        model = actor.ActorCVAE(
            actor.ActorConfig(
                num_classes=len(self.train.label_names),
                depth=self.settings.depth,
                num_neutrals=len(np.unique(self.train.subjects)),
            )
        )
        model.scale.fill_(float(self.delta.std()))
        model.neutrals.copy_(torch.as_tensor(self.train.subject_neutrals()))
        self.x_all = self.delta / model.scale
        return model

    def loss(self, model, draws):
        idx = draws.examples(self.size)
        x, y = self.x_all[idx], self.labels[idx]
        mu, logvar = model.encode(x, y)
        z = mu + (0.5 * logvar).exp() * draws.randn(mu.shape[1])
        rec = ((model.decode(z, y, x.shape[1]) - x) ** 2).mean()
        kl = (0.5 * (mu**2 + logvar.exp() - 1 - logvar)).sum(1).mean()
        return rec + self.settings.kl_weight * kl, {
            "reconstruction": rec.item(),
            "kl": kl.item(),
        }


class MotionClipRecipe(_BaselineRecipe):
    """The MotionCLIP-style decoder: text embedding -> motion, mean squared error."""

    def __init__(self, settings=MotionClipTraining(), encoder=None):
        self._prepare(settings, "motionclip")
        self.table = description_embeddings(self.train, encoder or get_encoder())
        self.delta = torch.as_tensor(self.train.delta_landmarks())
        self.labels, self.kinds = (
            torch.as_tensor(self.train.labels).long(),
            torch.as_tensor(self.train.kinds).long(),
        )
        self.size = len(self.delta)

    def build(self, generator):
        model = motionclip.TextToMotion(
            motionclip.MotionClipConfig(embedding_dim=self.table.shape[-1])
        )
        model.scale.fill_(float(self.delta.std()))
        model.neutral.copy_(torch.as_tensor(self.train.subject_neutrals().mean(0)))
        self.x_all = self.delta / model.scale
        return model

    def loss(self, model, draws):
        idx = draws.examples(self.size)
        choice = draws.randint(0, self.table.shape[2])
        text = self.table[self.labels[idx], self.kinds[idx], choice]
        loss = ((model.decode(text, self.x_all.shape[1]) - self.x_all[idx]) ** 2).mean()
        return loss, {"reconstruction": loss.item()}


class Motion3DGANRecipe(_BaselineRecipe):
    """The Motion3DGAN-style WGAN-GP on SRVFs (Eq. 4-7 of Otberdout et al.): a critic
    and a generator."""

    # the reconstruction partner of each example is drawn within its class
    distributed = False

    def __init__(self, settings=Motion3DGANTraining()):
        self._prepare(settings, "motion3dgan")
        self.num_classes = len(self.train.label_names)
        q, self.length = motion3dgan.prepare(self.train, settings.smoothing)
        self.reference = srvf.reference_point(q)
        self.real = srvf.log_map(q, self.reference).float()
        self.labels = torch.as_tensor(self.train.labels)
        self.by_class = [
            torch.nonzero(self.labels == y)[:, 0] for y in range(self.num_classes)
        ]
        self.size = len(self.real)

    def build(self, generator):
        k, train = self.num_classes, self.train
        config_ = motion3dgan.Motion3DGANConfig(
            num_classes=k,
            num_frames=train.landmarks.shape[1],
            channels=self.settings.channels,
        )
        model = motion3dgan.Motion3DGAN(
            config_, num_neutrals=len(np.unique(train.subjects))
        )
        model.reference.copy_(self.reference.float())
        model.tangent_scale.fill_(float(self.real.std()))
        model.arc_length.copy_(
            torch.stack(
                [self.length[self.labels == y].mean() for y in range(k)]
            ).float()
        )
        e2n = [np.mean(train.kinds[train.labels == y] == 1) for y in range(k)]
        model.e2n_fraction.copy_(torch.as_tensor(e2n).float())
        model.neutrals.copy_(torch.as_tensor(train.subject_neutrals()))
        self.critic = motion3dgan.Critic(model.config)
        return model

    def objectives(self, model):
        return [
            Objective(
                self.critic,
                lambda d: self.critic_loss(model, d),
                self.settings.critic_steps,
            ),
            Objective(model.generator, lambda d: self.generator_loss(model, d)),
        ]

    def _fake(self, model, y, draws):
        z = draws.randn(model.config.noise_dim)
        return (
            model.tangent(z, nn.functional.one_hot(y, self.num_classes).float())
            / model.tangent_scale
        )

    def critic_loss(self, model, draws):
        idx = draws.examples(self.size)
        y, onehot = (
            self.labels[idx],
            nn.functional.one_hot(self.labels[idx], self.num_classes).float(),
        )
        u_real = self.real[idx] / model.tangent_scale
        with torch.no_grad():
            u_fake = self._fake(model, y, draws)
        tau = draws.rand(1, 1)
        u_mix = ((1 - tau) * u_real + tau * u_fake).requires_grad_(True)
        grad = torch.autograd.grad(
            self.critic(u_mix, onehot).sum(), u_mix, create_graph=True
        )[0]
        penalty = ((grad.flatten(1).norm(dim=1) - 1) ** 2).mean()
        wasserstein = (
            self.critic(u_fake, onehot).mean() - self.critic(u_real, onehot).mean()
        )
        loss = wasserstein + self.settings.gp_weight * penalty
        return loss, {"critic": loss.item()}

    def generator_loss(self, model, draws):
        s, gen = self.settings, draws.generator
        y = self.labels[draws.examples(self.size)]
        partner = torch.stack(
            [
                members[torch.randint(0, len(members), (1,), generator=gen)][0]
                for members in (self.by_class[int(c)] for c in y)
            ]
        )
        u_fake = self._fake(model, y, draws)
        loss = (
            -s.adversarial_weight
            * self.critic(
                u_fake, nn.functional.one_hot(y, self.num_classes).float()
            ).mean()
            + s.reconstruction_weight
            * (u_fake - self.real[partner] / model.tangent_scale).abs().mean()
        )
        return loss, {"generator": loss.item()}

    def model_config(self, model):
        return motion3dgan.config_dict(model)


def random_masks(n, num_frames, generator):
    """Training masks (n, F) bool, True = known: a quarter each of FFB, FFE and FFM
    layouts (§5.3) and of one missing segment of random position and length (Berson et
    al.'s random gaps).
    """
    kind = torch.randint(0, 4, (n,), generator=generator)
    seed = int(torch.randint(0, 2**31 - 1, (1,), generator=generator))
    masks = [
        torch.as_tensor(fill_masks(s, n, num_frames, seed + i))
        for i, s in enumerate(FILL_SETTINGS)
    ]
    start = torch.randint(1, num_frames - 2, (n, 1), generator=generator)
    length = torch.randint(2, num_frames // 2, (n, 1), generator=generator)
    f = torch.arange(num_frames)[None]
    masks.append(~((f >= start) & (f < (start + length).clamp(max=num_frames - 1))))
    return torch.stack(masks)[kind, torch.arange(n)]


class LSTMFillerRecipe(_BaselineRecipe):
    """The bidirectional-LSTM filler (Berson et al.): random masks, the masked L1 of
    their Eq. 1."""

    distributed = False  # the filler draws its own noise inside the forward pass

    def __init__(self, settings=LSTMFillerTraining()):
        self._prepare(settings, "lstm_filler")
        self.normalizer = data.LandmarkNormalizer.fit(self.train)
        self.x_all = torch.as_tensor(self.normalizer.normalize(self.train.landmarks))
        self.size = len(self.x_all)

    def build(self, generator):
        model = lstm_filler.LSTMFiller()
        model.normalizer = self.normalizer
        return model

    def loss(self, model, draws):
        x = self.x_all[draws.examples(self.size)]
        known = draws.rows(lambda n, gen: random_masks(n, x.shape[1], gen))
        loss = lstm_filler.masked_l1(
            model(x, known, generator=draws.generator), x, known, self.settings.alpha_gt
        )
        return loss, {"loss": loss.item()}

    def metadata(self, model):
        return {
            "training": asdict(self.settings),
            "normalizer": self.normalizer.to_dict(),
            "torch_version": torch.__version__,
        }


# ------------------------------------------------------------------------------------
# mesh deformation
class DeformationRecipe(Recipe):
    """A Table 5 network: (neutral mesh, Delta L_f) -> Delta M_f, S2D's
    landmark-weighted L1."""

    kind = "deformer"

    def __init__(self, settings=DeformationTraining()):
        s = self.settings = settings
        self.name = (
            f"deformer ({deformation.check_method(s.method)},"
            f" {deformation.check_split(s.split)} split)"
        )
        train, _ = deformation.split_datasets(s.split)
        if s.max_sequences:
            train = train.subset(
                np.random.default_rng(s.seed).permutation(len(train))[: s.max_sequences]
            )
        pairs = deformation.make_pairs(train, s.frames_per_sequence, seed=s.seed)
        self.neutral, self.dl, self.dm = (
            torch.as_tensor(a)
            for a in (pairs.neutral, pairs.delta_landmarks, pairs.delta_mesh)
        )
        self.weights = deformation.loss_weights()
        self.size = len(pairs)

    def build(self, generator):
        return deformation.build_model(self.settings.method)

    def loss(self, model, draws):
        seq = draws.examples(self.size)
        k = self.dm.shape[1]
        frame = draws.rows(
            lambda n, gen: torch.stack(
                [
                    torch.randperm(k, generator=gen)[: self.settings.frames_per_batch]
                    for _ in range(n)
                ]
            )
        )
        target = self.dm[seq[:, None], frame]
        predicted = model(self.neutral[seq], self.dl[seq[:, None], frame])
        loss = deformation_loss(predicted, target, self.weights)
        return loss, {
            "loss": loss.item(),
            "error_mm": (predicted - target).norm(dim=-1).mean().item(),
        }

    def model_config(self, model):
        return deformation.METHODS[self.settings.method][0].config_dict(model)

    def metadata(self, model):
        return {
            "method": self.settings.method,
            "split": self.settings.split,
            "held_out_expressions": list(deformation.HELD_OUT_EXPRESSIONS),
        } | super().metadata(model)

    def checkpoint_name(self):
        # Table 5 over seeds (training.SHIPPED): seed 0 unnamed
        return checkpoint_name(
            "deform", self.settings.method, self.settings.split, self.settings.seed
        )


RECIPES = {
    "denoiser": DenoiserRecipe,
    "guide": GuideRecipe,
    "text_head": TextHeadRecipe,
    "evaluator": EvaluatorRecipe,
    "actor": ActorRecipe,
    "motionclip": MotionClipRecipe,
    "motion3dgan": Motion3DGANRecipe,
    "lstm_filler": LSTMFillerRecipe,
    "deformer": DeformationRecipe,
    "au_regressor": AURegressorRecipe,
    "student": DistillationRecipe,
}
SETTINGS = {
    "denoiser": DenoiserTraining,
    "guide": GuideTraining,
    "text_head": TextHeadTraining,
    "evaluator": EvaluatorTraining,
    "actor": ActorTraining,
    "motionclip": MotionClipTraining,
    "motion3dgan": Motion3DGANTraining,
    "lstm_filler": LSTMFillerTraining,
    "deformer": DeformationTraining,
    "au_regressor": AURegressorTraining,
    "student": DistillationTraining,
}
