"""Training loops (``python -m facelib train NAME``): the DDPM denoiser of §3.1 / §4.

Paper §4: T = 2000, linear betas 1e-4..0.02, 200K iterations, learning rate 1e-4, batch 256.
A CPU budget of about 20 minutes on 2 cores allows about 1/50 of that compute, so we train a
smaller transformer (:class:`~facelib.models.denoiser.DenoiserConfig`) for fewer, smaller steps
with a higher learning rate (warm-up, then cosine decay) and keep an exponential moving
average (EMA) of the weights, which gives visibly cleaner samples for short runs.  Chapter 03
shows the loss curve and what the shorter training costs.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from tqdm.auto import tqdm

from . import config, data
from .checkpoints import save_checkpoint
from .diffusion import GaussianDiffusion, named_betas
from .models.denoiser import Denoiser, DenoiserConfig


@dataclass(frozen=True)
class DenoiserTraining:
    """How the shipped denoisers are trained (each value: paper or our choice, and why)."""

    dataset: str = "coma"  # paper §4: "unless otherwise specified, solely CoMA"
    num_frames: object = 40  # paper §4: 40 frames; (35, 45) for the variable-length model of App. A
    steps: int = 12_000  # our choice: ~17 min on 2 CPU cores (paper: 200K iterations)
    batch_size: int = 64  # our choice (paper: 256): CPU time per step
    lr: float = 5e-4  # our choice (paper: 1e-4): 13x fewer, 4x smaller steps need a larger rate
    warmup: int = 500  # our choice: linear warm-up steps, then cosine decay to lr / 20
    weight_decay: float = 0.0
    grad_clip: float = 1.0  # our choice: clip the gradient norm (stabilises the first steps)
    ema_decay: float = 0.999  # our choice: EMA of the weights, used for sampling
    num_diffusion_steps: int = 2000  # paper §4: T = 2000
    schedule: str = "linear"  # paper §4: linear betas from 1e-4 to 0.02
    seed: int = 0
    model: DenoiserConfig = field(default_factory=DenoiserConfig)

    def __post_init__(self):
        if (self.model.num_diffusion_steps, self.model.schedule) != (self.num_diffusion_steps, self.schedule):
            raise ValueError("the denoiser's schedule must match the training schedule")


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
    variable = not isinstance(cfg.num_frames, int)
    diffusion = GaussianDiffusion(named_betas(cfg.schedule, cfg.num_diffusion_steps))
    model = Denoiser(cfg.model)
    frames = torch.cat([x_all[i, :n] for i, n in enumerate(train.lengths)])
    model.fit_prior(frames)
    ema = Denoiser(cfg.model)
    ema.load_state_dict(model.state_dict())
    ema.requires_grad_(False)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    history = {"step": [], "loss": [], "seconds": []}
    running, t0 = [], time.perf_counter()
    for step in tqdm(range(cfg.steps), desc=f"train denoiser ({cfg.dataset})", disable=not progress):
        for g in opt.param_groups:
            g["lr"] = _learning_rate(cfg, step)
        idx = torch.randint(0, len(x_all), (cfg.batch_size,), generator=gen)
        mask = mask_all[idx] if variable else None
        loss = diffusion.training_loss(model, x_all[idx], generator=gen, mask=mask)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
        opt.step()
        with torch.no_grad():
            decay = min(cfg.ema_decay, (1 + step) / (10 + step))
            for pe, pm in zip(ema.parameters(), model.parameters()):
                pe.lerp_(pm, 1 - decay)
        running.append(loss.item())
        if (step + 1) % log_every == 0 or step + 1 == cfg.steps:
            history["step"].append(step + 1)
            history["loss"].append(float(np.mean(running)))
            history["seconds"].append(time.perf_counter() - t0)
            running = []
    return ema.eval(), normalizer, history


def checkpoint_name(cfg):
    """Default checkpoint name: denoiser_<dataset>[_var]."""
    return f"denoiser_{cfg.dataset}" + ("" if isinstance(cfg.num_frames, int) else "_var")


def train_and_save(cfg, name=None, progress=True):
    """Train a denoiser and save it (state_dict + JSON config) in data/checkpoints; returns the paths."""
    model, normalizer, history = train_denoiser(cfg, progress=progress)
    training = asdict(cfg)
    training["num_frames"] = cfg.num_frames if isinstance(cfg.num_frames, int) else list(cfg.num_frames)
    return save_checkpoint(name or checkpoint_name(cfg), model, "denoiser", asdict(cfg.model),
                           training=training, normalizer=normalizer.to_dict(), history=history,
                           torch_version=torch.__version__, data_dir=str(config.SYNTHETIC_DIR.name))
