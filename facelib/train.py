"""Training loops (``python -m facelib train NAME``): the DDPM denoiser of §3.1 / §4, the
guidance classifiers of §3.2 (Alg. 1), the text head of Alg. 2 and the independent classifiers
of the evaluation (§5).

Paper §4: T = 2000, linear betas 1e-4..0.02, 200K iterations, learning rate 1e-4, batch 256.
A CPU budget of about 20 minutes on 2 cores allows about 1/50 of that compute, so we train a
smaller transformer (:class:`~facelib.models.denoiser.DenoiserConfig`) for fewer, smaller steps
with a higher learning rate (warm-up, then cosine decay) and keep an exponential moving
average (EMA) of the weights, which gives visibly cleaner samples for short runs.  Chapter 03
shows the loss curve and what the shorter training costs.

Anatomy augmentation (our addition): CoMA-like data has only 9 training faces, so a DDPM
trained on it alone can only draw those 9 anatomies.  With probability ``anatomy_swap`` a
training sequence has its subject's neutral landmarks replaced by those of another training
face from ``anatomy_pool`` (x - N_subject + N_other, in every frame): the motion is kept, the
anatomy is new.  Only training splits enter the pool, so no test face leaks into training.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from tqdm import tqdm

from . import config, data
from .checkpoints import save_checkpoint
from .diffusion import GaussianDiffusion, named_betas
from .models.classifier import train_classifier
from .models.denoiser import Denoiser, DenoiserConfig
from .models.noisy_classifier import NoisyClassifier, NoisyClassifierConfig, NoisyTextHead, TextHeadConfig
from .training_log import TrainingLog


@dataclass(frozen=True)
class DenoiserTraining:
    """How the shipped denoisers are trained (each value: paper or our choice, and why)."""

    dataset: str = "coma"  # paper §4: "unless otherwise specified, solely CoMA"
    num_frames: object = 40  # paper §4: 40 frames; (35, 45) for the variable-length model of App. A
    steps: int = 12_000  # our choice: ~19 min on 2 CPU cores (paper: 200K iterations)
    batch_size: int = 64  # our choice (paper: 256): CPU time per step
    lr: float = 5e-4  # our choice (paper: 1e-4): 13x fewer, 4x smaller steps need a larger rate
    warmup: int = 500  # our choice: linear warm-up steps, then cosine decay to lr / 20
    weight_decay: float = 0.0
    grad_clip: float = 1.0  # our choice: clip the gradient norm (stabilises the first steps)
    ema_decay: float = 0.999  # our choice: EMA of the weights, used for sampling
    num_diffusion_steps: int = 2000  # paper §4: T = 2000
    schedule: str = "linear"  # paper §4: linear betas from 1e-4 to 0.02
    anatomy_pool: tuple = ("coma", "bu")  # our choice: training faces of these datasets (9 + 81)
    anatomy_swap: float = 0.5  # our choice: probability that a sequence gets another anatomy
    seed: int = 0
    model: DenoiserConfig = field(default_factory=DenoiserConfig)

    def __post_init__(self):
        if (self.model.num_diffusion_steps, self.model.schedule) != (self.num_diffusion_steps, self.schedule):
            raise ValueError("the denoiser's schedule must match the training schedule")
        if not 0 <= self.anatomy_swap <= 1:
            raise ValueError(f"anatomy_swap is a probability in [0, 1], got {self.anatomy_swap}")


def training_anatomies(datasets):
    """Neutral landmarks (K, 68, 3) in mm of every training subject of the given datasets."""
    return np.concatenate([data.load_dataset(name, "train").subject_neutrals() for name in datasets])


def swap_anatomy(x, own, pool, swap, generator):
    """Anatomy augmentation: x (B, F, 68, 3) minus each sequence's own neutral frame ``own``
    (B, 68, 3), plus a random neutral frame of ``pool`` (K, 68, 3), with probability ``swap``."""
    other = pool[torch.randint(0, len(pool), (len(x),), generator=generator)]
    keep = torch.rand(len(x), generator=generator) >= swap
    shift = torch.where(keep[:, None, None], torch.zeros_like(own), other - own)
    return x + shift[:, None]


def _learning_rate(cfg, step):
    if step < cfg.warmup:
        return cfg.lr * (step + 1) / cfg.warmup
    progress = (step - cfg.warmup) / max(1, cfg.steps - cfg.warmup)
    return cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * progress)))


def train_denoiser(cfg=DenoiserTraining(), progress=True, log_every=50):
    """Train eps_theta with the simple loss (Eq. 8).  Returns (EMA model, normalizer, history)."""
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    train = data.load_dataset(cfg.dataset, "train", num_frames=cfg.num_frames)
    normalizer = data.LandmarkNormalizer.fit(train)
    x_all = torch.as_tensor(normalizer.normalize(train.landmarks))
    mask_all = torch.arange(x_all.shape[1])[None, :] < torch.as_tensor(train.lengths)[:, None]
    x_all = x_all * mask_all[:, :, None, None]
    own = torch.as_tensor(train.sequence_neutrals()) / normalizer.scale
    pool = torch.as_tensor(training_anatomies(cfg.anatomy_pool) if cfg.anatomy_swap > 0 else np.zeros((1, 68, 3))) / normalizer.scale
    pool = pool.float()
    variable = not isinstance(cfg.num_frames, int)
    diffusion = GaussianDiffusion(named_betas(cfg.schedule, cfg.num_diffusion_steps))
    model = Denoiser(cfg.model)
    swapped = swap_anatomy(x_all, own, pool, cfg.anatomy_swap, gen)  # the prior sees augmented frames too
    frames = torch.cat([seqs[i, :n] for seqs in (x_all, swapped) for i, n in enumerate(train.lengths)])
    model.fit_prior(frames)
    ema = Denoiser(cfg.model)
    ema.load_state_dict(model.state_dict())
    ema.requires_grad_(False)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    log = TrainingLog(cfg.steps, log_every, "loss")
    for step in tqdm(range(cfg.steps), desc=f"train denoiser ({cfg.dataset})", disable=not progress):
        for g in opt.param_groups:
            g["lr"] = _learning_rate(cfg, step)
        idx = torch.randint(0, len(x_all), (cfg.batch_size,), generator=gen)
        mask = mask_all[idx] if variable else None
        x0 = swap_anatomy(x_all[idx], own[idx], pool, cfg.anatomy_swap, gen) * mask_all[idx][:, :, None, None]
        loss = diffusion.training_loss(model, x0, generator=gen, mask=mask)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
        opt.step()
        with torch.no_grad():
            decay = min(cfg.ema_decay, (1 + step) / (10 + step))
            for pe, pm in zip(ema.parameters(), model.parameters()):
                pe.lerp_(pm, 1 - decay)
        log.add(step, loss=loss.item())
    return ema.eval(), normalizer, log.history


def checkpoint_name(cfg):
    """Default checkpoint name: denoiser_<dataset>[_var]."""
    return f"denoiser_{cfg.dataset}" + ("" if isinstance(cfg.num_frames, int) else "_var")


def train_and_save(cfg, name=None, progress=True):
    """Train a denoiser and save it (state_dict + JSON config) in data/checkpoints; returns the paths."""
    model, normalizer, history = train_denoiser(cfg, progress=progress)
    training = asdict(cfg)
    training["num_frames"] = cfg.num_frames if isinstance(cfg.num_frames, int) else list(cfg.num_frames)
    training["anatomy_pool"] = list(cfg.anatomy_pool)
    return save_checkpoint(name or checkpoint_name(cfg), model, "denoiser", asdict(cfg.model),
                           training=training, normalizer=normalizer.to_dict(), history=history,
                           torch_version=torch.__version__, data_dir=str(config.SYNTHETIC_DIR.name))


@dataclass(frozen=True)
class GuideTraining:
    """How the shipped guidance classifiers p_phi(y | x_t, t) are trained (Alg. 1; our choices)."""

    dataset: str = "coma"
    classifier_type: str = "I"  # paper §5.1: type I for label control, type S for Alg. 4
    steps: int = 3000  # our choice: ~3 min on 2 CPU cores; accuracy vs t is shown in chapter 05
    batch_size: int = 64
    lr: float = 3e-4
    warmup: int = 200
    weight_decay: float = 0.01
    grad_clip: float = 1.0
    num_diffusion_steps: int = 2000  # the DDPM's schedule (paper §4): x_t must look like the sampler's
    schedule: str = "linear"
    seed: int = 0
    model: NoisyClassifierConfig = None  # default: NoisyClassifierConfig(num_classes of the type)


def _train_on_noisy_sequences(model, cfg, dataset, batch_loss, desc, metrics, progress, log_every):
    """The loop shared by the guidance networks: x_t = q_sample(x_0, t) with t ~ U{0..T} (t = 0 is
    the clean sequence), ``batch_loss(output, idx, generator) -> (loss, {metric: value})`` on
    model(x_t, t).  The caller seeds torch before building the model (dropout draws follow it)."""
    gen = torch.Generator().manual_seed(cfg.seed)
    normalizer = data.LandmarkNormalizer.fit(dataset)  # = the denoiser's (fitted on the same split)
    x_all = torch.as_tensor(normalizer.normalize(dataset.landmarks))
    diffusion = GaussianDiffusion(named_betas(cfg.schedule, cfg.num_diffusion_steps))
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    log = TrainingLog(cfg.steps, log_every, *metrics)
    model.train()
    for step in tqdm(range(cfg.steps), desc=desc, disable=not progress):
        for g in opt.param_groups:
            g["lr"] = _learning_rate(cfg, step)
        idx = torch.randint(0, len(x_all), (cfg.batch_size,), generator=gen)
        t = torch.randint(0, cfg.num_diffusion_steps + 1, (cfg.batch_size,), generator=gen)
        loss, values = batch_loss(model(diffusion.q_sample(x_all[idx], t, generator=gen), t.float()), idx, gen)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
        opt.step()
        log.add(step, **values)
    return model.eval(), normalizer, log.history


def train_guide(cfg=GuideTraining(), progress=True, log_every=50):
    """Train p_phi(y | x_t, t) with cross-entropy on x_t = q_sample(x_0, t), t ~ U{0..T}.

    Returns (model, normalizer, history); the normalizer is the denoiser's (fitted on the same split)."""
    data.check_classifier_type(cfg.classifier_type)
    train = data.load_dataset(cfg.dataset, "train")
    y_all = torch.as_tensor(train.targets(cfg.classifier_type))
    model_cfg = cfg.model or NoisyClassifierConfig(num_classes=len(train.class_names(cfg.classifier_type)))
    torch.manual_seed(cfg.seed)
    model = NoisyClassifier(model_cfg)

    def batch_loss(logits, idx, gen):
        loss = torch.nn.functional.cross_entropy(logits, y_all[idx])
        return loss, {"loss": loss.item(), "accuracy": (logits.argmax(1) == y_all[idx]).float().mean().item()}
    return _train_on_noisy_sequences(model, cfg, train, batch_loss, f"train guide ({cfg.dataset}, type "
                                     f"{cfg.classifier_type})", ("loss", "accuracy"), progress, log_every)


