"""A 2-D toy for the DDPM chapter: a smiley-face point cloud and a small MLP noise
predictor.

The same :class:`~facelib.diffusion.GaussianDiffusion` that drives the landmark model
works on any tensor shape, so a 2-D toy trained in seconds shows the whole DDPM: the
forward process dissolving the data, the reverse process re-creating it.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from .models.bit import sinusoidal_embedding


def smiley(n, seed=0, noise=0.025):
    """n points (n, 2) float32 on a smiley: outline (40 %), two eyes (15 % each), a
    smile (30 %)."""
    rng = np.random.default_rng(seed)
    part = rng.choice(4, size=n, p=[0.4, 0.15, 0.15, 0.3])
    angle = rng.uniform(0, 2 * np.pi, n)
    pts = np.stack([np.cos(angle), np.sin(angle)], 1)  # outline, radius 1
    eye = 0.08 * np.sqrt(rng.uniform(0, 1, n))[:, None] * pts
    pts = np.where((part == 1)[:, None], eye + [-0.35, 0.35], pts)
    pts = np.where((part == 2)[:, None], eye + [0.35, 0.35], pts)
    smile = rng.uniform(np.pi * 1.2, np.pi * 1.8, n)
    pts = np.where(
        (part == 3)[:, None],
        0.55 * np.stack([np.cos(smile), np.sin(smile)], 1) + [0, 0.05],
        pts,
    )
    return (pts + noise * rng.standard_normal((n, 2))).astype(np.float32)


class ToyDenoiser(nn.Module):
    """eps_theta(x_t, t) for 2-D points: an MLP whose every hidden layer also sees the
    step t.

    The coordinates enter raw and through sinusoidal (Fourier) features: a plain MLP is
    biased towards smooth functions and cannot follow the sharp noise estimate of the
    last steps.
    """

    def __init__(
        self, hidden=128, depth=3, time_dim=32, coord_dim=32, coord_scale=10.0
    ):
        super().__init__()
        self.time_dim, self.coord_dim, self.coord_scale = (
            time_dim,
            coord_dim,
            coord_scale,
        )
        self.inp = nn.Linear(2 + 2 * coord_dim, hidden)
        self.time = nn.ModuleList(nn.Linear(time_dim, hidden) for _ in range(depth))
        self.hidden = nn.ModuleList(nn.Linear(hidden, hidden) for _ in range(depth - 1))
        self.out = nn.Linear(hidden, 2)

    def forward(self, xt, t, mask=None):
        emb = sinusoidal_embedding(t, self.time_dim)
        coords = torch.cat(
            [
                xt,
                sinusoidal_embedding(self.coord_scale * xt, self.coord_dim).flatten(-2),
            ],
            dim=-1,
        )
        h = nn.functional.silu(self.inp(coords) + self.time[0](emb))
        for layer, time in zip(self.hidden, self.time[1:]):
            h = nn.functional.silu(layer(h) + time(emb))
        return self.out(h)


def train_toy(
    diffusion, points, steps=3000, batch_size=512, lr=2e-3, seed=0, progress=True
):
    """Train a ToyDenoiser on ``points`` (n, 2) with the simple loss (Eq. 8); returns
    (model, losses)."""
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    x = torch.as_tensor(points)
    model = ToyDenoiser()
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    losses = []
    for _ in tqdm(range(steps), desc="train toy", disable=not progress):
        loss = diffusion.training_loss(
            model,
            x[torch.randint(0, len(x), (batch_size,), generator=gen)],
            generator=gen,
        )
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        losses.append(loss.item())
    return model.eval(), np.array(losses)
