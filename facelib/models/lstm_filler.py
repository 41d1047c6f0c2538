"""A learned filling baseline in the spirit of Berson et al. (2020, paper 002): a bidirectional LSTM
trained with random masks to regenerate the missing frames of an animation.

As in their generator: 2 bidirectional LSTM layers of 128 units, dropout 0.3, a dense output
layer; per frame the input is the masked animation (1 - M) * X, the mask and one N(0, 1) noise
value.  Their GAN critic is left out (optional in the issue): the model is trained with the
reconstruction loss of their Eq. 1 alone,

    L_feat = alpha_gt (1 - M) |G(X_i) - X| + M |G(X_i) - X|,     alpha_gt = 10 (their value),

with M = 1 on the missing frames.  Our one change, for the landmark space: the network predicts a
correction to the mean of the known frames (mean imputation), so the anatomy given by the known
frames is kept without having to be relearned.  Frames are in the denoiser's normalised space.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn


@dataclass
class LSTMFillerConfig:
    num_landmarks: int = 68
    hidden: int = 128
    layers: int = 2
    dropout: float = 0.3


class LSTMFiller(nn.Module):
    """G(X_i): (masked sequence, mask, noise) -> the whole sequence (B, F, 68, 3)."""

    def __init__(self, config=LSTMFillerConfig()):
        super().__init__()
        self.config = config
        d = config.num_landmarks * 3
        self.lstm = nn.LSTM(d + 2, config.hidden, num_layers=config.layers, dropout=config.dropout,
                            bidirectional=True, batch_first=True)
        self.out = nn.Linear(2 * config.hidden, d)

    def forward(self, x, known, z=None, generator=None):
        """x: (B, F, 68, 3) (unknown frames ignored), known: (B, F) bool; returns (B, F, 68, 3)."""
        b, f = known.shape
        k = known.to(x.dtype)[:, :, None]
        flat = torch.where(known[:, :, None], x.flatten(2), torch.zeros((), dtype=x.dtype))
        mean = flat.sum(1, keepdim=True) / k.sum(1, keepdim=True)  # mean imputation, (B, 1, D)
        if z is None:
            z = torch.randn((b, f, 1), generator=generator, dtype=x.dtype)
        h, _ = self.lstm(torch.cat([flat - k * mean, k, z], dim=2))
        return (mean + self.out(h)).reshape(x.shape)


def masked_l1(prediction, target, known, alpha_gt=10.0):
    """Berson et al. Eq. 1: alpha_gt |G - X| on the known frames + |G - X| on the missing ones
    (each a mean over its frames' coordinates)."""
    err = (prediction - target).abs().flatten(2).mean(2)  # (B, F)
    k = known.to(err.dtype)
    return alpha_gt * (err * k).sum() / k.sum().clamp(min=1) + (err * (1 - k)).sum() / (1 - k).sum().clamp(min=1)


@dataclass(frozen=True)
class LSTMFillerTraining:
    """How the shipped ``lstm_filler_<dataset>`` is trained (Berson et al.: Adam, lr 1e-3)."""

    dataset: str = "coma"
    steps: int = 1500  # our choice: ~9 min on one CPU core (a 2x40-step BiLSTM is sequential)
    batch_size: int = 64
    lr: float = 1e-3
    alpha_gt: float = 10.0
    seed: int = 0


def random_masks(n, num_frames, generator):
    """Training masks (n, F) bool, True = known: a quarter each of FFB, FFE and FFM layouts (§5.3)
    and of one missing segment of random position and length (Berson et al.'s random gaps)."""
    from ..inpainting import FILL_SETTINGS, fill_masks
    kind = torch.randint(0, 4, (n,), generator=generator)
    seed = int(torch.randint(0, 2**31 - 1, (1,), generator=generator))
    masks = [torch.as_tensor(fill_masks(s, n, num_frames, seed + i)) for i, s in enumerate(FILL_SETTINGS)]
    start = torch.randint(1, num_frames - 2, (n, 1), generator=generator)
    length = torch.randint(2, num_frames // 2, (n, 1), generator=generator)
    f = torch.arange(num_frames)[None]
    masks.append(~((f >= start) & (f < (start + length).clamp(max=num_frames - 1))))
    return torch.stack(masks)[kind, torch.arange(n)]


def train_lstm_filler(cfg=LSTMFillerTraining(), progress=True, log_every=50):
    """Train the filler on the training split with random masks and Eq. 1; returns (model, history)."""
    from tqdm import tqdm

    from .. import data
    from ..training_log import TrainingLog
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    train = data.load_dataset(cfg.dataset, "train")
    normalizer = data.LandmarkNormalizer.fit(train)
    x_all = torch.as_tensor(normalizer.normalize(train.landmarks))
    model = LSTMFiller()
    model.normalizer = normalizer
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    log = TrainingLog(cfg.steps, log_every, "loss")
    model.train()
    for step in tqdm(range(cfg.steps), desc=f"train LSTM filler ({cfg.dataset})", disable=not progress):
        x = x_all[torch.randint(0, len(x_all), (cfg.batch_size,), generator=gen)]
        known = random_masks(cfg.batch_size, x.shape[1], gen)
        loss = masked_l1(model(x, known, generator=gen), x, known, cfg.alpha_gt)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        log.add(step, loss=loss.item())
    return model.eval(), log.history