def train_and_save_guide(cfg=GuideTraining(), name=None, progress=True):
    """Train a guidance classifier and save it as guide_<dataset>_<type> in data/checkpoints."""
    model, normalizer, history = train_guide(cfg, progress=progress)
    training = asdict(cfg)
    training["model"] = asdict(model.config)
    return save_checkpoint(name or f"guide_{cfg.dataset}_{cfg.classifier_type}", model, "guide",
                           asdict(model.config), training=training, normalizer=normalizer.to_dict(),
                           class_names=list(data.load_dataset(cfg.dataset, "train").class_names(cfg.classifier_type)),
                           history=history, torch_version=torch.__version__)


@dataclass(frozen=True)
class TextHeadTraining:
    """How the shipped text head BiT(x_t, t) of Alg. 2 is trained (§3.2, §5.2; our choices)."""

    dataset: str = "coma+bu"  # paper §5.2: CoMA and BU-4DFE merged (18 actions)
    steps: int = 4000  # our choice: ~8 min on 2 CPU cores
    batch_size: int = 64
    lr: float = 3e-4
    warmup: int = 200
    weight_decay: float = 0.01
    grad_clip: float = 1.0
    contrastive_weight: float = 1.0  # our addition (0 = the paper's cosine loss alone): see train_text_head
    temperature: float = 0.05  # of the contrastive term (CLIP learns 0.01; 0.07 at its start)
    num_diffusion_steps: int = 2000
    schedule: str = "linear"
    seed: int = 0
    model: TextHeadConfig = field(default_factory=TextHeadConfig)


def description_embeddings(dataset, encoder, split="train"):
    """Text embeddings (labels, 2 kinds, K, D) of every description of every (label, order): the
    raw text, its paraphrases and the enriched sentences of ``split`` (facelib/descriptions.py).
    Where a split has fewer descriptions for some (label, order), as the "vocabulary" does, they are
    repeated in turn up to the longest list's K (for a nearest-description match, a repeat changes
    nothing; the "train" split has the same K for all)."""
    from .descriptions import descriptions
    texts = [[list(descriptions(label, kind, split)) for kind in dataset.kind_names] for label in dataset.label_names]
    k = max(len(d) for row in texts for d in row)
    return torch.stack([torch.stack([torch.as_tensor(encoder.encode([d[i % len(d)] for i in range(k)])) for d in row])
                        for row in texts])


def text_head_loss(output, table, labels, kinds, choice, contrastive_weight=1.0, temperature=0.05):
    """The loss of the text head for outputs (B, D), description table (labels, 2, K, D) and, per
    sequence, its label, order (kind) and the index of its drawn description.

    * MotionCLIP's cosine term (§5.2): 1 - cos(output, E(c)), c = the drawn description.
    * Our contrastive term (CLIP's InfoNCE, one direction): softmax over the descriptions *in the
      same wording* of every label (and, for an enriched sentence, of both orders) at temperature
      tau; the cross-entropy of the right one.  The cosine alone is nearly satisfied by pointing
      at the average description of a label: the two orders' sentences have a cosine of about
      0.97-0.99 for the encoder, so it never learns the order (chapter 06).

    Returns (loss, cosine term, accuracy of the contrastive choice)."""
    out = torch.nn.functional.normalize(output, dim=-1)
    candidates = table[:, :, choice].permute(2, 0, 1, 3)  # (B, labels, 2, D): the same wording for every class
    logits = torch.einsum("bd,blkd->blk", out, candidates) / temperature
    cosine = 1 - logits[torch.arange(len(out)), labels, kinds].mean() * temperature
    enriched = (table[0, 0, choice] != table[0, 1, choice]).any(-1)  # the order is in the words
    flat = torch.where(enriched[:, None], logits.flatten(1), torch.cat([logits[:, :, 0], logits[:, :, 0]], 1)
                       .masked_fill(torch.arange(2 * table.shape[0]) >= table.shape[0], -torch.inf))
    target = torch.where(enriched, labels * 2 + kinds, labels)
    contrastive = torch.nn.functional.cross_entropy(flat, target)
    return cosine + contrastive_weight * contrastive, cosine, (flat.argmax(1) == target).float().mean()


def train_text_head(cfg=TextHeadTraining(), encoder=None, progress=True, log_every=50):
    """Train BiT(x_t, t) so that cos(BiT(x_t, t), E(c)) is high for c a random training description
    of x_0 (:func:`text_head_loss`), on x_t = q_sample(x_0, t).  Returns (model, normalizer, history).

    Logged: the loss, its cosine term and how often the contrastive choice is right (all t)."""
    from .text import get_encoder
    train = data.load_dataset(cfg.dataset, "train")
    table = description_embeddings(train, encoder or get_encoder())
    labels, kinds = torch.as_tensor(train.labels).long(), torch.as_tensor(train.kinds).long()
    torch.manual_seed(cfg.seed)
    model = NoisyTextHead(cfg.model)

    def batch_loss(output, idx, gen):
        choice = torch.randint(0, table.shape[2], (len(idx),), generator=gen)
        loss, cosine, hit = text_head_loss(output, table, labels[idx], kinds[idx], choice,
                                           cfg.contrastive_weight, cfg.temperature)
        return loss, {"loss": loss.item(), "cosine_loss": cosine.item(), "accuracy": hit.item()}
    return _train_on_noisy_sequences(model, cfg, train, batch_loss, f"train text head ({cfg.dataset})",
                                     ("loss", "cosine_loss", "accuracy"), progress, log_every)


def train_and_save_text_head(cfg=TextHeadTraining(), name=None, progress=True):
    """Train the text head and save it as guide_<dataset>_text in data/checkpoints."""
    from .text import MODEL_NAME
    model, normalizer, history = train_text_head(cfg, progress=progress)
    training = asdict(cfg)
    return save_checkpoint(name or f"guide_{cfg.dataset}_text", model, "text_head", asdict(model.config),
                           training=training, normalizer=normalizer.to_dict(), text_encoder=MODEL_NAME,
                           class_names=list(data.load_dataset(cfg.dataset, "train").label_names),
                           history=history, torch_version=torch.__version__)


@dataclass(frozen=True)
class EvaluatorTraining:
    """How the independent classifiers (IC, paper §5) are trained: the recipe of chapter 01."""

    dataset: str = "coma"
    classifier_type: str = "I"
    epochs: int = 30
    batch_size: int = 32
    lr: float = 1e-3
    hidden: int = 128
    inputs: str = "motion"  # chapter 01: motion generalises to unseen faces, absolute does not
    seed: int = 0


def train_and_save_evaluator(cfg=EvaluatorTraining(), name=None, progress=True):
    """Train the IC of a dataset and type on its training split; save it as ic_<dataset>_<type>."""
    data.check_classifier_type(cfg.classifier_type)
    train = data.load_dataset(cfg.dataset, "train")
    names = train.class_names(cfg.classifier_type)
    model, losses = train_classifier(train.landmarks, train.targets(cfg.classifier_type), len(names),
                                     epochs=cfg.epochs, batch_size=cfg.batch_size, lr=cfg.lr, seed=cfg.seed,
                                     inputs=cfg.inputs, hidden=cfg.hidden, progress=progress)
    config = {"num_classes": len(names), "hidden": cfg.hidden, "num_landmarks": 68, "inputs": cfg.inputs}
    return save_checkpoint(name or f"ic_{cfg.dataset}_{cfg.classifier_type}", model, "evaluator", config,
                           training=asdict(cfg), class_names=list(names), history={"loss": losses.tolist()},
                           torch_version=torch.__version__)
